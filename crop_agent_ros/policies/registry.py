"""Every policy a user can name, in one registry: the agent node's ``policy`` parameter, ``crop-sim farm
--policy``, the launch file's ``policy`` argument and ``crop-sim evaluate --policies`` all read it.

=============== ===================================================================== ==================== ====
name            what it is                                                            reads                node
=============== ===================================================================== ==================== ====
``zero``        never irrigates                                                       -                    yes
``constant``    the same amount every day (the paper's baseline: 10 mm)               ``constant_mm``      yes
``best-constant`` the constant tuned on generated Benton seasons                      -                    yes
``refill``      the refill rule tuned on generated Benton seasons                     -                    yes
``margin``      refill to ET0/0.096 + a margin (where the shipped PPO's action starts) ``margin_mm``       no
``ppo``         a paper-task Stable-Baselines3 PPO policy file (default: the shipped) ``policy_file``      yes
``oracle``      the hindsight oracle (knows the season's weather: evaluation only)    -                    no
``budget-rule`` the water-budget rule tuned for a family task                         ``task``             yes
``paced-rule``  the paced rule tuned for a family task (issue 33)                     ``task``             yes
``es``          the shipped evolution-strategies agent of a family task               ``task``             yes
``es-residual`` the shipped residual agent of a family task (ES correcting the paced  ``task``             yes
                rule)
``agent``       a family agent trained by ``crop-sim train --task``                   ``policy_file``      yes
=============== ===================================================================== ==================== ====

"node": the agent node (and ``crop-sim farm``, the launch file) can run it. A kind that reads ``task`` takes the
simulator's scenario when the agent node is not given one.

Shipped agents are package data, ``crop_agent_ros/agents/<task>/<policy>/model.zip`` (+ ``model.json``): the
policy name (``es``, ``es-residual``) resolves to the agent of the current task (:func:`shipped_agent_file`); a task without one
is refused in one line naming the tasks that have one (:func:`shipped_agent_tasks`). Short names for evaluation
(:func:`make_policy`): a name above, ``constant<mm>`` and ``margin<mm>`` (e.g. ``constant10``, ``margin4``) and
``ppo:<path.zip>``. Heavy libraries (torch, stable_baselines3) load only when a learned policy is built.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .base import BasePolicy


@dataclass(frozen=True)
class PolicyArguments:
    """What a policy may need besides its name (each kind reads only its own)."""
    policy_file: str = ""  # ppo: a PPO zip ('' = the shipped one); agent: a family agent's model.zip
    constant_mm: float = 10.0  # constant: mm per day
    margin_mm: float = 4.0  # margin: mm above ET0/0.096
    task: str = ""  # budget-rule, es: the family task whose tuned rule or shipped agent


@dataclass(frozen=True)
class PolicyKind:
    name: str
    description: str
    build: Callable[[PolicyArguments], BasePolicy]
    node: bool = True  # the agent node can run it (the oracle needs the season's future)
    reads_task: bool = False  # built for a family task (PolicyArguments.task; the node: the simulator's scenario)


def _constant(arguments: PolicyArguments) -> BasePolicy:
    from .rules import ConstantPolicy
    return ConstantPolicy(arguments.constant_mm)


def _margin(arguments: PolicyArguments) -> BasePolicy:
    from .rules import DemandMarginPolicy
    return DemandMarginPolicy(arguments.margin_mm)


def _ppo(arguments: PolicyArguments) -> BasePolicy:
    from .sb3 import SHIPPED_PPO, SB3Policy
    return SB3Policy(arguments.policy_file or SHIPPED_PPO, name="ppo")


def _oracle(arguments: PolicyArguments) -> BasePolicy:
    from .oracle import OraclePolicy
    return OraclePolicy()


def _budget_rule(arguments: PolicyArguments) -> BasePolicy:
    if not arguments.task:
        raise ValueError("policy budget-rule needs a family task (task:=, --task)")
    from .family_tuning import tuned_rule
    return tuned_rule(arguments.task)


def _paced_rule(arguments: PolicyArguments) -> BasePolicy:
    if not arguments.task:
        raise ValueError("policy paced-rule needs a family task (task:=, --task)")
    from .family_tuning import tuned_rule
    return tuned_rule(arguments.task, "paced-rule")


def _agent(arguments: PolicyArguments) -> BasePolicy:
    if not arguments.policy_file:
        raise ValueError("policy agent needs policy_file:=<model.zip of a family agent>")
    from .learned import LearnedPolicy
    return LearnedPolicy(arguments.policy_file)


# crop_agent_ros/agents/<task>/<policy name>/model.zip (+ model.json): the shipped agents (package data)
AGENTS_DIR = Path(__file__).resolve().parents[1] / "agents"
SHIPPED_POLICIES = ("es", "es-residual")  # the policy names that resolve to a shipped agent of the task


def shipped_agent_tasks(policy: str) -> list[str]:
    """The tasks that have a shipped agent of the policy name ``policy`` (e.g. ``es``), sorted."""
    return sorted(path.parent.parent.name for path in AGENTS_DIR.glob(f"*/{policy}/model.zip"))


def shipped_agent_file(policy: str, task: str) -> Path:
    """The ``model.zip`` of the shipped ``policy`` agent of ``task``; ValueError in one line naming the task and
    the tasks that have one."""
    path = AGENTS_DIR / task / policy / "model.zip"
    if not task or "/" in task or not path.is_file():
        raise ValueError(f"policy {policy}: no shipped agent for task {task!r}; tasks with one: "
                         f"{', '.join(shipped_agent_tasks(policy))}")
    return path


def _shipped(policy: str) -> Callable[[PolicyArguments], BasePolicy]:
    """The builder of the shipped agent named ``policy`` (one of SHIPPED_POLICIES) for the arguments' task."""
    def build(arguments: PolicyArguments) -> BasePolicy:
        if not arguments.task:
            raise ValueError(f"policy {policy} needs a family task (task:=, --task)")
        from .learned import LearnedPolicy
        return LearnedPolicy(shipped_agent_file(policy, arguments.task), name=policy)
    return build


