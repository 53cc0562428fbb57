"""A family agent's policy file as a policy: what the network sees and does, and the loader of ``model.zip`` +
``model.json`` (the shipped agents, :mod:`crop_agent_ros.policies.registry`, and any agent ``crop-sim train
--task`` writes). Training (:mod:`crop_agent_ros.learning`) imports it from here; this module never imports
training.

The headline agent is Stable-Baselines3 PPO on the **normalised raw observation** with an **action in mm**
(no hand-made feature and no rule inside the action):

- observation: the task's 29 values (:mod:`crop_sim_ros.task.layout`), each centred and scaled by fixed
  statistics measured once before training (:class:`ObservationScaler`: mean and standard deviation over
  training seasons under a simple rule, saved with the policy), clipped to [-10, 10]; with ``history`` k > 1
  the network sees the last k scaled observations (a frame stack: memory for imperfect sensing);
- action: a in [-1, 1] -> irrigation (a + 1) / 2 x ``ACTION_SCALE_MM`` mm today (the environment then
  applies capacity and quota limits, and the observation shows what was applied).

The **residual variant** (action kind ``"residual"``, reported as a variant, never as the headline agent) puts
the task's tuned water-budget rule inside the action: the rule (its parameters saved with the policy) sees
every observation and proposes r mm; the network also sees r / ``RESIDUAL_SPAN_MM`` as one more input value
and its action a in [-1, 1] corrects it: irrigation = clip(r + a x ``RESIDUAL_SPAN_MM``, 0, ``ACTION_SCALE_MM``)
mm. Training starts from a zero last layer (a = 0 for every input), i.e. at the rule.

With a **soil-water filter** (``crop-sim train --paw-filter``, a labelled feature of the agent, not of the
headline agent) the network also sees one more value: the PAW estimate of
:class:`~crop_agent_ros.policies.family.SoilWaterFilter` (the checkbook corrected by each reading, a Kalman
filter knowing the sensor's stated error), as (estimate / capacity) x 2 - 1. On ``benton-sensing`` (10 mm
noise, a third of the readings missing) its error is about a fifth of the readings'.

The recurrent agent (sb3-contrib RecurrentPPO, an LSTM policy) sees one scaled observation per day and
carries its memory in the LSTM state. The off-policy agent (Stable-Baselines3 TD3: a deterministic policy
improved along its critic's action gradient, exploring with Gaussian noise on the action) sees and acts as
PPO's. The evolution strategies agent (:mod:`crop_agent_ros.learning.evolution`) is the same network, improved by perturbing its
parameters rather than its actions (its file is a PPO policy file). What the network sees and what its action
does is one object, :class:`AgentInterface`, used alike by training and by the loaded policy. All are
:class:`~crop_agent_ros.policies.base.BasePolicy` objects once loaded (:class:`LearnedPolicy`): ``reset`` clears
the memory (and the rule's checkbook), ``act`` takes (N, 29) observations.
"""

from __future__ import annotations

import copy
import functools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from crop_sim_ros.task.layout import EXTENDED
from crop_sim_ros.usage import shown

from .base import BasePolicy
from .outlook import ClimateOutlook, ReadsOutlook

ACTION_SCALE_MM = 25.0  # a = 1 asks 25 mm: above any day's need (ET0 <= ~11 mm/d), below drainage waste
# The residual's reach: a in [-1, 1] corrects the rule by up to 10 mm either way, enough to cancel any day's
# rule action (the rule never asks more than the pivot's 8 mm/d) or to add more than a day of a pivot's water,
# while a unit of the action stays a few mm (the exploration noise, exp(log_std_init) x 10 mm, stays small).
RESIDUAL_SPAN_MM = 10.0
ALGORITHMS = ("ppo", "recurrent-ppo", "td3", "es", "grpo")
ACTION_KINDS = ("mm", "residual")
DAY = EXTENDED.index("days_since_sowing")


def algorithm_class(algorithm: str):
    """The Stable-Baselines3 class of ``algorithm`` (one of ALGORITHMS), imported on demand (evolution strategies'
    network lives in a PPO policy)."""
    if algorithm in ("ppo", "es", "grpo"):
        from stable_baselines3 import PPO
        return PPO
    if algorithm == "td3":
        from stable_baselines3 import TD3
        return TD3
    from sb3_contrib import RecurrentPPO
    return RecurrentPPO


