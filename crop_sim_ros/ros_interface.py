"""The simulator node's ROS interface in one place: names, QoS, message fillers and readers.

Used by the simulator node (which publishes) and by the agent node, the Gymnasium bridge and the tests
(which read), so that a layout is written once. No science here: it only puts numbers into messages and back.
The state topics, the step result, the services and the action are the typed interfaces of the
``crop_sim_interfaces`` package (``ros2 interface show crop_sim_interfaces/msg/CropState``): named fields with
their units, stamped in farm time (sowing date 00:00 UTC + day days) with the field as ``header.frame_id``
(the simulator's namespace, ``field7`` under ``/field7``; ``farm`` at the root). The RL observation stays a
``std_msgs/Float32MultiArray`` (a learner's vector, exactly as the Gymnasium env gives it). The irrigation
command (crop_sim_interfaces/msg/IrrigationCommand) is stamped with the farm time of the day it is for and
addressed to the field; its fate comes back as an IrrigationStatus. The node's status is diagnostic_msgs'.

Names are relative to the simulator node (``~/...``, default node name ``crop_sim``), so
``-r __ns:=/field7`` or ``-r __node:=...`` runs several farms side by side. Two names are global: ``/clock``
(the ROS time source: farms side by side each publish their own with ``-p clock_topic:=clock``, i.e.
``/field7/clock``, or none with ``-p clock_topic:=''``) and ``/diagnostics`` (each node's status is named after
the node, so farms side by side share it as every ROS node does).

==================================== ============================== ==========================================
Name                                 Type                           Content
==================================== ============================== ==========================================
``~/step`` (service)                 crop_sim_interfaces/srv/Step   today's irrigation_mm (day, episode: -1
                                                                    = the current) in; the day's StepResult
                                                                    and the new observation out
``~/reset`` (service)                crop_sim_interfaces/srv/Reset  scenario ('' = the parameter), seed,
                                                                    weather_season (-2 = the parameter, -1 =
                                                                    draw) in; FarmTerms and day 0's
                                                                    observation out
``~/observation``                    std_msgs/Float32MultiArray     the observation, float32 exactly as the
                                                                    Gymnasium env gives it: 20 values (the
                                                                    paper's task) or 29 (a family task), the
                                                                    labels from the scenario's layout
``~/crop_state``                     crop_sim_interfaces/CropState  the day's sensed crop: biomass t/ha, PAW
                                                                    mm (NaN: no reading), thermal time degC
                                                                    d; canopy fsolar and maturity (model
                                                                    state, monitoring only)
``~/weather/today``                  crop_sim_interfaces/Weather    the day's TMAX, TMIN, TAVG degC, RAIN mm,
                                                                    SRAD MJ m-2, CO2 ppm, VAP hPa, WIND m/s
``~/weather/forecast``               crop_sim_interfaces/Forecast   tomorrow's noisy forecast of the same 8
                                                                    and the noise SD of each
``~/step_result``                    crop_sim_interfaces/StepResult after each step (and day 0 after a reset):
                                                                    irrigation mm applied and requested,
                                                                    reward, return, reward_unit, terminated,
                                                                    truncated, yield t/ha, command sequence
``~/farm_terms``                     crop_sim_interfaces/FarmTerms  at each reset: scenario, seed, weather,
                                                                    tuber price USD/t, water cost USD/mm,
                                                                    event cost USD, quota mm, capacity mm/d,
                                                                    action bound mm, potential yield t/ha
``/clock`` (parameter clock_topic)   rosgraph_msgs/Clock            farm time: sowing date 00:00 UTC + day
``~/irrigation`` (subscribed)        crop_sim_interfaces/IrrigationCommand  the day's command: day, irrigation
                                                                    mm, episode (-1 = any); header: farm
                                                                    time of the day (0 = unchecked), the
                                                                    field ('' = any)
``~/irrigation_step`` (subscribed)   crop_sim_interfaces/IrrigationCommand  the same command, and step at once
                                                                    (lockstep): one round trip per day
``~/irrigation_status``              crop_sim_interfaces/IrrigationStatus  each command's fate: ACCEPTED,
                                                                    REFUSED (why), or CUT after a step whose
                                                                    command the capacity or the quota cut
                                                                    (mm applied); the command as received,
                                                                    its sequence
``/diagnostics``                     diagnostic_msgs/DiagnosticArray   the node's status (one DiagnosticStatus
                                                                    named ``<node>: farm``): days without a
                                                                    command, commands received / accepted /
                                                                    rejected, season-log rows written / lost
                                                                    (level WARN, ERROR); every second and at
                                                                    once on a change (rqt_robot_monitor and
                                                                    the diagnostic aggregator read it)
``<agent>/run_season`` (action)      crop_sim_interfaces/action/RunSeason  served by the agent node: scenario,
                                                                    seed, policy in; a StepResult per day
                                                                    as feedback; yield, water, return out
==================================== ============================== ==========================================

``day`` is the number of days since sowing of the state the message describes (0 after a reset); the
observation carries it at index 2. Values that come from the observation (biomass, thermal time, PAW, today's
weather, forecast) are the observation's float32 values widened to float64, so they equal the observation
exactly.

The observation's layout is the scenario's (:mod:`crop_sim_ros.task.layout`): the paper's 20 values, or the
task family's 29 (the same 20, then prices, quota left, days left, capacity, whether PAW was read, yesterday's
irrigation, ET0). A scenario change at a reset changes the size and labels of the next observation; readers
take the layout from the message's size (:func:`observation_from_message`). In a family task the PAW sensor
may miss a day (``paw_observed`` 0, the observation's PAW 0): CropState then carries ``paw_mm`` NaN and
``paw_observed`` false.

Reward units (StepResult's ``reward_unit``): the paper's task pays t/ha (dry yield at harvest minus
``irrigation_cost_per_mm`` x mm); a family task pays net return in USD/ha. ``~/farm_terms`` (latched) gives
the season's terms, drawn at each reset: the fresh tuber price (USD/t), water cost (delivered water + pumping
energy, USD per mm on one ha), the fixed cost of a day with irrigation (USD/ha), the season's water quota (mm;
+inf = none) and the most the system applies in a day (mm/d; the action bound when unlimited). A paper-task
scenario has no money terms: price, water cost and event cost are NaN there.

QoS (explicit, see the constants below): the state topics (observation, farm_terms, crop_state, weather,
step_result) and /diagnostics are reliable + transient_local with depth 1, so a subscriber that joins late
still gets the latest day (a volatile reader, as the diagnostic aggregator's, matches too). ``/clock`` has
the QoS of ROS time sources (best effort, volatile, depth 1: what rclpy's and rclcpp's ``use_sim_time``
subscribe with), so a node that starts later reads farm time from the next step on. Commands and their status are reliable + volatile (a command is for one day; a late-joining
simulator must not apply an old one); the simulator's command subscriptions keep all messages, so a burst
is queued, never overwritten; clients publish with depth 10 (or keep-all for bursts of their own).
"""

