"""The training recipes of ``crop-sim train``: hyperparameters per algorithm and task, in YAML, validated.

``crop_agent_ros/learning/hyperparams/<algorithm>.yml`` (package data, rl-baselines3-zoo style) maps a task name
to its settings; ``default`` holds the algorithm's recipe for a family task without an entry of its own. The
values in those files are the settings that produced the published agents (``test/test_hyperparameters.py``
compares them with the agents' recorded settings). ``--hyperparams key=value`` overrides one setting (the value
read as YAML: ``net_arch=[64,64]``, ``paw_filter=true``). Each recipe is checked by a pydantic model (unknown
key, wrong type or a value out of range: :class:`~crop_sim_ros.usage.UsageError`, one line).

Units: ``timesteps`` and ``eval_freq`` count field-days (environment steps of one field); learning rates are
per update (Adam's step; for ES the step on the parameters themselves).
"""

from __future__ import annotations

import re
from importlib import resources
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from crop_sim_ros.usage import UsageError

ALGORITHMS = ("ppo", "es", "grpo")
DEFAULT_ENTRY = "default"
# Upper bounds of what a user may ask of training (refused above them)
MAX_TIMESTEPS = 1_000_000_000
MAX_TRAINING_FIELDS = 100_000

PositiveSteps = Field(ge=1, le=MAX_TIMESTEPS)


class Recipe(BaseModel):
    """What every algorithm's run has: its budget, its checkpoints' validation and the network's size."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    timesteps: int = PositiveSteps
    eval_freq: int = PositiveSteps
    validation_seasons: int = Field(ge=1, le=10_000)
    net_arch: tuple[int, ...] = Field(min_length=1)
    learning_rate: float = Field(gt=0)
    final_learning_rate: float = Field(ge=0)

    def record(self) -> dict:
        """The settings as a run records them (plain JSON types)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self.model_dump().items()}


class GradientSettings(BaseModel):
    """PPO's update (Stable-Baselines3's names and meanings)."""

    n_envs: int = Field(ge=1, le=MAX_TRAINING_FIELDS)
    n_steps: int = Field(ge=1, le=100_000)
    batch_size: int = Field(ge=2, le=10_000_000)
    n_epochs: int = Field(ge=1, le=1_000)
    gamma: float = Field(gt=0, le=1)
    gae_lambda: float = Field(ge=0, le=1)
    clip_range: float = Field(gt=0)
    ent_coef: float = Field(ge=0)
    log_std_init: float


class PaperPPO(GradientSettings, Recipe):
    """PPO on the paper's task (a generated-weather scenario of 20 observed values): the fixed features and action
    mapping of :mod:`crop_agent_ros.policies.sb3` (``margin``: mm above the day's no-stress level), reward shaped by
    the crop's biomass; the held-out real seasons' regret is reported, never used to choose."""

    eval_seeds: int = Field(ge=1, le=1_000)
    action_mode: Literal["mm", "target", "margin", "demand"]
    feature_set: Literal["full", "compact", "phenology"]
    margin_center_mm: float
    margin_span_mm: float = Field(gt=0)
    demand_span: float = Field(gt=0)
    reward_shaping: Literal["none", "biomass"]


class FamilyRecipe(Recipe):
    """A family task's agent: the normalised raw observation, action in mm (:mod:`.agent`); ``paw_filter``: the
    network also sees a soil-water filter's PAW estimate (the sensor's stated error known)."""

    paw_filter: bool = False


class FamilyPPO(GradientSettings, FamilyRecipe):
    """PPO on a family task (shaped reward: the value of the yield so far)."""


class EvolutionStrategies(FamilyRecipe):
    """Evolution strategies (:mod:`.evolution`): ``pairs`` antithetic candidate pairs per generation, each
    perturbed by ``noise_std``, all running the same ``seasons`` training seasons."""

    pairs: int = Field(ge=1, le=1_000)
    noise_std: float = Field(gt=0, le=10)
    seasons: int = Field(ge=1, le=1_000)  # (at most a task's pool: every task draws 1,000 seasons or more)


