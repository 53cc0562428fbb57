"""The simulator node's class. Run it with ``sim_node`` (:mod:`crop_sim_ros.sim_node`, whose docstring describes
the day protocol, the season log, stopping and the parameters). What commands, steps and resets do to the farm
is decided by its :class:`~crop_sim_ros.session.FarmSession`; the node wires it to parameters, topics, services,
the season log and timers."""

from __future__ import annotations

import difflib
import math
import os
import re
import socket
import threading
from collections import deque
from dataclasses import dataclass, fields, replace
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import rclpy.parameter
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType,
                                SetParametersResult)
from rclpy.node import Node
from crop_sim_interfaces.msg import (CropState, FarmTerms, Forecast, IrrigationCommand, IrrigationStatus, StepResult,
                                     Weather)
from crop_sim_interfaces.srv import Reset, Step
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float32MultiArray, Header

from . import ros_interface as ri
from .safe_yaml import YamlInputError, read_yaml
from .season_log import TERM_COLUMNS, SeasonLog, log_path_problem
from .session import Command, FarmSession
from .sim_parameters import MODES, NODE_NAME, PARAMETERS, READ_ONLY_PARAMETERS, ParameterSpec
from .task import IrrigationEnv, ObservationNoise, Scenario, get_scenario, load_scenario
from .task.layout import PAPER, layout_of_size
from .task.scenario import DATA_DIR_ENV, INSTALLED_DATA_SUBDIR, SCENARIO_FILE_KEYS

# Parameters that define the environment (a change rebuilds it at the next reset).
ENV_PARAMETERS = ("scenario", "data_dir", "crop", "cultivar", "soil", "co2_ppm", "noise_scale",
                  "irrigation_cost_per_mm")
# Parameters rclpy itself reads from the command line (not unknown, though not in PARAMETERS).
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")
REFUSAL_MAX_CHARS = 400
_QUOTED = re.compile(r"'(?:[^'\\\n]|\\.)*'|\"(?:[^\"\\\n]|\\.)*\"")
STATUS_PERIOD_S = 1.0  # /diagnostics: the node's status is published this often (and at once on a change)


class StartupError(RuntimeError):
    """The node cannot start with its parameters (unknown scenario or crop, unreadable weather, ...)."""


class ScenarioFileError(ValueError):
    """A scenario file that is not a scenario YAML (the message names the file and what is wrong)."""


def one_line(error: BaseException | str) -> str:
    """An error as one line of text (with its type, unless it is plain text or one of this module's errors)."""
    text = (str(error) if isinstance(error, (str, StartupError, ScenarioFileError))
            else f"{type(error).__name__}: {error}")
    return " ".join(text.split())


def _descriptor(spec: ParameterSpec, read_only: bool = False) -> ParameterDescriptor:
    kind = {str: ParameterType.PARAMETER_STRING, int: ParameterType.PARAMETER_INTEGER,
            float: ParameterType.PARAMETER_DOUBLE}[type(spec.default)]
    descriptor = ParameterDescriptor(type=kind, description=spec.description,
                                     additional_constraints=spec.constraints, read_only=read_only)
    if spec.low is not None and kind == ParameterType.PARAMETER_DOUBLE:
        descriptor.floating_point_range = [FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high),
                                                              step=0.0)]
    elif spec.low is not None:
        descriptor.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    return descriptor


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


# --- scenarios: built from parameters; a refusal about a file never quotes what the file holds -------------

def _is_file_scenario(name: str) -> bool:
    return name.endswith((".yaml", ".yml")) or os.sep in name


def scenario_file_problem(path: Path) -> str | None:
    """Why ``path`` is not a scenario YAML file, or None. The reason names the file and what is wrong, never
    its contents: any peer on the domain can set the ``scenario`` parameter to any readable file, and the
    refusal goes back to that peer."""
    if not path.is_file():
        return f"scenario file {path} does not exist" if not path.exists() else f"scenario {path} is not a file"
    try:  # a regular file of at most CONFIG_MAX_BYTES, UTF-8, YAML without aliases, deep nesting or duplicate keys
        values = read_yaml(path, source=f"scenario file {path}")
    except YamlInputError as error:
        return str(error)
    known = ", ".join(sorted(SCENARIO_FILE_KEYS))
    if not isinstance(values, dict):
        kind = {str: "text", list: "a list", type(None): "nothing"}.get(type(values), "a single value")
        return f"scenario file {path} is not a scenario: it holds {kind}, not a mapping of the fields {known}"
    unknown = [key for key in values if not (isinstance(key, str) and key in SCENARIO_FILE_KEYS)]
    if unknown:
        near = sorted({match for key in unknown if isinstance(key, str)
                       for match in difflib.get_close_matches(key, SCENARIO_FILE_KEYS, n=1, cutoff=0.8)})
        hint = f" (did you mean {', '.join(near)}?)" if near else ""
        return (f"scenario file {path}: {len(unknown)} of its {len(values)} top-level fields are not scenario "
                f"fields{hint}; known: {known}")
    return None


