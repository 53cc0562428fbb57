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


# A tiny budget for each algorithm's tests: its recipe's settings that make a run take seconds.
TINY = {"ppo": {"n_envs": 4, "n_steps": 64, "batch_size": 64, "n_epochs": 1, "eval_freq": 100_000},
        "es": {"pairs": 3, "seasons": 3, "eval_freq": 100_000},
        "grpo": {"groups": 3, "group_size": 4, "batch_size": 256, "n_epochs": 1, "eval_freq": 100_000}}


def tiny_task_training(out: Path, task: str, seed: int, algorithm: str = "ppo", timesteps: int = 512,
                       net_arch: tuple[int, ...] = (8,), **hyperparams) -> dict:
    """``crop-sim train --task TASK --algorithm A`` with a tiny budget (``hyperparams``: more settings, e.g.
    ``paw_filter=True``, over :data:`TINY`): the training run's summary; its files go to ``out``. A refused
    setting raises UsageError (as the command's ``run`` does)."""
    import argparse
    import json
    from crop_agent_ros.learning import train
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    settings = {**TINY[algorithm], "timesteps": timesteps, "validation_seasons": 2, "net_arch": list(net_arch),
                **hyperparams}
    argv = ["--task", task, "--algorithm", algorithm, "--seed", str(seed), "--out", str(out), "--no-progress"]
    for key, value in settings.items():
        argv += ["--hyperparams", f"{key}={json.dumps(value)}"]
    train.run(parser.parse_args(argv))
    return json.loads((out / "summary.json").read_text())
