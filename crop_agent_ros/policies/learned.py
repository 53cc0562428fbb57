"""A family agent's policy file as a policy: what the network sees and does, and the loader of ``model.zip`` +
``model.json`` (the shipped agents, :mod:`crop_agent_ros.policies.registry`, and any agent ``crop-sim train
--task`` writes). Training (:mod:`crop_agent_ros.learning`) imports it from here; this module never imports
training.

The headline agent is Stable-Baselines3 PPO on the **normalised raw observation** with an **action in mm**
(no hand-made feature and no rule inside the action):

- observation: the task's 29 values (:mod:`crop_sim_ros.task.layout`), each centred and scaled by fixed
  statistics measured once before training (:class:`ObservationScaler`: mean and standard deviation over
  training seasons under a simple rule, saved with the policy), clipped to [-10, 10];
- action: a in [-1, 1] -> irrigation (a + 1) / 2 x ``ACTION_SCALE_MM`` mm today (the environment then
  applies capacity and quota limits, and the observation shows what was applied).

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
the memory (and the filter's estimate), ``act`` takes (N, 29) observations.

The **residual agent** (``crop-sim train --task T --algorithm es --hyperparams residual=true``; shipped as
``es-residual``, evaluated beside the headline agent) puts the task's tuned paced rule
(:mod:`~crop_agent_ros.policies.paced_rule`, its facts and parameters saved in ``model.json`` as
``residual_rule``) inside the action: the rule reads every observation and proposes r mm; the network also sees
r / ``RESIDUAL_SPAN_MM`` as one more input and its action a in [-1, 1] corrects it: irrigation =
clip(r + a x ``RESIDUAL_SPAN_MM``, 0, ``ACTION_SCALE_MM``) mm. Training starts from a zero last layer (a = 0
for every input), i.e. at the rule, and the run's checkpoint at step 0 is the rule itself: the validation
choice (:func:`~crop_agent_ros.learning.train_task.select_model`) keeps the rule where learning found nothing.

Research variants of earlier versions (a residual action on the budget rule, a climate outlook, hidden
observation columns, a frame history of more than one day) are no longer run: a ``model.json`` that asks for one
is refused at load in one line (git history keeps their code).
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from crop_sim_ros.task.layout import EXTENDED
from crop_sim_ros.usage import shown

from .base import BasePolicy

ACTION_SCALE_MM = 25.0  # a = 1 asks 25 mm: above any day's need (ET0 <= ~11 mm/d), below drainage waste
# The residual's reach: a in [-1, 1] corrects the rule by up to 10 mm either way, enough to cancel any day's
# rule action (a pivot gives at most 8 mm/d) or add more than a day of the pivot's water, while the
# perturbations of evolution strategies move the action by a few mm.
RESIDUAL_SPAN_MM = 10.0
ACTION_KINDS = ("mm", "residual")
# The columns of the day's weather that say which climate a field is in: temperatures, radiation, humidity,
# wind and ET0, today's and forecast. An agent trained with ``weather_inputs`` false sees them at their training
# mean (0 once scaled): a correction keyed on one site's weather has no evidence behind it in another climate.
# Rain (today's and forecast) stays: it is water, not climate.
CLIMATE_COLUMNS = ("tmax_degc", "tmin_degc", "tavg_degc", "srad_mj_m2", "vap_hpa", "wind_m_s", "et0_mm",
                   "forecast_tmax_degc", "forecast_tmin_degc", "forecast_tavg_degc", "forecast_srad_mj_m2",
                   "forecast_vap_hpa", "forecast_wind_m_s")
ALGORITHMS = ("ppo", "recurrent-ppo", "td3", "es", "grpo")
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
    """Network actions in [-1, 1] as corrections of the rule's ``rule_mm`` (N,): irrigation mm =
    clip(rule_mm + a x RESIDUAL_SPAN_MM, 0, ACTION_SCALE_MM)."""
    correction = np.clip(np.asarray(action, dtype=float).reshape(-1), -1.0, 1.0) * RESIDUAL_SPAN_MM
    return np.clip(np.asarray(rule_mm, dtype=float).reshape(-1) + correction, 0.0, ACTION_SCALE_MM)


# Least std of a scaled column (in the column's unit): a constant column scales to 0.
FLOOR_STD = 1e-3


@dataclass(frozen=True)
class ObservationScaler:
    """Fixed affine scaling of the observation: (obs - mean) / std, clipped to [-10, 10] (std floored at
    1e-3 of the column's unit, so a constant column scales to 0)."""

    mean: tuple[float, ...]
    std: tuple[float, ...]

    def record(self) -> dict:
        """The scaler as a policy file holds it."""
        return {"mean": list(self.mean), "std": list(self.std)}

    @classmethod
    def fit(cls, observations: np.ndarray) -> "ObservationScaler":
        """Mean and std of each column of ``observations`` (the training task's)."""
        obs = np.asarray(observations, dtype=float).reshape(-1, EXTENDED.size)
        mean, std = obs.mean(axis=0), np.maximum(obs.std(axis=0), FLOOR_STD)
        return cls(tuple(mean.tolist()), tuple(std.tolist()))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        scaled = (np.atleast_2d(np.asarray(obs, dtype=float)) - np.asarray(self.mean)) / np.asarray(self.std)
        return np.clip(scaled, -10.0, 10.0).astype(np.float32)


AGENT_CONFIG_MAX_BYTES = 1024 * 1024  # model.json: a few kB (the scaler, the settings)
_STRICT = ConfigDict(strict=True, frozen=True, allow_inf_nan=False)
# what a model.json of an earlier version's research variant is told (those variants' code is in git history)
REMOVED = "is a research variant of an earlier version that this one no longer runs (git history keeps its code)"


class ScalerRecord(BaseModel):
    """``scaler`` of a policy file: a finite mean and a finite std > 0 per observed value (29 each)."""

    model_config = ConfigDict(_STRICT, extra="forbid")

    mean: list[float] = Field(min_length=EXTENDED.size, max_length=EXTENDED.size)
    std: list[Annotated[float, Field(gt=0)]] = Field(min_length=EXTENDED.size, max_length=EXTENDED.size)
    hidden: Any = None  # an earlier version's hidden columns: refused

    @field_validator("hidden")
    @classmethod
    def _no_hidden_columns(cls, hidden):
        if hidden:
            raise ValueError(f"hiding observation columns {REMOVED}")
        return None


class AgentConfig(BaseModel):
    """``model.json`` beside a family agent's ``model.zip`` (what :class:`LearnedPolicy` and ``crop-sim evaluate
    --task`` read), validated strictly: types (a number is a number, never a string or a bool), ranges, finite
    values, the scaler's length the observation's. Keys it does not name (a description of the run) are kept
    unread; those it names must be right. ``action_kind`` ``residual`` needs ``residual_rule`` (the paced rule
    it corrects: ``facts`` and ``parameters``, as in ``family_<task>-paced.json``), and ``mm`` takes none. An
    earlier version's research variant (a residual on the budget rule, an ``outlook``, ``scaler.hidden``
    columns, ``history`` above 1) is refused, naming the key."""

    model_config = ConfigDict(_STRICT, extra="allow")

    task: str = Field(min_length=1, max_length=200)
    algorithm: Literal[ALGORITHMS]
    history: int = Field(default=1, ge=1)  # days of observations the network sees: 1
    action_kind: str = "mm"
    residual_rule: dict[str, Any] | None = None
    weather_inputs: bool = True  # False: the network sees CLIMATE_COLUMNS at their training mean
    scaler: ScalerRecord
    seed: int = Field(default=-1, ge=-1, le=2**32 - 1)  # the training seed (-1: not recorded)
    timesteps: int = Field(default=0, ge=0)
    timesteps_at_save: int | None = Field(default=None, ge=0)
    training_seasons: int = Field(default=0, ge=0)
    n_envs: int = Field(default=0, ge=0)
    net_arch: list[Annotated[int, Field(ge=1)]] = []
    paw_filter: dict[str, Any] | None = None
    outlook: Any = None  # an earlier version's climate outlook: refused

    @field_validator("history")
    @classmethod
    def _one_day(cls, history: int) -> int:
        if history != 1:
            raise ValueError(f"a frame history of more than one day {REMOVED}")
        return history

    @field_validator("action_kind")
    @classmethod
    def _known_action(cls, kind: str) -> str:
        if kind not in ACTION_KINDS:
            raise ValueError(f"Input should be {' or '.join(map(repr, ACTION_KINDS))}")
        return kind

    @model_validator(mode="after")
    def _residual_names_its_rule(self):
        if self.action_kind == "residual" and self.residual_rule is None:
            extra = self.model_extra or {}
            if "rule" in extra:  # what an earlier version's residual on the budget rule wrote
                raise ValueError(f"action_kind: the residual action on the budget rule {REMOVED}")
            raise ValueError("action_kind: 'residual' needs residual_rule (the paced rule it corrects, as "
                             "`crop-sim train --task T --algorithm es --hyperparams residual=true` writes)")
        if self.action_kind == "mm" and self.residual_rule is not None:
            raise ValueError("residual_rule: only for action_kind 'residual' (an action in mm corrects no rule)")
        return self

    @field_validator("outlook")
    @classmethod
    def _no_outlook(cls, outlook):
        if outlook is not None:
            raise ValueError(f"the climate outlook {REMOVED}")
        return None


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
        problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or 'model.json'}: {e['msg'].removeprefix('Value error, ')}"
                             for e in error.errors()[:10])
        raise ValueError(f"{path}: {problems}") from None


