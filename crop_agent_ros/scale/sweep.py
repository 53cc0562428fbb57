"""``crop-sim sweep CONFIG.yaml [--address auto|HOST:PORT] [--resume]``: training and evaluation sweeps on Ray Tune.

A sweep is tasks x hyperparameter configurations x training seeds; each trial is one ``crop-sim train --task``
run followed by one ``crop-sim evaluate --task`` of that run, on one CPU (torch with one thread), scheduled
by Ray Tune. Without ``--address`` the sweep starts a private local Ray instance (``--cpus``, default the CPUs
this process may use); with it, it joins a running cluster (see the README's recipe).

The configuration (YAML; every key but ``tasks`` optional)::

    name: quota-lr                   # the sweep's name; output in runs/sweeps/<name> unless --out
    tasks: [benton-quota, benton-sensing]
    seeds: [0, 1, 2, 3, 4]           # training seeds (default [0])
    train:                           # fixed `crop-sim train` options (algorithm, no-progress) by long name
      timesteps: 2000000             # without dashes; any other key is a setting of the algorithm's recipe
      eval-freq: 400000              # (--hyperparams eval_freq=400000; crop_agent_ros/learning/hyperparams)
      no-progress: true              # a flag: true adds it; false adds its --no- form if it has one
    grid:                            # searched settings: every combination of the listed values
      learning-rate: [3.0e-4, 1.0e-4]
    random:                          # searched settings: drawn `samples` times per grid point
      log-std-init: {uniform: [-1.5, -0.5]}
      net-arch: {choice: [[64, 64], [128, 128]]}
      n-epochs: {randint: [5, 10]}   # inclusive
      ent-coef: {loguniform: [1.0e-4, 1.0e-2]}
    samples: 4                       # random draws per grid point (default 1)
    search-seed: 0                   # seed of the random draws (the configurations are fixed before any trial)
    evaluate:                        # fixed `crop-sim evaluate --task` options (never --agents / --out)
      sets: heldout-real,far-benton
      noise-seeds: 3
    retries: 2                       # a trial whose worker dies or that raises is retried this often
    cpus-per-trial: 1

Configurations are numbered ``c00``, ``c01``, ...: the grid's combinations in order, each with its random
draws. Before Ray starts, the file is checked by a strict schema (:class:`SweepConfig`, pydantic: types, ranges,
unknown keys; each task a built-in family task, named once; every distribution finite and bounded), the number of
trials (at most MAX_TRIALS) is computed before any configuration is built, every option is checked by its
command's own parser, every trial's training settings by its recipe's validation and the evaluation's options by
``crop-sim evaluate --task``'s checks: one error lists every problem with its path. Trial ``<task>-cNN-sS``
writes under ``<out>/trials/<trial>/``: ``run/`` (the training run: checkpoints, curve, ``model.zip``), ``eval/``
(the evaluation's tables), ``trial.log`` (its output) and ``attempts.log`` (one line per attempt: node and
process). A retry reuses a finished training (``run/summary.json``) and redoes the rest; an unfinished
training is started again from scratch (training is deterministic for its seed). The trials share the
oracle's plans (``<out>/oracle-cache``, ``crop-sim evaluate --oracle-cache``): the oracle of a task's sets is
planned once, by the first trial that evaluates them, not once per trial.

Outputs in ``<out>`` (each written atomically, :mod:`crop_sim_ros.output`): ``table.csv`` and ``table.json`` (a row
per planned trial: ``finished`` (its evaluation wrote its table), ``failed`` with its error, or ``unfinished`` (an
interrupted sweep); hyperparameters, node, attempts, training figures, and per evaluation set the
oracle's return, the rule's and the agent's regret with its 95 % CI, the ratio agent/rule with its CI,
paired wins, final / 1 % regret), ``best.json`` and ``table.md`` (the best configuration per task: the highest
mean validation return over its seeds -- generated validation seasons, never a held-out set -- with its
held-out figures and the `crop-sim evaluate` command that pools its seeds), ``sweep.png``, and ``tune/``
(Ray Tune's experiment state). ``--resume`` continues an interrupted sweep in the same ``--out``: finished
trials are kept, unfinished and failed ones run again.

While it runs, one line tells the trials finished / running / failed / retried and the best validation
return so far (on a terminal it is rewritten in place); Ray's own log goes to ``<out>/tune`` only.
Exit status 0 when every trial finished, 1 when some failed for good (the table says which), 2 for a
mistake in the command or the configuration.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import itertools
import json
import math
import os
import re
import shutil
import sys
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, ClassVar, Union

import numpy as np
from pydantic import (BaseModel, ConfigDict, Discriminator, Field, PlainValidator, StringConstraints,
                      Tag, ValidationError, field_validator, model_validator)
from pydantic_core import PydanticCustomError

from crop_sim_ros.output import check_output_directory, save_figure_atomic, write_csv_atomic, write_json_atomic, \
    write_text_atomic
from crop_sim_ros.usage import UsageError, shown, user_input

from .cluster import check_address, probe

RESERVED_TRAIN = {"task", "seed", "out", "hyperparams", "show"}  # set by the sweep for each trial (or meaningless)
RESERVED_EVALUATE = {"task", "agents", "out", "address", "cpus", "oracle-cache"}  # set per trial
MAX_TRIALS = 10_000
MAX_VALUES = 1_000           # values of one grid option, one choice, one list value
MAX_MAGNITUDE = 1e12         # |low|, |high| of a uniform or loguniform draw
MAX_RANDINT = 2**53          # |low|, |high| of a randint draw (every integer exact as a float too)
MAX_TEXT = 200               # characters of a string option value
MAX_LISTED = 20              # problems listed in one error (then "and N more")
EXIT_INTERRUPTED = 130
AGENT = "agent"


def add_arguments(parser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = "the configuration (YAML):\n" + __doc__.split("::\n\n", 1)[1].split("\n\n", 1)[0]
    parser.add_argument("config", type=Path, help="the sweep's YAML file (its keys below)")
    parser.add_argument("--address", default=None,
                        help="join a running Ray cluster (auto or HOST:PORT); default: a local instance")
    parser.add_argument("--cpus", type=int, default=None,
                        help="CPUs of the local Ray instance (default: those this process may use)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default runs/sweeps/<name>)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the interrupted sweep in --out: keep finished trials, run the others")


# --- the configuration's schema ----------------------------------------------------------------------------

def _scalar(value):
    """An option's value: true/false, a finite number (an integer within int64) or a short string."""
    if isinstance(value, bool) or (isinstance(value, str) and len(value) <= MAX_TEXT):
        return value
    if isinstance(value, int) and -2**63 <= value < 2**63:
        return value
    if isinstance(value, float) and math.isfinite(value):
        return value
    raise PydanticCustomError("option_value", "has value {value}; give a number (finite; an integer within int64), "
                              "a string (at most {chars} characters) or true/false",
                              {"value": shown(value), "chars": MAX_TEXT})