from __future__ import annotations

import math
from datetime import date, datetime, timezone

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from crop_sim_interfaces.msg import (CropState, FarmTerms, Forecast, IrrigationCommand, IrrigationStatus, StepResult,
                                     Weather)
from std_msgs.msg import Float32MultiArray, Header, MultiArrayDimension

from .session import Command, farm_time_ns
from .task.layout import (BIOMASS, DAY, FORECAST, PAPER, PAW, PAW_OBSERVED, THERMAL_TIME, TODAY, WEATHER_NAMES,
                          ObservationLayout, layout_of_size)

NODE_NAME = "crop_sim"

STEP_SERVICE = "step"
RESET_SERVICE = "reset"
OBSERVATION_TOPIC = "observation"
CROP_STATE_TOPIC = "crop_state"
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
OBS_THERMAL_TIME = THERMAL_TIME

# The season's money terms and limits in FarmSession.terms order (crop_sim_interfaces/msg/FarmTerms's fields).
TERM_FIELDS = ("tuber_price_usd_per_t", "water_cost_usd_per_mm", "event_cost_usd", "quota_mm", "capacity_mm_per_day")
# Forecast's noise SD fields, in WEATHER_NAMES order: tmax_degc -> tmax_sd_degc, wind_m_s -> wind_sd_m_s.
FORECAST_SD_FIELDS = tuple("_sd_".join(name.split("_", 1)) for name in WEATHER_NAMES)

# --- the typed state messages (crop_sim_interfaces) -----------------------------------------------------------

def field_frame(namespace: str) -> str:
    """header.frame_id of a simulator's messages: the field, i.e. its namespace without the leading ``/``
    (``/field7`` -> ``field7``), ``farm`` for a simulator at the root."""
    return namespace.strip("/") or "farm"


def stamped(message, frame_id: str):
    """``message`` (a crop_sim_interfaces message) with header.frame_id set; returns it."""
    message.header.frame_id = frame_id
    return message


def fill_crop_state(message: CropState, stamp: Time, episode: int, day: int, wide: list[float], fsolar: float,
                    mature: bool) -> CropState:
    """``message`` now carries the day's crop state: ``wide`` is the observation widened to float64 (exact); a
    family task's missing PAW reading (paw_observed 0) is NaN, not a PAW of 0 mm."""
    read = len(wide) == PAPER.size or wide[OBS_PAW_OBSERVED] > 0.5
    message.header.stamp = stamp
    message.episode, message.day = episode, day
    message.biomass_t_ha, message.thermal_time_degc_d = wide[OBS_BIOMASS], wide[OBS_THERMAL_TIME]
    message.paw_mm, message.paw_observed = (wide[OBS_PAW] if read else math.nan), read
    message.canopy_fsolar, message.mature = float(fsolar), bool(mature)
    return message


