"""Tiny Stable-Baselines3 PPO policy files for the tests, made in the test (never trained: only their spaces
matter): one whose network observes ``observation_shape`` and acts with ``action_shape``."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np


class Spaces(gym.Env):
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

    model = PPO("MlpPolicy", Spaces(observation_shape, action_shape), n_steps=8, batch_size=8, seed=0,
                policy_kwargs={"net_arch": [4]}, device="cpu")
    model.save(str(path))
    return path


def tiny_task_training(out: Path, task: str, seed: int, *extra: str, timesteps: int = 512, n_envs: int = 4,
                       net_arch: str = "8") -> dict:
    """``crop-sim train --task`` with a tiny budget (``extra``: more arguments, e.g. ``--action residual``):
    the training run's summary; its files go to ``out``."""
    import argparse
    from crop_agent_ros.learning import train
    from crop_agent_ros.learning.train_task import train_task
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    args = parser.parse_args(["--task", task, "--seed", str(seed), "--timesteps", str(timesteps), "--n-envs",
                              str(n_envs), "--n-steps", "64", "--batch-size", "64", "--n-epochs", "1", "--eval-freq",
                              "100000", "--validation-seasons", "2", "--net-arch", net_arch, "--no-progress",
                              "--out", str(out), *extra])
    return train_task(args)