def _value(value):
    """A setting's value: a scalar (:func:`_scalar`) or a list of at most MAX_VALUES scalars (``net-arch``)."""
    if isinstance(value, list):
        if not 1 <= len(value) <= MAX_VALUES:
            raise PydanticCustomError("option_value", "a list value needs 1..{n} items, not {count}",
                                      {"n": MAX_VALUES, "count": len(value)})
        return [_scalar(v) for v in value]
    return _scalar(value)


Scalar = Annotated[object, PlainValidator(_scalar)]
Value = Annotated[object, PlainValidator(_value)]
OptionName = Annotated[str, StringConstraints(pattern=r"^[A-Za-z][A-Za-z0-9_-]{0,63}$")]


def _task_name(name) -> str:
    """A built-in task's name: a string of letters, digits and '-' (never a path: it names the trial's folder and
    Ray Tune's trial) that :func:`~crop_sim_ros.task.scenario.scenario_names` knows."""
    from crop_sim_ros.task.scenario import scenario_names
    if not isinstance(name, str):
        raise PydanticCustomError("task_name", "give a task's name, not {value}", {"value": shown(name)})
    if not re.fullmatch(r"[a-z0-9][a-z0-9-]{0,63}", name):
        raise PydanticCustomError("task_name", "{name} is not a task's name (lower-case letters, digits and '-'; no "
                                  "'/' or other path characters)", {"name": shown(name)})
    if name not in scenario_names():
        raise PydanticCustomError("unknown_task", "unknown task {name}; known: {known}",
                                  {"name": shown(name), "known": ", ".join(scenario_names())})
    return name


TaskName = Annotated[str, PlainValidator(_task_name)]
Seed = Annotated[int, Field(ge=0, le=2**31 - 1)]
Bound = Annotated[float, Field(ge=-MAX_MAGNITUDE, le=MAX_MAGNITUDE, allow_inf_nan=False)]
IntBound = Annotated[int, Field(ge=-MAX_RANDINT, le=MAX_RANDINT)]
STRICT = ConfigDict(extra="forbid", strict=True, frozen=True)


class _Range(BaseModel):
    """[low, high] with low < high."""

    model_config = STRICT

    def bounds(self) -> list:
        return getattr(self, self.kind)

    @model_validator(mode="after")
    def _ordered(self):
        low, high = self.bounds()
        if not low < high:
            raise PydanticCustomError("range", "needs [low, high] with low < high")
        return self


class Uniform(_Range):
    kind: ClassVar[str] = "uniform"
    uniform: list[Bound] = Field(min_length=2, max_length=2)


class LogUniform(_Range):
    kind: ClassVar[str] = "loguniform"
    loguniform: list[Annotated[float, Field(gt=0, le=MAX_MAGNITUDE, allow_inf_nan=False)]] = Field(
        min_length=2, max_length=2)


class RandInt(_Range):
    """Inclusive: [5, 10] draws 5..10."""

    kind: ClassVar[str] = "randint"
    randint: list[IntBound] = Field(min_length=2, max_length=2)


class Choice(BaseModel):
    model_config = STRICT
    kind: ClassVar[str] = "choice"
    choice: list[Value] = Field(min_length=1, max_length=MAX_VALUES)


DISTRIBUTIONS = (Uniform, LogUniform, RandInt, Choice)


def _distribution_kind(value) -> str | None:
    kind = next(iter(value)) if isinstance(value, dict) and len(value) == 1 else None
    return kind if kind in {d.kind for d in DISTRIBUTIONS} else None


Distribution = Annotated[
    Union[tuple(Annotated[d, Tag(d.kind)] for d in DISTRIBUTIONS)],
    Discriminator(_distribution_kind, custom_error_type="distribution",
                  custom_error_message="must be one of " + ", ".join(f"{{{d.kind}: [...]}}" for d in DISTRIBUTIONS))]