def check_agent_task(config: AgentConfig, task: str, where: str) -> None:
    """ValueError unless the agent was trained on ``task`` (a network reads its own task's observation: the
    numbers of another task, even of the same layout, mean other things)."""
    if config.task != task:
        raise ValueError(f"{where}: trained on {shown(config.task)}, not {shown(task)} (an agent acts on its own "
                         f"task only; train one with `crop-sim train --task {shown(task)[1:-1]}`)")


class AgentInterface:
    """What a family agent's network sees and what its action does, for a batch of N fields (one object per
    batch: training's environment wrapper and the loaded policy both use it).

    ``observe(raw)`` takes the fields' (N, 29) observations of the day, in order, each exactly once: it scales
    them and updates the ``paw_filter`` (a :class:`~crop_agent_ros.policies.family.SoilWaterFilter`, if any); with
    a ``rule`` (the residual agent's :class:`~crop_agent_ros.policies.paced_rule.PacedRule`) the rule reads them
    too and proposes today's mm. It returns the network's (N, input_size) input. ``to_mm(action)`` turns the
    network's action for that day into mm (for the residual: the rule's proposal corrected)."""

    def __init__(self, scaler: ObservationScaler, paw_filter=None, rule=None, weather_inputs: bool = True):
        self.scaler = scaler
        self.paw_filter = paw_filter
        self.rule = rule
        self.weather_inputs = bool(weather_inputs)
        self._blind = [] if self.weather_inputs else [EXTENDED.index(name) for name in CLIMATE_COLUMNS]
        self._rule_mm: np.ndarray | None = None

    def scaled(self, raw: np.ndarray) -> np.ndarray:
        """The scaled observations the network sees (without ``weather_inputs``: CLIMATE_COLUMNS at 0, their
        training mean)."""
        scaled = self.scaler(raw)
        scaled[:, self._blind] = 0.0
        return scaled

    @property
    def action_kind(self) -> str:
        return "mm" if self.rule is None else "residual"

    @property
    def input_size(self) -> int:
        """The 29 scaled values, plus the filter's PAW estimate, plus the rule's proposal."""
        return EXTENDED.size + (self.paw_filter is not None) + (self.rule is not None)

    def reset(self) -> None:
        self._rule_mm = None
        if self.paw_filter is not None:
            self.paw_filter.reset()
        if self.rule is not None:
            self.rule.reset()

    def scaled_estimate(self, paw_mm: np.ndarray) -> np.ndarray:
        """The filter's PAW estimates (N,) mm as the network sees them: (estimate / capacity) x 2 - 1."""
        return np.asarray(paw_mm, dtype=float) / self.paw_filter.capacity_mm * 2.0 - 1.0

    def network_input(self, scaled: np.ndarray, paw_mm: np.ndarray | None,
                      rule_mm: np.ndarray | None = None) -> np.ndarray:
        """The network's input: the scaled observations, then the filter's estimate where there is a filter, then
        the rule's proposal / RESIDUAL_SPAN_MM where there is a rule."""
        parts = [scaled]
        if paw_mm is not None:
            parts.append(self.scaled_estimate(paw_mm)[:, None])
        if rule_mm is not None:
            parts.append((np.asarray(rule_mm, dtype=float) / RESIDUAL_SPAN_MM)[:, None])
        return np.concatenate(parts, axis=1).astype(np.float32)

    def observe(self, raw: np.ndarray, terminal: dict[int, np.ndarray] | None = None):
        """The network's input for the day's raw (N, 29) observations; with ``terminal`` (field -> the last
        observation of a season that just ended, which ``raw`` replaces by the next season's first), also
        returns the input each such last observation would have given (for bootstrapping a truncated season:
        the filter's estimate and the rule's proposal from their state before today)."""
        raw = np.asarray(raw, dtype=float)
        terminal_inputs = {}
        if terminal:
            rows = sorted(terminal)
            last = raw.copy()
            last[rows] = np.stack([np.asarray(terminal[i], dtype=float).reshape(-1) for i in rows])
            # copies of the filter and the rule read the last observations, so each sees an observation once
            paw_last = None if self.paw_filter is None else copy.deepcopy(self.paw_filter).update(last)
            rule_last = None if self.rule is None else copy.deepcopy(self.rule).act(last)
            for i in rows:
                terminal_inputs[i] = self.network_input(self.scaled(last[i]),
                                                        None if paw_last is None else paw_last[[i]],
                                                        None if rule_last is None else rule_last[[i]])[0]
        paw_mm = None if self.paw_filter is None else self.paw_filter.update(raw)
        self._rule_mm = None if self.rule is None else np.asarray(self.rule.act(raw), dtype=float).reshape(-1)
        return self.network_input(self.scaled(raw), paw_mm, self._rule_mm), terminal_inputs

    def to_mm(self, action: np.ndarray) -> np.ndarray:
        """The network's action for the day last observed -> irrigation mm (N,)."""
        if self.rule is None:
            return action_to_mm(action)
        if self._rule_mm is None:
            raise RuntimeError("the residual action corrects the rule's proposal: observe the day first")
        return residual_to_mm(action, self._rule_mm)