def fill_weather(message: Weather, stamp: Time, day: int, values: list[float]) -> Weather:
    """``message`` now carries the weather of ``day`` (the 8 values in WEATHER_NAMES order)."""
    message.header.stamp = stamp
    message.day = day
    for name, value in zip(WEATHER_NAMES, values):
        setattr(message, name, value)
    return message


def forecast_noise(message: Forecast, noise) -> Forecast:
    """``message``'s noise SDs from the scenario's ObservationNoise (set at each reset)."""
    for field, name in zip(FORECAST_SD_FIELDS, WEATHER_NAMES):
        setattr(message, field, float(getattr(noise, name)))
    return message


def weather_of(message: Weather) -> list[float]:
    """The 8 values of a Weather message in WEATHER_NAMES order (the observation's)."""
    return [getattr(message, name) for name in WEATHER_NAMES]


def stamp_date(stamp: Time) -> str:
    """The farm date (ISO) of a farm-time stamp."""
    return datetime.fromtimestamp(stamp.sec, timezone.utc).date().isoformat()


def step_summary(result: StepResult, observation=None) -> dict:
    """A StepResult (topic or Step reply) as the dict the Gymnasium bridge gives as ``info`` (``return``: the
    season's return so far; ``date``: the new day's farm date); with ``observation``, its values as floats."""
    summary = {"episode": result.episode, "day": result.day, "irrigation_mm": result.irrigation_mm,
               "reward": result.reward, "terminated": result.terminated, "truncated": result.truncated,
               "yield_t_ha": result.yield_t_ha, "return": result.episode_return,
               "command_sequence": result.command_sequence, "date": stamp_date(result.header.stamp),
               "irrigation_requested_mm": result.irrigation_requested_mm, "reward_unit": result.reward_unit}
    if observation is not None:
        summary["observation"] = [float(v) for v in observation]
    return summary


def reset_summary(terms: FarmTerms, observation) -> dict:
    """A Reset reply's terms and observation as the dict the Gymnasium bridge gives as ``info`` (farm terms
    NaN/inf as None, as JSON would have them)."""
    observation = [float(v) for v in observation]
    return {"episode": terms.episode, "day": int(observation[OBS_DAY]), "date": terms.sowing_date,
            "scenario": terms.scenario, "seed": None if terms.seed < 0 else terms.seed,
            "weather_season": terms.weather_season, "weather_source": terms.weather_source,
            "site_climate": terms.site_climate or None, "max_irrigation_mm": terms.max_irrigation_mm,
            "potential_yield_t_ha": terms.potential_yield_t_ha, "reward_unit": terms.reward_unit,
            "yield_value_per_t": terms.yield_value_per_t,
            "farm_terms": {name: (value if math.isfinite(value) else None)
                           for name in TERM_FIELDS for value in [getattr(terms, name)]},
            "observation_size": len(observation), "observation": observation}


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


def sim_time(sowing: date, day: int) -> Time:
    """Farm time of ``day``: midnight UTC of the sowing date plus ``day`` days."""
    return Time(sec=farm_time_ns(sowing, day) // 10**9, nanosec=0)


def command_of(message: IrrigationCommand) -> Command:
    """What the simulator checks of a received IrrigationCommand (plain Python, for the FarmSession)."""
    stamp = message.header.stamp
    return Command(message.day, message.irrigation_mm, message.episode, stamp.sec * 10**9 + stamp.nanosec,
                   message.header.frame_id)


def command_message(command: Command) -> IrrigationCommand:
    """A Command back as the IrrigationCommand it came as (for its IrrigationStatus)."""
    stamp = Time(sec=command.stamp_ns // 10**9, nanosec=command.stamp_ns % 10**9)
    return IrrigationCommand(header=Header(stamp=stamp, frame_id=command.field), day=command.day,
                             irrigation_mm=command.mm, episode=command.episode)


def status_message(fate: int, text: str, command: Command, sequence: int, header: Header, episode: int,
                   current_day: int, applied_mm: float = math.nan) -> IrrigationStatus:
    """The fate of one irrigation command: IrrigationStatus.ACCEPTED, REFUSED, or CUT (``applied_mm``: what the
    step applied); ``header``: the simulator's current day in farm time and its field."""
    return IrrigationStatus(header=header, fate=fate, message=text, sequence=sequence, episode=episode,
                            current_day=current_day, command=command_message(command), applied_mm=applied_mm)


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
