"""The family's learned agents: what the network sees and does, and the policy-file loader.

The headline agent is Stable-Baselines3 PPO on the **normalised raw observation** with an **action in mm**
(no hand-made feature and no rule inside the action):

- observation: the task's 29 values (:mod:`crop_sim_ros.task.layout`), each centred and scaled by fixed
  statistics measured once before training (:class:`ObservationScaler`: mean and standard deviation over
  training seasons under a simple rule, saved with the policy), clipped to [-10, 10]; with ``history`` k > 1
  the network sees the last k scaled observations (a frame stack: memory for imperfect sensing);
- action: a in [-1, 1] -> irrigation (a + 1) / 2 x ``ACTION_SCALE_MM`` mm today (the environment then
  applies capacity and quota limits, and the observation shows what was applied).

The recurrent agent (sb3-contrib RecurrentPPO, an LSTM policy) sees one scaled observation per day and
carries its memory in the LSTM state. Both are :class:`~crop_agent_ros.policies.base.BasePolicy` objects once
loaded (:class:`LearnedPolicy`): ``reset`` clears the memory, ``act`` takes (N, 29) observations.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crop_sim_ros.task.layout import EXTENDED

from ..policies.base import BasePolicy

ACTION_SCALE_MM = 25.0  # a = 1 asks 25 mm: above any day's need (ET0 <= ~11 mm/d), below drainage waste
ALGORITHMS = ("ppo", "recurrent-ppo")
DAY = EXTENDED.index("days_since_sowing")


def action_to_mm(action: np.ndarray) -> np.ndarray:
    """Network actions in [-1, 1] -> irrigation mm in [0, ACTION_SCALE_MM]."""
    return (np.clip(np.asarray(action, dtype=float).reshape(-1), -1.0, 1.0) + 1.0) * 0.5 * ACTION_SCALE_MM


@dataclass(frozen=True)
class ObservationScaler:
    """Fixed affine scaling of the observation: (obs - mean) / std, clipped to [-10, 10] (std floored at
    1e-3 of the column's unit, so a constant column scales to 0)."""

    mean: tuple[float, ...]
    std: tuple[float, ...]

    @classmethod
    def fit(cls, observations: np.ndarray) -> "ObservationScaler":
        obs = np.asarray(observations, dtype=float).reshape(-1, EXTENDED.size)
        return cls(tuple(obs.mean(axis=0).tolist()), tuple(np.maximum(obs.std(axis=0), 1e-3).tolist()))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        scaled = (np.atleast_2d(np.asarray(obs, dtype=float)) - np.asarray(self.mean)) / np.asarray(self.std)
        return np.clip(scaled, -10.0, 10.0).astype(np.float32)


class History:
    """The last ``k`` scaled observations of N fields, newest last, flattened to (N, k x 29); a field whose
    day is 0 (a new season) starts its history with copies of its first observation."""

    def __init__(self, k: int):
        self.k = int(k)
        self._stack: np.ndarray | None = None

    def reset(self) -> None:
        self._stack = None

    def push(self, scaled: np.ndarray, day: np.ndarray) -> np.ndarray:
        n = len(scaled)
        if self._stack is None or self._stack.shape[0] != n:
            self._stack = np.repeat(scaled[:, None, :], self.k, axis=1)
        else:
            self._stack = np.concatenate([self._stack[:, 1:], scaled[:, None, :]], axis=1)
            fresh = day < 0.5
            if fresh.any():
                self._stack[fresh] = scaled[fresh][:, None, :]
        return self._stack.reshape(n, -1)


class LearnedPolicy(BasePolicy):
    """A family agent's policy file (``.zip`` + ``.json`` beside it) as a policy; deterministic actions."""

    observation_sizes = (EXTENDED.size,)

    def __init__(self, path: str | Path, name: str = "agent"):
        self.path = Path(path)
        config_file = self.path.with_suffix(".json")
        if not self.path.is_file() or not config_file.is_file():
            raise FileNotFoundError(f"{self.path} (and {config_file.name} beside it) must exist: train with "
                                    "`crop-sim train --task TASK`")
        self.config = json.loads(config_file.read_text())
        self.algorithm = self.config.get("algorithm")
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"{config_file}: algorithm {self.algorithm!r} is not one of {', '.join(ALGORITHMS)}")
        self.scaler = ObservationScaler(tuple(self.config["scaler"]["mean"]), tuple(self.config["scaler"]["std"]))
        self.history = History(self.config.get("history", 1))
        if self.algorithm == "ppo":
            from stable_baselines3 import PPO
            self.model = PPO.load(str(self.path), device="cpu")
        else:
            from sb3_contrib import RecurrentPPO
            self.model = RecurrentPPO.load(str(self.path), device="cpu")
        expected = (EXTENDED.size * self.history.k,)
        if self.model.observation_space.shape != expected or self.model.action_space.shape != (1,):
            raise ValueError(f"{self.path}: the network takes {self.model.observation_space.shape} and gives "
                             f"{self.model.action_space.shape}; this task needs {expected} -> (1,)")
        self.name = name
        self._lstm = None

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.history.reset()
        self._lstm = None

    def _act_batch(self, obs):
        scaled = self.history.push(self.scaler(obs), obs[:, DAY])
        if self.algorithm == "ppo":
            action, _ = self.model.predict(scaled, deterministic=True)
        else:
            starts = obs[:, DAY] < 0.5
            if self._lstm is not None and len(self._lstm[0][0]) != len(obs):
                self._lstm = None
            action, self._lstm = self.model.predict(scaled, state=self._lstm, episode_start=starts,
                                                    deterministic=True)
        return action_to_mm(action)

    def describe(self):
        return {"name": self.name, "path": str(self.path), "algorithm": self.algorithm,
                "history": self.history.k, "trained_on": self.config.get("task")}