class LearnedPolicy(BasePolicy):
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
        paw_filter = None
        if agent.paw_filter is not None:
            from .family import SoilWaterFilter
            try:
                paw_filter = SoilWaterFilter(**agent.paw_filter)
            except (TypeError, ValueError) as error:
                raise ValueError(f"{config_file}: paw_filter {shown(agent.paw_filter)}: {error}") from None
        rule = None
        if agent.residual_rule is not None:
            from .family_tuning import paced_rule_from_record
            try:
                rule = paced_rule_from_record(agent.residual_rule)
            except (TypeError, ValueError) as error:
                raise ValueError(f"{config_file}: residual_rule: {str(error).splitlines()[0]}") from None
        scaler = ObservationScaler(tuple(agent.scaler.mean), tuple(agent.scaler.std))
        self.interface = AgentInterface(scaler, paw_filter, rule, agent.weather_inputs)
        self.model = algorithm_class(self.algorithm).load(str(self.path), device="cpu")
        expected = (self.interface.input_size,)
        if self.model.observation_space.shape != expected or self.model.action_space.shape != (1,):
            raise ValueError(f"{self.path}: the network takes {self.model.observation_space.shape} and gives "
                             f"{self.model.action_space.shape}; this task needs {expected} -> (1,)")
        self.name = name
        self._lstm = None

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.interface.reset()
        self._lstm = None

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
                "action_kind": self.interface.action_kind, "weather_inputs": self.interface.weather_inputs,
                "paw_filter": None if self.interface.paw_filter is None else self.interface.paw_filter.record(),
                "trained_on": self.config.get("task")}
