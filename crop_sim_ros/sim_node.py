"""The simulator node: one :class:`~crop_sim_ros.task.IrrigationEnv` served over ROS 2 (a thin adapter).

    ros2 run crop_sim_ros sim_node [--ros-args -p scenario:=benton-2000 -p seed:=3 ...]
    python -m crop_sim_ros.sim_node [--ros-args ...]        # the same without a ROS workspace

The node holds exactly the environment the offline users use and converts to and from standard messages;
it computes nothing of its own beyond bookkeeping (the episode counter, the pending command, the log).
Names, message layouts and QoS are in :mod:`crop_sim_ros.ros_interface`.

Day protocol (lockstep, the default)
------------------------------------
After a reset the field is on day 0 (the sowing day) and the node publishes day 0's observation. A client
publishes an irrigation command ``[day, mm]`` (or ``[day, mm, episode]``) on ``~/irrigation``, then calls
``~/step``: the node applies the latest command accepted for the current day, advances exactly one day, and
publishes the new day. Each command is applied at most once and only to the day it names:

- a command for a past day, a future day, another episode, or after the season ended is rejected;
- NaN, infinite, negative or over-limit (> the scenario's ``max_irrigation_mm``) amounts are rejected;
- rejected commands are logged and reported on ``~/irrigation_status`` (level ERROR, with the reason);
  accepted ones are reported too (level OK), so a client can wait for the acknowledgement before it calls
  ``~/step`` (the command topic and the step service are separate channels: without that wait a step
  could overtake the command);
- a step with no accepted command for the day applies 0 mm.

A client that drives the season can do both in one message: a command on ``~/irrigation_step`` is validated
the same way and, if accepted, the day is stepped at once (one topic round trip per day; the outcome is on
``~/step_result`` and ``~/observation``; a repeated message cannot step twice, its day being past by then).

The ``~/step`` response (std_srvs/Trigger) message is a JSON summary of the new day: episode, day, date,
irrigation_mm, reward, return, terminated, truncated, yield_t_ha, command_sequence and the observation (the
float32 values as exact decimals); ``~/reset`` answers likewise (episode, day 0, scenario, seed, weather,
observation). A refusal is ``success: false`` with ``{"error": ...}``; the state is then unchanged.

Commands, steps, resets and the free-running timer all run on one single-threaded executor, and every
state change is also taken under one lock, so a command and a step never interleave. After a step, the
observation and ``~/step_result`` are published at once; the other topics (biomass, PAW, weather, /clock)
right after the callback has returned (so the caller waiting for the step waits less), always in day order.

Season log
----------
One CSV row per simulated day (appended, flushed after every row: killing the node loses nothing it has
simulated): the observation the day started with, the irrigation applied, the reward, the day's water
fluxes and the true state at the end of the day. A restarted node appends under a new ``run_id``.

Parameters: see :data:`PARAMETERS` (``ros2 param describe /crop_sim <name>``). Changes of ``scenario``,
``data_dir``, ``crop``, ``cultivar``, ``soil``, ``co2_ppm``, ``noise_scale``, ``irrigation_cost_per_mm``,
``seed``, ``weather_season`` and ``log_path`` take effect at the next reset; ``mode`` and ``days_per_second``
at once. Every change is validated first (an unknown scenario or crop is refused, not stored).
"""

from __future__ import annotations

import csv
from collections import deque
import math
import os
import socket
import sys
import threading
from dataclasses import dataclass, fields, replace
from datetime import date, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import rclpy
import rclpy.parameter
from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType,
                                SetParametersResult)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float32MultiArray, Float64MultiArray
from std_srvs.srv import Trigger

from . import ros_interface as ri
from .task import IrrigationEnv, ObservationNoise, get_scenario, load_scenario
from .task.scenario import Scenario

MODES = ("lockstep", "free_running")
INT32_MAX = 2**31 - 1


def _string(description: str, constraints: str = "") -> ParameterDescriptor:
    return ParameterDescriptor(type=ParameterType.PARAMETER_STRING, description=description,
                               additional_constraints=constraints)


def _double(description: str, low: float, high: float, constraints: str = "") -> ParameterDescriptor:
    return ParameterDescriptor(type=ParameterType.PARAMETER_DOUBLE, description=description,
                               additional_constraints=constraints,
                               floating_point_range=[FloatingPointRange(from_value=low, to_value=high, step=0.0)])