def action_to_mm(action: np.ndarray) -> np.ndarray:
    """Network actions in [-1, 1] -> irrigation mm in [0, ACTION_SCALE_MM]."""
    return (np.clip(np.asarray(action, dtype=float).reshape(-1), -1.0, 1.0) + 1.0) * 0.5 * ACTION_SCALE_MM


def residual_to_mm(action: np.ndarray, rule_mm: np.ndarray) -> np.ndarray:
    """Network actions in [-1, 1] as corrections of the rule's ``rule_mm``: irrigation mm =
    clip(rule_mm + a x RESIDUAL_SPAN_MM, 0, ACTION_SCALE_MM)."""
    correction = np.clip(np.asarray(action, dtype=float).reshape(-1), -1.0, 1.0) * RESIDUAL_SPAN_MM
    return np.clip(np.asarray(rule_mm, dtype=float).reshape(-1) + correction, 0.0, ACTION_SCALE_MM)


# Least std of a scaled column (in the column's unit): a constant column scales to 0.
FLOOR_STD = 1e-3


@dataclass(frozen=True)
class ObservationScaler:
    """Fixed affine scaling of the observation: (obs - mean) / std, clipped to [-10, 10] (std floored at
    1e-3 of the column's unit, so a constant column scales to 0). The ``hidden`` columns (names of
    :data:`~crop_sim_ros.task.layout.EXTENDED`) always scale to 0: the network cannot read them (``crop-sim
    train --hide``, a labelled feature: e.g. the day count, whose meaning for the crop differs between climates;
    measured on ``climates6-quota``, hiding it made the transfer to the late-sown held-out climate worse, README)."""

    mean: tuple[float, ...]
    std: tuple[float, ...]
    hidden: tuple[str, ...] = ()

    def __post_init__(self):
        for name in self.hidden:
            EXTENDED.index(name)  # KeyError naming the columns that exist

    @functools.cached_property
    def _hidden_columns(self) -> list[int]:
        return [EXTENDED.index(name) for name in self.hidden]

    def record(self) -> dict:
        """The scaler as a policy file holds it (``hidden`` only when some column is hidden)."""
        return {"mean": list(self.mean), "std": list(self.std), **({"hidden": list(self.hidden)} if self.hidden else {})}

    @classmethod
    def from_record(cls, record: dict) -> "ObservationScaler":
        return cls(tuple(record["mean"]), tuple(record["std"]), tuple(record.get("hidden", ())))

    @classmethod
    def fit(cls, observations: np.ndarray, demonstrations: np.ndarray | None = None) -> "ObservationScaler":
        """Mean and std of each column of ``observations`` (the training task's). With ``demonstrations``, each
        column those observations hold constant (std at the floor) is scaled over both sets together:
        demonstrations of a task that differs from the training task in a constant the observation carries
        (another pivot's capacity, :func:`crop_agent_ros.learning.imitation.serves`) would otherwise scale to
        the +-10 clip in that column. Every other column keeps the training task's scaling."""
        obs = np.asarray(observations, dtype=float).reshape(-1, EXTENDED.size)
        mean, std = obs.mean(axis=0), np.maximum(obs.std(axis=0), FLOOR_STD)
        if demonstrations is not None:
            both = np.concatenate([obs, np.asarray(demonstrations, dtype=float).reshape(-1, EXTENDED.size)])
            constant = std <= FLOOR_STD
            mean = np.where(constant, both.mean(axis=0), mean)
            std = np.where(constant, np.maximum(both.std(axis=0), FLOOR_STD), std)
        return cls(tuple(mean.tolist()), tuple(std.tolist()))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        scaled = (np.atleast_2d(np.asarray(obs, dtype=float)) - np.asarray(self.mean)) / np.asarray(self.std)
        scaled[:, self._hidden_columns] = 0.0
        return np.clip(scaled, -10.0, 10.0).astype(np.float32)


AGENT_CONFIG_MAX_BYTES = 1024 * 1024  # model.json: a few kB (the scaler, the settings, a rule)
MAX_HISTORY = 365  # days of observations a network may see at once
_STRICT = ConfigDict(strict=True, frozen=True, allow_inf_nan=False)