def without_file_values(text: str) -> str:
    """``text`` on one line, every quoted value replaced by '…', at most REFUSAL_MAX_CHARS long: an error
    about a scenario file that may be told to peers (the field at fault and why, not the value it holds)."""
    text = _QUOTED.sub("'…'", one_line(text))
    return text if len(text) <= REFUSAL_MAX_CHARS else text[:REFUSAL_MAX_CHARS - 1] + "…"


def scenario_error(config: EnvConfig, error: BaseException) -> str:
    """The refusal of ``config``'s scenario, one line (see :func:`without_file_values` for file scenarios)."""
    name = config.scenario.strip()
    if isinstance(error, ScenarioFileError):
        return one_line(error)
    if _is_file_scenario(name):
        path = str(Path(name).expanduser())
        text = str(error).removeprefix(f"{path}: ")  # load_scenario names the file first: once is enough
        return f"scenario file {path}: {without_file_values(f'{type(error).__name__}: {text}')}"
    if isinstance(error, FileNotFoundError) and not config.data_dir:  # no reference data where the node looked
        text = one_line(error).removeprefix(f"{type(error).__name__}: ").split(" (data directory ")[0]
        return f"scenario {name!r}: {text} ({data_dir_hint()})"
    return f"scenario {name!r}: {one_line(error)}"


def build_scenario(config: EnvConfig) -> Scenario:
    """The Scenario of ``config``: a built-in name or YAML path, with the overrides applied and the crop,
    cultivar and soil looked up (UnknownNameError, ValueError or FileNotFoundError on bad values; for a file that
    is not a scenario YAML, ScenarioFileError first). With no ``data_dir``: the scenario's default
    (:func:`crop_sim_ros.task.scenario.default_data_dir`: the ament index's share/crop_sim_ros/data,
    ``$CROP_SIM_DATA_DIR``, else the checkout's shared/data)."""
    data_dir = config.data_dir or None
    name = config.scenario.strip()
    if not name:
        raise ValueError("empty name")
    if _is_file_scenario(name):
        path = Path(name).expanduser()
        problem = scenario_file_problem(path)
        if problem:
            raise ScenarioFileError(problem)
        scenario = load_scenario(path, data_dir)
        for season in scenario.weather.seasons:
            scenario.season_path(season)
    else:
        scenario = get_scenario(name, data_dir)
    changes = {key: value for key, value in (("crop", config.crop), ("cultivar", config.cultivar),
                                             ("soil", config.soil)) if value}
    if config.co2_ppm >= 0:
        changes["co2_ppm"] = config.co2_ppm
    if config.noise_scale != 1.0:
        changes["noise"] = ObservationNoise(**{f.name: getattr(scenario.noise, f.name) * config.noise_scale
                                               for f in fields(ObservationNoise)})
    changes["irrigation_cost_per_mm"] = config.irrigation_cost_per_mm
    scenario = replace(scenario, **changes)
    scenario.field_parameters()  # UnknownNameError for an unknown crop, cultivar or soil
    return scenario


def data_dir_hint() -> str:
    """Where a node without ``data_dir`` looked for the reference data, and how to point it there (one line)."""
    env = os.environ.get(DATA_DIR_ENV)
    return (f"looked in share/crop_sim_ros/{INSTALLED_DATA_SUBDIR} of the ament index, then "
            + (f"${DATA_DIR_ENV}={env}" if env else f"${DATA_DIR_ENV} (unset), then a shared/data above the current "
                                                    "directory or the package")
            + f"; set it with -p data_dir:=/path/to/shared/data or export {DATA_DIR_ENV}=/path/to/shared/data")