class SweepConfig(BaseModel):
    """The sweep's YAML file (see the module docstring): types, ranges, required and unknown keys."""

    model_config = STRICT

    name: Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_-]{1,64}$")] | None = None
    tasks: list[TaskName] = Field(min_length=1, max_length=MAX_TRIALS)
    seeds: list[Seed] = Field(default=[0], min_length=1, max_length=MAX_TRIALS)
    train: dict[OptionName, Value] = {}
    grid: dict[OptionName, Annotated[list[Value], Field(min_length=1, max_length=MAX_VALUES)]] = {}
    random: dict[OptionName, Distribution] = {}
    samples: int = Field(default=1, ge=1, le=MAX_TRIALS)
    search_seed: int = Field(default=0, ge=0, le=2**32 - 1, alias="search-seed")
    evaluate: dict[OptionName, Scalar] = {}
    retries: int = Field(default=2, ge=0, le=100)
    cpus_per_trial: float = Field(default=1, gt=0, le=1024, allow_inf_nan=False, alias="cpus-per-trial")

    @field_validator("train", "grid", "random", "evaluate", mode="before")
    @classmethod
    def _empty_section(cls, value):
        return {} if value is None else value   # `train:` with nothing under it

    @field_validator("tasks", "seeds")
    @classmethod
    def _distinct(cls, values: list):
        repeated = sorted(str(v) for v, count in Counter(values).items() if count > 1)
        if repeated:
            raise PydanticCustomError("repeated", "{repeated} named more than once (each trial's key and folder "
                                      "must be its own)", {"repeated": ", ".join(repeated)})
        return values

    @field_validator("train")
    @classmethod
    def _train_not_reserved(cls, options: dict):
        return _not_reserved(options, RESERVED_TRAIN)

    @field_validator("evaluate")
    @classmethod
    def _evaluate_not_reserved(cls, options: dict):
        return _not_reserved(options, RESERVED_EVALUATE)

    @model_validator(mode="after")
    def _each_option_once(self):
        searched = set(self.grid) | set(self.random)
        clash = sorted((set(self.grid) & set(self.random)) | (searched & set(self.train)) | (searched & RESERVED_TRAIN))
        if clash:
            raise PydanticCustomError("clash", "option(s) {clash} set in more than one of train / grid / random (or "
                                      "reserved for the sweep)", {"clash": ", ".join(clash)})
        if self.samples > 1 and not self.random:
            raise PydanticCustomError("samples", "samples {samples} without random options would repeat the same "
                                      "configuration", {"samples": self.samples})
        return self

    def n_configurations(self) -> int:
        """The grid's combinations times the random draws of each: arithmetic, nothing built."""
        return math.prod(len(values) for values in self.grid.values()) * self.samples


def _not_reserved(options: dict, reserved: set) -> dict:
    clash = sorted(set(options) & reserved)
    if clash:
        raise PydanticCustomError("reserved", "may not set {clash} (the sweep sets them per trial)",
                                  {"clash": ", ".join(clash)})
    return options


def schema_problems(error: ValidationError) -> list[str]:
    """Every problem of a validation error, one ``path: what`` each (a distribution's tag not repeated)."""
    problems = []
    for e in error.errors(include_url=False, include_input=False, include_context=False):
        parts = []
        for part in e["loc"]:
            if not parts or parts[-1] != str(part):
                parts.append(str(part))
        message = e["msg"]
        if e["type"] == "extra_forbidden" and len(parts) == 1:
            message = "unknown key; known: " + ", ".join(f.alias or n for n, f in SweepConfig.model_fields.items())
        problems.append(f"{'.'.join(parts) or 'the file'}: {message}")
    return problems


def listed(what: str, problems: list[str]) -> UsageError:
    """One error naming ``what`` and listing its problems (the first MAX_LISTED, then how many more)."""
    unique = list(dict.fromkeys(problems))
    text = "; ".join(unique[:MAX_LISTED]) + (f"; and {len(unique) - MAX_LISTED} more" if len(unique) > MAX_LISTED
                                               else "")
    count = f"{len(unique)} problems: " if len(unique) > 1 else ""
    return UsageError(f"{what}: {count}{text}")


# --- the trials' command lines -----------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    """A command's parser whose mistakes raise UsageError (a trial option checked before Ray starts)."""

    def error(self, message):
        raise UsageError(f"{self.prog}: {message}")


def command_parser(command: str) -> argparse.ArgumentParser:
    from ..cli import COMMANDS
    parser = _Parser(prog=f"crop-sim {command}", add_help=False)
    importlib.import_module(COMMANDS[command][0]).add_arguments(parser)
    return parser


def option_argv(options: dict, what: str, parser: argparse.ArgumentParser) -> list[str]:
    """``{"timesteps": 5000, "no-progress": True, "curves": False}`` -> ``["--timesteps", "5000",
    "--no-progress", "--no-curves"]``: true gives the flag, false its ``--no-`` form if the command has one
    (else nothing), a number or string ``--name value``."""
    known = {o for action in parser._actions for o in action.option_strings}
    argv = []
    for name, value in options.items():
        if f"--{name}" not in known:
            raise UsageError(f"{what}: {parser.prog} has no option --{name}")
        if isinstance(value, bool):
            argv += [f"--{name}"] if value else [f"--no-{name}"] if f"--no-{name}" in known else []
        elif isinstance(value, (int, float, str)):
            argv += [f"--{name}", str(value)]
        else:
            raise UsageError(f"{what}: option {name!r} has value {shown(value)}; give a number, a string or "
                             "true/false")
    return argv


def training_argv(options: dict, what: str, parser: argparse.ArgumentParser) -> list[str]:
    """A trial's ``crop-sim train`` arguments: an option of the command (``algorithm``, ``no-progress``) as
    :func:`option_argv` gives it, anything else as one setting of the recipe, ``--hyperparams key=value`` (``-`` in
    the name read as ``_``: ``learning-rate`` is ``learning_rate``; a list, e.g. ``net-arch: [64, 64]``, as YAML)."""
    known = {o for action in parser._actions for o in action.option_strings}
    commands = {name: value for name, value in options.items() if f"--{name}" in known}
    argv = option_argv(commands, what, parser)
    for name, value in options.items():
        if name not in commands:
            text = json.dumps(value) if isinstance(value, (list, bool)) else value
            argv += ["--hyperparams", f"{name.replace('-', '_')}={text}"]
    return argv


@dataclass(frozen=True)
class Trial:
    """One planned trial: task, configuration (id and searched values), training seed, and its command lines."""

    key: str
    task: str
    config: str
    seed: int
    hyperparameters: dict
    train_argv: tuple[str, ...]
    evaluate_argv: tuple[str, ...]

    def as_dict(self) -> dict:
        return {"key": self.key, "task": self.task, "config": self.config, "seed": self.seed,
                "hyperparameters": dict(self.hyperparameters), "train_argv": list(self.train_argv),
                "evaluate_argv": list(self.evaluate_argv)}


