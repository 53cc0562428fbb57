"""Training's side of the family agents: the spaces of the network that evolution strategies and GRPO train.
What the network sees and does and the policy-file loader live in :mod:`crop_agent_ros.policies.learned` (a
shipped agent runs without training).
"""

from __future__ import annotations

import numpy as np

__all__ = ["network_spaces"]


def network_spaces(input_size: int):
    """A one-field SB3 VecEnv that only declares the family network's spaces (``input_size`` scaled inputs in
    [-10, 10], one action in [-1, 1]): what Stable-Baselines3 needs to build a policy that never trains on an
    environment (the container of evolution strategies' and GRPO's actor)."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    class Spaces(gym.Env):
        observation_space = gym.spaces.Box(-10.0, 10.0, (input_size,), np.float32)
        action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    return DummyVecEnv([Spaces])