class ScalerRecord(BaseModel):
    """``scaler`` of a policy file: a finite mean and a finite std > 0 per observed value (29 each), the hidden
    columns by name."""

    model_config = ConfigDict(_STRICT, extra="forbid")

    mean: list[float] = Field(min_length=EXTENDED.size, max_length=EXTENDED.size)
    std: list[Annotated[float, Field(gt=0)]] = Field(min_length=EXTENDED.size, max_length=EXTENDED.size)
    hidden: list[Literal[EXTENDED.names]] = []


class AgentConfig(BaseModel):
    """``model.json`` beside a family agent's ``model.zip`` (what :class:`LearnedPolicy` and ``crop-sim evaluate
    --task`` read), validated strictly: types (a number is a number, never a string or a bool), ranges, finite
    values, the scaler's length the observation's. Keys it does not name (a description of the run) are kept
    unread; those it names must be right."""

    model_config = ConfigDict(_STRICT, extra="allow")

    task: str = Field(min_length=1, max_length=200)
    algorithm: Literal[ALGORITHMS]
    history: int = Field(default=1, ge=1, le=MAX_HISTORY)
    action_kind: Literal[ACTION_KINDS] = "mm"  # files written before the residual variant have none: "mm"
    scaler: ScalerRecord
    seed: int = Field(default=-1, ge=-1, le=2**32 - 1)  # the training seed (-1: not recorded)
    timesteps: int = Field(default=0, ge=0)
    timesteps_at_save: int | None = Field(default=None, ge=0)
    training_seasons: int = Field(default=0, ge=0)
    n_envs: int = Field(default=0, ge=0)
    net_arch: list[Annotated[int, Field(ge=1)]] = []
    rule: dict[str, Any] | None = None
    paw_filter: dict[str, Any] | None = None
    outlook: dict[str, Any] | None = None

    @model_validator(mode="after")
    def _residual_has_its_rule(self) -> "AgentConfig":
        if self.action_kind == "residual" and self.rule is None:
            raise ValueError("action_kind 'residual' needs the rule it corrects (\"rule\": its facts and parameters)")
        return self


def _refuse_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict:
    keys = [key for key, _ in pairs]
    if len(set(keys)) != len(keys):
        raise ValueError(f"the key {shown(next(k for k in keys if keys.count(k) > 1))} appears twice")
    return dict(pairs)


def read_agent_config(path: str | Path) -> AgentConfig:
    """The validated ``model.json`` at ``path``: a regular file of at most 1 MB, one JSON object without
    duplicate keys, as :class:`AgentConfig` says. ValueError naming the file and every problem (with its path
    in the file, ``scaler.std.3: ...``), never quoting the file."""
    from crop_sim_ros.safe_yaml import read_text
    path = Path(path)
    text = read_text(path, AGENT_CONFIG_MAX_BYTES)  # not a regular file, too big, not UTF-8: ValueError
    try:
        record = json.loads(text, object_pairs_hook=_refuse_duplicate_keys)
    except RecursionError:
        raise ValueError(f"{path}: nested too deep") from None
    except ValueError as error:  # JSONDecodeError and the duplicate keys
        where = f" (line {error.lineno})" if isinstance(error, json.JSONDecodeError) else ""
        message = error.msg if isinstance(error, json.JSONDecodeError) else str(error)
        raise ValueError(f"{path}: not valid JSON{where}: {message}") from None
    if not isinstance(record, dict):
        raise ValueError(f"{path}: not a JSON object")
    try:
        return AgentConfig.model_validate(record)
    except ValidationError as error:
        problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or 'model.json'}: {e['msg']}" for e in error.errors()[:10])
        raise ValueError(f"{path}: {problems}") from None


def check_agent_task(config: AgentConfig, task: str, where: str) -> None:
    """ValueError unless the agent was trained on ``task`` (a network reads its own task's observation: the
    numbers of another task, even of the same layout, mean other things)."""
    if config.task != task:
        raise ValueError(f"{where}: trained on {shown(config.task)}, not {shown(task)} (an agent acts on its own "
                         f"task only; train one with `crop-sim train --task {shown(task)[1:-1]}`)")


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