@dataclass(frozen=True)
class SweepSpec:
    """A checked sweep configuration (see the module docstring)."""

    name: str
    tasks: tuple[str, ...]
    seeds: tuple[int, ...]
    train: dict
    grid: dict
    random: dict
    samples: int
    search_seed: int
    evaluate: dict
    retries: int
    cpus_per_trial: float
    source: str = ""
    configurations: tuple[dict, ...] = field(default=(), compare=False)

    @classmethod
    def load(cls, path: Path) -> "SweepSpec":
        """The checked sweep of the YAML file ``path``, read by :mod:`crop_sim_ros.safe_yaml` (a regular file of at
        most 64 KiB, no aliases, no duplicate keys, bounded nesting) and checked by :meth:`from_dict`."""
        from crop_sim_ros.safe_yaml import YamlInputError, read_yaml
        try:
            raw = read_yaml(path)
        except YamlInputError as error:
            raise UsageError(f"sweep configuration {error}") from None
        return cls.from_dict(raw, str(path))

    @classmethod
    def from_dict(cls, raw, source: str = "<dict>") -> "SweepSpec":
        """The checked sweep of the mapping ``raw``: UsageError listing every problem with its path, first of
        the file (:class:`SweepConfig`), then of the trials' command lines and settings; the number of trials is
        checked against MAX_TRIALS before any configuration is built."""
        what = f"sweep configuration {source}"
        if not isinstance(raw, dict):
            keys = (f.alias or name for name, f in SweepConfig.model_fields.items())
            raise UsageError(f"{what}: expected a mapping of keys ({', '.join(keys)})")
        try:
            config = SweepConfig.model_validate(raw)
        except ValidationError as error:
            raise listed(what, schema_problems(error)) from None
        name = config.name if config.name is not None else Path(source).stem
        if not name.replace("-", "").replace("_", "").isalnum() or not name.isascii() or len(name) > 64:
            raise UsageError(f"{what}: name: the file's name {shown(name)} is not a sweep name (letters, digits, "
                             "- and _); give one with name:")
        n_trials = len(config.tasks) * config.n_configurations() * len(config.seeds)
        if n_trials > MAX_TRIALS:
            raise UsageError(f"{what}: {n_trials:,} trials (tasks x configurations x seeds) is above {MAX_TRIALS:,}")
        spec = cls(name, tuple(config.tasks), tuple(config.seeds), dict(config.train), dict(config.grid),
                   {option: distribution.model_dump() for option, distribution in config.random.items()},
                   config.samples, config.search_seed, dict(config.evaluate), config.retries,
                   float(config.cpus_per_trial), source)
        spec = replace(spec, configurations=spec._draw_configurations())
        problems = spec.problems()
        if problems:
            raise listed(what, problems)
        return spec

    def _draw_configurations(self) -> tuple[dict, ...]:
        rng = np.random.default_rng(self.search_seed)
        options = list(self.grid)
        configurations = []
        for point in itertools.product(*(self.grid[o] for o in options)):
            for _ in range(self.samples):
                drawn = {option: _draw(rng, spec) for option, spec in self.random.items()}
                configurations.append({**dict(zip(options, point)), **drawn})
        return tuple(configurations)

    def _config_id(self, index: int) -> str:
        return f"c{index:0{max(2, len(str(len(self.configurations) - 1)))}d}"

    def trials(self) -> list[Trial]:
        """Every planned trial, task-major, then configuration, then seed (command lines built, not checked:
        :meth:`problems` checks them)."""
        train_parser, evaluate_parser = command_parser("train"), command_parser("evaluate")
        fixed_train = training_argv(self.train, "train", train_parser)
        fixed_evaluate = option_argv(self.evaluate, "evaluate", evaluate_parser)
        searched = [training_argv(values, f"configuration {self._config_id(i)}", train_parser)
                    for i, values in enumerate(self.configurations)]
        return [Trial(f"{task}-{self._config_id(i)}-s{seed}", task, self._config_id(i), seed, values,
                      ("--task", task, "--seed", str(seed), *fixed_train, *searched[i]), ("--task", task, *fixed_evaluate))
                for task in self.tasks for i, values in enumerate(self.configurations) for seed in self.seeds]

    def problems(self) -> list[str]:
        """Every problem of the trials, before Ray starts: each option known to its command and parsed by its
        parser, each configuration's training settings valid for each task (the recipe's pydantic model,
        :mod:`crop_agent_ros.learning.hyperparameters`), the evaluation's options valid for each task."""
        train_parser, evaluate_parser = command_parser("train"), command_parser("evaluate")
        problems = []
        for what, check in [("train", lambda: training_argv(self.train, "train", train_parser)),
                            ("evaluate", lambda: option_argv(self.evaluate, "evaluate", evaluate_parser))]:
            try:
                check()
            except UsageError as error:
                problems.append(str(error))
        if problems:
            return problems
        for index, values in enumerate(self.configurations):
            config = self._config_id(index)
            try:
                training_argv(values, f"configuration {config}", train_parser)
            except UsageError as error:
                problems.append(str(error))
        if problems:
            return problems
        trials = self.trials()
        for task in self.tasks:
            problems += _evaluation_problems(task, trials[self.tasks.index(task) * len(self.configurations)
                                                         * len(self.seeds)].evaluate_argv, evaluate_parser)
        checked = set()
        for trial in trials:
            try:
                args = train_parser.parse_args([*trial.train_argv, "--out", "x"])
            except UsageError as error:
                problems.append(f"configuration {trial.config}: {error}")
                continue
            key = (trial.task, args.algorithm, tuple(args.hyperparams))
            if key not in checked:
                checked.add(key)
                problem = _training_problem(trial.task, args)
                if problem:
                    problems.append(f"configuration {trial.config} on task {trial.task}: crop-sim train: {problem}")
        return problems