def _integer(description: str, low: int, high: int) -> ParameterDescriptor:
    return ParameterDescriptor(type=ParameterType.PARAMETER_INTEGER, description=description,
                               integer_range=[IntegerRange(from_value=low, to_value=high, step=1)])


# name -> (default, descriptor)
PARAMETERS = {
    "scenario": ("benton-generated", _string(
        "built-in scenario name (benton-generated, benton-2000, paterson-1992..1995, heldout) or the path of "
        "a scenario YAML file; applied at the next reset", "must load: unknown names and bad files are refused")),
    "data_dir": ("", _string("directory of the scenario weather files ('' = ../shared/data beside the "
                             "repository); applied at the next reset")),
    "seed": (0, _integer("seed of every reset (weather draw and all noise); -1 = do not reseed: continue the "
                         "random stream like Gymnasium's reset(seed=None)", -1, INT32_MAX)),
    "weather_season": (-1, _integer("index of the scenario's season to grow at the next resets; -1 = drawn "
                                    "with the seed", -1, INT32_MAX)),
    "crop": ("", _string("crop override ('' = the scenario's), e.g. potato", "a crop of the parameter library")),
    "cultivar": ("", _string("cultivar override ('' = the scenario's), e.g. Russet Burbank")),
    "soil": ("", _string("soil override ('' = the scenario's), e.g. Benton USA potato")),
    "co2_ppm": (-1.0, _double("atmospheric CO2 override, ppm (-1 = the scenario's)", -1.0, 5000.0,
                              "-1 or 0..5000")),
    "noise_scale": (1.0, _double("factor on every observation noise standard deviation of the scenario "
                                 "(0 = exact observations)", 0.0, 100.0)),
    "irrigation_cost_per_mm": (-1.25e-4, _double("reward per mm irrigated (C_I; <= 0)", -1.0, 0.0)),
    "mode": ("lockstep", _string("lockstep: one day per ~/step call; free_running: the node steps by itself, "
                                 "days_per_second days per second of wall time (~/step is then refused)",
                                 "lockstep | free_running")),
    "days_per_second": (5.0, _double("free_running: simulated days per second of wall time", 0.01, 1000.0)),
    "log_path": ("", _string("season log CSV, one row per day, appended and flushed daily ('' = "
                             "$ROS_HOME/crop_sim/season_log.csv, ROS_HOME defaulting to ~/.ros); applied at "
                             "the next reset")),
}
# Parameters that define the environment (a change rebuilds it at the next reset).
ENV_PARAMETERS = ("scenario", "data_dir", "crop", "cultivar", "soil", "co2_ppm", "noise_scale",
                  "irrigation_cost_per_mm")


class StartupError(RuntimeError):
    """The node cannot start with its parameters (unknown scenario or crop, unreadable weather, ...)."""


@dataclass(frozen=True)
class EnvConfig:
    scenario: str
    data_dir: str
    crop: str
    cultivar: str
    soil: str
    co2_ppm: float
    noise_scale: float
    irrigation_cost_per_mm: float


def build_scenario(config: EnvConfig) -> Scenario:
    """The Scenario of ``config``: a built-in name or YAML path, with the overrides applied and the crop,
    cultivar and soil looked up (UnknownNameError, ValueError or FileNotFoundError on bad values)."""
    data_dir = config.data_dir or None
    name = config.scenario.strip()
    if not name:
        raise ValueError("scenario: empty name")
    if name.endswith((".yaml", ".yml")) or os.sep in name:
        scenario = load_scenario(Path(name).expanduser(), data_dir)
        for season in scenario.weather.seasons:
            scenario.season_path(season)
    else:
        scenario = get_scenario(name, data_dir)
    changes = {key: value for key, value in (("crop", config.crop), ("cultivar", config.cultivar),
                                             ("soil", config.soil)) if value}
    if config.co2_ppm >= 0:
        changes["co2_ppm"] = config.co2_ppm
    elif config.co2_ppm != -1.0:
        raise ValueError(f"co2_ppm: {config.co2_ppm} is neither -1 (the scenario's) nor in 0..5000 ppm")
    if config.noise_scale != 1.0:
        changes["noise"] = ObservationNoise(**{f.name: getattr(scenario.noise, f.name) * config.noise_scale
                                               for f in fields(ObservationNoise)})
    changes["irrigation_cost_per_mm"] = config.irrigation_cost_per_mm
    scenario = replace(scenario, **changes)
    scenario.field_parameters()  # UnknownNameError for an unknown crop, cultivar or soil
    return scenario


