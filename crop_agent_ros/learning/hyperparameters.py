"""The training recipes of ``crop-sim train``: hyperparameters per algorithm and task, in YAML, validated.

``crop_agent_ros/learning/hyperparams/<algorithm>.yml`` (package data, rl-baselines3-zoo style) maps a task name
to its settings; ``default`` holds the algorithm's recipe for a family task without an entry of its own. The
values in those files are the settings that produced the published agents (``test/test_hyperparameters.py``
compares them with the agents' recorded settings). ``--hyperparams key=value`` overrides one setting (the value
read as YAML: ``net_arch=[64,64]``, ``paw_filter=true``). Each recipe is checked by a pydantic model (unknown
key, wrong type, a value out of range, infinite or NaN: :class:`~crop_sim_ros.usage.UsageError`, one line listing
every problem). Every size is bounded (a network's layers, too), so a typo cannot ask for gigabytes.

Units: ``timesteps`` and ``eval_freq`` count field-days (environment steps of one field); learning rates are
per update (Adam's step; for ES the step on the parameters themselves).
"""

from __future__ import annotations

import re
from importlib import resources
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from crop_sim_ros.usage import UsageError, shown

ALGORITHMS = ("ppo", "es", "grpo")
DEFAULT_ENTRY = "default"
# Upper bounds of what a user may ask of training (refused above them)
MAX_TIMESTEPS = 1_000_000_000
MAX_TRAINING_FIELDS = 100_000
MAX_LAYER_WIDTH = 4096  # units of one hidden layer (two of 100,000 asked for a 40 GB allocation)
MAX_LAYERS = 16

PositiveSteps = Field(ge=1, le=MAX_TIMESTEPS)
LayerWidth = Annotated[int, Field(ge=1, le=MAX_LAYER_WIDTH)]
# every model: unknown keys refused, no coercion (a string or a bool is not a number), no inf or NaN
STRICT = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


class Recipe(BaseModel):
    """What every algorithm's run has: its budget, its checkpoints' validation and the network's size."""

    model_config = STRICT

    timesteps: int = PositiveSteps
    eval_freq: int = PositiveSteps
    validation_seasons: int = Field(ge=1, le=10_000)
    net_arch: tuple[LayerWidth, ...] = Field(min_length=1, max_length=MAX_LAYERS)  # units per hidden layer
    learning_rate: float = Field(gt=0, le=1)  # per update
    final_learning_rate: float = Field(ge=0, le=1)  # per update, at the end of the linear decay

    def record(self) -> dict:
        """The settings as a run records them (plain JSON types)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self.model_dump().items()}


class GradientSettings(BaseModel):
    """PPO's update (Stable-Baselines3's names and meanings)."""

    model_config = STRICT

    n_envs: int = Field(ge=1, le=MAX_TRAINING_FIELDS)
    n_steps: int = Field(ge=1, le=100_000)
    batch_size: int = Field(ge=2, le=10_000_000)
    n_epochs: int = Field(ge=1, le=1_000)
    gamma: float = Field(gt=0, le=1)
    gae_lambda: float = Field(ge=0, le=1)
    clip_range: float = Field(gt=0, le=10)
    ent_coef: float = Field(ge=0, le=10)
    log_std_init: float = Field(ge=-20, le=5)  # log of the action noise's std (action units)


class PaperPPO(GradientSettings, Recipe):
    """PPO on the paper's task (a generated-weather scenario of 20 observed values): the fixed features and action
    mapping of :mod:`crop_agent_ros.policies.sb3` (``margin``: mm above the day's no-stress level), reward shaped by
    the crop's biomass; the held-out real seasons' regret is reported, never used to choose."""

    eval_seeds: int = Field(ge=1, le=1_000)
    action_mode: Literal["mm", "target", "margin", "demand"]
    feature_set: Literal["full", "compact", "phenology"]
    margin_center_mm: float = Field(ge=-100, le=100)
    margin_span_mm: float = Field(gt=0, le=500)
    demand_span: float = Field(gt=0, le=100)
    reward_shaping: Literal["none", "biomass"]


class FamilyRecipe(Recipe):
    """A family task's agent: the normalised raw observation, action in mm (:mod:`.agent`); ``paw_filter``: the
    network also sees a soil-water filter's PAW estimate (the sensor's stated error known); ``residual``: the
    network corrects the task's tuned paced rule instead (the residual agent); ``weather_inputs`` false: the
    network sees the climate's columns (temperatures, radiation, humidity, wind, ET0) at their training mean."""

    paw_filter: bool = False
    residual: bool = False
    weather_inputs: bool = True


