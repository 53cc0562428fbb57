"""The simulator node's ROS interface in one place: names, QoS, message layouts, encoders and decoders.

Used by the simulator node (which publishes) and by the agent node, the Gymnasium bridge and the tests
(which read), so that a layout is written once. No science here: it only packs numbers into standard
messages and back. Only standard interfaces are used (std_msgs, std_srvs, rosgraph_msgs,
diagnostic_msgs), so stock ``ros2 topic echo`` shows every topic.

Names are relative to the simulator node (``~/...``, default node name ``crop_sim``), so
``-r __ns:=/field7`` or ``-r __node:=...`` runs several farms side by side. Two names are global: ``/clock``
(the ROS time source: farms side by side each publish their own with ``-p clock_topic:=clock``, i.e.
``/field7/clock``, or none with ``-p clock_topic:=''``) and ``/diagnostics`` (each node's status is named after
the node, so farms side by side share it as every ROS node does).

==================================== ============================== ==========================================
Name                                 Type                           Content
==================================== ============================== ==========================================
``~/step`` (service)                 std_srvs/Trigger               advance one day; message = JSON summary
``~/reset`` (service)                std_srvs/Trigger               new season (parameters ``scenario``,
                                                                    ``seed``, ...); message = JSON summary
``~/observation``                    std_msgs/Float32MultiArray     the observation, float32 exactly as the
                                                                    Gymnasium env gives it: 20 values (the
                                                                    paper's task) or 29 (a family task), the
                                                                    labels from the scenario's layout
``~/farm_terms``                     std_msgs/Float64MultiArray     at each reset: [episode, tuber price
                                                                    USD/t, water cost USD/mm, event cost USD,
                                                                    quota mm, capacity mm/d] (see below)
``~/biomass``                        std_msgs/Float64MultiArray     [day, noisy biomass t/ha]
``~/paw``                            std_msgs/Float64MultiArray     [day, noisy plant-available water mm];
                                                                    NaN when the day has no reading
``~/weather/today``                  std_msgs/Float64MultiArray     [day, TMAX, TMIN, TAVG, RAIN, SRAD, CO2,
                                                                    VAP, WIND] of the day
``~/weather/forecast``               std_msgs/Float64MultiArray     [day + 1, the same 8, noisy forecast]
``~/step_result``                    std_msgs/Float64MultiArray     [episode, day, irrigation mm, reward,
                                                                    terminated, truncated, yield t/ha,
                                                                    return, command sequence]; reward and
                                                                    return in the scenario's unit
``/clock`` (parameter clock_topic)   rosgraph_msgs/Clock            farm time: sowing date 00:00 UTC + day
``~/irrigation`` (subscribed)        std_msgs/Float64MultiArray     command [day, mm] or [day, mm, episode]
``~/irrigation_step`` (subscribed)   std_msgs/Float64MultiArray     the same command, and step at once
                                                                    (lockstep): one round trip per day
``~/irrigation_status``              diagnostic_msgs/DiagnosticStatus  each command's fate: level OK
                                                                    (accepted) or ERROR (rejected, why);
                                                                    WARN after a step whose command the
                                                                    capacity or the quota cut
``/diagnostics``                     diagnostic_msgs/DiagnosticArray   the node's status (one DiagnosticStatus
                                                                    named ``<node>: farm``): days without a
                                                                    command, commands received / accepted /
                                                                    rejected, season-log rows written / lost
                                                                    (level WARN, ERROR); every second and at
                                                                    once on a change (rqt_robot_monitor and
                                                                    the diagnostic aggregator read it)
==================================== ============================== ==========================================

``day`` is the number of days since sowing of the state the message describes (0 after a reset); the
observation carries it at index 2. Every Float64MultiArray has one dimension whose label lists the
values in order with their units, e.g. ``day[d],biomass_t_ha[t/ha]``. Values that come from the observation
(biomass, PAW, today's weather, forecast) are the observation's float32 values widened to float64, so they
equal the observation exactly.

The observation's layout is the scenario's (:mod:`crop_sim_ros.task.layout`): the paper's 20 values, or the
task family's 29 (the same 20, then prices, quota left, days left, capacity, whether PAW was read, yesterday's
irrigation, ET0). A scenario change at a reset changes the size and labels of the next observation; readers
take the layout from the message's size (:func:`observation_from_message`). In a family task the PAW sensor
may miss a day (``paw_observed`` 0, the observation's PAW 0): ``~/paw`` then carries NaN, not a reading.

Reward units (``~/step_result``, the JSON's ``reward_unit``): the paper's task pays t/ha (dry yield at
harvest minus ``irrigation_cost_per_mm`` x mm; labels ``reward[1]``, ``return[1]`` as ever); a family task
pays net return in USD/ha (labels ``reward[USD/ha]``, ``return[USD/ha]``). ``~/farm_terms`` (latched)
gives the season's terms, drawn at each reset: the fresh tuber price (USD/t), water cost (delivered water +
pumping energy, USD per mm on one ha), the fixed cost of a day with irrigation (USD/ha), the season's water
quota (mm; +inf = none) and the most the system applies in a day (mm/d; the action bound when unlimited).
A paper-task scenario has no money terms: price, water cost and event cost are NaN there.

QoS (explicit, see the constants below): the state topics (observation, farm_terms, biomass, paw, weather,
step_result) and /diagnostics are reliable + transient_local with depth 1, so a subscriber that joins late
still gets the latest day (a volatile reader, as the diagnostic aggregator's, matches too). ``/clock`` has
the QoS of ROS time sources (best effort, volatile, depth 1: what rclpy's and rclcpp's ``use_sim_time``
subscribe with), so a node that starts later reads farm time from the next step on. Commands and their status are reliable + volatile (a command is for one day; a late-joining
simulator must not apply an old one); the simulator's command subscriptions keep all messages, so a burst
is queued, never overwritten; clients publish with depth 10 (or keep-all for bursts of their own).
"""

