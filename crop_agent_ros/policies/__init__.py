"""Irrigation policies behind one interface (:class:`Policy`: ``name``, ``reset(seed)``,
``act(observation) -> mm``): zero, constant, best constant and refill rules (tuned on generated seasons),
a Stable-Baselines3 PPO policy file, the hindsight oracle, and the task family's water-budget rule.

Every policy a user can name is in one registry (:mod:`crop_agent_ros.policies.registry`): :func:`make_policy`
builds one from a short name (``zero``, ``constant<mm>`` e.g. ``constant10``, the paper's baseline,
``best-constant``, ``refill``, ``margin<mm>``, ``ppo`` or ``ppo:<path.zip>``, ``oracle``, ...), and the agent node
runs the kinds in :data:`NODE_POLICIES`. Heavy libraries (torch, stable_baselines3) load only when a PPO policy
is made.
"""

from __future__ import annotations

from .base import OBS_SIZE, BasePolicy, Policy, SeasonContext
from .registry import NODE_POLICIES, POLICY_KINDS, PolicyArguments, build_policy, make_policy
from .rules import ConstantPolicy, DemandMarginPolicy, RefillPolicy, ZeroPolicy, best_constant_policy, tuned_refill_policy

__all__ = ["NODE_POLICIES", "OBS_SIZE", "POLICY_KINDS", "BasePolicy", "ConstantPolicy", "DemandMarginPolicy",
           "Policy", "PolicyArguments", "RefillPolicy", "SeasonContext", "ZeroPolicy", "best_constant_policy",
           "build_policy", "make_policy", "tuned_refill_policy"]