class AgentInterface:
    """What a family agent's network sees and what its action does, for a batch of N fields (one object per
    batch: training's environment wrapper and the loaded policy both use it).

    ``observe(raw)`` takes the fields' (N, 29) observations of the day, in order, each exactly once: it pushes
    them into the history, updates the ``paw_filter`` (a
    :class:`~crop_agent_ros.policies.family.SoilWaterFilter`, if any) and, for ``action_kind="residual"``, lets
    the ``rule`` (a
    :class:`~crop_agent_ros.policies.family.WaterBudgetRule`) read them and propose today's mm (its checkbook
    restarts on a field's sowing day, day 0, so fields may start new seasons at different steps); it returns
    the network's (N, input_size) input. ``to_mm(action)`` turns the network's action for that day into mm."""

    def __init__(self, scaler: ObservationScaler, history: int, action_kind: str = "mm", rule=None,
                 paw_filter=None, outlook=None):
        if action_kind not in ACTION_KINDS:
            raise ValueError(f"action kind {action_kind!r} is not one of {', '.join(ACTION_KINDS)}")
        if (action_kind == "residual") != (rule is not None):
            raise ValueError("the residual action needs the rule it corrects; the mm action takes no rule")
        self.scaler = scaler
        self.history = History(history)
        self.action_kind = action_kind
        self.rule = rule
        self.paw_filter = paw_filter
        self.outlook = outlook
        self._rule_mm: np.ndarray | None = None

    @property
    def input_size(self) -> int:
        """29 values per day of history, plus the filter's PAW estimate, plus the rule's proposal for the
        residual, plus the climate outlook's values."""
        return (EXTENDED.size * self.history.k + (self.paw_filter is not None) + (self.action_kind == "residual")
                + (0 if self.outlook is None else self.outlook.size))

    def reset(self) -> None:
        self.history.reset()
        self._rule_mm = None
        for part in (self.rule, self.paw_filter):
            if part is not None:
                part.reset()

    def scaled_estimate(self, paw_mm: np.ndarray) -> np.ndarray:
        """The filter's PAW estimates (N,) mm as the network sees them: (estimate / capacity) x 2 - 1."""
        return np.asarray(paw_mm, dtype=float) / self.paw_filter.capacity_mm * 2.0 - 1.0

    def network_input(self, stacked: np.ndarray, paw_mm: np.ndarray | None, rule_mm: np.ndarray | None,
                      outlook: np.ndarray | None = None) -> np.ndarray:
        """The network's input: the (scaled, stacked) observations, then the filter's estimate, then the rule's
        proposal, then the climate outlook's values, each where the interface has one."""
        parts = [stacked]
        if paw_mm is not None:
            parts.append(self.scaled_estimate(paw_mm)[:, None])
        if rule_mm is not None:
            parts.append((rule_mm / RESIDUAL_SPAN_MM)[:, None])
        if outlook is not None:
            parts.append(outlook)
        return np.concatenate(parts, axis=1).astype(np.float32)

    def observe(self, raw: np.ndarray, terminal: dict[int, np.ndarray] | None = None, ended_outlook=None):
        """The network's input for the day's raw (N, 29) observations; with ``terminal`` (field -> the last
        observation of a season that just ended, which ``raw`` replaces by the next season's first), also
        returns the input each such last observation would have given (for bootstrapping a truncated season:
        its own day repeated as the history, the filter's and the rule's outputs from their state before
        today, and ``ended_outlook``'s values: a copy of the outlook with the fields' climates before today's new
        seasons)."""
        raw = np.asarray(raw, dtype=float)
        terminal_inputs = {}
        if terminal:
            rows = sorted(terminal)
            last = raw.copy()
            last[rows] = np.stack([np.asarray(terminal[i], dtype=float).reshape(-1) for i in rows])
            # copies of the rule and the filter read the last observations, so each sees each observation once
            rule_last = None if self.rule is None else copy.deepcopy(self.rule).act(last)
            paw_last = None if self.paw_filter is None else copy.deepcopy(self.paw_filter).update(last)
            # the outlook of a season that ended: its fields' climates before the training environment tells the
            # new seasons' (ended_outlook)
            outlook_last = None
            if self.outlook is not None:
                outlook_last = (self.outlook if ended_outlook is None else ended_outlook)(last)
            for i in rows:
                repeated = np.tile(self.scaler(last[i])[0], self.history.k)[None, :]
                terminal_inputs[i] = self.network_input(repeated, None if paw_last is None else paw_last[[i]],
                                                        None if rule_last is None else rule_last[[i]],
                                                        None if outlook_last is None else outlook_last[[i]])[0]
        stacked = self.history.push(self.scaler(raw), raw[:, DAY])
        paw_mm = None if self.paw_filter is None else self.paw_filter.update(raw)
        self._rule_mm = None if self.rule is None else np.asarray(self.rule.act(raw), dtype=float).reshape(-1)
        outlook = None if self.outlook is None else self.outlook(raw)
        return self.network_input(stacked, paw_mm, self._rule_mm, outlook), terminal_inputs

    def to_mm(self, action: np.ndarray) -> np.ndarray:
        """The network's action for the day last observed -> irrigation mm (N,)."""
        if self.action_kind == "mm":
            return action_to_mm(action)
        if self._rule_mm is None:
            raise RuntimeError("the residual action corrects the rule's proposal: observe the day first")
        return residual_to_mm(action, self._rule_mm)