@functools.lru_cache(maxsize=64)
def _scenario(task: str):
    from crop_sim_ros.task.scenario import get_scenario
    return get_scenario(task)


def _training_problem(task: str, args: argparse.Namespace) -> str:
    """What is wrong with a trial's training settings on ``task`` (:func:`hyperparameters.resolve`), or ''."""
    from ..learning.hyperparameters import parse_overrides, resolve
    try:
        with user_input(f"--task {task}", (KeyError, ValueError, OSError)):
            scenario = _scenario(task)
        resolve(scenario.name, args.algorithm, scenario.is_family_task, parse_overrides(args.hyperparams))
    except UsageError as error:
        return str(error)
    return ""


def _evaluation_problems(task: str, evaluate_argv: tuple[str, ...], parser: argparse.ArgumentParser) -> list[str]:
    """What is wrong with the trials' ``crop-sim evaluate --task`` options on ``task``: the parser's, the
    command's range checks, a task that is not a family task, an unknown evaluation set."""
    from ..learning import evaluate_task
    try:
        args = parser.parse_args([*evaluate_argv, "--agents", f"{AGENT}=x", "--out", "x"])
        evaluate_task._check_arguments(args)
        scenario = evaluate_task._task(task)
        with user_input("--far-seasons", (ValueError,)):
            evaluate_task._chosen_sets(evaluate_task.evaluation_sets(scenario, args.far_seasons, args.far_seed),
                                       args.sets)
    except UsageError as error:
        return [f"evaluate on task {task}: {error}"]
    return []


def _draw(rng: np.random.Generator, spec: dict):
    kind, args = next(iter(spec.items()))
    if kind == "choice":
        return args[int(rng.integers(len(args)))]
    if kind == "randint":
        return int(rng.integers(args[0], args[1] + 1))
    if kind == "uniform":
        return float(rng.uniform(args[0], args[1]))
    return float(np.exp(rng.uniform(np.log(args[0]), np.log(args[1]))))


# --- one trial (runs in a Ray worker) --------------------------------------------------------------------

class _OutputTo:
    """Send this process's stdout and stderr (file descriptors 1 and 2, so C libraries too) to ``path``."""

    def __init__(self, path: Path):
        self.path = path

    def __enter__(self):
        sys.stdout.flush()
        sys.stderr.flush()
        self.saved = os.dup(1), os.dup(2)
        self.file = open(self.path, "a", buffering=1, encoding="utf-8")
        os.dup2(self.file.fileno(), 1)
        os.dup2(self.file.fileno(), 2)
        return self.file

    def __exit__(self, *exc):
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(self.saved[0], 1)
        os.dup2(self.saved[1], 2)
        for fd in self.saved:
            os.close(fd)
        self.file.close()


def run_trial(param_space: dict) -> None:
    """Tune's function trainable: one trial (``param_space["trial"]``, a :meth:`Trial.as_dict`), training then
    evaluation; reports once after training and once at the end (the trial's row)."""
    from ray import tune

    from .cluster import this_node
    trial = param_space["trial"]
    trial_dir = Path(param_space["out"]) / "trials" / trial["key"]
    trial_dir.mkdir(parents=True, exist_ok=True)
    node = this_node()
    attempts_file = trial_dir / "attempts.log"
    attempt = 1 + (len(attempts_file.read_text().splitlines()) if attempts_file.exists() else 0)
    with open(attempts_file, "a", encoding="utf-8") as f:
        f.write(f"attempt {attempt} node {node['node_id']} address {node['address']} pid {node['pid']} "
                f"started {time.strftime('%Y-%m-%dT%H:%M:%S')}\n")
    (trial_dir / "worker.pid").write_text(f"{node['pid']}\n")
    started = time.perf_counter()
    run_dir, eval_dir = trial_dir / "run", trial_dir / "eval"
    with _OutputTo(trial_dir / "trial.log") as log:
        print(f"--- attempt {attempt} on node {node['node']} ({node['address']}), pid {node['pid']}", file=log)
        reused = (run_dir / "summary.json").is_file() and (run_dir / "model.zip").is_file()
        if reused:
            print(f"reusing the finished training in {run_dir}", file=log)
        else:
            shutil.rmtree(run_dir, ignore_errors=True)   # an interrupted attempt's partial run
            _command("train", [*trial["train_argv"], "--out", str(run_dir)])
        summary = json.loads((run_dir / "summary.json").read_text())
        training = {"steps_run": summary["steps_run"], "training_wall_s": summary["training_wall_s"],
                    "validation_return_usd_ha": summary["selected"]["validation_return"],
                    "selected_timesteps": summary["selected"]["timesteps"], "training_reused": reused}
        tune.report({"stage": "trained", "attempt": attempt, **node, **training})
        shutil.rmtree(eval_dir, ignore_errors=True)
        _command("evaluate", [*trial["evaluate_argv"], "--agents", f"{AGENT}={run_dir}", "--out", str(eval_dir),
                              "--oracle-cache", str(Path(param_space["out"]) / "oracle-cache")])
        evaluation = json.loads((eval_dir / "table.json").read_text())
    tune.report({"stage": "evaluated", "attempt": attempt, **node, **training,
                 "trial_wall_s": round(time.perf_counter() - started, 1), **evaluation_figures(evaluation)})


def _command(command: str, argv: list[str]) -> None:
    """Run ``crop-sim <command> argv`` in this process; its UsageError fails the trial with that line."""
    from ..cli import COMMANDS
    args = command_parser(command).parse_args(argv)
    try:
        importlib.import_module(COMMANDS[command][0]).run(args)
    except UsageError as error:
        raise RuntimeError(f"crop-sim {command}: {error}") from None


FIGURES = {"oracle": ("return_usd_ha",),
           "rule": ("regret_usd_ha", "regret_pct_of_reference"),
           "agent": ("return_usd_ha", "regret_usd_ha", "regret_ci_low", "regret_ci_high", "ratio_to_rule",
                     "ratio_ci_low", "ratio_ci_high", "paired_wins", "final_over_early", "beats_rule",
                     "learning_is_real"),
           "early": ("regret_usd_ha",)}


