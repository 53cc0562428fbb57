"""Irrigation policies behind one interface (:class:`Policy`: ``name``, ``reset(seed)``,
``act(observation) -> mm``): zero, constant, best constant and refill rules (tuned on generated seasons),
a Stable-Baselines3 PPO policy file, and the hindsight oracle.

:func:`make_policy` builds one from a short name: ``zero``, ``constant<mm>`` (e.g. ``constant10``, the paper's
baseline), ``best-constant``, ``refill``, ``ppo`` (the shipped ``ppo_benton.zip``) or ``ppo:<path.zip>``,
``oracle``; ``margin<mm>`` (e.g. ``margin4``) is the demand-aware refill that the PPO policy starts
from, a reference for how much PPO learned. Heavy libraries (torch, stable_baselines3) load only when a PPO policy is made.
"""

from __future__ import annotations

import re

from .base import OBS_SIZE, BasePolicy, Policy, SeasonContext
from .rules import ConstantPolicy, DemandMarginPolicy, RefillPolicy, ZeroPolicy, best_constant_policy, tuned_refill_policy

POLICY_NAMES = ("zero", "constant10", "best-constant", "refill", "ppo", "oracle")
# What an agent node (and `crop-sim farm`) runs: the paper task's policies above (constant: constant_mm), a
# family task's tuned rule (budget-rule) or a family agent's policy file (agent).
NODE_POLICIES = ("zero", "constant", "best-constant", "refill", "ppo", "budget-rule", "agent")


def make_policy(name: str, ppo_path: str | None = None) -> BasePolicy:
    """A policy from its short name (see the module docstring); ValueError lists the known names."""
    key = name.strip()
    if key == "zero":
        return ZeroPolicy()
    match = re.fullmatch(r"constant(\d+(?:\.\d+)?)", key)
    if match:
        return ConstantPolicy(float(match.group(1)))
    match = re.fullmatch(r"margin(\d+(?:\.\d+)?)", key)
    if match:
        return DemandMarginPolicy(float(match.group(1)))
    if key == "best-constant":
        return best_constant_policy()
    if key == "refill":
        return tuned_refill_policy()
    if key == "ppo" or key.startswith("ppo:"):
        from .sb3 import SHIPPED_PPO, SB3Policy
        path = key[4:] if key.startswith("ppo:") else (ppo_path or SHIPPED_PPO)
        return SB3Policy(path, name="ppo")
    if key == "oracle":
        from .oracle import OraclePolicy
        return OraclePolicy()
    raise ValueError(f"unknown policy {name!r}; known: {', '.join(POLICY_NAMES)}, constant<mm>, margin<mm>, "
                     "ppo:<path.zip>")


__all__ = ["NODE_POLICIES", "OBS_SIZE", "POLICY_NAMES", "BasePolicy", "ConstantPolicy", "DemandMarginPolicy", "Policy", "RefillPolicy", "SeasonContext",
           "ZeroPolicy", "best_constant_policy", "make_policy", "tuned_refill_policy"]