class FamilyPPO(GradientSettings, FamilyRecipe):
    """PPO on a family task (shaped reward: the value of the yield so far)."""


class EvolutionStrategies(FamilyRecipe):
    """Evolution strategies (:mod:`.evolution`): ``pairs`` antithetic candidate pairs per generation, each
    perturbed by ``noise_std``, all running the same ``seasons`` training seasons. ``backend``: ``numpy`` (the
    published agents' learner, :mod:`.evolution`) or ``jax`` (the same recipe with evosax, a generation in one
    jitted call: :mod:`.jax_evolution`; no ``paw_filter``, no ``residual``, every weather input)."""

    pairs: int = Field(ge=1, le=1_000)
    noise_std: float = Field(gt=0, le=10)
    seasons: int = Field(ge=1, le=1_000)  # (at most a task's pool: every task draws 1,000 seasons or more)
    backend: Literal["numpy", "jax"] = "numpy"

    @model_validator(mode="after")
    def _jax_without_filter(self):
        if self.backend == "jax" and self.paw_filter:
            raise ValueError("backend jax has no soil-water filter: train paw_filter agents with backend numpy")
        if self.backend == "jax" and not self.weather_inputs:
            raise ValueError("backend jax sees every observed value: train weather_inputs=false agents with backend "
                             "numpy")
        if self.backend == "jax" and self.residual:
            raise ValueError("backend jax has no paced rule inside its rollout: train residual agents with backend "
                             "numpy")
        return self


class GroupRelativePPO(FamilyRecipe):
    """PPO with group-relative advantages (:mod:`.grpo`): ``groups`` seasons per iteration, ``group_size`` fields
    each."""

    batch_size: int = Field(ge=2, le=10_000_000)
    n_epochs: int = Field(ge=1, le=1_000)
    clip_range: float = Field(gt=0, le=10)
    log_std_init: float = Field(ge=-20, le=5)
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
    from crop_sim_ros.safe_yaml import read_yaml
    with resources.as_file(recipe_file(algorithm)) as path:
        entries = read_yaml(path, aliases=True)  # the project's own file: its anchors share settings
    return {name: dict(settings) for name, settings in entries.items() if not name.startswith(".")}


def parse_overrides(pairs: list[str]) -> dict:
    """``["learning_rate=3e-4", "net_arch=[32,32]"]`` -> ``{"learning_rate": 0.0003, "net_arch": [32, 32]}``
    (each value read as YAML by :mod:`crop_sim_ros.safe_yaml`, or kept as text where it is not YAML; UsageError for
    an item without ``=`` and for YAML it refuses: aliases, deep nesting, duplicate keys)."""
    from crop_sim_ros.safe_yaml import YamlInputError, YamlSyntaxError, loads
    overrides = {}
    for item in pairs:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"--hyperparams {shown(item)}: give KEY=VALUE, e.g. learning_rate=3e-4")
        try:
            value = loads(text, f"--hyperparams {shown(key.strip())}")
        except YamlSyntaxError:
            value = text
        except YamlInputError as error:
            raise UsageError(str(error)) from None
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
        raise UsageError(_problems(error, model)) from None


def _problems(error: ValidationError, model: type[Recipe]) -> str:
    """Every problem of ``error`` on one line: ``hyperparameter KEY VALUE: what`` (the value cut short)."""
    problems = []
    errors = error.errors()
    locations = [problem["loc"] for problem in errors]
    for problem in errors:
        loc = problem["loc"]
        if any(len(other) > len(loc) and other[:len(loc)] == loc for other in locations):
            continue  # a list whose item was refused: the item's problem says it
        if not loc:  # a rule across settings (a model validator): its message names them
            problems.append(f"hyperparameters: {problem['msg'].removeprefix('Value error, ')}")
            continue
        where = ".".join(str(part) for part in loc)
        given = "" if problem["type"] == "missing" else " " + shown(problem["input"])
        hint = f" (known: {', '.join(model.model_fields)})" if problem["type"] == "extra_forbidden" else ""
        problems.append(f"hyperparameter {where}{given}: {problem['msg']}{hint}")
    return "; ".join(problems)