from __future__ import annotations

import json
import math
from datetime import date, datetime, timezone
from typing import Generic, NamedTuple, TypeVar, get_type_hints

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float32MultiArray, Float64MultiArray, MultiArrayDimension

from .task.layout import BIOMASS, DAY, FORECAST, PAPER, PAW, PAW_OBSERVED, TODAY, ObservationLayout, layout_of_size

NODE_NAME = "crop_sim"

STEP_SERVICE = "step"
RESET_SERVICE = "reset"
OBSERVATION_TOPIC = "observation"
BIOMASS_TOPIC = "biomass"
PAW_TOPIC = "paw"
WEATHER_TODAY_TOPIC = "weather/today"
WEATHER_FORECAST_TOPIC = "weather/forecast"
STEP_RESULT_TOPIC = "step_result"
FARM_TERMS_TOPIC = "farm_terms"
IRRIGATION_TOPIC = "irrigation"
IRRIGATION_STEP_TOPIC = "irrigation_step"
IRRIGATION_STATUS_TOPIC = "irrigation_status"
DIAGNOSTICS_TOPIC = "/diagnostics"
CLOCK_TOPIC = "/clock"  # the default of the clock_topic parameter

# State topics: the latest day survives for late subscribers.
STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
# Commands and command status: every message matters, none is replayed to a late joiner.
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
# The simulator's command subscriptions: keep every command until the node takes it (with depth 10, 69 of a
# burst of 1,000 arrived in a run here: the rest were overwritten while the node was busy). A publisher's own
# depth-10 queue can still drop a burst that outruns delivery on a loaded machine: a client that sends bursts
# publishes with this QoS too.
COMMAND_SUBSCRIPTION_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                                      durability=DurabilityPolicy.VOLATILE)
# The simulator's answers on ~/irrigation_status, one per command: a reliable writer drops from its history
# whatever exceeds the depth, acknowledged or not, so an answer that must be resent to a reader starved of CPU
# (a burst's answers outrun delivery) is lost at depth 10, as a client's depth-10 command queue lost its burst.
# Depth 1,000 keeps the answers of a burst of 1,000 commands for a lagging reader; keep-last, not keep-all, so a
# stuck reader can never block the simulator's publish.
COMMAND_STATUS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE)
# /clock: what ROS time sources subscribe with (rclpy's TimeSource and rclcpp's ClockQoS: best effort,
# volatile, depth 1). A transient-local publisher gave such a subscriber nothing more: it still read 0 until
# the next step.
CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)
# What a reader that must see every day (agent, bridge) uses on the state topics: reliable, volatile (no
# replay of a previous season's last day), a queue deep enough for a burst.
READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=50, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
# /diagnostics: the node's status, latched like the state topics (a late monitor gets it at once); the volatile
# readers of diagnostic_aggregator and rqt_robot_monitor match it too.
DIAGNOSTICS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
# A late joiner that wants the latest day at once (monitoring, tests).
LATCHED_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)
# A client of ~/step or ~/reset that shares the simulator with other clients. Every client of a ROS 2 service
# receives every response (rmw_fastrtps discards the other clients' ones when it takes them), so with the
# services' default depth of 10 a client that runs slower than the others loses its own response when more than
# 10 other answers arrive before it takes it (the day was stepped; the caller times out). Keep all responses.
SERVICE_CLIENT_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE)

