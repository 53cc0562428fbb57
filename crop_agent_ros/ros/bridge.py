"""The irrigation task through ROS: a Gymnasium environment whose reset and step go through a running
simulator node (``sim_node``), with the same spaces as the offline :class:`~crop_sim_ros.task.IrrigationEnv`.

    env = RosIrrigationEnv(sim_node="/crop_sim")      # a sim_node must be running (same ROS_DOMAIN_ID)
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(np.array([10.0], np.float32))

For the same seed, scenario and actions it gives exactly the observations, rewards and terminated/truncated
flags of the offline environment (the simulator node holds that very environment; observations travel as
float32 values, rewards as float64, both exactly). ``reset(seed=s)`` sets the simulator's ``seed`` parameter
to ``s``; ``reset()`` sets it to -1 so the simulator continues its random stream, as Gymnasium does.
``reset(options={"season": k})`` grows the scenario's season ``k``. Out-of-range actions are clipped to
the action space (as the offline environment does, and flagged in ``info["irrigation_clipped"]``); NaN or
infinite actions raise ValueError.

``via="topic"`` (default): each step is one topic round trip: the command on ``~/irrigation_step`` (which
the simulator applies and steps at once), the answer on ``~/step_result`` and ``~/observation``.
``via="service"``: the general protocol (command on ``~/irrigation``, its acknowledgement, the ``~/step``
service), about two round trips. See :mod:`crop_agent_ros.ros.sim_client` and ``python -m
crop_agent_ros.ros.bench``. One bridge per simulator node: a second client stepping the same
simulator is detected (the day it gets back is not the day it expected) and raises.

Family tasks (``scenario="benton-quota"``, or a simulator started with one): the observation space is the
scenario's layout (29 values, :mod:`crop_sim_ros.task.layout`), read from the scenario (the bridge's
``scenario``, else the simulator's ``scenario`` parameter) when the bridge is made; a reset whose observation
has another size (the simulator's scenario was changed behind the bridge) raises SimError. Rewards are in the
scenario's unit (USD/ha), and ``info["irrigation_applied_mm"]`` is what the capacity and the quota let through
(``irrigation_clipped`` when it differs from the request), as offline.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np

from .spin import PrivateRos
from .sim_client import SimClient, SimError, scenario_layout

__all__ = ["RosIrrigationEnv", "SimError"]


class RosIrrigationEnv(gym.Env[np.ndarray, np.ndarray]):
    """See the module docstring. ``scenario``/``data_dir`` (optional) are set on the simulator at every
    reset; ``max_irrigation_mm`` is the action bound (the scenario's, 100 mm for the built-in ones)."""

    metadata = {"render_modes": []}

    def __init__(self, sim_node: str = "/crop_sim", scenario: str | None = None, data_dir: str | None = None,
                 max_irrigation_mm: float = 100.0, connect_timeout: float = 30.0, timeout: float = 10.0,
                 verify_topics: bool = False, node_name: str | None = None, via: str = "topic"):
        self.action_space = gym.spaces.Box(0.0, max_irrigation_mm, (1,), np.float32)
        self._max_mm = float(max_irrigation_mm)
        self._scenario_parameters = {}
        if scenario is not None:
            self._scenario_parameters["scenario"] = str(scenario)
        if data_dir is not None:
            self._scenario_parameters["data_dir"] = str(data_dir)
        self._ros = PrivateRos(node_name or f"irrigation_bridge_{os.getpid()}_{id(self) & 0xffff:x}")
        try:
            self.client = SimClient(self._ros.node, self._ros.executor, sim_node, timeout=timeout,
                                    verify_topics=verify_topics, via=via)
            values = self.client.connect(connect_timeout)
            self.layout = scenario_layout(scenario if scenario is not None else values["scenario"])
        except BaseException:
            self._ros.close()
            raise
        self.observation_space = gym.spaces.Box(self.layout.low, self.layout.high, dtype=np.float32)
        self._closed = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        season = options.pop("season", None)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; the bridge knows: season")
        obs, info = self.client.reset(seed=seed, weather_season=season, **self._scenario_parameters)
        if info.get("max_irrigation_mm", self._max_mm) != self._max_mm:
            raise SimError(f"the simulator's irrigation limit is {info['max_irrigation_mm']} mm, this bridge's "
                           f"action space ends at {self._max_mm} mm: pass max_irrigation_mm=")
        if obs.shape != self.observation_space.shape:
            raise SimError(f"the simulator's observation has {obs.size} values, this bridge's space "
                           f"{self.layout.size}: its scenario changed since the bridge was made; make a new bridge")
        return obs, info

    def step(self, action):
        requested = np.asarray(action, dtype=np.float64)
        if requested.size != 1:
            raise ValueError(f"action must be one irrigation amount in mm, got shape {requested.shape}")
        requested = float(requested.reshape(()))
        if not np.isfinite(requested):
            raise ValueError(f"irrigation must be a finite number of mm, got {requested}")
        applied = min(max(requested, 0.0), self._max_mm)
        if self.client.ended:
            raise RuntimeError("the season has ended (terminated or truncated); call reset()")
        obs, reward, terminated, truncated, info = self.client.step(applied)
        info = dict(info, irrigation_requested_mm=requested, irrigation_applied_mm=info["irrigation_mm"],
                    irrigation_clipped=info["irrigation_mm"] != requested)
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        if not getattr(self, "_closed", True):
            self._closed = True
            try:
                self.client.close()
            finally:
                self._ros.close()
        super().close()