def evaluation_figures(table: dict) -> dict:
    """The trial's figures from its evaluation's ``table.json``: per set, ``<set>/<kind>_<figure>``."""
    figures = {"reference": "oracle" if table["regret"].startswith("oracle") else "best evaluated policy (gap)"}
    for s in table["sets"]:
        for row in s["rows"]:
            for name in FIGURES.get(row["kind"], ()):
                figures[f"{s['name']}/{row['kind']}_{name}"] = row.get(name)
    return figures


# --- the driver ------------------------------------------------------------------------------------------

def live_line(name: str, total: int, stream=None):
    """A Tune callback printing one progress line per change: finished / running / failed / retried trials and
    the best validation return so far per task (rewritten in place on a terminal)."""

    from ray import tune

    class LiveLine(tune.Callback):
        def __init__(self, name: str, total: int, stream):
            self.name, self.total, self.stream = name, total, stream
            self.retried: dict[str, int] = {}
            self.best: dict[str, tuple[float, str]] = {}
            self.last = ""
            self.tty = stream.isatty()

        def _show(self, trials):
            counts = {s: sum(1 for t in trials if t.status == s) for s in ("RUNNING", "ERROR")}
            counts["TERMINATED"] = sum(1 for t in trials if (t.last_result or {}).get("stage") == "evaluated")
            best = "; ".join(f"{task} {key} {value:,.0f}" for task, (value, key) in sorted(self.best.items()))
            line = (f"sweep {self.name}: {counts['TERMINATED']}/{self.total} finished, {counts['RUNNING']} "
                    f"running, {counts['ERROR']} failed, {sum(self.retried.values())} retried"
                    + (f" | best validation return (USD/ha): {best}" if best else ""))
            if line != self.last:
                self.last = line
                self.stream.write(("\r" + line.ljust(120)) if self.tty else line + "\n")
                self.stream.flush()

        def on_trial_start(self, iteration, trials, trial, **info):
            self._show(trials)

        def on_trial_result(self, iteration, trials, trial, result, **info):
            value = result.get("validation_return_usd_ha")
            if value is not None:
                task, key = trial.config["trial"]["task"], trial.config["trial"]["key"]
                if task not in self.best or value > self.best[task][0]:
                    self.best[task] = (float(value), key)
            self._show(trials)

        def on_trial_recover(self, iteration, trials, trial, **info):
            key = trial.config["trial"]["key"]
            self.retried[key] = self.retried.get(key, 0) + 1
            self._note(f"trial {key} failed (attempt {self.retried[key]}); retrying it")
            self._show(trials)

        def on_trial_error(self, iteration, trials, trial, **info):
            self._note(f"trial {trial.config['trial']['key']} failed for good; its error is in the table")
            self._show(trials)

        def _note(self, message: str) -> None:
            self.stream.write(("\r" + message.ljust(120) + "\n") if self.tty else message + "\n")
            self.last = ""

        def on_trial_complete(self, iteration, trials, trial, **info):
            self._show(trials)

        def on_experiment_end(self, trials, **info):
            self._show(trials)
            if self.tty:
                self.stream.write("\n")

    return LiveLine(name, total, stream or sys.stderr)


def run(args) -> int:
    spec = SweepSpec.load(args.config)
    if args.cpus is not None and (args.address is not None or args.cpus < 1):
        raise UsageError(f"--cpus {args.cpus}: " + ("sets the CPUs of the local instance; a cluster's CPUs are "
                                                    "its nodes'" if args.address is not None else "must be >= 1"))
    probe(check_address(args.address))
    out = (args.out if args.out is not None else Path("runs") / "sweeps" / spec.name).resolve()
    experiment = out / "tune"
    check_output_directory(out)
    if args.resume and not experiment.is_dir():
        raise UsageError(f"--resume: {out} holds no sweep to resume (no {experiment.name}/ folder)")
    if not args.resume and experiment.exists():
        raise UsageError(f"--out: {out} already holds a sweep; add --resume to continue it, or choose another --out")
    if args.resume:
        with user_input(f"--resume: {out / 'sweep.json'}", (OSError, UnicodeDecodeError, ValueError)):
            recorded = json.loads((out / "sweep.json").read_text(encoding="utf-8"))
        if not isinstance(recorded, dict) or recorded.get("trials") != [t.as_dict() for t in spec.trials()]:
            raise UsageError(f"--resume: {args.config} plans other trials than the sweep in {out} "
                             f"(its configuration is {out / 'sweep.json'})")
    out.mkdir(parents=True, exist_ok=True)
    trials = spec.trials()
    write_json_atomic(out / "sweep.json", {"name": spec.name, "config_file": str(args.config),
                                           "configurations": list(spec.configurations),
                                           "trials": [t.as_dict() for t in trials]})
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    from .cluster import connect, disconnect
    cluster = connect(args.address, args.cpus)
    _ray_log_to(out / "ray.log")
    print(f"sweep {spec.name}: {len(trials)} trials ({len(spec.tasks)} task(s) x {len(spec.configurations)} "
          f"configuration(s) x {len(spec.seeds)} seed(s)) on {cluster.describe()}; output {out}",
          file=sys.stderr, flush=True)
    started = time.perf_counter()
    try:
        grid = _tuner(spec, trials, out, args.resume).fit()
        results = {r.config["trial"]["key"]: r for r in grid if r.config}
    finally:
        disconnect()
    rows = table_rows(trials, results, out)
    best = best_configurations(spec, rows, out)
    write_outputs(out, spec, rows, best, cluster, time.perf_counter() - started)
    line, status = summary_line(spec.name, rows, out)
    print(line, file=sys.stderr)
    return status