def default_log_path(node_name: str = "/" + NODE_NAME) -> Path:
    """The season log of the node whose fully qualified name is ``node_name``: $ROS_HOME/<namespace>/<node
    name>/season_log.csv (``/crop_sim``: $ROS_HOME/crop_sim/season_log.csv; ``/field7/crop_sim``:
    $ROS_HOME/field7/crop_sim/season_log.csv), so that farms side by side never share a log."""
    ros_home = os.environ.get("ROS_HOME") or os.path.join(os.path.expanduser("~"), ".ros")
    return Path(ros_home).joinpath(*node_name.strip("/").split("/")) / "season_log.csv"


class SimNode(Node):
    """See :mod:`crop_sim_ros.sim_node`."""

    def __init__(self, node_name: str = NODE_NAME, **kwargs):
        # no type-description service: one entity less for the executor to wait on per callback
        overrides = list(kwargs.pop("parameter_overrides", None) or [])
        overrides.append(rclpy.parameter.Parameter("start_type_description_service", value=False))
        super().__init__(node_name, parameter_overrides=overrides, **kwargs)
        self._log: SeasonLog | None = None
        self._deferred: deque = deque()
        ri.set_up_or_destroy(self, self._setup)

    def _setup(self) -> None:
        self._lock = threading.RLock()
        for name, spec in PARAMETERS.items():
            self.declare_parameter(name, spec.default, _descriptor(spec, read_only=name in READ_ONLY_PARAMETERS))
        self._warn_unknown_parameters()
        values = self._values()
        problem = self._problem(values, set(PARAMETERS))
        if problem:
            raise StartupError(problem)
        self._env_config = self._config()
        try:
            env = IrrigationEnv(build_scenario(self._env_config))
        except Exception as error:  # noqa: BLE001 - a broken weather file, ...: a start-up configuration error
            raise StartupError(scenario_error(self._env_config, error)) from None
        # what commands, steps and resets do to the farm (under self._lock)
        self._session = FarmSession(env, ri.field_frame(self.get_namespace()))
        self._log_path = self._resolve_log_path()
        self._log = self._open_log(self._log_path)
        self._run_id = f"{socket.gethostname()}-{os.getpid()}-{datetime.now(timezone.utc):%Y%m%dT%H%M%S}"

        # the season log's counters of the node's status (/diagnostics)
        self._log_rows_lost = 0
        self._log_error = ""  # why the last row could not be written; "" once a row is written again

        # publishers (messages reused: publish() serialises at once)
        self._pub_obs = self.create_publisher(Float32MultiArray, "~/" + ri.OBSERVATION_TOPIC, ri.STATE_QOS)
        self._pub_crop = self.create_publisher(CropState, "~/" + ri.CROP_STATE_TOPIC, ri.STATE_QOS)
        self._pub_today = self.create_publisher(Weather, "~/" + ri.WEATHER_TODAY_TOPIC, ri.STATE_QOS)
        self._pub_forecast = self.create_publisher(Forecast, "~/" + ri.WEATHER_FORECAST_TOPIC, ri.STATE_QOS)
        self._pub_result = self.create_publisher(StepResult, "~/" + ri.STEP_RESULT_TOPIC, ri.STATE_QOS)
        self._pub_terms = self.create_publisher(FarmTerms, "~/" + ri.FARM_TERMS_TOPIC, ri.STATE_QOS)
        self._pub_clock = self._clock_publisher(self.get_parameter("clock_topic").value)
        self._pub_status = self.create_publisher(IrrigationStatus, "~/" + ri.IRRIGATION_STATUS_TOPIC,
                                                 ri.COMMAND_STATUS_QOS)
        self._pub_diagnostics = self.create_publisher(DiagnosticArray, ri.DIAGNOSTICS_TOPIC, ri.DIAGNOSTICS_QOS)
        self._status_name = ri.node_status_name(self.get_fully_qualified_name())
        self._msg_obs = ri.observation_message(np.zeros(PAPER.size, np.float32))  # relabelled at each reset
        # Messages reused day after day (publishing serialises at once), stamped with the field as frame_id
        frame = self._session.field
        self._msg_crop = ri.stamped(CropState(), frame)
        self._msg_today = ri.stamped(Weather(), frame)
        self._msg_forecast = ri.stamped(Forecast(), frame)
        ri.stamped(self._msg_forecast.weather, frame)
        self._msg_result = ri.stamped(StepResult(), frame)
        self._msg_terms = ri.stamped(FarmTerms(), frame)

        self.create_subscription(IrrigationCommand, "~/" + ri.IRRIGATION_TOPIC, self._on_irrigation,
                                 ri.COMMAND_SUBSCRIPTION_QOS)
        self.create_subscription(IrrigationCommand, "~/" + ri.IRRIGATION_STEP_TOPIC, self._on_irrigation_step,
                                 ri.COMMAND_SUBSCRIPTION_QOS)
        self.create_service(Step, "~/" + ri.STEP_SERVICE, self._on_step)
        self.create_service(Reset, "~/" + ri.RESET_SERVICE, self._on_reset)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self.create_timer(STATUS_PERIOD_S, self._on_status_timer)
        self._timer = None
        self._configure_timer()

        error = self._reset()
        if error:
            raise StartupError(error)
        scenario = self._session.env.scenario
        files = (f", weather files from {scenario.resolved_data_dir}" if scenario.weather.kind != "generator"
                 else "")
        self.get_logger().info(f"ready: scenario {scenario.name!r}{files}, mode {self._mode()}, max irrigation "
                               f"{self._session.max_mm:g} mm, log {self._log_path}")

    # --- parameters --------------------------------------------------------------------------------------

    def _values(self) -> dict:
        return {name: self.get_parameter(name).value for name in PARAMETERS}

    def _config(self, values: dict | None = None) -> EnvConfig:
        values = values or self._values()
        return EnvConfig(**{name: values[name] for name in ENV_PARAMETERS})

    def _mode(self) -> str:
        return self.get_parameter("mode").value

    def _resolve_log_path(self, value: str | None = None) -> Path:
        value = self.get_parameter("log_path").value if value is None else value
        return Path(value).expanduser() if value else default_log_path(self.get_fully_qualified_name())

    def _clock_publisher(self, topic: str):
        """The farm-time publisher on ``topic`` (the ``clock_topic`` parameter), or None for ''."""
        if not topic:
            return None
        try:
            return self.create_publisher(Clock, topic, ri.CLOCK_QOS)
        except Exception as error:  # noqa: BLE001 - an invalid topic name: a start-up configuration error
            raise StartupError(f"clock_topic: {topic!r} is not a valid topic name ({one_line(error)})") from None

    def _warn_unknown_parameters(self) -> None:
        # rclpy keeps this node's -p / --params-file values in _parameter_overrides (there is no public
        # accessor); a value for a name that is never declared is otherwise dropped without a word
        unknown = sorted(name for name in self._parameter_overrides
                         if name not in PARAMETERS and name not in RCLPY_PARAMETERS
                         and not name.startswith("qos_overrides."))
        if unknown:
            self.get_logger().warning(f"unknown parameter{'s' if len(unknown) > 1 else ''} "
                                      f"{', '.join(unknown)} ignored; known: {', '.join(PARAMETERS)}")

    def _problem(self, values: dict, changed: set[str]) -> str | None:
        """Why the parameter values ``values`` (all of them, ``changed`` being the ones set now) are refused,
        or None. Checked when they are set, so that a bad value is refused then, not at the next reset."""
        if "mode" in changed and values["mode"] not in MODES:
            return f"mode: {values['mode']!r} is not one of {', '.join(MODES)}"
        co2 = values["co2_ppm"]
        if "co2_ppm" in changed and not (co2 == -1.0 or 0.0 <= co2 <= 5000.0):
            return f"co2_ppm: {co2} is neither -1 (the scenario's) nor in 0..5000 ppm"
        for name in ("co2_ppm", "noise_scale", "irrigation_cost_per_mm", "days_per_second"):
            if name in changed and not math.isfinite(values[name]):
                return f"{name}: {values[name]} is not finite"
        if changed & {*ENV_PARAMETERS, "weather_season"}:
            config = self._config(values)
            try:
                scenario = build_scenario(config)
            except Exception as error:  # noqa: BLE001 - reported to the caller, nothing stored
                return scenario_error(config, error)
            season, n_seasons = values["weather_season"], scenario.n_seasons
            if season >= n_seasons:
                return (f"weather_season: {season} is beyond the {n_seasons} season{'s' if n_seasons > 1 else ''} "
                        f"of scenario {scenario.name!r} (0..{n_seasons - 1}, or -1 to draw one)")
        if "log_path" in changed:
            return log_path_problem(self._resolve_log_path(values["log_path"]))
        return None

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        changed = {p.name: p.value for p in parameters}
        problem = self._problem({**self._values(), **changed}, set(changed))
        if problem:
            self.get_logger().warning(f"parameter change refused: {problem}")
            return SetParametersResult(successful=False, reason=problem)
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, parameters) -> None:
        if any(p.name in ("mode", "days_per_second") for p in parameters):
            self._configure_timer()
            self._publish_status()

    def _configure_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        if self._mode() == "free_running":
            self._timer = self.create_timer(1.0 / self.get_parameter("days_per_second").value, self._on_tick)

    # --- commands ----------------------------------------------------------------------------------------

    def _accept(self, command: Command, and_step: bool = False):
        """The session checks a command (an accepted one becomes the day's pending command); its fate goes to
        ~/irrigation_status and refusals to the log. Returns the session's CommandOutcome."""
        outcome = self._session.command(command, and_step, lockstep=self._mode() == "lockstep")
        if not outcome.accepted:
            where = (f"{'irrigation_step' if and_step else 'irrigation'} command #{outcome.sequence} "
                     f"(day {command.day}, {command.mm!r} mm, episode {command.episode})")
            if outcome.timing:  # a command that came too late or too early: at most one log line a second
                self.get_logger().warning(f"{where}: {outcome.text} (such rejections are logged at most once a "
                                          "second; all are on ~/irrigation_status)", throttle_duration_sec=1.0)
            else:
                self.get_logger().warning(f"{where}: {outcome.text}")
        if not outcome.accepted or not and_step:  # an accepted stepping command's fate is its ~/step_result
            fate = IrrigationStatus.ACCEPTED if outcome.accepted else IrrigationStatus.REFUSED
            self._publish_command_status(fate, outcome.text, command, outcome.sequence)
        return outcome

    def _publish_command_status(self, fate: int, text: str, command: Command, sequence: int,
                                applied_mm: float = math.nan) -> None:
        """A command's IrrigationStatus, stamped with the current day's farm time."""
        session = self._session
        header = Header(stamp=ri.sim_time(session.sowing, session.day), frame_id=session.field)
        self._pub_status.publish(ri.status_message(fate, text, command, sequence, header, session.episode,
                                                   session.day, applied_mm))

    def _on_irrigation(self, message: IrrigationCommand) -> None:
        with self._lock:
            self._accept(ri.command_of(message))

    def _on_irrigation_step(self, message: IrrigationCommand) -> None:
        """A command that also asks for the step: validated like ~/irrigation, then the day is stepped at once
        (lockstep mode). One topic round trip per day instead of a command, its acknowledgement and a service
        call; the outcome is on ~/step_result and ~/observation (and ~/irrigation_status if refused)."""
        with self._lock:
            if self._accept(ri.command_of(message), and_step=True).accepted:
                error = self._step(defer=True)
                if error:
                    self.get_logger().error(error)

    # --- step --------------------------------------------------------------------------------------------

    def _on_step(self, request: Step.Request, response: Step.Response) -> Step.Response:
        """Today's command from the request (``day``/``episode`` -1: the current one; or, with
        ``use_pending_command``, the one accepted on ~/irrigation), checked as a command on ~/irrigation_step is,
        then the day stepped. The reply carries the day's result and observation."""
        with self._lock:
            session = self._session
            error = None
            if self._mode() != "lockstep":
                error = "mode is free_running: the node steps by itself; set mode:=lockstep to step by service"
            elif request.use_pending_command:
                error = self._step(defer=True)
            else:
                day = session.day if request.day == Step.Request.ANY else request.day
                outcome = self._accept(Command(day, request.irrigation_mm, request.episode), and_step=True)
                error = outcome.text if not outcome.accepted else self._step(defer=True)
            if error:
                response.success, response.message = False, error
                response.result.episode, response.result.day = session.episode, session.day
                return response
            response.success, response.message = True, self._log_error
            response.result = self._msg_result
            response.observation = session.obs
            return response

    def _on_tick(self) -> None:
        if not self._session.ended:
            error = self._step(free_running=True)
            if error:
                self.get_logger().error(error)

    def _step(self, defer: bool = False, free_running: bool = False) -> str | None:
        """Advance one day and publish it; None, or why not (nothing changed)."""
        with self._lock:
            session = self._session
            outcome = session.step()
            if not outcome.ok:
                if outcome.environment_failed:
                    self.get_logger().error(f"step of day {session.day} failed: {outcome.error}")
                return outcome.error
            day, info = outcome.day_before, outcome.info
            if outcome.cut:  # the capacity or the quota cut the command (it was within the action bound)
                self._publish_command_status(IrrigationStatus.CUT, session.cut_reason(outcome), outcome.command,
                                             outcome.sequence, applied_mm=outcome.applied_mm)
            if outcome.sequence < 0:
                if free_running:  # in lockstep a step without a command is the caller's choice of 0 mm
                    self.get_logger().warning(
                        f"free running: day {day} of episode {session.episode} passed without a command (0 mm); "
                        f"{session.days_without_command} of {day + 1} days so far (logged at most once a second; "
                        "counted on /diagnostics)", throttle_duration_sec=1.0)
            self._write_log_row(
                {**self._log_common(day, outcome.obs_before),
                 "command_sequence": outcome.sequence, "irrigation_mm": outcome.applied_mm,
                 "irrigation_requested_mm": outcome.requested_mm, "reward": outcome.reward,
                 "episode_return": info["episode_return"], "terminated": outcome.terminated,
                 "truncated": outcome.truncated,
                 **{k: info[k] for k in ("rain_mm", "runoff_mm", "drainage_mm", "transpiration_mm", "et0_mm",
                                         "arid", "potential_yield_t_ha", "normalized_return")},
                 "end_true_biomass_t_ha": info["true_biomass_t_ha"], "end_true_paw_mm": info["true_paw_mm"],
                 "end_thermal_time_degc_d": info["thermal_time_degc_d"], "end_fsolar": info["fsolar"],
                 "end_yield_t_ha": info["yield_t_ha"], "end_mature": info["mature"]}, day)
            self._fill_result(outcome.applied_mm, outcome.requested_mm, outcome.reward, outcome.terminated,
                              outcome.truncated, outcome.yield_t_ha, outcome.sequence)
            self._publish(info, defer=defer)
            if session.ended:
                self.get_logger().info(
                    f"episode {session.episode} ended: {session.end_reason}, yield {outcome.yield_t_ha:.3f} t/ha, "
                    f"return {session.episode_return:.4f}; {session.days_without_command} of {session.day} days "
                    "without a command")
                self._publish_status()
            return None

    def _write_log_row(self, row: dict, day: int) -> str | None:
        """Append the day's row to the season log; None, or why it could not be written (the day stands; the
        caller is told, the failure is logged and counted on /diagnostics; the file keeps its last whole row)."""
        try:
            self._log.write(row)
        except OSError as error:
            self._log_rows_lost += 1
            failing_before = bool(self._log_error)
            self._log_error = (f"season log {self._log_path}: the row of episode {self._session.episode} day {day} "
                               f"was not written ({error.strerror or error}); {self._log_rows_lost} row"
                               f"{'s' if self._log_rows_lost > 1 else ''} lost so far")
            self.get_logger().error(self._log_error + " (logged at most once a second; counted on /diagnostics)",
                                    throttle_duration_sec=1.0)
            if not failing_before:
                self._publish_status()
            return self._log_error
        if self._log_error:
            self._log_error = ""
            self.get_logger().info(f"season log {self._log_path} written again ({self._log_rows_lost} rows lost)")
            self._publish_status()
        return None

    def _log_common(self, day: int, obs: np.ndarray) -> dict:
        session = self._session
        row = {"wall_time_utc": datetime.now(timezone.utc).isoformat(timespec="milliseconds"), "run_id": self._run_id,
               "episode": session.episode, "scenario": session.env.scenario.name,
               "seed": "" if session.seed is None else session.seed, "weather_season": session.weather_season,
               "day": day, "date": (session.sowing + timedelta(days=day)).isoformat(),
               "reward_unit": session.env.scenario.reward_unit}
        row.update({f"obs_{name}": float(value) for name, value in zip(layout_of_size(len(obs)).names, obs)})
        row.update(zip(TERM_COLUMNS, session.terms))
        return row

    # --- reset -------------------------------------------------------------------------------------------

    def _on_reset(self, request: Reset.Request, response: Reset.Response) -> Reset.Response:
        """A new season: the request's scenario set as the ``scenario`` parameter (for good), its seed and weather
        season for this season only (FROM_PARAMETER: the parameters'). The reply carries the terms and day 0's
        observation."""
        with self._lock:
            error = self._reset_request_problem(request)
            if not error and request.scenario.strip():
                result = self.set_parameters([rclpy.parameter.Parameter("scenario", value=request.scenario)])[0]
                error = None if result.successful else f"scenario: {result.reason}"
            if not error:
                error = self._reset(seed=request.seed, season=request.weather_season)
            response.success, response.message = not error, error or ""
            if not error:
                response.terms = self._msg_terms
                response.observation = self._session.obs
            return response

    @staticmethod
    def _reset_request_problem(request: Reset.Request) -> str | None:
        for name in ("seed", "weather_season"):
            if getattr(request, name) < Reset.Request.FROM_PARAMETER:
                return (f"{name}: {getattr(request, name)} is neither >= 0, DRAW (-1) nor FROM_PARAMETER (-2)")
        return None

    def _open_log(self, path: Path) -> SeasonLog:
        log = SeasonLog(path)
        if log.repaired_bytes:
            self.get_logger().warning(f"season log {path}: removed a torn last line ({log.repaired_bytes} bytes of a "
                                      "row cut short, e.g. by a crash) before appending")
        return log

    def _reset(self, seed: int = Reset.Request.FROM_PARAMETER, season: int = Reset.Request.FROM_PARAMETER
               ) -> str | None:
        """A new season (``seed``/``season``: a value, DRAW, or FROM_PARAMETER); None, or why not (the current
        season is unchanged)."""
        with self._lock:
            session = self._session
            values = self._values()
            if seed == Reset.Request.FROM_PARAMETER:
                seed = values["seed"]
            if season == Reset.Request.FROM_PARAMETER:
                season = values["weather_season"]
            config = self._config(values)
            env, log, log_path = session.env, self._log, self._log_path
            try:
                if config != self._env_config:
                    try:
                        env = IrrigationEnv(build_scenario(config))
                    except Exception as error:  # noqa: BLE001 - reported below, as one line
                        raise StartupError(scenario_error(config, error)) from None
                wanted_log = self._resolve_log_path()
                if wanted_log != self._log_path:
                    log, log_path = self._open_log(wanted_log), wanted_log
                info = session.reset(env, seed if seed >= 0 else None, season if season >= 0 else None)
            except Exception as error:  # noqa: BLE001 - the old season stays as it was
                if log is not self._log:
                    log.close()
                message = f"reset failed, the current season is unchanged: {one_line(error)}"
                self.get_logger().error(message)
                return message
            self._env_config = config
            if log is not self._log:
                self._log.close()
                self._log, self._log_path = log, log_path
            self._msg_obs = ri.observation_message(session.obs)  # the layout's labels (20 or 29 values)
            self._fill_terms(info)
            ri.forecast_noise(self._msg_forecast, env.scenario.noise)
            self._pub_terms.publish(self._msg_terms)
            self._fill_result(0.0, 0.0, 0.0, False, False, 0.0, -1)
            self._publish(info)
            self._publish_status()
            self.get_logger().info(f"episode {session.episode}: {env.scenario.name}, weather "
                                   f"{info['weather_source']}, sown {info['date']}, seed {session.seed}")
            return None

    def _fill_terms(self, info: dict) -> None:
        """The reset's FarmTerms (reused message) from the session and the environment's reset ``info``."""
        session, scenario, terms = self._session, self._session.env.scenario, self._msg_terms
        terms.header.stamp = ri.sim_time(session.sowing, 0)
        terms.episode, terms.scenario = session.episode, scenario.name
        terms.seed = -1 if session.seed is None else session.seed
        terms.weather_season, terms.weather_source = info["season"], info["weather_source"]
        terms.site_climate, terms.sowing_date = scenario.weather.climate or "", info["date"]
        terms.reward_unit, terms.max_irrigation_mm = scenario.reward_unit, session.max_mm
        terms.potential_yield_t_ha = info["potential_yield_t_ha"]
        terms.yield_value_per_t = float(info["yield_value_per_t"])
        for name, value in zip(ri.TERM_FIELDS, session.terms):
            setattr(terms, name, float(value))

    def _fill_result(self, applied_mm: float, requested_mm: float, reward: float, terminated: bool,
                     truncated: bool, yield_t_ha: float, sequence: int) -> None:
        """The day's StepResult (reused message) for the session's current day."""
        session, result = self._session, self._msg_result
        result.header.stamp = ri.sim_time(session.sowing, session.day)
        result.episode, result.day = session.episode, session.day
        result.irrigation_mm, result.irrigation_requested_mm = float(applied_mm), float(requested_mm)
        result.reward, result.episode_return = float(reward), float(session.episode_return)
        result.reward_unit = session.env.scenario.reward_unit
        result.terminated, result.truncated = bool(terminated), bool(truncated)
        result.yield_t_ha, result.command_sequence = float(yield_t_ha), int(sequence)

    # --- publishing --------------------------------------------------------------------------------------

    def _publish(self, info: dict, defer: bool = False) -> None:
        """Publish the current day (``info``: the environment's, for the model state): the observation and the
        step result at once; the other topics at once, or (``defer``, when a client waits) right after this
        callback, so that the client waits less."""
        self._flush_deferred()  # keep each topic in day order
        session = self._session
        self._msg_obs.data = session.obs
        self._pub_obs.publish(self._msg_obs)
        self._pub_result.publish(self._msg_result)
        rest = (session.obs, session.episode, session.day, session.sowing, info["fsolar"], info["mature"])
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

    def _publish_rest(self, obs, episode: int, day: int, sowing, fsolar: float, mature: bool) -> None:
        wide = obs.astype(np.float64).tolist()
        today = ri.sim_time(sowing, day)
        self._pub_crop.publish(ri.fill_crop_state(self._msg_crop, today, episode, day, wide, fsolar, mature))
        self._pub_today.publish(ri.fill_weather(self._msg_today, today, day, wide[ri.OBS_TODAY]))
        forecast = self._msg_forecast
        forecast.header.stamp = today
        ri.fill_weather(forecast.weather, ri.sim_time(sowing, day + 1), day + 1, wide[ri.OBS_FORECAST])
        self._pub_forecast.publish(forecast)
        if self._pub_clock is not None:
            self._pub_clock.publish(Clock(clock=today))

    def _on_status_timer(self) -> None:
        with self._lock:  # a heartbeat, as diagnostic_updater's: a monitor marks a silent node stale
            self._publish_status()

    def _publish_status(self) -> None:
        """The node's status on /diagnostics now (one DiagnosticStatus named after the node, in a
        DiagnosticArray): level ERROR while the season log cannot be written, WARN after rows were lost or when
        free-running days passed without a command this season, else OK."""
        free_running = self._mode() == "free_running"
        session = self._session
        if self._log_error:
            level, text = DiagnosticStatus.ERROR, self._log_error
        elif self._log_rows_lost:
            level, text = DiagnosticStatus.WARN, f"season log: {self._log_rows_lost} rows lost"
        elif free_running and session.days_without_command:
            level, text = DiagnosticStatus.WARN, (f"free running: {session.days_without_command} days of this "
                                                  "season passed without a command")
        else:
            level, text = DiagnosticStatus.OK, "ok"
        status = ri.node_status_message(level, text, {
            "episode": session.episode, "day": session.day, "mode": self._mode(), "season_ended": session.ended,
            "days_without_command": session.days_without_command, "commands_received": session.commands_received,
            "commands_accepted": session.commands_accepted, "commands_rejected": session.commands_rejected,
            "log_path": self._log_path, "log_rows_written": self._log.rows_written,
            "log_rows_lost": self._log_rows_lost, "log_error": self._log_error}, name=self._status_name)
        self._pub_diagnostics.publish(ri.diagnostics_message(self.get_clock().now().to_msg(), [status]))

    def destroy_node(self):
        self.finish()
        return super().destroy_node()

    def finish(self) -> None:
        """Publish what is deferred and close the season log (what must not be cut short when stopping)."""
        if self._deferred and self.context.ok():
            self._flush_deferred()  # the last day's topics, which the executor did not get to
        if self._log is not None and not self._log.closed:
            self._log.close()
            lost = getattr(self, "_log_rows_lost", 0)
            self.get_logger().info(f"season log {self._log.path} closed: {self._log.rows_written} rows written by "
                                   f"this run" + (f", {lost} lost" if lost else ""))