def default_log_path() -> Path:
    ros_home = os.environ.get("ROS_HOME") or os.path.join(os.path.expanduser("~"), ".ros")
    return Path(ros_home) / "crop_sim" / "season_log.csv"


OBS_COLUMNS = tuple(f"obs_{name}" for name in ri.OBSERVATION_NAMES)
LOG_COLUMNS = (("wall_time_utc", "run_id", "episode", "scenario", "seed", "weather_season", "day", "date")
               + OBS_COLUMNS
               + ("command_sequence", "irrigation_mm", "reward", "episode_return", "terminated", "truncated",
                  "rain_mm", "runoff_mm", "drainage_mm", "transpiration_mm", "et0_mm", "arid",
                  "end_true_biomass_t_ha", "end_true_paw_mm", "end_thermal_time_degc_d", "end_fsolar",
                  "end_yield_t_ha", "end_mature", "potential_yield_t_ha", "normalized_return"))


class SeasonLog:
    """Append-only CSV, one row per simulated day, flushed after each row."""

    def __init__(self, path: Path):
        self.path = Path(path).expanduser()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists() or self.path.stat().st_size == 0
        if not new:
            with open(self.path, newline="") as existing:
                header = next(csv.reader(existing), None)
            if header != list(LOG_COLUMNS):
                raise StartupError(f"season log {self.path} exists with other columns; choose another log_path")
        self._file = open(self.path, "a", newline="")
        self._writer = csv.writer(self._file)
        if new:
            self._writer.writerow(LOG_COLUMNS)
            self._file.flush()

    def write(self, row: dict) -> None:
        self._writer.writerow([_cell(row[column]) if column in row else "" for column in LOG_COLUMNS])
        self._file.flush()  # to the OS: survives the process being killed

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


def _cell(value) -> str:
    kind = type(value)
    if kind is float:
        return repr(value)
    if kind is bool or kind is np.bool_:
        return "1" if value else "0"
    if isinstance(value, np.floating):
        return repr(float(value))
    return str(value)