def _ray_log_to(path: Path) -> None:
    """Ray's and Tune's Python log (a traceback per failed attempt, ...) to ``path`` instead of the terminal:
    the live line and the table say what failed."""
    import logging
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    for name in ("ray", "ray.tune", "ray.air", "ray.train"):
        logger = logging.getLogger(name)
        for old in list(logger.handlers):
            logger.removeHandler(old)
        logger.propagate = False
        logger.addHandler(handler)


def _tuner(spec: SweepSpec, trials: list[Trial], out: Path, resume: bool):
    from ray import tune
    trainable = tune.with_resources(run_trial, {"cpu": spec.cpus_per_trial})
    if resume:
        return tune.Tuner.restore(str(out / "tune"), trainable=trainable, resume_unfinished=True,
                                  resume_errored=False, restart_errored=True)
    return tune.Tuner(
        trainable,
        param_space={"out": str(out), "trial": tune.grid_search([t.as_dict() for t in trials])},
        tune_config=tune.TuneConfig(trial_name_creator=lambda t: t.config["trial"]["key"],
                                    trial_dirname_creator=lambda t: t.config["trial"]["key"]),
        run_config=tune.RunConfig(name="tune", storage_path=str(out), verbose=0,
                                  failure_config=tune.FailureConfig(max_failures=spec.retries),
                                  callbacks=[live_line(spec.name, len(trials))]))


def _error_line(error) -> str:
    """The line that says what went wrong (the last 'SomethingError: ...' line of a Ray error's text)."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    named = [line for line in lines if "Error" in line.split(":")[0] or "Exception" in line.split(":")[0]]
    return (named[-1] if named else lines[-1] if lines else type(error).__name__)[:500]


def table_rows(trials: list[Trial], results: dict, out: Path) -> list[dict]:
    """A row per planned trial, in plan order: status, error, where and how often it ran, its figures."""
    rows = []
    for trial in trials:
        result = results.get(trial.key)
        metrics = dict(result.metrics or {}) if result is not None else {}
        attempts_file = out / "trials" / trial.key / "attempts.log"
        attempts = len(attempts_file.read_text().splitlines()) if attempts_file.exists() else metrics.get("attempt", 0)
        if result is not None and result.error is not None:
            status, error = "failed", _error_line(result.error)
        elif metrics.get("stage") != "evaluated":   # the sweep was interrupted before the trial ended
            stage = metrics.get("stage")
            status, error = "unfinished", f"interrupted after stage {stage!r}" if stage else ""
        else:   # finished only if its evaluation wrote its table
            error = evaluation_table_problem(out / "trials" / trial.key / "eval" / "table.json")
            status = "failed" if error else "finished"
        row = {"trial": trial.key, "task": trial.task, "config": trial.config, "seed": trial.seed,
               "status": status, "error": error, "attempts": attempts,
               "node": metrics.get("node", ""), "node_address": metrics.get("address", ""),
               **{f"hp/{k}": v for k, v in trial.hyperparameters.items()}}
        if status == "finished":
            row.update({k: v for k, v in metrics.items() if k in ("steps_run", "training_wall_s", "trial_wall_s",
                                                                  "validation_return_usd_ha", "selected_timesteps",
                                                                  "training_reused", "reference")
                        or "/" in k})
        rows.append(row)
    return rows


def evaluation_table_problem(path: Path) -> str:
    """'' if ``path`` holds an evaluation's table (a JSON object with its sets), else what is wrong with it."""
    try:
        table = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return f"its evaluation wrote no table ({path.name} is missing)"
    except (OSError, UnicodeDecodeError, ValueError) as error:
        return f"its evaluation's {path.name} is unreadable ({type(error).__name__})"
    if not isinstance(table, dict) or not isinstance(table.get("sets"), list):
        return f"its evaluation's {path.name} holds no table of sets"
    return ""


def summary_line(name: str, rows: list[dict], out: Path) -> tuple[str, int]:
    """The sweep's last line and its exit status: 0 when every trial finished, 1 when some failed (a trial
    whose evaluation wrote no table included), EXIT_INTERRUPTED when some are unfinished."""
    failed = [r["trial"] for r in rows if r["status"] == "failed"]
    unfinished = [r["trial"] for r in rows if r["status"] == "unfinished"]
    finished = sum(1 for r in rows if r["status"] == "finished")
    line = (f"sweep {name}: {finished}/{len(rows)} trials finished"
            + (f"; {len(failed)} FAILED: {', '.join(failed)}" if failed else "")
            + (f"; interrupted, unfinished: {', '.join(unfinished)} (continue with --resume)" if unfinished else "")
            + f"; wrote {out}/table.csv, table.json, table.md, best.json, sweep.png")
    return line, EXIT_INTERRUPTED if unfinished else 1 if failed else 0


def best_configurations(spec: SweepSpec, rows: list[dict], out: Path) -> dict:
    """Per task: the configuration with the highest mean validation return over its finished seeds (validation
    seasons are generated with a seed no training pool uses; no held-out set chooses anything), its held-out
    figures averaged over those seeds, and the command that evaluates its seeds together."""
    best = {}
    for task in spec.tasks:
        by_config: dict[str, list[dict]] = {}
        for row in rows:
            if row["task"] == task and row["status"] == "finished":
                by_config.setdefault(row["config"], []).append(row)
        if not by_config:
            best[task] = None
            continue
        config, chosen = max(by_config.items(),
                             key=lambda kv: float(np.mean([r["validation_return_usd_ha"] for r in kv[1]])))
        sets = sorted({k.split("/")[0] for r in chosen for k in r if "/" in k and not k.startswith("hp/")})
        figures = {}
        for s in sets:
            agent = [r.get(f"{s}/agent_regret_usd_ha") for r in chosen]
            rule = [r.get(f"{s}/rule_regret_usd_ha") for r in chosen]
            if all(v is not None for v in agent + rule):
                figures[s] = {"agent_regret_usd_ha": float(np.mean(agent)), "rule_regret_usd_ha": float(np.mean(rule)),
                              "ratio_of_means": float(np.mean(agent) / np.mean(rule)) if np.mean(rule) > 0 else None}
        index = int(config[1:])
        best[task] = {
            "config": config, "hyperparameters": spec.configurations[index],
            "seeds": [r["seed"] for r in chosen],
            "mean_validation_return_usd_ha": float(np.mean([r["validation_return_usd_ha"] for r in chosen])),
            "held_out": figures,
            "evaluate_command": (f"crop-sim evaluate --task {task} --agents "
                                 f"'{config}={out}/trials/{task}-{config}-s*/run' --out {out}/best-{task}")}
    return best


