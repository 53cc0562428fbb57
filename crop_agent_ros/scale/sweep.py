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
draws. Every option value is checked by the commands' own parsers, and every trial's training settings by its
recipe's validation, before Ray starts. Trial ``<task>-cNN-sS``
writes under ``<out>/trials/<trial>/``: ``run/`` (the training run: checkpoints, curve, ``model.zip``), ``eval/``
(the evaluation's tables), ``trial.log`` (its output) and ``attempts.log`` (one line per attempt: node and
process). A retry reuses a finished training (``run/summary.json``) and redoes the rest; an unfinished
training is started again from scratch (training is deterministic for its seed). The trials share the
oracle's plans (``<out>/oracle-cache``, ``crop-sim evaluate --oracle-cache``): the oracle of a task's sets is
planned once, by the first trial that evaluates them, not once per trial.

Outputs in ``<out>``: ``table.csv`` and ``table.json`` (a row per planned trial: ``finished``, ``failed`` with
its error, or ``unfinished`` (an interrupted sweep); hyperparameters, node, attempts, training figures, and per evaluation set the
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
import csv
import importlib
import itertools
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from crop_sim_ros.usage import UsageError, user_input

from .cluster import check_address, probe

TOP_KEYS = {"name", "tasks", "seeds", "train", "grid", "random", "samples", "search-seed", "evaluate", "retries",
            "cpus-per-trial"}
DISTRIBUTIONS = ("uniform", "loguniform", "randint", "choice")
RESERVED_TRAIN = {"task", "seed", "out", "hyperparams", "show"}  # set by the sweep for each trial (or meaningless)
RESERVED_EVALUATE = {"task", "agents", "out", "address", "cpus", "oracle-cache"}  # set per trial
MAX_TRIALS = 10_000
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


# --- the configuration -----------------------------------------------------------------------------------

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
        if not isinstance(name, str) or not name or name.startswith("-"):
            raise UsageError(f"{what}: option {name!r} must be a long option name without dashes, e.g. timesteps")
        if f"--{name}" not in known:
            raise UsageError(f"{what}: {parser.prog} has no option --{name}")
        if isinstance(value, bool):
            argv += [f"--{name}"] if value else [f"--no-{name}"] if f"--no-{name}" in known else []
        elif isinstance(value, (int, float, str)):
            argv += [f"--{name}", str(value)]
        else:
            raise UsageError(f"{what}: option {name!r} has value {value!r}; give a number, a string or true/false")
    return argv


def training_argv(options: dict, what: str, parser: argparse.ArgumentParser) -> list[str]:
    """A trial's ``crop-sim train`` arguments: an option of the command (``algorithm``, ``no-progress``) as
    :func:`option_argv` gives it, anything else as one setting of the recipe, ``--hyperparams key=value`` (``-`` in
    the name read as ``_``: ``learning-rate`` is ``learning_rate``; a list, e.g. ``net-arch: [64, 64]``, as YAML)."""
    known = {o for action in parser._actions for o in action.option_strings}
    commands = {name: value for name, value in options.items() if isinstance(name, str) and f"--{name}" in known}
    argv = option_argv(commands, what, parser)
    for name, value in options.items():
        if name in commands:
            continue
        if not isinstance(name, str) or not name or name.startswith("-"):
            raise UsageError(f"{what}: option {name!r} must be a long option name without dashes, e.g. timesteps")
        if isinstance(value, (dict, type(None))):
            raise UsageError(f"{what}: setting {name!r} has value {value!r}; give a number, a string, true/false "
                             "or a list")
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
        import yaml
        with user_input(f"sweep configuration {path}", (OSError, UnicodeDecodeError, yaml.YAMLError)):
            text = path.read_text(encoding="utf-8")
            raw = yaml.safe_load(text)
        return cls.from_dict(raw, str(path))

    @classmethod
    def from_dict(cls, raw, source: str = "<dict>") -> "SweepSpec":
        what = f"sweep configuration {source}"
        if not isinstance(raw, dict):
            raise UsageError(f"{what}: expected a mapping of keys ({', '.join(sorted(TOP_KEYS))})")
        unknown = sorted(set(map(str, raw)) - TOP_KEYS)
        if unknown:
            raise UsageError(f"{what}: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(TOP_KEYS))}")
        name = raw.get("name", Path(source).stem)
        if not isinstance(name, str) or not name.replace("-", "").replace("_", "").isalnum():
            raise UsageError(f"{what}: name {name!r} must be letters, digits, - and _")
        tasks = raw.get("tasks")
        if not isinstance(tasks, list) or not tasks or not all(isinstance(t, str) for t in tasks):
            raise UsageError(f"{what}: tasks must be a non-empty list of family task names, e.g. [benton-quota]")
        seeds = raw.get("seeds", [0])
        if (not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) and not isinstance(s, bool)
                                                                  and 0 <= s < 2**31 for s in seeds)
                or len(set(seeds)) != len(seeds)):
            raise UsageError(f"{what}: seeds must be a non-empty list of distinct integers in 0..2**31-1")
        sections = {}
        for key in ("train", "grid", "random", "evaluate"):
            value = raw.get(key) or {}
            if not isinstance(value, dict):
                raise UsageError(f"{what}: {key} must be a mapping of option names to values")
            sections[key] = value
        for key, reserved in (("train", RESERVED_TRAIN), ("evaluate", RESERVED_EVALUATE)):
            clash = sorted(set(sections[key]) & reserved)
            if clash:
                raise UsageError(f"{what}: {key} may not set {', '.join(clash)} (the sweep sets them per trial)")
        searched = set(sections["grid"]) | set(sections["random"])
        clash = sorted((set(sections["grid"]) & set(sections["random"])) | (searched & set(sections["train"]))
                       | (searched & RESERVED_TRAIN))
        if clash:
            raise UsageError(f"{what}: option(s) {', '.join(clash)} set in more than one of train / grid / random "
                             "(or reserved for the sweep)")
        for option, values in sections["grid"].items():
            if not isinstance(values, list) or not values:
                raise UsageError(f"{what}: grid option {option!r} must list its values, e.g. [3.0e-4, 1.0e-4]")
        for option, spec in sections["random"].items():
            _check_distribution(option, spec, what)
        samples = _integer(raw.get("samples", 1), "samples", 1, 10_000, what)
        if samples > 1 and not sections["random"]:
            raise UsageError(f"{what}: samples {samples} without random options would repeat the same configuration")
        search_seed = _integer(raw.get("search-seed", 0), "search-seed", 0, 2**32 - 1, what)
        retries = _integer(raw.get("retries", 2), "retries", 0, 100, what)
        cpus = raw.get("cpus-per-trial", 1)
        if isinstance(cpus, bool) or not isinstance(cpus, (int, float)) or not 0 < cpus <= 1024:
            raise UsageError(f"{what}: cpus-per-trial {cpus!r} must be a number in (0, 1024]")
        spec = cls(name, tuple(tasks), tuple(seeds), sections["train"], sections["grid"], sections["random"], samples,
                   search_seed, sections["evaluate"], retries, float(cpus), source)
        configurations = spec._draw_configurations()
        n_trials = len(tasks) * len(configurations) * len(seeds)
        if n_trials > MAX_TRIALS:
            raise UsageError(f"{what}: {n_trials:,} trials (tasks x configurations x seeds) is above {MAX_TRIALS:,}")
        spec = replace(spec, configurations=configurations)
        spec.trials()  # every trial's command lines parse
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

    def trials(self) -> list[Trial]:
        """Every planned trial, task-major, then configuration, then seed; each command line checked by the
        command's own parser (UsageError names the first that does not parse)."""
        train_parser, evaluate_parser = command_parser("train"), command_parser("evaluate")
        fixed_train = training_argv(self.train, "train", train_parser)
        fixed_evaluate = option_argv(self.evaluate, "evaluate", evaluate_parser)
        planned, checked = [], set()
        width = max(2, len(str(len(self.configurations) - 1)))
        for task in self.tasks:
            for index, values in enumerate(self.configurations):
                config = f"c{index:0{width}d}"
                searched = training_argv(values, f"configuration {config}", train_parser)
                for seed in self.seeds:
                    trial_train = ("--task", task, "--seed", str(seed), *fixed_train, *searched)
                    evaluate_argv = ("--task", task, *fixed_evaluate)
                    _check_training(task, config, train_parser.parse_args([*trial_train, "--out", "x"]), checked)
                    evaluate_parser.parse_args([*evaluate_argv, "--agents", f"{AGENT}=x", "--out", "x"])
                    planned.append(Trial(f"{task}-{config}-s{seed}", task, config, seed, values, trial_train,
                                         evaluate_argv))
        return planned