class GroupRelativePPO(FamilyRecipe):
    """PPO with group-relative advantages (:mod:`.grpo`): ``groups`` seasons per iteration, ``group_size`` fields
    each."""

    batch_size: int = Field(ge=2, le=10_000_000)
    n_epochs: int = Field(ge=1, le=1_000)
    clip_range: float = Field(gt=0)
    log_std_init: float
    groups: int = Field(ge=1, le=1_000)  # (distinct seasons of the pool, like ES's seasons)
    group_size: int = Field(ge=2, le=1_000)


def recipe_model(algorithm: str, family_task: bool) -> type[Recipe]:
    """The settings' model of ``algorithm`` on a family task or on the paper's task (PPO only)."""
    if not family_task:
        if algorithm != "ppo":
            raise UsageError(f"--algorithm {algorithm}: for a family task only (the paper's task trains ppo)")
        return PaperPPO
    return {"ppo": FamilyPPO, "es": EvolutionStrategies, "grpo": GroupRelativePPO}[algorithm]


def recipe_file(algorithm: str):
    """The YAML file of ``algorithm``'s recipes (package data)."""
    return resources.files(__package__) / "hyperparams" / f"{algorithm}.yml"


def recipes(algorithm: str) -> dict[str, dict]:
    """Every entry of ``algorithm``'s file, task name -> settings, as written (anchors merged)."""
    import yaml
    entries = yaml.safe_load(recipe_file(algorithm).read_text(encoding="utf-8"))
    return {name: dict(settings) for name, settings in entries.items() if not name.startswith(".")}


def parse_overrides(pairs: list[str]) -> dict:
    """``["learning_rate=3e-4", "net_arch=[32,32]"]`` -> ``{"learning_rate": 0.0003, "net_arch": [32, 32]}``
    (each value read as YAML; UsageError for an item without ``=``)."""
    import yaml
    overrides = {}
    for item in pairs:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"--hyperparams {item!r}: give KEY=VALUE, e.g. learning_rate=3e-4")
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        overrides[key.strip()] = value
    return overrides


def _coerce(value):
    """YAML's reading of a number written as 3.0e-4 is a float, of 3e-4 a string (YAML 1.1): a string that is a
    number is read as one, so both spellings mean the same."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def resolve(task: str, algorithm: str, family_task: bool, overrides: dict | None = None) -> Recipe:
    """The settings of ``algorithm`` on ``task``: its entry (else ``default``, for a family task) with
    ``overrides`` applied, validated. UsageError naming the first problem."""
    if algorithm not in ALGORITHMS:
        raise UsageError(f"--algorithm {algorithm}: not one of {', '.join(ALGORITHMS)}")
    model = recipe_model(algorithm, family_task)
    entries = recipes(algorithm)
    if task in entries:
        settings = entries[task]
    elif family_task and DEFAULT_ENTRY in entries:
        settings = entries[DEFAULT_ENTRY]
    else:
        raise UsageError(f"no {algorithm} hyperparameters for task {task!r} in {recipe_file(algorithm).name} "
                         f"(entries: {', '.join(sorted(entries))})")
    merged = {key: _coerce(value) for key, value in {**settings, **(overrides or {})}.items()}
    layers = merged.get("net_arch")
    if isinstance(layers, str) and re.fullmatch(r"\d+(,\d+)*", layers.replace(" ", "")):
        layers = [int(size) for size in layers.split(",")]  # "64,64", as the earlier --net-arch took it
    if isinstance(layers, list):
        merged["net_arch"] = tuple(layers)
    try:
        return model(**merged)
    except ValidationError as error:
        first = error.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "settings"
        given = f" {first['input']!r}" if first["type"] != "missing" else ""
        known = ", ".join(model.model_fields)
        hint = f" (known: {known})" if first["type"] == "extra_forbidden" else ""
        raise UsageError(f"hyperparameter {where}{given}: {first['msg']}{hint}") from None
