"""A client of the simulator node: reset (a service call), and one simulated day, in one of two ways.

Shared by the Gymnasium bridge (:mod:`crop_agent_ros.ros.bridge`) and the agent node's drive mode. It runs on
the caller's node and executor (one thread; no background spinning), with ``call_async`` and its own
``spin_once`` loop.

``via="topic"`` (the default; one round trip per day):
    publish an IrrigationCommand (day, mm, episode; stamped with the day's farm time and addressed to the field,
    both from the reset reply's FarmTerms) on ``<sim>/irrigation_step``; the simulator validates the command,
    applies it and steps at once; the client waits for ``<sim>/step_result`` and ``<sim>/observation`` of the
    new day (float32 observation and float64 reward, exactly). A refusal arrives on ``<sim>/irrigation_status``.
    The day is named in the command, so a repeated message can never step twice (it would be for a past day).

``via="service"`` (the typed service any client can use; one round trip per day):
    call ``<sim>/step`` (crop_sim_interfaces/srv/Step) with ``irrigation_mm``, ``day`` and ``episode``: the
    simulator checks the command as it checks one on ``<sim>/irrigation``, applies it and steps; the reply
    carries the day's StepResult and the new day's float32 observation, exactly. With ``verify_topics`` the
    client also waits for the observation topic and checks it equals the reply's observation bit for bit.

``reset`` calls ``<sim>/reset`` (crop_sim_interfaces/srv/Reset) with the season's ``seed`` and
``weather_season`` in the request: the simulator's parameters stay as their user set them. The reply carries
the season's FarmTerms and day 0's observation.

Family tasks: the observation has the scenario's layout (29 values; :func:`scenario_layout` tells it from the
simulator's ``scenario`` parameter before a reset, :attr:`SimClient.layout` after one), and the simulator
applies min(command, capacity, quota left): a step whose irrigation is below the command is accepted when
the season's farm terms (the reset's ``farm_terms``) have a capacity below the action bound or a quota, and
refused as someone else's command otherwise.

A command published before the two endpoints have matched is lost; :meth:`connect` waits for the matching
and the client republishes after ``ack_timeout`` (harmless: the latest command of a day counts, a stepping
command for a day already stepped is refused).
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from datetime import date
from pathlib import Path

import numpy as np
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from crop_sim_interfaces.msg import IrrigationCommand, IrrigationStatus, StepResult
from crop_sim_interfaces.srv import Reset, Step
from std_msgs.msg import Float32MultiArray, Header

from crop_sim_ros import ros_interface as ri
from crop_sim_ros.task.layout import PAPER, ObservationLayout, layout_of_size

from .spin import ServiceTimeout, call, spin_until, wait_for_service


UNCHANGED = object()  # reset(): leave this simulator parameter as it is


class SimError(RuntimeError):
    """The simulator refused a request (the message says why)."""


def scenario_layout(scenario: str) -> ObservationLayout:
    """The observation layout of the simulator's ``scenario`` parameter (a built-in name, or a YAML file read on
    this machine): the paper's 20 values or the family's 29. ValueError for an unknown name; only the task's
    terms are read (no weather file is looked for)."""
    from crop_sim_ros.task.scenario import SCENARIO_DIR, load_scenario, scenario_names  # noqa: PLC0415

    name = scenario.strip()
    if name.endswith((".yaml", ".yml")) or os.sep in name:
        return load_scenario(Path(name).expanduser()).layout
    if name not in scenario_names():
        raise ValueError(f"unknown scenario {name!r}; known: {', '.join(scenario_names())}")
    return load_scenario(SCENARIO_DIR / f"{name}.yaml").layout


class SimClient:
    """Talks to the simulator node ``sim_node`` (its fully qualified name, e.g. ``/crop_sim``)."""

    def __init__(self, node, executor, sim_node: str = "/" + ri.NODE_NAME, timeout: float = 10.0,
                 ack_timeout: float = 0.5, verify_topics: bool = False, via: str = "topic"):
        if via not in ("topic", "service"):
            raise ValueError(f"via: {via!r} is neither 'topic' nor 'service'")
        self.via = via
        self.node, self.executor = node, executor
        self.sim = sim_node.rstrip("/") or "/" + ri.NODE_NAME
        if not self.sim.startswith("/"):
            self.sim = "/" + self.sim
        self.timeout, self.ack_timeout, self.verify_topics = timeout, ack_timeout, verify_topics
        # keep-all: every client of a service receives every client's answers; a depth-10 queue loses its own
        # answer when another client's flood arrives first (seen under load)
        self._step = node.create_client(Step, f"{self.sim}/{ri.STEP_SERVICE}", qos_profile=ri.SERVICE_CLIENT_QOS)
        self._reset = node.create_client(Reset, f"{self.sim}/{ri.RESET_SERVICE}", qos_profile=ri.SERVICE_CLIENT_QOS)
        self._set_parameters = node.create_client(SetParameters, f"{self.sim}/set_parameters")
        self._get_parameters = node.create_client(GetParameters, f"{self.sim}/get_parameters")
        self._command = node.create_publisher(IrrigationCommand, f"{self.sim}/{ri.IRRIGATION_TOPIC}", ri.COMMAND_QOS)
        self._acks: deque[IrrigationStatus] = deque(maxlen=1000)
        self._status = node.create_subscription(IrrigationStatus, f"{self.sim}/{ri.IRRIGATION_STATUS_TOPIC}",
                                                lambda m: self._acks.append(m), ri.COMMAND_QOS)
        self._topic_obs: deque[np.ndarray] = deque(maxlen=100)
        self._results: deque[StepResult] = deque(maxlen=100)
        self._obs_sub = self._result_sub = None
        if verify_topics or via == "topic":
            self._obs_sub = node.create_subscription(
                Float32MultiArray, f"{self.sim}/{ri.OBSERVATION_TOPIC}",
                lambda m: self._topic_obs.append(ri.observation_from_message(m)), ri.READER_QOS)
        if via == "topic":
            self._step_command = node.create_publisher(IrrigationCommand, f"{self.sim}/{ri.IRRIGATION_STEP_TOPIC}",
                                                       ri.COMMAND_QOS)
            self._result_sub = node.create_subscription(StepResult, f"{self.sim}/{ri.STEP_RESULT_TOPIC}",
                                                        lambda m: self._results.append(m), ri.READER_QOS)
        self._parameters: dict = {}
        self.episode = 0
        self.day = 0
        self.ended = True
        self.max_irrigation_mm = math.inf
        self.layout: ObservationLayout = PAPER  # of the current season (from the reset's observation)
        self.limited = False  # the season's capacity or quota may cut a command (from the reset's farm terms)
        self.last_response: dict = {}
        self.last_result = StepResult()  # of the latest step
        self.sowing = date(1970, 1, 1)  # the season's sowing date: farm time of day 0 (from the reset's terms)
        self.field = ""  # the simulator's field (its messages' frame_id; '' before a reset: any)
        self.retries = 0

    # --- connection --------------------------------------------------------------------------------------

    def connect(self, timeout: float | None = None) -> dict:
        """Wait until the simulator's services exist and the command/status topics have matched, then read
        its ``mode`` and ``scenario`` parameters (an idempotent round trip: by the time it returns, the
        simulator has discovered this node's endpoints, all created before). Returns those parameters.
        ``timeout`` (s; default: the client's) bounds the whole wait: ServiceTimeout names what is missing."""
        timeout = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        for client in (self._reset, self._step, self._set_parameters, self._get_parameters):
            try:
                wait_for_service(self.executor, client, max(0.0, deadline - time.monotonic()))
            except ServiceTimeout:
                raise ServiceTimeout(f"no simulator {self.sim} within {timeout:.1f} s (service {client.srv_name} "
                                     "not found)") from None
        spin_until(self.executor, lambda: self._command.get_subscription_count() >= 1
                   and self._status.get_publisher_count() >= 1
                   and (self._obs_sub is None or self._obs_sub.get_publisher_count() >= 1)
                   and (self._result_sub is None or (self._result_sub.get_publisher_count() >= 1
                                                     and self._step_command.get_subscription_count() >= 1)),
                   max(0.1, deadline - time.monotonic()), what=f"the topics of {self.sim}", step=0.02)
        values = self.get_parameters(["mode", "scenario"])
        if values.get("mode") not in (None, "lockstep"):
            raise SimError(f"{self.sim} is in mode {values['mode']!r}: a client steps it only in lockstep mode")
        return values

    def close(self) -> None:
        for client in (self._step, self._reset, self._set_parameters, self._get_parameters):
            self.node.destroy_client(client)
        self.node.destroy_publisher(self._command)
        self.node.destroy_subscription(self._status)
        for sub in (self._obs_sub, self._result_sub):
            if sub is not None:
                self.node.destroy_subscription(sub)
        if self._result_sub is not None:
            self.node.destroy_publisher(self._step_command)

    # --- parameters --------------------------------------------------------------------------------------

    def get_parameters(self, names: list[str]) -> dict:
        """The simulator's current values of the parameters ``names`` (as Python values)."""
        response = self._call_idempotent(self._get_parameters, GetParameters.Request(names=list(names)))
        return {name: _python_value(value) for name, value in zip(names, response.values)}

    def set_parameters(self, **values) -> None:
        """Set simulator parameters (skipping those already set to the same value by this client)."""
        changed = {k: v for k, v in values.items() if self._parameters.get(k, object()) != v
                   or type(self._parameters.get(k)) is not type(v)}
        self._set(changed)
        self._parameters.update(changed)

    def _set(self, values: dict) -> None:
        if not values:
            return
        request = SetParameters.Request()
        for name, value in values.items():
            request.parameters.append(Parameter(name=name, value=_parameter_value(value)))
        response = self._call_idempotent(self._set_parameters, request)
        for (name, value), result in zip(values.items(), response.results):
            if not result.successful:
                raise SimError(f"{self.sim}: parameter {name}={value!r} refused: {result.reason}")

    # --- season ------------------------------------------------------------------------------------------

    def reset(self, seed=None, weather_season=None, **parameters):
        """New season; ``seed`` None continues the simulator's random stream (like Gymnasium), UNCHANGED
        uses the simulator's own seed parameter; likewise ``weather_season`` (None: drawn). The seed and
        season apply to this reset only (they travel in the Reset request). ``parameters`` (crop, scenario, ...)
        are set for good.
        Returns (observation float32 (20,) or (29,): see :attr:`layout`, info dict: the reply's terms as
        :func:`crop_sim_ros.ros_interface.reset_summary` gives them)."""
        def requested(value) -> int:
            return (Reset.Request.FROM_PARAMETER if value is UNCHANGED else Reset.Request.DRAW if value is None
                    else int(value))
        self.set_parameters(**parameters)
        self._topic_obs.clear()
        response = self._call(self._reset, Reset.Request(seed=requested(seed), weather_season=requested(weather_season)))
        summary = ri.reset_summary(response.terms, response.observation)
        self.last_response = summary
        self.sowing, self.field = date.fromisoformat(response.terms.sowing_date), response.terms.header.frame_id
        self.episode, self.day, self.ended = summary["episode"], summary["day"], False
        self.max_irrigation_mm = float(summary.get("max_irrigation_mm", math.inf))
        terms = summary.get("farm_terms") or {}
        self.limited = terms.get("quota_mm", None) is not None or terms.get("capacity_mm_per_day",
                                                                              math.inf) < self.max_irrigation_mm
        obs = self._observation(summary["day"], response.observation)
        self.layout = layout_of_size(obs.size)
        return obs, summary

    def step(self, mm: float):
        """Irrigate ``mm`` today and advance one day.
        Returns (observation, reward, terminated, truncated, summary)."""
        if self.ended:
            raise SimError("the season has ended; call reset()")
        mm = float(mm)
        if self.via == "topic":
            return self._step_by_topic(mm)
        self._topic_obs.clear()
        response = self._call(self._step, Step.Request(irrigation_mm=mm, day=self.day, episode=self.episode))
        result = self.last_result = response.result
        summary = ri.step_summary(result, response.observation)
        self.last_response = summary
        if result.episode != self.episode or result.day != self.day + 1:
            raise SimError(f"{self.sim}: expected episode {self.episode} day {self.day + 1}, got episode "
                           f"{result.episode} day {result.day} (another client is stepping this simulator)")
        self._check_applied(self.day, result.irrigation_mm, mm)
        self.day = result.day
        self.ended = result.terminated or result.truncated
        return (self._observation(result.day, response.observation), result.reward, result.terminated,
                result.truncated, summary)

    def _step_by_topic(self, mm: float):
        day, episode = self.day, self.episode
        message = self._today_command(mm)
        self._acks.clear()
        self._results.clear()
        self._topic_obs.clear()
        found = {}

        def arrived() -> bool:
            if "result" not in found:
                for r in self._results:
                    if r.episode == episode and r.day == day + 1:
                        found["result"] = r
                        break
            if "obs" not in found:
                for o in self._topic_obs:
                    if o[ri.OBS_DAY] == day + 1:
                        found["obs"] = o
                        break
            if "result" in found and "obs" in found:
                return True
            for ack in self._acks:  # refused (another client stepped, the season ended, a bad amount ...)
                if ack.fate == IrrigationStatus.REFUSED and ack.command == message and "result" not in found:
                    raise SimError(f"{self.sim} refused {mm} mm and a step for day {day}: {ack.message}")
            return False

        deadline = time.monotonic() + self.timeout
        while True:
            self._step_command.publish(message)
            try:
                spin_until(self.executor, arrived, min(self.ack_timeout, max(0.01, deadline - time.monotonic())),
                           what="the step result")
                break
            except ServiceTimeout:
                if time.monotonic() > deadline:
                    raise ServiceTimeout(f"{self.sim} did not step day {day} within {self.timeout:.1f} s") from None
                self.retries += 1
        result, obs = found["result"], found["obs"]
        self.last_result = result
        self._check_applied(day, result.irrigation_mm, mm)
        summary = ri.step_summary(result)
        self.last_response = summary
        self.day = day + 1
        self.ended = result.terminated or result.truncated
        return obs, result.reward, result.terminated, result.truncated, summary

    def _check_applied(self, day: int, applied: float, mm: float) -> None:
        """SimError unless the day got ``mm``, or less when the season's capacity or quota may cut it."""
        if applied != mm and not (self.limited and 0.0 <= applied < mm):
            raise SimError(f"{self.sim}: day {day} was irrigated {applied} mm, not {mm} mm")

    def _today_command(self, mm: float) -> IrrigationCommand:
        """``mm`` for today, in this season only, stamped with today's farm time and addressed to the field."""
        today = Header(stamp=ri.sim_time(self.sowing, self.day), frame_id=self.field)
        return IrrigationCommand(header=today, day=self.day, irrigation_mm=mm, episode=self.episode)

    def command(self, mm: float) -> IrrigationStatus:
        """Publish today's command and wait until the simulator has accepted it; returns its status."""
        message = self._today_command(mm)
        self._acks.clear()
        deadline = time.monotonic() + self.timeout
        while True:
            self._command.publish(message)
            try:
                spin_until(self.executor, lambda: self._find_ack(message) is not None,
                           min(self.ack_timeout, max(0.01, deadline - time.monotonic())), what="an acknowledgement")
            except ServiceTimeout:
                if time.monotonic() > deadline:
                    raise ServiceTimeout(f"{self.sim} did not acknowledge the irrigation command for day "
                                         f"{self.day} within {self.timeout:.1f} s") from None
                self.retries += 1
                continue
            ack = self._find_ack(message)
            if ack.fate == IrrigationStatus.REFUSED:
                raise SimError(f"{self.sim} rejected {mm} mm for day {self.day}: {ack.message}")
            return ack

    def _find_ack(self, message: IrrigationCommand) -> IrrigationStatus | None:
        """The simulator's answer to ``message`` (the first, if it was sent more than once)."""
        return next((ack for ack in self._acks if ack.command == message), None)

    def _call_idempotent(self, client, request, attempts: int = 4):
        """A call that may be repeated: DDS can lose a request sent right after discovery (the server's reader
        had not matched this client's writer yet), and ROS 2 services do not resend it."""
        per_attempt = max(self.timeout / attempts, 1.0)
        for attempt in range(attempts):
            try:
                return call(self.executor, client, request, per_attempt)
            except ServiceTimeout:
                if attempt == attempts - 1:
                    raise
                self.retries += 1

    def _call(self, client, request):
        """The reply of a typed Step or Reset call; SimError with the simulator's reason if it refused."""
        response = call(self.executor, client, request, self.timeout)
        if not response.success:
            self.last_response = {"error": response.message}
            raise SimError(f"{client.srv_name}: {response.message}")
        return response

    def _observation(self, day: int, values) -> np.ndarray:
        """A reply's observation (float32 values, exactly); with ``verify_topics``, checked bit for bit against
        the observation topic of the same ``day``."""
        obs = np.asarray(values, dtype=np.float32)
        if self.verify_topics:
            spin_until(self.executor, lambda: any(o[ri.OBS_DAY] == day for o in self._topic_obs), self.timeout,
                       what=f"the observation topic of day {day}")
            topic = next(o for o in self._topic_obs if o[ri.OBS_DAY] == day)
            if topic.tobytes() != obs.tobytes():
                raise SimError(f"day {day}: the observation topic differs from the step response: {topic} != {obs}")
        return obs


def _python_value(value: ParameterValue):
    """The Python value of a ParameterValue (None when the parameter is not set)."""
    return {ParameterType.PARAMETER_BOOL: value.bool_value, ParameterType.PARAMETER_INTEGER: value.integer_value,
            ParameterType.PARAMETER_DOUBLE: value.double_value,
            ParameterType.PARAMETER_STRING: value.string_value}.get(value.type)


def _parameter_value(value) -> ParameterValue:
    if isinstance(value, bool):
        return ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value)
    if isinstance(value, int):
        return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
    if isinstance(value, float):
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    if isinstance(value, str):
        return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
    raise TypeError(f"unsupported parameter value {value!r}")