def write_outputs(out: Path, spec: SweepSpec, rows: list[dict], best: dict, cluster, wall_s: float) -> None:
    from ..learning.evaluate_task import _plain
    write_csv_atomic(out / "table.csv", list(dict.fromkeys(k for row in rows for k in row)), rows)
    result = {"name": spec.name, "config_file": spec.source, "cluster": cluster.describe(),
              "nodes": list(cluster.nodes), "wall_s": round(wall_s, 1), "command": "crop-sim " + " ".join(sys.argv[1:]),
              "configurations": list(spec.configurations), "rows": rows, "best": best}
    write_json_atomic(out / "table.json", _plain(result), allow_nan=False)
    write_json_atomic(out / "best.json", _plain(best), allow_nan=False)
    write_text_atomic(out / "table.md", markdown(spec, rows, best))
    plot(out / "sweep.png", spec, rows)


def markdown(spec: SweepSpec, rows: list[dict], best: dict) -> str:
    first_set = next((k.split("/")[0] for r in rows for k in r if k.endswith("/agent_regret_usd_ha")), None)
    lines = [f"# Sweep {spec.name}", "", f"{len(rows)} trials; regrets in USD/ha"
             + (f" on {first_set}" if first_set else "") + ".", "",
             "| trial | status | node | attempts | validation return | agent regret [95 % CI] | rule regret | "
             "agent / rule [95 % CI] | error |", "|---|---|---|---:|---:|---:|---:|---:|---|"]

    def fmt(value, digits=0):
        return "n/a" if value is None or not np.isfinite(value) else f"{value:,.{digits}f}"

    for r in rows:
        s = first_set
        agent = (f"{fmt(r.get(f'{s}/agent_regret_usd_ha'))} [{fmt(r.get(f'{s}/agent_regret_ci_low'))}, "
                 f"{fmt(r.get(f'{s}/agent_regret_ci_high'))}]") if r["status"] == "finished" and s else ""
        ratio = (f"{fmt(r.get(f'{s}/agent_ratio_to_rule'), 2)} [{fmt(r.get(f'{s}/agent_ratio_ci_low'), 2)}, "
                 f"{fmt(r.get(f'{s}/agent_ratio_ci_high'), 2)}]") if r["status"] == "finished" and s else ""
        lines.append(f"| {r['trial']} | {r['status']} | {r['node']} | {r['attempts']} | "
                     f"{fmt(r.get('validation_return_usd_ha'))} | {agent} | "
                     f"{fmt(r.get(f'{s}/rule_regret_usd_ha')) if r['status'] == 'finished' and s else ''} | {ratio} | "
                     f"{r['error']} |")
    lines += ["", "## Best configuration per task (highest mean validation return; no held-out set chooses)", ""]
    for task, b in best.items():
        if b is None:
            lines.append(f"- {task}: no finished trial")
            continue
        held = "; ".join(f"{s}: agent {fmt(f['agent_regret_usd_ha'])}, rule {fmt(f['rule_regret_usd_ha'])}, "
                         f"ratio of means {fmt(f['ratio_of_means'], 2)}" for s, f in b["held_out"].items())
        lines.append(f"- {task}: {b['config']} {json.dumps(b['hyperparameters'])} (seeds {b['seeds']}), mean "
                     f"validation return {fmt(b['mean_validation_return_usd_ha'])} USD/ha; {held}. Pool its seeds: "
                     f"`{b['evaluate_command']}`")
    return "\n".join(lines) + "\n"


def plot(path: Path, spec: SweepSpec, rows: list[dict]) -> None:
    """Per task: each configuration's agent regret per seed (points) on the first evaluation set, and the
    rule's regret (dashed)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(spec.tasks), figsize=(4.5 * len(spec.tasks) + 1, 4), squeeze=False)
    for ax, task in zip(axes[0], spec.tasks):
        finished = [r for r in rows if r["task"] == task and r["status"] == "finished"]
        key = next((k for r in finished for k in r if k.endswith("/agent_regret_usd_ha")), None)
        configs = sorted({r["config"] for r in rows if r["task"] == task})
        if key is not None:
            for x, config in enumerate(configs):
                values = [r[key] for r in finished if r["config"] == config and r.get(key) is not None]
                ax.scatter([x] * len(values), values, color="tab:blue", s=18)
                if values:
                    ax.plot([x - 0.3, x + 0.3], [np.mean(values)] * 2, color="tab:blue")
            rule = [r[key.replace("agent_regret", "rule_regret")] for r in finished]
            if rule:
                ax.axhline(float(np.mean(rule)), color="gray", ls="--", label="tuned rule")
                ax.legend(fontsize=8)
            ax.set_ylabel(f"{key.split('/')[0]} regret, USD/ha")
        failed = [r["config"] for r in rows if r["task"] == task and r["status"] != "finished"]
        labels = [config + "".join(f"\n{k}={_short(v)}" for k, v in spec.configurations[int(config[1:])].items())
                  for config in configs]
        ax.set_xticks(range(len(configs)), labels, fontsize=7)
        ax.set_title(f"{task}" + (f" ({len(failed)} trial(s) not finished)" if failed else ""), fontsize=9)
    fig.suptitle(f"sweep {spec.name}: agent regret per configuration (points: seeds)", fontsize=10)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


def _short(value) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)