def _zero(arguments: PolicyArguments) -> BasePolicy:
    from .rules import ZeroPolicy
    return ZeroPolicy()


def _best_constant(arguments: PolicyArguments) -> BasePolicy:
    from .rules import best_constant_policy
    return best_constant_policy()


def _refill(arguments: PolicyArguments) -> BasePolicy:
    from .rules import tuned_refill_policy
    return tuned_refill_policy()


POLICY_KINDS: dict[str, PolicyKind] = {kind.name: kind for kind in (
    PolicyKind("zero", "never irrigates", _zero),
    PolicyKind("constant", "the same mm every day (constant_mm)", _constant),
    PolicyKind("best-constant", "the constant tuned on generated Benton seasons", _best_constant),
    PolicyKind("refill", "the refill rule tuned on generated Benton seasons", _refill),
    PolicyKind("margin", "refill to ET0/0.096 + margin_mm", _margin, node=False),
    PolicyKind("ppo", "a paper-task PPO policy file (default: the shipped one)", _ppo),
    PolicyKind("oracle", "the hindsight oracle (evaluation only)", _oracle, node=False),
    PolicyKind("budget-rule", "the water-budget rule tuned for a family task", _budget_rule, reads_task=True),
    PolicyKind("paced-rule", "the paced rule tuned for a family task", _paced_rule, reads_task=True),
    PolicyKind("es", "the shipped evolution-strategies agent of a family task", _shipped("es"), reads_task=True),
    PolicyKind("es-residual", "the shipped residual agent of a family task (ES correcting the paced rule)",
               _shipped("es-residual"), reads_task=True),
    PolicyKind("agent", "a family agent's policy file", _agent),
)}
NODE_POLICIES = tuple(name for name, kind in POLICY_KINDS.items() if kind.node)

_WITH_MM = re.compile(r"(constant|margin)(\d+(?:\.\d+)?)")


def build_policy(name: str, arguments: PolicyArguments = PolicyArguments(), node: bool = False) -> BasePolicy:
    """The policy of kind ``name`` (``node``: only a kind the agent node can run). ValueError for an unknown
    kind or a missing argument, FileNotFoundError for a missing policy or rule file."""
    kind = POLICY_KINDS.get(name)
    if kind is None or (node and not kind.node):
        known = NODE_POLICIES if node else tuple(POLICY_KINDS)
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(known)}")
    return kind.build(arguments)


def make_policy(name: str, ppo_path: str | None = None) -> BasePolicy:
    """A policy from its short name (see the module docstring; ``ppo_path``: the file of ``ppo``). ValueError
    lists the known names."""
    key = name.strip()
    match = _WITH_MM.fullmatch(key)
    if match:
        kind, mm = match.groups()
        return build_policy(kind, PolicyArguments(**{f"{kind}_mm": float(mm)}))
    if key.startswith("ppo:"):
        return build_policy("ppo", PolicyArguments(policy_file=key[4:]))
    if key not in POLICY_KINDS:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(POLICY_KINDS)}, constant<mm>, margin<mm>, "
                         "ppo:<path.zip>")
    return build_policy(key, PolicyArguments(policy_file=ppo_path or ""))