def _check_training(task: str, config: str, args: argparse.Namespace, checked: set) -> None:
    """The trial's training settings resolve and validate (:mod:`crop_agent_ros.learning.hyperparameters`), before
    Ray starts; ``checked`` keeps the combinations already seen."""
    key = (task, args.algorithm, tuple(args.hyperparams))
    if key in checked:
        return
    from ..learning.train import resolved_settings
    try:
        resolved_settings(task, args.algorithm, args.hyperparams)
    except UsageError as error:
        raise UsageError(f"configuration {config} on task {task}: crop-sim train: {error}") from None
    checked.add(key)


def _integer(value, name: str, low: int, high: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise UsageError(f"{what}: {name} {value!r} must be an integer in {low}..{high:,}")
    return value


def _check_distribution(option: str, spec, what: str) -> None:
    if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in DISTRIBUTIONS:
        raise UsageError(f"{what}: random option {option!r} must be one of "
                         + ", ".join(f"{{{d}: [...]}}" for d in DISTRIBUTIONS) + f", not {spec!r}")
    kind, args = next(iter(spec.items()))
    if kind == "choice":
        if not isinstance(args, list) or not args:
            raise UsageError(f"{what}: random option {option!r}: choice needs a non-empty list")
        return
    numbers = isinstance(args, list) and len(args) == 2 and all(
        isinstance(a, (int, float)) and not isinstance(a, bool) for a in args)
    if not numbers or not args[0] < args[1] or (kind == "loguniform" and args[0] <= 0) or (
            kind == "randint" and not all(isinstance(a, int) for a in args)):
        raise UsageError(f"{what}: random option {option!r}: {kind} needs [low, high] with low < high"
                         + (" and low > 0" if kind == "loguniform" else "")
                         + (" (integers)" if kind == "randint" else ""))


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
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out: {out} exists and is not a folder")
    if args.resume and not experiment.is_dir():
        raise UsageError(f"--resume: {out} holds no sweep to resume (no {experiment.name}/ folder)")
    if not args.resume and experiment.exists():
        raise UsageError(f"--out: {out} already holds a sweep; add --resume to continue it, or choose another --out")
    if args.resume:
        recorded = json.loads((out / "sweep.json").read_text())
        if recorded["trials"] != [t.as_dict() for t in spec.trials()]:
            raise UsageError(f"--resume: {args.config} plans other trials than the sweep in {out} "
                             f"(its configuration is {out / 'sweep.json'})")
    out.mkdir(parents=True, exist_ok=True)
    trials = spec.trials()
    (out / "sweep.json").write_text(json.dumps({"name": spec.name, "config_file": str(args.config),
                                                "configurations": list(spec.configurations),
                                                "trials": [t.as_dict() for t in trials]}, indent=1) + "\n")
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
    failed = [r["trial"] for r in rows if r["status"] == "failed"]
    unfinished = [r["trial"] for r in rows if r["status"] == "unfinished"]
    print(f"sweep {spec.name}: {len(rows) - len(failed) - len(unfinished)}/{len(rows)} trials finished"
          + (f"; FAILED: {', '.join(failed)}" if failed else "")
          + (f"; interrupted, unfinished: {', '.join(unfinished)} (continue with --resume)" if unfinished else "")
          + f"; wrote {out}/table.csv, table.json, table.md, best.json, sweep.png", file=sys.stderr)
    return EXIT_INTERRUPTED if unfinished else 1 if failed else 0


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
        else:
            status, error = "finished", ""
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
    columns = list(dict.fromkeys(k for row in rows for k in row))
    with open(out / "table.csv", "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    result = {"name": spec.name, "config_file": spec.source, "cluster": cluster.describe(),
              "nodes": list(cluster.nodes), "wall_s": round(wall_s, 1), "command": "crop-sim " + " ".join(sys.argv[1:]),
              "configurations": list(spec.configurations), "rows": rows, "best": best}
    (out / "table.json").write_text(json.dumps(_plain(result), indent=1, allow_nan=False) + "\n", encoding="utf-8")
    (out / "best.json").write_text(json.dumps(_plain(best), indent=1, allow_nan=False) + "\n", encoding="utf-8")
    (out / "table.md").write_text(markdown(spec, rows, best), encoding="utf-8")
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
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _short(value) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)