class LearnedPolicy(ReadsOutlook, BasePolicy):
    """A family agent's policy file (``.zip`` + ``.json`` beside it) as a policy; deterministic actions."""

    observation_sizes = (EXTENDED.size,)

    def __init__(self, path: str | Path, name: str = "agent"):
        self.path = Path(path)
        config_file = self.path.with_suffix(".json")
        if not self.path.is_file() or not config_file.is_file():
            raise FileNotFoundError(f"{self.path} (and {config_file.name} beside it) must exist: train with "
                                    "`crop-sim train --task TASK`")
        agent = read_agent_config(config_file)
        self.agent_config = agent
        self.config = agent.model_dump()
        self.algorithm = agent.algorithm
        self.task = agent.task
        action_kind = agent.action_kind
        rule = None
        if action_kind == "residual":
            from .family_tuning import rule_from_record
            try:
                rule = rule_from_record(agent.rule)
            except (KeyError, TypeError, ValueError) as error:
                raise ValueError(f"{config_file}: rule: {shown(error)}") from None
        paw_filter = None
        if agent.paw_filter is not None:
            from .family import SoilWaterFilter
            try:
                paw_filter = SoilWaterFilter(**agent.paw_filter)
            except (TypeError, ValueError) as error:
                raise ValueError(f"{config_file}: paw_filter {shown(agent.paw_filter)}: {error}") from None
        outlook = None
        if agent.outlook is not None:
            outlook = ClimateOutlook()
            if agent.outlook != outlook.record():
                raise ValueError(f"{config_file}: outlook {shown(agent.outlook)} is not this version's "
                                 f"{outlook.record()!r}")
        scaler = ObservationScaler(tuple(agent.scaler.mean), tuple(agent.scaler.std), tuple(agent.scaler.hidden))
        self.interface = AgentInterface(scaler, agent.history, action_kind, rule, paw_filter, outlook)
        self.model = algorithm_class(self.algorithm).load(str(self.path), device="cpu")
        expected = (self.interface.input_size,)
        if self.model.observation_space.shape != expected or self.model.action_space.shape != (1,):
            raise ValueError(f"{self.path}: the network takes {self.model.observation_space.shape} and gives "
                             f"{self.model.action_space.shape}; this task needs {expected} -> (1,)")
        self.name = name
        self._lstm = None

    @property
    def history(self) -> History:
        return self.interface.history

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.interface.reset()
        self._lstm = None

    @property
    def outlook(self):
        """The climate outlook the network reads (:class:`~.outlook.ClimateOutlook`), or None."""
        return self.interface.outlook

    def _act_batch(self, obs):
        inputs, _ = self.interface.observe(obs)
        if self.algorithm != "recurrent-ppo":
            action, _ = self.model.predict(inputs, deterministic=True)
        else:
            starts = obs[:, DAY] < 0.5
            if self._lstm is not None and len(self._lstm[0][0]) != len(obs):
                self._lstm = None
            action, self._lstm = self.model.predict(inputs, state=self._lstm, episode_start=starts,
                                                    deterministic=True)
        return self.interface.to_mm(action)

    def describe(self):
        return {"name": self.name, "path": str(self.path), "algorithm": self.algorithm,
                "history": self.history.k, "action_kind": self.interface.action_kind,
                "paw_filter": None if self.interface.paw_filter is None else self.interface.paw_filter.record(),
                "outlook": None if self.interface.outlook is None else self.interface.outlook.record(),
                "trained_on": self.config.get("task")}