# Observation labels: the layout's names and units (crop_sim_ros.task.layout), "name[unit]": the paper's task
# has PAPER's 20, a family task EXTENDED's 29 (layout.labels). Columns both share (EXTENDED starts with PAPER):
OBSERVATION_LABELS = PAPER.labels
OBS_BIOMASS, OBS_DAY, OBS_TODAY, OBS_FORECAST, OBS_PAW, OBS_PAW_OBSERVED = BIOMASS, DAY, TODAY, FORECAST, PAW, PAW_OBSERVED

Record = TypeVar("Record", bound=tuple)
_CASTS = {int: int, float: float, bool: lambda value: value == 1.0}


class ArrayCodec(Generic[Record]):
    """One Float64MultiArray layout, declared once: a NamedTuple's fields (typed ``int``, ``bool`` or ``float``)
    and, for each, its label ``name[unit]``; the message's labels, :meth:`message`/:meth:`fill` (record ->
    message) and :meth:`read` (message -> record) all derive from it. ``int`` and ``bool`` travel as float64
    (exact for whole numbers; a bool is 1.0 or 0.0)."""

    def __init__(self, record: type[Record], labels: tuple[str, ...]):
        if len(labels) != len(record._fields):
            raise ValueError(f"{record.__name__}: {len(record._fields)} fields, {len(labels)} labels")
        self.record, self.labels = record, tuple(labels)
        types = get_type_hints(record)
        self._casts = tuple(_CASTS[types[name]] for name in record._fields)

    def labelled(self) -> Float64MultiArray:
        """A new message with this layout's labels and no values yet (to :meth:`fill` day after day)."""
        message = Float64MultiArray()
        _layout(message, self.labels)
        return message

    def message(self, record: Record) -> Float64MultiArray:
        """A new labelled message carrying ``record``."""
        return self.fill(self.labelled(), record)

    def fill(self, message: Float64MultiArray, record: Record) -> Float64MultiArray:
        """``message`` (made by :meth:`labelled`, reused: publishing serialises at once) now carries ``record``."""
        message.data = [float(value) for value in record]
        return message

    def read(self, message: Float64MultiArray) -> Record:
        """The record a message carries; ValueError if it has another number of values than the fields."""
        values = message.data
        if len(values) != len(self._casts):
            raise ValueError(f"{self.record.__name__} message has {len(values)} values, expected "
                             f"{len(self._casts)} ({','.join(self.labels)})")
        return self.record(*(cast(value) for cast, value in zip(self._casts, values)))


