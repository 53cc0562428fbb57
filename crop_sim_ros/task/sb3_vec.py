"""Stable-Baselines3 face of the batched irrigation task: an SB3 ``VecEnv`` over :class:`IrrigationVectorEnv`.

Kept apart from ``crop_sim_ros.task`` (which does not import it) because Stable-Baselines3 imports torch.
SB3 semantics: an ending field resets within the same step; its last observation is in
``infos[i]["terminal_observation"]``, ``infos[i]["TimeLimit.truncated"]`` is True when the season's weather
ran out before maturity, and ``infos[i]["episode_return"]``, ``infos[i]["normalized_return"]`` and
``infos[i]["potential_yield_t_ha"]`` describe the ended season. Every step's ``infos[i]["true_biomass_t_ha"]``
is the field's noise-free biomass behind its next observation.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv

from .scenario import Scenario
from .vector_env import IrrigationVectorEnv

_FINAL_KEYS = ("episode_return", "normalized_return", "potential_yield_t_ha", "yield_t_ha")


class IrrigationSB3VecEnv(VecEnv):
    """N fields of one scenario as an SB3 VecEnv (observations (N, 20) float32, actions (N, 1) mm)."""

    def __init__(self, num_envs: int, scenario: str | Scenario = "benton-generated",
                 data_dir: str | Path | None = None, seed: int | None = None):
        self.venv = IrrigationVectorEnv(num_envs, scenario, data_dir, autoreset_mode=AutoresetMode.SAME_STEP)
        super().__init__(num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._actions: np.ndarray | None = None
        if seed is not None:
            self.seed(seed)

    def reset(self) -> np.ndarray:
        obs, _ = self.venv.reset(seed=self._seeds[0], options=self._options[0] or None)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rewards, terminations, truncations, infos = self.venv.step(self._actions)
        dones = terminations | truncations
        # Each field's true biomass after the step (for a field that ended, its new season's sowing day):
        # what the next observation shows, without noise (for potential-based reward shaping).
        result = [{"true_biomass_t_ha": float(b)} for b in infos["true_biomass_t_ha"]]
        if dones.any():
            final = infos["final_info"]
            for i in np.flatnonzero(dones):
                result[i] |= {"terminal_observation": infos["final_obs"][i],
                             "TimeLimit.truncated": bool(truncations[i]),
                             **{key: float(final[key][i]) for key in _FINAL_KEYS}}
        return obs, rewards.astype(np.float32), dones, result

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        raise AttributeError(f"IrrigationSB3VecEnv fields share one batched environment; cannot set {attr_name!r}")

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        raise AttributeError(f"IrrigationSB3VecEnv has no per-field environments to call {method_name!r} on")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(self._get_indices(indices))

    def _get_indices(self, indices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, int) else indices


def make_sb3_vec_env(scenario: str | Scenario = "benton-generated", n_envs: int = 8, seed: int | None = None,
                     data_dir: str | Path | None = None) -> IrrigationSB3VecEnv:
    """The batched irrigation task for Stable-Baselines3 (``PPO("MlpPolicy", make_sb3_vec_env(...))``)."""
    return IrrigationSB3VecEnv(n_envs, scenario, data_dir, seed)
