"""Tiny Stable-Baselines3 PPO policy files for the tests, made in the test (never trained: only their spaces
matter): one whose network observes ``observation_shape`` and acts with ``action_shape``."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np


class _Spaces(gym.Env):
    """An environment that only declares its spaces (PPO needs one to build its network)."""

    def __init__(self, observation_shape: tuple[int, ...], action_shape: tuple[int, ...]):
        self.observation_space = gym.spaces.Box(-1.0, 1.0, observation_shape, np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, action_shape, np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(self.observation_space.shape, np.float32), {}

    def step(self, action):
        return np.zeros(self.observation_space.shape, np.float32), 0.0, True, False, {}


def ppo_file(path: Path, observation_shape: tuple[int, ...], action_shape: tuple[int, ...] = (1,)) -> Path:
    """Save an untrained PPO policy with these spaces at ``path`` (a .zip, no .json config beside it)."""
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", _Spaces(observation_shape, action_shape), n_steps=8, batch_size=8, seed=0,
                policy_kwargs={"net_arch": [4]}, device="cpu")
    model.save(str(path))
    return path