class StepResult(NamedTuple):
    """~/step_result: the day a step produced (also the core of the step's JSON summary)."""
    episode: int
    day: int  # of the state after the step
    irrigation_mm: float  # applied (after capacity and quota)
    reward: float  # in the scenario's reward unit
    terminated: bool  # the crop matured
    truncated: bool
    yield_t_ha: float  # dry yield, 0 before maturity
    episode_return: float  # the season's return so far (JSON key "return")
    command_sequence: int  # the command applied (-1: none)

    def summary(self) -> dict:
        """The step JSON's keys for these values."""
        values = self._asdict()
        values["return"] = values.pop("episode_return")
        return values

    @classmethod
    def from_summary(cls, summary: dict) -> "StepResult":
        """The step JSON's values as a record (KeyError names a missing key)."""
        return cls(**{name: summary["return" if name == "episode_return" else name] for name in cls._fields})


class FarmTerms(NamedTuple):
    """~/farm_terms: the season's terms, drawn at each reset (NaN where the paper's task has none; inf: no limit)."""
    episode: int
    tuber_price_usd_per_t: float  # fresh tubers
    water_cost_usd_per_mm: float  # delivered water + pumping energy, per mm on one ha
    event_cost_usd: float  # per day with irrigation, per ha
    quota_mm: float  # the season's water quota
    capacity_mm_per_day: float  # the most the system applies in a day


class IrrigationCommand(NamedTuple):
    """~/irrigation and ~/irrigation_step: ``irrigation_mm`` for ``day``, valid only in ``episode`` (a command of
    two values, without the episode, is valid in any; the simulator checks what arrives, see FarmSession)."""
    day: int
    irrigation_mm: float
    episode: int


class BiomassReading(NamedTuple):
    """~/biomass: the day's noisy biomass (the observation's value)."""
    day: int
    biomass_t_ha: float


class PawReading(NamedTuple):
    """~/paw: the day's noisy plant-available water; NaN when the sensor gave no reading."""
    day: int
    paw_mm: float


WeatherToday = NamedTuple("WeatherToday", [("day", int)] + [(name, float) for name in PAPER.names[TODAY]])
WeatherToday.__doc__ = "~/weather/today: the day and its weather (the observation's values and units)."
WeatherForecast = NamedTuple("WeatherForecast", [("for_day", int)] + [(name, float) for name in PAPER.names[FORECAST]])
WeatherForecast.__doc__ = "~/weather/forecast: the noisy forecast for the next day (the observation's values)."

_STEP_RESULT_LABELS = ("episode[1]", "day[d]", "irrigation[mm]", "reward[1]", "terminated[0/1]", "truncated[0/1]",
                       "yield[t/ha]", "return[1]", "command_sequence[1]")
STEP_RESULT = ArrayCodec(StepResult, _STEP_RESULT_LABELS)
# A family task's reward and return are net return in USD/ha (crop_sim_ros.task.terms).
FAMILY_STEP_RESULT = ArrayCodec(StepResult, tuple(label.replace("[1]", "[USD/ha]")
                                                  if label.startswith(("reward", "return")) else label
                                                  for label in _STEP_RESULT_LABELS))
FARM_TERMS = ArrayCodec(FarmTerms, ("episode[1]", "tuber_price_usd_per_t[USD/t]", "water_cost_usd_per_mm[USD/mm]",
                                    "event_cost_usd[USD]", "quota_mm[mm]", "capacity_mm_per_day[mm/d]"))
IRRIGATION = ArrayCodec(IrrigationCommand, ("day[d]", "irrigation[mm]", "episode[1]"))
BIOMASS_READING = ArrayCodec(BiomassReading, ("day[d]", OBSERVATION_LABELS[BIOMASS]))
PAW_READING = ArrayCodec(PawReading, ("day[d]", OBSERVATION_LABELS[PAW]))
WEATHER_TODAY = ArrayCodec(WeatherToday, ("day[d]",) + OBSERVATION_LABELS[TODAY])
WEATHER_FORECAST = ArrayCodec(WeatherForecast, ("for_day[d]",) + OBSERVATION_LABELS[FORECAST])