class SimNode(Node):
    """See the module docstring."""

    def __init__(self, node_name: str = ri.NODE_NAME, **kwargs):
        # no type-description service: one entity less for the executor to wait on per callback
        overrides = list(kwargs.pop("parameter_overrides", None) or [])
        overrides.append(rclpy.parameter.Parameter("start_type_description_service", value=False))
        super().__init__(node_name, parameter_overrides=overrides, **kwargs)
        try:
            self._setup()
        except BaseException:
            self.destroy_node()  # a half-built node must not outlive the context (a hang at exit)
            raise

    def _setup(self) -> None:
        self._lock = threading.RLock()
        for name, (default, descriptor) in PARAMETERS.items():
            self.declare_parameter(name, default, descriptor)
        problem = self._check({name: self.get_parameter(name).value for name in PARAMETERS})
        if problem:
            raise StartupError(problem)
        self._env_config = self._config()
        try:
            self._env = IrrigationEnv(build_scenario(self._env_config))
        except Exception as error:  # noqa: BLE001 - any failure here is a start-up configuration error
            raise StartupError(f"scenario {self._env_config.scenario!r}: {type(error).__name__}: {error}") from error
        self._max_mm = float(self._env.scenario.max_irrigation_mm)
        self._log_path = self._resolve_log_path()
        self._log = SeasonLog(self._log_path)
        self._run_id = f"{socket.gethostname()}-{os.getpid()}-{datetime.now(timezone.utc):%Y%m%dT%H%M%S}"

        # season bookkeeping (under self._lock)
        self._episode = 0
        self._day = 0
        self._ended = True
        self._end_reason = "no season yet"
        self._return = 0.0
        self._obs: np.ndarray | None = None
        self._seed_used: int | None = None
        self._info_season = -1
        self._sowing: date = date(2000, 1, 1)
        self._pending: tuple[int, float, int] | None = None  # (day, mm, sequence)
        self._sequence = 0

        # publishers (messages reused: publish() serialises at once)
        self._pub_obs = self.create_publisher(Float32MultiArray, "~/" + ri.OBSERVATION_TOPIC, ri.STATE_QOS)
        self._pub_biomass = self.create_publisher(Float64MultiArray, "~/" + ri.BIOMASS_TOPIC, ri.STATE_QOS)
        self._pub_paw = self.create_publisher(Float64MultiArray, "~/" + ri.PAW_TOPIC, ri.STATE_QOS)
        self._pub_today = self.create_publisher(Float64MultiArray, "~/" + ri.WEATHER_TODAY_TOPIC, ri.STATE_QOS)
        self._pub_forecast = self.create_publisher(Float64MultiArray, "~/" + ri.WEATHER_FORECAST_TOPIC, ri.STATE_QOS)
        self._pub_result = self.create_publisher(Float64MultiArray, "~/" + ri.STEP_RESULT_TOPIC, ri.STATE_QOS)
        self._pub_clock = self.create_publisher(Clock, ri.CLOCK_TOPIC, ri.STATE_QOS)
        self._pub_status = self.create_publisher(DiagnosticStatus, "~/" + ri.IRRIGATION_STATUS_TOPIC, ri.COMMAND_QOS)
        self._msg_obs = ri.observation_message(np.zeros(ri.OBS_SIZE, np.float32))
        self._msg_biomass = ri.float64_array(ri.BIOMASS_LABELS, (0, 0))
        self._msg_paw = ri.float64_array(ri.PAW_LABELS, (0, 0))
        self._msg_today = ri.float64_array(ri.WEATHER_TODAY_LABELS, [0] * 9)
        self._msg_forecast = ri.float64_array(ri.WEATHER_FORECAST_LABELS, [0] * 9)
        self._msg_result = ri.float64_array(ri.STEP_RESULT_LABELS, [0] * len(ri.STEP_RESULT_LABELS))
        self._deferred: deque = deque()

        self.create_subscription(Float64MultiArray, "~/" + ri.IRRIGATION_TOPIC, self._on_irrigation, ri.COMMAND_QOS)
        self.create_subscription(Float64MultiArray, "~/" + ri.IRRIGATION_STEP_TOPIC, self._on_irrigation_step,
                                 ri.COMMAND_QOS)
        self.create_service(Trigger, "~/" + ri.STEP_SERVICE, self._on_step)
        self.create_service(Trigger, "~/" + ri.RESET_SERVICE, self._on_reset)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self._timer = None
        self._configure_timer()

        ok, message = self._reset()
        if not ok:
            raise StartupError(message)
        self.get_logger().info(
            f"ready: scenario {self._env.scenario.name!r}, mode {self._mode()}, max irrigation {self._max_mm:g} mm, "
            f"log {self._log_path}")

    # --- parameters --------------------------------------------------------------------------------------

    def _config(self, values: dict | None = None) -> EnvConfig:
        def get(name):
            return values[name] if values and name in values else self.get_parameter(name).value
        return EnvConfig(**{name: get(name) for name in ENV_PARAMETERS})

    def _mode(self) -> str:
        return self.get_parameter("mode").value

    def _resolve_log_path(self, value: str | None = None) -> Path:
        value = self.get_parameter("log_path").value if value is None else value
        return Path(value).expanduser() if value else default_log_path()

    @staticmethod
    def _check(values: dict) -> str | None:
        """A reason to refuse these parameter values, or None."""
        if "mode" in values and values["mode"] not in MODES:
            return f"mode: {values['mode']!r} is not one of {', '.join(MODES)}"
        if "co2_ppm" in values and not (values["co2_ppm"] == -1.0 or 0.0 <= values["co2_ppm"] <= 5000.0):
            return f"co2_ppm: {values['co2_ppm']} is neither -1 (the scenario's) nor in 0..5000 ppm"
        for name in ("co2_ppm", "noise_scale", "irrigation_cost_per_mm", "days_per_second"):
            if name in values and not math.isfinite(values[name]):
                return f"{name}: {values[name]} is not finite"
        return None

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        values = {p.name: p.value for p in parameters}
        problem = self._check(values)
        if problem is None and any(name in values for name in ENV_PARAMETERS):
            try:
                build_scenario(self._config(values))
            except Exception as error:  # noqa: BLE001 - reported to the caller, nothing stored
                problem = f"{type(error).__name__}: {error}"
        if problem is None and "log_path" in values:
            path = self._resolve_log_path(values["log_path"])
            if path.is_dir():
                problem = f"log_path: {path} is a directory"
        if problem:
            self.get_logger().warning(f"parameter change refused: {problem}")
            return SetParametersResult(successful=False, reason=problem)
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, parameters) -> None:
        if any(p.name in ("mode", "days_per_second") for p in parameters):
            self._configure_timer()

    def _configure_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        if self._mode() == "free_running":
            self._timer = self.create_timer(1.0 / self.get_parameter("days_per_second").value, self._on_tick)

    # --- commands ----------------------------------------------------------------------------------------

    def _check_command(self, values: list) -> tuple[str | None, bool]:
        """(why this command [day, mm] or [day, mm, episode] is refused, or None; whether it is only a question
        of timing: a past or future day, another episode, a season that ended)."""
        day = values[0] if values else math.nan
        mm = values[1] if len(values) > 1 else math.nan
        if len(values) not in (2, 3):
            return f"expected [day, mm] or [day, mm, episode], got {len(values)} values", False
        if not (math.isfinite(day) and day == int(day)):
            return f"day {day!r} is not a whole number", False
        if len(values) == 3 and values[2] != self._episode:
            return f"episode {values[2]!r} is not the current episode {self._episode}", True
        if self._ended:
            return f"the season has ended ({self._end_reason}); call ~/reset", True
        if day < self._day:
            return f"day {int(day)} is past: the current day is {self._day}", True
        if day > self._day:
            return f"day {int(day)} is in the future: the current day is {self._day}", True
        if not math.isfinite(mm):
            return f"irrigation {mm!r} mm is not a finite number", False
        if mm < 0.0:
            return f"irrigation {mm!r} mm is negative", False
        if mm > self._max_mm:
            return f"irrigation {mm!r} mm exceeds the limit of {self._max_mm:g} mm/day", False
        return None, False

    def _accept(self, values: list, and_step: bool = False) -> bool:
        """Validate a command; if valid it becomes the day's pending command. Reports its fate on
        ~/irrigation_status and logs refusals. Returns whether it was accepted."""
        self._sequence += 1
        sequence = self._sequence
        day = values[0] if values else math.nan
        mm = values[1] if len(values) > 1 else math.nan
        problem, timing = self._check_command(values)
        if problem is None and and_step and self._mode() != "lockstep":
            problem, timing = "mode is free_running: the node steps by itself; use ~/irrigation", False
        if problem is None:
            self._pending = (self._day, float(mm), sequence)
            text = (f"accepted {mm:g} mm for day {self._day} (episode {self._episode})"
                    + (", stepping" if and_step else ""))
        else:
            text = f"rejected: {problem}"
            where = "irrigation_step" if and_step else "irrigation"
            if timing:  # a command that came too late or too early: at most one log line a second
                self.get_logger().warning(f"{where} command #{sequence} {values}: {text} (such rejections are "
                                          "logged at most once a second; all are on ~/irrigation_status)",
                                          throttle_duration_sec=1.0)
            else:
                self.get_logger().warning(f"{where} command #{sequence} {values}: {text}")
        if problem is not None or not and_step:  # an accepted stepping command's fate is its ~/step_result
            self._pub_status.publish(ri.status_message(problem is None, text, day, mm, sequence, self._day))
        return problem is None

    def _on_irrigation(self, message: Float64MultiArray) -> None:
        with self._lock:
            self._accept(list(message.data))

    def _on_irrigation_step(self, message: Float64MultiArray) -> None:
        """A command that also asks for the step: validated like ~/irrigation, then the day is stepped at once
        (lockstep mode). One topic round trip per day instead of a command, its acknowledgement and a service
        call; the outcome is on ~/step_result and ~/observation (and ~/irrigation_status if refused)."""
        with self._lock:
            if self._accept(list(message.data), and_step=True):
                ok, summary = self._step(defer=True)
                if not ok:
                    self.get_logger().error(ri.summary_json(summary))

    # --- step --------------------------------------------------------------------------------------------

    def _on_step(self, request, response):
        if self._mode() != "lockstep":
            response.success = False
            response.message = ri.summary_json({"error": "mode is free_running: the node steps by itself; set "
                                                "mode:=lockstep to step by service", "episode": self._episode,
                                                "day": self._day})
            return response
        response.success, summary = self._step(defer=True)
        response.message = ri.summary_json(summary)
        return response

    def _on_tick(self) -> None:
        if not self._ended:
            ok, summary = self._step()
            if not ok:
                self.get_logger().error(ri.summary_json(summary))

    def _step(self, defer: bool = False) -> tuple[bool, dict]:
        """Advance one day; (success, summary). The summary is a dict: callers that answer a service encode
        it (JSON costs time the topic path does not need to spend)."""
        with self._lock:
            if self._ended:
                return False, {"error": f"the season has ended ({self._end_reason}); call ~/reset",
                               "episode": self._episode, "day": self._day}
            day, obs_before = self._day, self._obs
            if self._pending is not None and self._pending[0] == day:
                _, mm, sequence = self._pending
            else:
                mm, sequence = 0.0, -1
            self._pending = None
            try:
                obs, reward, terminated, truncated, info = self._env.step(mm)
            except Exception as error:  # noqa: BLE001 - the environment refused: state unchanged
                self.get_logger().error(f"step of day {day} failed: {error}")
                return False, {"error": f"{type(error).__name__}: {error}", "episode": self._episode,
                               "day": self._day}
            terminated, truncated, reward = bool(terminated), bool(truncated), float(reward)
            self._obs = obs
            self._day = int(info["day"])
            self._return = float(info["episode_return"])
            if terminated or truncated:
                self._ended = True
                self._end_reason = (f"crop mature on day {self._day}" if terminated
                                    else f"weather ran out on day {self._day}")
            self._log.write({**self._log_common(day, obs_before),
                             "command_sequence": sequence, "irrigation_mm": info["irrigation_applied_mm"],
                             "reward": reward, "episode_return": info["episode_return"], "terminated": terminated,
                             "truncated": truncated, **{k: info[k] for k in ("rain_mm", "runoff_mm", "drainage_mm",
                                                                             "transpiration_mm", "et0_mm", "arid",
                                                                             "potential_yield_t_ha",
                                                                             "normalized_return")},
                             "end_true_biomass_t_ha": info["true_biomass_t_ha"],
                             "end_true_paw_mm": info["true_paw_mm"],
                             "end_thermal_time_degc_d": info["thermal_time_degc_d"], "end_fsolar": info["fsolar"],
                             "end_yield_t_ha": info["yield_t_ha"], "end_mature": info["mature"]})
            yield_t_ha = info["yield_t_ha"] if terminated else 0.0
            self._publish(info["irrigation_applied_mm"], reward, terminated, truncated, yield_t_ha, sequence,
                          defer=defer)
            summary = {"episode": self._episode, "day": self._day, "date": info["date"],
                       "irrigation_mm": info["irrigation_applied_mm"], "reward": reward, "return": self._return,
                       "terminated": terminated, "truncated": truncated, "yield_t_ha": yield_t_ha,
                       "command_sequence": sequence, "observation": ri.observation_list(obs)}
            return True, summary

    def _log_common(self, day: int, obs: np.ndarray) -> dict:
        row = {"wall_time_utc": datetime.now(timezone.utc).isoformat(timespec="milliseconds"), "run_id": self._run_id,
               "episode": self._episode, "scenario": self._env.scenario.name,
               "seed": "" if self._seed_used is None else self._seed_used, "weather_season": self._info_season,
               "day": day, "date": (self._sowing + timedelta(days=day)).isoformat()}
        row.update({column: float(value) for column, value in zip(OBS_COLUMNS, obs)})
        return row

    # --- reset -------------------------------------------------------------------------------------------

    def _on_reset(self, request, response):
        response.success, response.message = self._reset()
        return response

    def _reset(self) -> tuple[bool, str]:
        with self._lock:
            config = self._config()
            env, log, log_path = self._env, self._log, self._log_path
            try:
                if config != self._env_config:
                    env = IrrigationEnv(build_scenario(config))
                wanted_log = self._resolve_log_path()
                if wanted_log != self._log_path:
                    log, log_path = SeasonLog(wanted_log), wanted_log
                seed = self.get_parameter("seed").value
                season = self.get_parameter("weather_season").value
                options = {"season": season} if season >= 0 else None
                obs, info = env.reset(seed=seed if seed >= 0 else None, options=options)
            except Exception as error:  # noqa: BLE001 - the old season stays as it was
                message = f"reset failed, the current season is unchanged: {type(error).__name__}: {error}"
                self.get_logger().error(message)
                return False, ri.summary_json({"error": message, "episode": self._episode, "day": self._day})
            if env is not self._env:
                self._env, self._env_config = env, config
                self._max_mm = float(env.scenario.max_irrigation_mm)
            if log is not self._log:
                self._log.close()
                self._log, self._log_path = log, log_path
            self._episode += 1
            self._seed_used = seed if seed >= 0 else None
            self._obs = obs
            self._info_season = info["season"]
            self._day = int(info["day"])
            self._sowing = date.fromisoformat(info["date"])
            self._ended = False
            self._end_reason = ""
            self._return = 0.0
            self._pending = None
            self._publish(0.0, 0.0, False, False, 0.0, -1)
            summary = {"episode": self._episode, "day": self._day, "date": info["date"],
                       "scenario": env.scenario.name, "seed": self._seed_used, "weather_season": info["season"],
                       "weather_source": info["weather_source"], "max_irrigation_mm": self._max_mm,
                       "potential_yield_t_ha": info["potential_yield_t_ha"], "observation": ri.observation_list(obs)}
            self.get_logger().info(f"episode {self._episode}: {env.scenario.name}, weather {info['weather_source']}, "
                                   f"sown {info['date']}, seed {self._seed_used}")
            return True, ri.summary_json(summary)

    # --- publishing --------------------------------------------------------------------------------------

    def _publish(self, irrigation_mm: float, reward: float, terminated: bool, truncated: bool,
                 yield_t_ha: float, sequence: int, defer: bool = False) -> None:
        """Publish the current day: the observation and the step result at once; the other topics at once, or
        (``defer``, when a client waits) right after this callback, so that the client waits less."""
        self._flush_deferred()  # keep each topic in day order
        self._msg_obs.data = self._obs
        self._pub_obs.publish(self._msg_obs)
        self._msg_result.data = [float(self._episode), float(self._day), float(irrigation_mm), float(reward),
                                 float(terminated), float(truncated), float(yield_t_ha), float(self._return),
                                 float(sequence)]
        self._pub_result.publish(self._msg_result)
        rest = (self._obs, self._day, self._sowing)
        if defer and self.executor is not None:
            self._deferred.append(rest)
            self.executor.create_task(self._on_deferred)  # runs after this callback (and its response)
        else:
            self._publish_rest(*rest)

    def _flush_deferred(self) -> None:
        while self._deferred:
            self._publish_rest(*self._deferred.popleft())

    def _on_deferred(self) -> None:
        with self._lock:
            self._flush_deferred()

    def _publish_rest(self, obs, day, sowing) -> None:
        wide = obs.astype(np.float64).tolist()
        self._msg_biomass.data = [float(day), wide[ri.OBS_BIOMASS]]
        self._pub_biomass.publish(self._msg_biomass)
        self._msg_paw.data = [float(day), wide[ri.OBS_PAW]]
        self._pub_paw.publish(self._msg_paw)
        self._msg_today.data = [float(day), *wide[ri.OBS_TODAY]]
        self._pub_today.publish(self._msg_today)
        self._msg_forecast.data = [float(day + 1), *wide[ri.OBS_FORECAST]]
        self._pub_forecast.publish(self._msg_forecast)
        self._pub_clock.publish(ri.clock_message(sowing, day))

    def destroy_node(self):
        log = getattr(self, "_log", None)
        if log is not None:
            log.close()
        return super().destroy_node()


def main(args: list[str] | None = None) -> int:
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = SimNode()
        except (KeyboardInterrupt, ExternalShutdownException):
            raise
        except Exception as error:  # noqa: BLE001 - bad parameters, scenario or weather: a clear message, exit 2
            detail = str(error) if isinstance(error, StartupError) else f"{type(error).__name__}: {error}"
            rclpy.logging.get_logger(ri.NODE_NAME).fatal(f"cannot start: {detail}")
            return 2
        executor = SingleThreadedExecutor()  # one thread: callbacks run one at a time
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