STATUS_NAME = "crop_sim/irrigation"
# The node's status on /diagnostics is named "<fully qualified node name without the leading />: farm".
NODE_STATUS_SUFFIX = ": farm"
# The node's status values: counters are whole numbers, season_ended is "true"/"false", the others are text.
NODE_STATUS_COUNTERS = ("episode", "day", "days_without_command", "commands_received", "commands_accepted",
                        "commands_rejected", "log_rows_written", "log_rows_lost")
NODE_STATUS_KEYS = NODE_STATUS_COUNTERS + ("mode", "season_ended", "log_path", "log_error")


def _layout(message, labels) -> None:
    message.layout.dim = [MultiArrayDimension(label=",".join(labels), size=len(labels), stride=len(labels))]
    message.layout.data_offset = 0


def observation_message(observation) -> Float32MultiArray:
    """The observation (20 or 29 float32: the layout of its size) as a Float32MultiArray labelled with that
    layout; the values are not re-rounded. ValueError for a size no layout has."""
    message = Float32MultiArray()
    _layout(message, layout_of_size(len(observation)).labels)
    message.data = observation  # a float32 numpy array is copied as-is (no float64 round trip)
    return message


def observation_from_message(message, layout: ObservationLayout | None = None):
    """Float32MultiArray -> float32 numpy array of 20 or 29 values, bit for bit. ValueError for a size no layout
    has, or (``layout`` given) another size than that layout's."""
    import numpy as np  # noqa: PLC0415

    values = np.asarray(message.data, dtype=np.float32)
    if layout is not None and values.shape != (layout.size,):
        raise ValueError(f"observation message has {values.size} values, expected {layout.size}")
    if layout is None:
        layout_of_size(values.size)  # ValueError names the sizes that exist
    return values


def observation_layout(message) -> ObservationLayout:
    """The layout of an observation message (by its size); ValueError for a size no layout has."""
    return layout_of_size(len(message.data))


def step_result_codec(family_task: bool) -> ArrayCodec[StepResult]:
    """~/step_result's labels name the reward unit: t/ha-based ``[1]`` for the paper's task, USD/ha for a family task."""
    return FAMILY_STEP_RESULT if family_task else STEP_RESULT


def observation_list(observation) -> list[float]:
    """The float32 observation as JSON-ready floats (float64 widening is exact; JSON keeps float64 exactly)."""
    return [float(v) for v in observation]


def irrigation_command(day: int, mm: float, episode: int | None = None) -> Float64MultiArray:
    """A command for ``day`` (optionally only valid in ``episode``, the simulator's reset counter)."""
    if episode is None:  # the two-value form, valid in any episode
        message = Float64MultiArray()
        _layout(message, IRRIGATION.labels[:2])
        message.data = [float(day), float(mm)]
        return message
    return IRRIGATION.message(IrrigationCommand(day, mm, episode))


def sim_time(sowing: date, day: int) -> Time:
    """Farm time of ``day``: midnight UTC of the sowing date plus ``day`` days."""
    seconds = int(datetime(sowing.year, sowing.month, sowing.day, tzinfo=timezone.utc).timestamp()) + 86400 * day
    return Time(sec=seconds, nanosec=0)


def clock_message(sowing: date, day: int) -> Clock:
    return Clock(clock=sim_time(sowing, day))


def status_message(accepted: bool, text: str, day, mm, sequence: int, current_day: int,
                   applied_mm: float | None = None) -> DiagnosticStatus:
    """The fate of one irrigation command (values as repr strings: they parse back to the same floats). With
    ``applied_mm`` (after the step: the capacity or the quota cut the command), level WARN and the mm applied."""
    level = (DiagnosticStatus.ERROR if not accepted else DiagnosticStatus.OK if applied_mm is None
             else DiagnosticStatus.WARN)
    values = [KeyValue(key="day", value=repr(day)), KeyValue(key="irrigation_mm", value=repr(mm)),
              KeyValue(key="sequence", value=str(sequence)), KeyValue(key="current_day", value=str(current_day)),
              KeyValue(key="accepted", value="true" if accepted else "false")]
    if applied_mm is not None:
        values.append(KeyValue(key="applied_mm", value=repr(applied_mm)))
    return DiagnosticStatus(level=level, name=STATUS_NAME, message=text, hardware_id="", values=values)


def status_values(message: DiagnosticStatus) -> dict:
    """DiagnosticStatus of a command -> {"day", "irrigation_mm", "sequence", "current_day", "accepted", "message",
    "applied_mm" (NaN unless the status reports a cut command)}."""
    values = {kv.key: kv.value for kv in message.values}
    out = {"accepted": values.get("accepted") == "true", "message": message.message}
    for key in ("day", "irrigation_mm", "applied_mm"):
        try:
            out[key] = float(values.get(key, "nan"))
        except ValueError:
            out[key] = math.nan
    for key in ("sequence", "current_day"):
        out[key] = int(values.get(key, "-1"))
    return out


def summary_json(summary: dict) -> str:
    """A step/reset summary as compact JSON (floats as repr: they parse back exactly; NaN/inf as null)."""
    def clean(v):
        if isinstance(v, float) and not math.isfinite(v):
            return None
        return v
    return json.dumps({k: clean(v) for k, v in summary.items()}, separators=(",", ":"))


def node_status_name(node_name: str) -> str:
    """The name of the status of the simulator whose fully qualified name is ``node_name`` on /diagnostics:
    ``/crop_sim`` -> ``crop_sim: farm``, ``/field7/crop_sim`` -> ``field7/crop_sim: farm``."""
    return node_name.lstrip("/") + NODE_STATUS_SUFFIX


def node_status_message(level: bytes, text: str, values: dict, name: str = node_status_name("/" + NODE_NAME)
                        ) -> DiagnosticStatus:
    """The node's status: ``level`` one of DiagnosticStatus.OK / WARN / ERROR, ``values`` every key of
    NODE_STATUS_KEYS (counters as whole numbers, season_ended as a bool), ``name`` :func:`node_status_name`."""
    def text_of(value):
        return ("true" if value else "false") if isinstance(value, bool) else str(value)
    return DiagnosticStatus(level=level, name=name, message=text, hardware_id="",
                            values=[KeyValue(key=key, value=text_of(values[key])) for key in NODE_STATUS_KEYS])


def diagnostics_message(stamp: Time, statuses: list[DiagnosticStatus]) -> DiagnosticArray:
    """What goes on /diagnostics: ``statuses`` stamped ``stamp`` (the node's clock: farm time under use_sim_time)."""
    message = DiagnosticArray(status=statuses)
    message.header.stamp = stamp
    return message


def node_statuses(message: DiagnosticArray, node_name: str) -> list[dict]:
    """The statuses of the simulator ``node_name`` (fully qualified) in a /diagnostics message, as
    :func:`node_status_values` reads them (other nodes' statuses are left out)."""
    name = node_status_name(node_name)
    return [node_status_values(status) for status in message.status if status.name == name]


def node_status_values(message: DiagnosticStatus) -> dict:
    """The node's status -> {"level": 0 OK / 1 WARN / 2 ERROR, "message", and every key of NODE_STATUS_KEYS}."""
    values = {kv.key: kv.value for kv in message.values}
    out = {"level": message.level[0] if isinstance(message.level, bytes) else int(message.level),
           "message": message.message, **{key: values.get(key, "") for key in NODE_STATUS_KEYS}}
    for key in NODE_STATUS_COUNTERS:
        out[key] = int(values.get(key, "-1"))
    out["season_ended"] = values.get("season_ended") == "true"
    return out


def set_up_or_destroy(node, set_up) -> None:
    """Run ``set_up()`` for a node under construction; if it fails, destroy the node before the error goes on
    (a half-built node must not outlive its context: the process would hang at exit)."""
    try:
        set_up()
    except BaseException:
        node.destroy_node()
        raise
