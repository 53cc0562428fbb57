"""``crop-sim evaluate --task TASK``: the evaluation protocol of a family task.

    crop-sim evaluate --task benton-quota --agents 'ppo=runs/benton-quota-ppo-s*' [--noise-seeds 5]
        [--far-seasons 50] [--bootstrap 2000] [--oracle | --no-oracle] [--curves | --no-curves] [--out DIR]

Evaluation sets (every one is the task's terms on other weather, :func:`~crop_sim_ros.task.scenario.with_weather_of`;
nothing here was seen in training or used to choose anything):

- ``heldout-real``: the real seasons, Benton 2000 and Paterson 1992-1995 (scenario ``heldout``);
- ``far-<generator>``: the task's own weather generator (each part's, for a mixture) with seed ``--far-seed``
  (900,001; training uses seed 0, validation 10,007 + the training seed), ``--far-seasons`` seasons;
- ``maricopa-generated`` (re-seeded likewise) and ``maricopa-real`` (2007-2009): the held-out climate. For a
  task trained on one climate (the Benton tasks) these are a transfer test, and the tables say so;
- ``far-<part>``: a mixture part on a generator another part also uses, i.e. the same site sown on another
  date (``climates3-quota``'s ``far-benton-early``), named by its scenario (``benton-early-generated``);
- ``maricopa-late-generated`` (weather seed ``--far-seed`` + 1) and ``maricopa-late-real``: the held-out
  climate sown February 28, where a quota's timing matters more (the rule's headroom is >= 2 % there, under
  2 % when sown January 15);
- ``maricopa-march15-generated`` (weather seed ``--far-seed`` + 2, last): the held-out climate sown March 15, a
  blind check: the late-sown sets were used to diagnose the agents' transfer and to design training climates
  after it; this one chooses nothing.

Terms: one draw of the task's episode terms (tuber price, water cost, quota) per season and set, from a
fixed seed (``--terms-seed`` + the set's position), the same for every policy; each policy runs every season
with noise seeds 0..K-1 (``--noise-seeds`` K). The oracle's return depends on the weather and the terms, not on
the noise: one oracle plan per (set, season).

Policies: the hindsight oracle (:class:`~crop_agent_ros.policies.family_oracle.FamilyOraclePolicy`, an upper
bound that knows the season's weather), the tuned water-budget rule (``crop_agent_ros/policies/
family_<task>.json``; tuned here on generated training seasons and written if missing, and the output says
so), and the agents: ``--agents NAME=GLOB`` names a group of training runs (one run directory per training
seed, each with ``model.zip`` + ``model.json`` of ``crop-sim train --task``), with the run's 1 % checkpoint
(``early_model.zip``) as a row of its own.

Statistics (USD/ha): regret = oracle return - policy return, per (training seed, season, noise seed). Means
with 95 % bootstrap intervals from a hierarchical resample: training seeds, seasons and noise seeds each
drawn with replacement (``--bootstrap`` resamples, seed ``--bootstrap-seed``); every policy of a set is
resampled on the same seasons and noise seeds (and an agent's final and 1 % checkpoints on the same training
seeds), so the ratio agent regret / rule regret and the final / 1 % regret ratio are paired: each resample's
ratio is the ratio of that resample's means. Paired wins: the share of (training seed, season, noise seed)
where the policy's return is above the rule's on the same season, terms and noise (a policy above the oracle
in some episodes is flagged: the oracle's search is local). Headroom: the rule's regret as a share of the
oracle's mean return (the task is worth learning if >= 2 %). Learning is real when the final regret is at
most half the 1 % checkpoint's.

Without the oracle (``--no-oracle``) every "regret" is instead the **gap to the best evaluated policy** on each
(season, noise seed), and every output labels it so: it is not a regret.

Outputs in ``--out`` (default ``runs/eval-<task>``): ``table.csv`` (one row per set and policy), ``table.json``
(every number, the per-episode returns, the terms, the seeds, the command, package versions), ``summary.json``
(its compact summary, what ``crop-sim leaderboard`` reads: :mod:`crop_agent_ros.learning.summary`), ``table.md``
(one table per set), ``regret.png`` (regret with 95 % intervals per set), ``learning_curves.csv`` and
``learning_curves.png`` (each run's held-out real regret against environment steps, from every checkpoint in
its directory: ``*.zip`` with a ``.json`` giving ``timesteps_at_save``).

Units of work: one policy on one set with one noise seed (all the set's seasons: the vector env draws one
noise stream for the whole batch, so splitting a set's seasons would change the noise), and the oracle on up to
``ORACLE_SEASONS_PER_UNIT`` seasons of a set. Without ``--address`` they run one after the other in this
process; with ``--address`` as Ray tasks (:mod:`crop_agent_ros.scale.evaluate_units`), each computed by the
same :func:`run_unit` on the same inputs, so the tables are the same bit for bit; ``table.json``'s
``execution`` says where each unit ran.
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from crop_sim_ros.output import (check_output_directory, output_directory, save_figure_atomic, write_csv_atomic,
                                 write_json_atomic, write_text_atomic)
from crop_sim_ros.usage import UsageError, user_input

from ..scale.evaluate_units import LOCAL_RAY, run_on_ray
from .evaluation_units import ORACLE, AgentFile, Unit, UnitResult, load_agent, run_unit

FAR_SEED = 900_001
FAR_SEASONS = 50            # seasons of each far generated set (a pool's first seasons depend on its size)
TERMS_SEED = 4_049
HEADROOM_PCT = 2.0          # the rule's regret must be at least this share of the oracle's return
LEARNING_RATIO = 0.5        # learning is real when final regret <= this x the 1 % checkpoint's
HELD_OUT_REAL = "heldout-real"
MARICOPA = ("maricopa-generated", "maricopa-real")
MARICOPA_LATE = ("maricopa-late-generated", "maricopa-late-real")
MARICOPA_BLIND = "maricopa-march15-generated"
RULE = "budget-rule"
PACED = "paced-rule"        # the paced rule (issue 33): a second rule row where family_<task>-paced.json exists
KINDS = ("oracle", "rule", "agent", "early")
MAX_NOISE_SEEDS = 1_000
# The oracle plans a unit's seasons side by side (12 seasons at once: 1.2 s a season; one at a time: 3.3 s);
# its plans and returns are the same however the seasons are chunked (test_distributed_evaluate checks it).
ORACLE_SEASONS_PER_UNIT = 10
MAX_RESAMPLES = 100_000
CSV_COLUMNS = (
    "set", "role", "policy", "kind", "group", "runs", "training_seeds", "seasons", "noise_seeds", "timesteps",
    "reference", "reference_rule", "return_usd_ha", "return_ci_low", "return_ci_high", "regret_usd_ha",
    "regret_ci_low", "regret_ci_high", "regret_pct_of_reference", "regret_pct_ci_low", "regret_pct_ci_high",
    "ratio_to_rule", "ratio_ci_low", "ratio_ci_high", "paired_wins", "paired_ties", "above_reference",
    "final_over_early", "final_over_early_ci_low",
    "final_over_early_ci_high", "beats_rule", "learning_is_real", "note")


def add_task_arguments(parser) -> None:
    """The options of ``crop-sim evaluate --task`` (all but ``--out``, which ``crop-sim evaluate`` has)."""
    parser.add_argument("--task", default=None, help="a family task (e.g. benton-quota): run its evaluation protocol")
    parser.add_argument("--agents", action="append", default=[], metavar="NAME=GLOB",
                        help="a group of trained runs (one directory per training seed, glob allowed, quote it), "
                             "e.g. 'ppo=runs/benton-quota-ppo-s*'; repeat for more groups")
    parser.add_argument("--noise-seeds", type=int, default=5, help="observation-noise seeds 0..K-1 per season")
    parser.add_argument("--far-seasons", type=int, default=FAR_SEASONS, help="seasons of each far generated set")
    parser.add_argument("--far-seed", type=int, default=FAR_SEED, help="weather seed of the far generated sets")
    parser.add_argument("--terms-seed", type=int, default=TERMS_SEED, help="seed of the drawn terms (set i: + i)")
    parser.add_argument("--bootstrap", type=int, default=2000, help="bootstrap resamples")
    parser.add_argument("--bootstrap-seed", type=int, default=0)
    parser.add_argument("--sets", default=None,
                        help="comma-separated evaluation sets (default all: heldout-real, far-<generator>..., "
                             "maricopa-generated, maricopa-real, far-<part>..., maricopa-late-generated, maricopa-late-real, "
                             "maricopa-march15-generated); "
                             "a set's terms are the same as in the whole protocol")
    parser.add_argument("--oracle", action=argparse.BooleanOptionalAction, default=True,
                        help="plan the hindsight oracle per season (regret); --no-oracle: gaps to the best "
                             "evaluated policy instead")
    parser.add_argument("--curves", action=argparse.BooleanOptionalAction, default=True,
                        help="learning curves from every checkpoint of each run on heldout-real")
    parser.add_argument("--tune-seasons", type=int, default=150,
                        help="if the task's tuned rule file is missing: tune it (as crop-sim tune-rule) on training "
                             "seasons 0..N-1 (of each part of a mixture)")
    parser.add_argument("--tune-candidates", type=int, default=128)
    parser.add_argument("--tune-rounds", type=int, default=4)
    parser.add_argument("--address", default=None,
                        help="run the units (policy x set x noise seed, oracle season chunks) as Ray tasks: 'auto' "
                             "or HOST:PORT joins a running cluster, 'local' starts a private instance on this "
                             "machine; same results as without it (default: in this process, no Ray)")
    parser.add_argument("--cpus", type=int, default=None,
                        help="CPUs of the private Ray instance of --address local (default: this process's CPUs)")
    parser.add_argument("--oracle-cache", type=Path, default=None,
                        help="a folder keeping the oracle's plans by season, terms and oracle code: a later "
                             "evaluation of the same sets (another agent, another trial of a sweep) reuses them")


def add_arguments(parser) -> None:
    """Every option, ``--out`` included (for a parser of this command alone)."""
    add_task_arguments(parser)
    parser.add_argument("--out", type=Path, default=None, help="output directory (default runs/eval-<task>)")


# --- evaluation sets ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class EvaluationSet:
    """One evaluation set: the task's terms on ``scenario``'s weather, seasons ``seasons`` (indices).
    ``continuations``: (climate, generated-weather scenario) whose seasons a planner draws its weather
    continuations from here (the set's own site and sowing date; None: no planner runs on this set)."""

    name: str
    role: str
    scenario: object
    seasons: np.ndarray
    continuations: tuple[str, object] | None = None

    @property
    def site_climate(self) -> str | None:
        """The weather generator of a real set's site, as its scenario names it (what an agent with a climate
        outlook reads there; a generated season's source names its own)."""
        return self.scenario.weather.climate or None


def evaluation_sets(task, far_seasons: int, far_seed: int = FAR_SEED) -> list[EvaluationSet]:
    """The protocol's sets for ``task`` (see the module docstring), in table order."""
    from crop_sim_ros.task.scenario import climates, get_scenario, reseeded, with_weather_of
    with user_input("--task (the protocol evaluates tasks trained on generated seasons)", (ValueError,)):
        sources = climates(task)
    generators = sorted({s.weather.generator for s in sources.values()})
    held_out_climate = ("held-out climate" if len(generators) > 1
                        else f"transfer test: trained on {generators[0]} weather only")
    heldout = get_scenario("heldout", task.data_dir)
    def own(real):  # a real set's continuations: its site climate's generated seasons, as that scenario sows them
        return real.weather.climate, get_scenario(f"{real.weather.climate}-generated", task.data_dir)

    sets = [EvaluationSet(HELD_OUT_REAL, "held-out real seasons (Benton 2000, Paterson 1992-1995)",
                          with_weather_of(task, heldout), np.arange(heldout.n_seasons), own(heldout))]
    other_dates = []  # far sets of a site sown on another date (a part named apart from its generator)
    for name, source in sources.items():
        generator = source.weather.generator
        sown = "" if name == generator else f", sown {source.sowing_date:%B} {source.sowing_date.day}"
        if source.weather.warming_degc:
            sown += f", {source.weather.warming_degc:+g} degC"
        if source.weather.diurnal_range_degc:
            sown += f", diurnal range {source.weather.diurnal_range_degc:+g} degC"
        if source.weather.drying_degc:
            sown += f", dew-point depression {source.weather.drying_degc:+g} degC"
        if source.weather.radiation_factor != 1.0:
            sown += f", radiation x {source.weather.radiation_factor:g}"
        if source.weather.rain_factor != 1.0:
            sown += f", rain x {source.weather.rain_factor:g}"
        if source.weather.spread is not None:
            sown += f", each season its own climate: {source.weather.spread.describe()}"
        far = replace(reseeded(source, far_seed, far_seasons), name=f"{name}-generated-seed{far_seed}")
        (sets if name == generator else other_dates).append(EvaluationSet(
            f"far-{name}", f"far generated seeds ({generator} generator{sown}, seed {far_seed})",
            with_weather_of(task, far), np.arange(far_seasons), (name, source)))
    generated, real = (get_scenario(name, task.data_dir) for name in MARICOPA)
    sets.append(EvaluationSet("maricopa-generated",
                              f"{held_out_climate} (Maricopa AZ generator, seed {far_seed})",
                              with_weather_of(task, reseeded(generated, far_seed, far_seasons)),
                              np.arange(far_seasons), ("maricopa", generated)))
    sets.append(EvaluationSet("maricopa-real", f"{held_out_climate} (Maricopa AZ, real seasons 2007-2009)",
                              with_weather_of(task, real), np.arange(real.n_seasons), own(real)))
    # Those come last: each set's terms are drawn with a seed from its position, so climates3-quota's other
    # sets keep climates-quota's positions, seasons and terms (their oracle returns are the same).
    sets += other_dates
    # The held-out climate sown late (February 28): a quota's timing matters more there than in January, so
    # these sets leave the rule >= 2 % of the oracle's return where the January ones do not (README). Last, so
    # that every set above keeps its position; weather seed far_seed + 1, as the late pool's seed is the January
    # pool's + 1 (the same seed would repeat the January set's random draws six weeks later).
    late_generated, late_real = (get_scenario(name, task.data_dir) for name in MARICOPA_LATE)
    late = f"sown {late_generated.sowing_date:%B} {late_generated.sowing_date.day}"
    sets.append(EvaluationSet("maricopa-late-generated",
                              f"{held_out_climate}, {late} (Maricopa AZ generator, seed {far_seed + 1})",
                              with_weather_of(task, reseeded(late_generated, far_seed + 1, far_seasons)),
                              np.arange(far_seasons), ("maricopa", late_generated)))
    sets.append(EvaluationSet("maricopa-late-real", f"{held_out_climate}, {late} (Maricopa AZ, real seasons 2007-2009)",
                              with_weather_of(task, late_real), np.arange(late_real.n_seasons),
                              ("maricopa", late_generated)))
    # A blind check of the held-out climate, sown later still: the late sets above were used to diagnose the
    # agents' transfer and to design training climates after it (climates6/8/10-quota); this one chooses nothing.
    blind = get_scenario(MARICOPA_BLIND, task.data_dir)
    sets.append(EvaluationSet(MARICOPA_BLIND, f"{held_out_climate}, sown {blind.sowing_date:%B} {blind.sowing_date.day}, "
                              f"a blind check (Maricopa AZ generator, seed {far_seed + 2})",
                              with_weather_of(task, reseeded(blind, far_seed + 2, far_seasons)), np.arange(far_seasons),
                              ("maricopa", blind)))
    return sets


def table_set(table: dict, set_name: str) -> tuple[dict, EvaluationSet]:
    """Set ``set_name`` of an evaluation's ``table`` (its table.json, read): the table's entry for it and the
    :class:`EvaluationSet` it was evaluated on, rebuilt from the table's task and arguments (ValueError naming
    the table's sets if it has no such set)."""
    from crop_sim_ros.task.scenario import get_scenario
    entry = next((s for s in table["sets"] if s["name"] == set_name), None)
    if entry is None:
        raise ValueError(f"--set: {set_name!r} is not in the table (it has {', '.join(s['name'] for s in table['sets'])})")
    arguments = table["arguments"]
    evaluation_set = next(s for s in evaluation_sets(get_scenario(table["task"]), arguments["far_seasons"],
                                                     arguments["far_seed"]) if s.name == set_name)
    return entry, evaluation_set


def set_terms(evaluation_set: EvaluationSet, seed: int) -> dict:
    """One draw of the task's episode terms per season of the set (name -> (M,) array)."""
    from ..policies.rollout import draw_terms
    return draw_terms(evaluation_set.scenario, evaluation_set.seasons, seed)


# --- policies -------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class AgentRun:
    """One training run: its directory, training seed and saved policies ((timesteps, zip) by timesteps)."""

    group: str
    directory: Path
    seed: int
    checkpoints: tuple[tuple[int, Path], ...]

    @property
    def final(self) -> Path:
        return self.directory / "model.zip"

    @property
    def early(self) -> Path | None:
        path = self.directory / "early_model.zip"
        return path if path.is_file() else None

    @staticmethod
    def timesteps_of(path: Path) -> int:
        """The environment steps a saved policy had trained for (-1 if its .json does not say)."""
        steps = json.loads(path.with_suffix(".json").read_text(encoding="utf-8")).get("timesteps_at_save")
        return steps if isinstance(steps, int) else -1


def _read_config(path: Path, what: str) -> dict:
    with user_input(what):
        config = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(config, dict):
        raise UsageError(f"{what}: {path} is not a JSON object")
    return config


def run_checkpoints(directory: Path, what: str) -> tuple[tuple[int, Path], ...]:
    """Every saved policy of a run directory: each ``*.zip`` whose ``.json`` gives ``timesteps_at_save``
    (``model``, ``early_model``, ``checkpoint_*``), one per step count, by step count."""
    found: dict[int, Path] = {}
    # the final and 1 % models first: a checkpoint saved at the same step is the same network
    for path in sorted(directory.glob("*.zip"), key=lambda p: (p.name not in ("model.zip", "early_model.zip"), p.name)):
        config_file = path.with_suffix(".json")
        if not config_file.is_file():
            continue
        steps = _read_config(config_file, what).get("timesteps_at_save")
        if isinstance(steps, int) and steps not in found:
            found[steps] = path
    return tuple(sorted(found.items()))


def agent_runs(specs: list[str], task_name: str) -> dict[str, list[AgentRun]]:
    """The groups of ``--agents NAME=GLOB`` (UsageError names a malformed spec, a pattern matching no run, a
    run without a final model, a run of another task, or two runs of one training seed in a group)."""
    from ..policies.learned import check_agent_task, read_agent_config
    groups: dict[str, list[AgentRun]] = {}
    for spec in specs:
        name, sep, pattern = spec.partition("=")
        name, pattern = name.strip(), pattern.strip()
        if not sep or not name or not pattern:
            raise UsageError(f"--agents: {spec!r} is not NAME=GLOB (e.g. 'ppo=runs/benton-quota-ppo-s*')")
        if name in groups or name in (RULE, ORACLE):
            raise UsageError(f"--agents: the name {name!r} is taken; give each group its own name")
        directories = sorted(Path(p) for p in glob.glob(pattern) if Path(p).is_dir())
        if not directories:
            raise UsageError(f"--agents {name}: no run directory matches {pattern!r}")
        runs = []
        for directory in directories:
            what = f"--agents {name}"
            if not (directory / "model.zip").is_file() or not (directory / "model.json").is_file():
                raise UsageError(f"{what}: {directory} holds no model.zip + model.json (a finished "
                                 "`crop-sim train --task` run)")
            with user_input(what):  # model.json validated (types, ranges, scaler), and of this task
                config = read_agent_config(directory / "model.json")
                check_agent_task(config, task_name, str(directory))
            runs.append(AgentRun(name, directory, config.seed, run_checkpoints(directory, what)))
        seeds = [run.seed for run in runs]
        if len(set(seeds)) != len(seeds):
            raise UsageError(f"--agents {name}: training seeds {seeds} repeat; a group holds one run per seed")
        groups[name] = runs
    return groups


def the_rule(task, args, log):
    """The tuned rule of ``task`` and where it came from; tuned on training seasons and written if missing."""
    from ..policies import family_tuning
    path = family_tuning.rule_file(task.name)
    if path.is_file():
        with user_input(f"tuned rule {path}", (ValueError, KeyError, TypeError, OSError)):
            return family_tuning.tuned_rule(task.name), {"file": str(path), "tuned_now": False}
    seasons = family_tuning.training_seasons(task, 0, args.tune_seasons - 1)
    log(f"{path} is missing: tuning the rule now on {len(seasons)} generated training seasons "
        f"({args.tune_candidates} candidates, {args.tune_rounds} rounds: as `crop-sim tune-rule --task {task.name} "
        f"--seasons 0..{args.tune_seasons - 1} --candidates {args.tune_candidates} --rounds {args.tune_rounds}`) "
        "and writing it")
    result = family_tuning.tune_rule(task, seasons, seed=0, candidates=args.tune_candidates,
                                     rounds=args.tune_rounds, log=log)
    family_tuning.write_tuned(task.name, result)
    return family_tuning.tuned_rule(task.name), {"file": str(path), "tuned_now": True,
                                                 "tuned_on_seasons": seasons.tolist()}


def the_paced_rule(task, log):
    """The paced rule tuned for ``task`` (``crop-sim tune-rule --rule paced-rule``) and its file, or (None, None)
    where it has none (the output says so); a malformed file is refused in one line."""
    from ..policies import family_tuning
    path = family_tuning.family_file(task.name, PACED)
    if not path.is_file():
        log(f"no {PACED} row: {path.name} is missing (`crop-sim tune-rule --task {task.name} --rule {PACED}`)")
        return None, None
    with user_input(f"tuned rule {path}", (ValueError, KeyError, TypeError, OSError)):
        return family_tuning.tuned_rule(task.name, PACED), {"file": str(path), "tuned_now": False}


def plan_units(sets: list[EvaluationSet], agent_keys: list[str], curve_keys: list[str], noise_seeds: int,
               with_oracle: bool, oracle_seasons_per_unit: int = ORACLE_SEASONS_PER_UNIT) -> list[Unit]:
    """Every unit of the run, set by set: the oracle's chunks (the longest units first), then the rule and each
    agent file with noise seeds 0..K-1; on heldout-real also the learning curves' other checkpoints."""
    units = []
    for index, evaluation_set in enumerate(sets):
        m = len(evaluation_set.seasons)
        if with_oracle:
            units += [Unit(index, ORACLE, 0, start, min(start + oracle_seasons_per_unit, m))
                      for start in range(0, m, oracle_seasons_per_unit)]
        keys = [RULE, *agent_keys, *(curve_keys if evaluation_set.name == HELD_OUT_REAL else [])]
        units += [Unit(index, key, seed, 0, m) for key in keys for seed in range(noise_seeds)]
    return units


def run_units_here(units: list[Unit], sets: list[EvaluationSet], terms: list[dict], policies: dict,
                   log) -> list[UnitResult]:
    """Every unit, one after the other, in this process (no Ray), on one thread as a Ray worker runs them
    (``scale.cluster.ONE_THREAD``): a network's matrix products split over more threads round differently (seen
    on an AMD EPYC: returns apart in the 10th digit), and a table must not depend on where its units ran."""
    import torch
    torch.set_num_threads(1)
    results = []
    for position, unit in enumerate(units):
        if position == 0 or units[position - 1].set_index != unit.set_index:
            mine = [u for u in units if u.set_index == unit.set_index]
            log(f"{sets[unit.set_index].name}: {len(mine)} units ({len(sets[unit.set_index].seasons)} seasons; "
                f"{sum(u.policy == ORACLE for u in mine)} of the oracle)")
        results.append(run_unit(unit, sets[unit.set_index], terms[unit.set_index], policies.get(unit.policy)))
    return results


ORACLE_CODE = ("crop_agent_ros/policies/family_oracle.py", "crop_agent_ros/policies/family_dp.py",
               "crop_agent_ros/policies/rollout.py", "crop_sim_ros/task", "crop_sim_ros/model", "crop_sim_ros/weather")


def oracle_code_digest() -> str:
    """A digest of the source the oracle's result depends on (its search, the environment, the model, the
    weather): a cached plan is used only by the code that made it."""
    root = Path(__file__).resolve().parents[2]
    digest = hashlib.sha256()
    for entry in ORACLE_CODE:
        for path in sorted((root / entry).rglob("*.py")) if (root / entry).is_dir() else [root / entry]:
            digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def oracle_cache_key(unit: Unit, evaluation_set: EvaluationSet, terms: dict, code: str) -> str:
    """The key of an oracle unit's result: the set's scenario (every field), the unit's seasons, their terms and
    the oracle's code."""
    digest = hashlib.sha256(code.encode())
    digest.update(repr(evaluation_set.scenario).encode())
    digest.update(np.asarray(evaluation_set.seasons[unit.start:unit.stop], dtype=np.int64).tobytes())
    for name in sorted(terms):
        digest.update(name.encode() + np.ascontiguousarray(terms[name][unit.start:unit.stop], dtype=float).tobytes())
    return digest.hexdigest()[:32]


class OracleCache:
    """Oracle units' results in a folder, one JSON file per key (written whole: a temporary file renamed, so
    trials of a sweep may share the folder)."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        if self.folder.exists() and not self.folder.is_dir():
            raise UsageError(f"--oracle-cache: {self.folder} exists and is not a folder")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.code = oracle_code_digest()

    def get(self, key: str) -> UnitResult | None:
        path = self.folder / f"{key}.json"
        try:
            stored = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return UnitResult(np.asarray(stored["returns"], dtype=float), stored["plans"], 0.0,
                          {"node": "oracle cache", "pid": 0})

    def put(self, key: str, result: UnitResult) -> None:
        write_json_atomic(self.folder / f"{key}.json", _plain({"returns": result.returns, "plans": result.plans}),
                          indent=None)


# --- statistics ------------------------------------------------------------------------------------------

def resample_counts(rng: np.random.Generator, units: int, resamples: int) -> np.ndarray:
    """(resamples, units): how often each unit is drawn in each resample of ``units`` draws with replacement."""
    draws = rng.integers(0, units, size=(resamples, units))
    flat = (draws + units * np.arange(resamples)[:, None]).ravel()
    return np.bincount(flat, minlength=resamples * units).reshape(resamples, units)


def grid_means(values: np.ndarray, runs: np.ndarray, seasons: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """(B,) mean of ``values`` (R, M, K) over each resample's grid: training runs x seasons x noise seeds,
    each unit counted as often as it was drawn (counts (B, R), (B, M), (B, K))."""
    r, m, k = values.shape
    if runs.shape[1:] != (r,) or seasons.shape[1:] != (m,) or noise.shape[1:] != (k,):
        raise ValueError(f"resample counts {runs.shape}, {seasons.shape}, {noise.shape} do not fit values "
                         f"{values.shape}")
    return np.einsum("rmk,br,bm,bk->b", values, runs, seasons, noise, optimize=True) / (r * m * k)


@dataclass(frozen=True)
class Resamples:
    """The hierarchical bootstrap of one set: season and noise-seed counts shared by every policy, and the
    training-seed counts of each agent group (shared by its final and 1 % checkpoints)."""

    seasons: np.ndarray
    noise: np.ndarray
    runs: dict

    @classmethod
    def draw(cls, seed: int, set_index: int, seasons: int, noise_seeds: int, group_sizes: dict,
             resamples: int) -> "Resamples":
        rng = np.random.default_rng([seed, set_index])
        season_counts = resample_counts(rng, seasons, resamples)
        noise_counts = resample_counts(rng, noise_seeds, resamples)
        runs = {group: resample_counts(np.random.default_rng([seed, set_index, i + 1]), size, resamples)
                for i, (group, size) in enumerate(group_sizes.items())}
        return cls(season_counts, noise_counts, runs)

    def means(self, values: np.ndarray, group: str | None = None) -> np.ndarray:
        """(B,) resampled means of ``values`` (R, M, K); no group: one run (the rule, the oracle)."""
        runs = self.runs[group] if group is not None else np.ones((len(self.seasons), 1), dtype=np.int64)
        return grid_means(values, runs, self.seasons, self.noise)


def interval(distribution: np.ndarray) -> tuple[float, float]:
    """The 95 % percentile interval of a bootstrap distribution (NaN if any resample is undefined)."""
    if not np.all(np.isfinite(distribution)):
        return float("nan"), float("nan")
    low, high = np.percentile(distribution, [2.5, 97.5])
    return float(low), float(high)


@dataclass
class Evaluated:
    """Returns (USD/ha) of one policy on one set, shape (R, M, K): training runs x seasons x noise seeds (R = 1
    for the rule and the oracle)."""

    name: str
    kind: str
    returns: np.ndarray
    group: str | None = None
    timesteps: tuple[int, ...] = ()
    training_seeds: tuple[int, ...] = ()
    partner: str | None = None   # a final agent's 1 % checkpoint row


def _ratio(numerator: np.ndarray, denominator: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(denominator > 0, numerator / np.where(denominator > 0, denominator, 1.0), np.nan)


def compare(evaluated: list[Evaluated], reference: np.ndarray, resamples: Resamples, with_oracle: bool) -> list[dict]:
    """One row per policy: return, regret (or gap) with 95 % intervals, as % of the reference's mean return,
    ratio to the rule (paired), paired wins against the rule, final / 1 % ratio, and the note. "The rule" is the
    strongest rule of the set: of the rule rows (the budget rule, the paced rule), the one with the lower mean
    regret on this set; every row names it (``reference_rule``), and a weaker rule's note says so."""
    reference = np.asarray(reference, dtype=float)[None]           # (1, M, K)
    rule = min((e for e in evaluated if e.kind == "rule"), key=lambda e: float((reference - e.returns).mean()))
    reference_mean, reference_dist = float(reference.mean()), resamples.means(reference)
    rule_regret = reference - rule.returns
    rule_dist = resamples.means(rule_regret)
    by_name = {e.name: e for e in evaluated}
    word = "regret" if with_oracle else "gap"
    rows = []
    for e in evaluated:
        regret = reference - e.returns
        dist = resamples.means(regret, e.group)
        returns_dist = resamples.means(e.returns, e.group)
        ratio = float(regret.mean() / rule_regret.mean()) if rule_regret.mean() > 0 else float("nan")
        ratio_low, ratio_high = interval(_ratio(dist, rule_dist))
        row = {"policy": e.name, "kind": e.kind, "group": e.group or "", "runs": len(e.returns),
               "training_seeds": " ".join(map(str, e.training_seeds)), "seasons": e.returns.shape[1],
               "noise_seeds": e.returns.shape[2],
               "timesteps": " ".join(map(str, e.timesteps)),
               "reference": "oracle" if with_oracle else "best evaluated policy (gap, not regret)",
               "reference_rule": rule.name,
               "return_usd_ha": float(e.returns.mean()), **_named_interval("return", interval(returns_dist)),
               "regret_usd_ha": float(regret.mean()), **_named_interval("regret", interval(dist)),
               "regret_pct_of_reference": 100.0 * float(regret.mean()) / reference_mean,
               **_named_interval("regret_pct", interval(100.0 * dist / reference_dist)),
               "ratio_to_rule": ratio, "ratio_ci_low": ratio_low, "ratio_ci_high": ratio_high,
               "paired_wins": float(np.mean(e.returns > rule.returns)),
               "paired_ties": float(np.mean(e.returns == rule.returns)),
               "above_reference": float(np.mean(regret < 0.0)),
               "final_over_early": float("nan"), "final_over_early_ci_low": float("nan"),
               "final_over_early_ci_high": float("nan"), "beats_rule": "", "learning_is_real": ""}
        notes = []
        if e.kind == "oracle":
            notes.append("hindsight upper bound (plans knowing the season's weather)")
        elif e.kind == "rule":
            headroom = row["regret_pct_of_reference"]
            notes.append(("the paced rule (issue 33); " if e.name == PACED else "the budget rule; ")
                         + ("the strongest rule of this set (the ratios' reference); " if e is rule
                            else "a weaker baseline; ") + (
                f"headroom: regret {headroom:.1f} % of the oracle's return "
                + ("(>= " if headroom >= HEADROOM_PCT else "(NOT >= ") + f"{HEADROOM_PCT:g} %)" if with_oracle
                else "headroom unknown without the oracle"))
        elif e.kind == "early":
            notes.append(f"1 % checkpoint ({_steps_text(e.timesteps)} steps)")
        if e.kind in ("agent", "early"):
            beats = bool(np.isfinite(ratio_high) and ratio_high < 1.0)
            row["beats_rule"] = beats
            notes.append("beats the rule" if beats else "no better than the rule")
        if e.kind == "agent" and e.partner is not None:
            early = by_name[e.partner]
            early_regret = reference - early.returns
            row["final_over_early"] = float(regret.mean() / early_regret.mean()) if early_regret.mean() > 0 \
                else float("nan")
            low, high = interval(_ratio(dist, resamples.means(early_regret, e.group)))
            row["final_over_early_ci_low"], row["final_over_early_ci_high"] = low, high
            real = bool(row["final_over_early"] <= LEARNING_RATIO)
            row["learning_is_real"] = real
            notes.append(f"final / 1 % {word} {_fmt(row['final_over_early'], 2)} [{_fmt(low, 2)}, {_fmt(high, 2)}]: "
                         + ("learning is real" if real else f"NOT <= {LEARNING_RATIO:g}"))
        elif e.kind == "agent":
            notes.append("no 1 % checkpoint in the run directories")
        if row["above_reference"] > 0 and with_oracle:
            notes.append(f"above the oracle in {100 * row['above_reference']:.0f} % of episodes (the oracle's search "
                         "is local)")
        if not np.isfinite(ratio_low) and e.kind != "oracle":
            notes.append(f"ratio undefined: the rule's {word} is not positive in every resample")
        row["note"] = "; ".join(notes)
        rows.append(row)
    return rows


def _named_interval(prefix: str, bounds: tuple[float, float]) -> dict:
    return {f"{prefix}_ci_low": bounds[0], f"{prefix}_ci_high": bounds[1]}


def _steps_text(timesteps) -> str:
    steps = sorted(set(timesteps))
    return f"{steps[0]:,}" if len(steps) == 1 else f"{steps[0]:,}-{steps[-1]:,}"


def _fmt(value: float, digits: int = 0) -> str:
    return "n/a" if value is None or not np.isfinite(value) else f"{value:,.{digits}f}"


# --- the run --------------------------------------------------------------------------------------------

def _check_arguments(args) -> None:
    checks = (("--noise-seeds", args.noise_seeds, 1, MAX_NOISE_SEEDS),
              ("--bootstrap", args.bootstrap, 100, MAX_RESAMPLES),
              ("--far-seasons", args.far_seasons, 1, 10_000), ("--far-seed", args.far_seed, 0, 2**32 - 1),
              ("--terms-seed", args.terms_seed, 0, 2**32 - 1),
              ("--bootstrap-seed", args.bootstrap_seed, 0, 2**32 - 1),
              ("--tune-seasons", args.tune_seasons, 1, 1_000), ("--tune-candidates", args.tune_candidates, 1, 10_000),
              ("--tune-rounds", args.tune_rounds, 0, 50))
    for name, value, low, high in checks:
        if not low <= value <= high:
            raise UsageError(f"{name}: {value} is not in {low}..{high}")
    if args.address != LOCAL_RAY:
        from ..scale.cluster import check_address
        check_address(args.address)
        if args.cpus is not None:
            raise UsageError("--cpus: sets the CPUs of the private Ray instance of --address local; a cluster's "
                             "CPUs are its own")
    elif args.cpus is not None and args.cpus < 1:
        raise UsageError(f"--cpus: {args.cpus} is not a positive number of CPUs")


def _task(name: str | None):
    from crop_sim_ros.task.scenario import get_scenario
    if not name:
        raise UsageError("--task: give a family task, e.g. --task benton-quota")
    with user_input("--task"):
        task = get_scenario(name)
    if not task.is_family_task:
        raise UsageError(f"--task: {name!r} is not a family task (its observation has 20 values)")
    return task


def _chosen_sets(sets: list[EvaluationSet], text: str | None) -> tuple[list[EvaluationSet], list[int]]:
    """The sets ``--sets`` names (all without it) and each one's position in the whole protocol: its terms and
    bootstrap resamples are seeded by that position, so a set evaluated alone gives the rows it has in the whole
    evaluation."""
    if text is None:
        return sets, list(range(len(sets)))
    names = [n.strip() for n in text.split(",") if n.strip()]
    known = [s.name for s in sets]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise UsageError(f"--sets: {', '.join(unknown) or repr(text)} unknown; this task's sets: {', '.join(known)}")
    positions = [i for i, s in enumerate(sets) if s.name in names]
    return [sets[i] for i in positions], positions


def _versions() -> dict:
    from importlib import metadata
    versions = {"python": platform.python_version()}
    for package in ("numpy", "gymnasium", "torch", "stable-baselines3", "sb3-contrib", "matplotlib"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = None
    root = Path(__file__).resolve().parents[2]
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10)
        versions["git_commit"] = commit.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        versions["git_commit"] = None
    return versions


def run_task(args) -> dict:
    """Run the protocol of ``args.task`` (see the module docstring); writes the outputs and returns the
    ``table.json`` content."""
    from crop_sim_ros.task import core
    started = time.perf_counter()
    log = _log
    _check_arguments(args)
    task = _task(args.task)
    out = Path(args.out) if getattr(args, "out", None) else Path("runs") / f"eval-{task.name}"
    check_output_directory(out)
    with user_input("--far-seasons", (ValueError,)):
        sets, positions = _chosen_sets(evaluation_sets(task, args.far_seasons, args.far_seed), args.sets)
    groups = agent_runs(args.agents, task.name)
    if args.oracle:
        try:
            from ..policies import family_oracle  # noqa: F401
        except ModuleNotFoundError:
            raise UsageError("--oracle: the family oracle (crop_agent_ros/policies/family_oracle.py) is not "
                             "available; --no-oracle reports gaps to the best evaluated policy instead") from None
    rule, rule_info = the_rule(task, args, log)
    paced, paced_info = the_paced_rule(task, log)
    rules = {RULE: rule, **({PACED: paced} if paced is not None else {})}
    agent_files = {str(path): name for runs in groups.values() for run in runs
                   for path, name in ((run.final, run.group), (run.early, f"{run.group}-1%")) if path is not None}
    with_curves = bool(args.curves and groups and any(s.name == HELD_OUT_REAL for s in sets))
    if args.curves and groups and not with_curves:
        log(f"no learning curves: --sets leaves out {HELD_OUT_REAL}")
    curve_files = {str(path): run.group for runs in groups.values() for run in runs for _, path in run.checkpoints
                   if with_curves and str(path) not in agent_files}
    # every policy is loaded here first: a broken file is the user's, before any unit runs
    agent_names = {**agent_files, **curve_files}
    policies = {**rules, **{key: load_agent(Path(key), name) for key, name in agent_names.items()}}
    terms = [set_terms(evaluation_set, args.terms_seed + position) for evaluation_set, position in zip(sets, positions)]
    units = plan_units(sets, [key for key in rules if key != RULE] + list(agent_files), list(curve_files),
                       args.noise_seeds, args.oracle)
    wall = {"setup_s": time.perf_counter() - started}
    output_directory(out)
    t0 = time.perf_counter()
    cache = OracleCache(args.oracle_cache) if args.oracle_cache is not None else None
    cached = {}
    if cache is not None:
        keys = {u: oracle_cache_key(u, sets[u.set_index], terms[u.set_index], cache.code)
                for u in units if u.policy == ORACLE}
        cached = {u: hit for u, key in keys.items() if (hit := cache.get(key)) is not None}
        log(f"oracle cache {args.oracle_cache}: {len(cached)} of {len(keys)} oracle units found")
    to_run = [u for u in units if u not in cached]
    if args.address is None:
        ran = run_units_here(to_run, sets, terms, policies, log)
        where, cluster_nodes = None, []
    else:
        sources = {**rules, **{key: AgentFile.read(Path(key), name) for key, name in agent_names.items()}}
        ran, cluster = run_on_ray(to_run, sets, terms, sources, args.address, args.cpus, log)
        where, cluster_nodes = cluster.address, list(cluster.nodes)
    if cache is not None:
        for unit, result in zip(to_run, ran):
            if unit.policy == ORACLE:
                cache.put(keys[unit], result)
    wall["units_s"] = round(time.perf_counter() - t0, 1)
    done = {**cached, **dict(zip(to_run, ran))}
    results = [done[u] for u in units]
    k = args.noise_seeds

    def returns_of(index: int, key: str) -> np.ndarray:
        """(M, K) returns of policy ``key`` on set ``index``, noise seeds 0..K-1."""
        m = len(sets[index].seasons)
        return np.stack([done[Unit(index, key, seed, 0, m)].returns for seed in range(k)], axis=1)

    report_sets, rows, curve_inputs = [], [], None
    for index, evaluation_set in enumerate(sets):
        m = len(evaluation_set.seasons)
        evaluated: list[Evaluated] = []
        oracle, plans = None, None
        if args.oracle:
            chunks = [done[u] for u in units if u.set_index == index and u.policy == ORACLE]
            oracle = np.concatenate([chunk.returns for chunk in chunks])
            plans = [plan for chunk in chunks for plan in chunk.plans]
            evaluated.append(Evaluated(ORACLE, "oracle", np.broadcast_to(oracle[None, :, None], (1, m, k)).copy()))
        evaluated.append(Evaluated(RULE, "rule", returns_of(index, RULE)[None]))
        if paced is not None:
            evaluated.append(Evaluated(PACED, "rule", returns_of(index, PACED)[None]))
        for group, runs in groups.items():
            seeds = tuple(run.seed for run in runs)
            has_early = all(run.early is not None for run in runs)
            evaluated.append(Evaluated(group, "agent", np.stack([returns_of(index, str(run.final)) for run in runs]),
                                       group, tuple(run.timesteps_of(run.final) for run in runs), seeds,
                                       partner=f"{group}, 1 % checkpoint" if has_early else None))
            if has_early:
                evaluated.append(Evaluated(f"{group}, 1 % checkpoint", "early",
                                           np.stack([returns_of(index, str(run.early)) for run in runs]), group,
                                           tuple(run.timesteps_of(run.early) for run in runs), seeds))
        reference = (np.broadcast_to(oracle[:, None], (m, k)) if oracle is not None
                     else np.max([e.returns.max(axis=0) for e in evaluated], axis=0))
        resamples = Resamples.draw(args.bootstrap_seed, positions[index], m, k, {g: len(r) for g, r in groups.items()},
                                   args.bootstrap)
        set_rows = [{"set": evaluation_set.name, "role": evaluation_set.role, **row}
                    for row in compare(evaluated, reference, resamples, oracle is not None)]
        rows.extend(set_rows)
        if evaluation_set.name == HELD_OUT_REAL:
            curve_inputs = (index, reference)
        table = core.scenario_table(evaluation_set.scenario)
        mine = [(u, done[u]) for u in units if u.set_index == index]
        report_sets.append({
            "name": evaluation_set.name, "role": evaluation_set.role, "scenario": evaluation_set.scenario.name,
            "seasons": evaluation_set.seasons.tolist(),
            "season_sources": [f"{table.sources[s]} sown {table.sowing_dates[s]}" for s in evaluation_set.seasons],
            "terms_seed": args.terms_seed + positions[index],
            "terms": {name: values.tolist() for name, values in terms[index].items()},
            "oracle_returns_usd_ha": None if oracle is None else oracle.tolist(),
            "oracle_plans": plans,
            "reference": "oracle" if oracle is not None else "best evaluated policy per (season, noise seed)",
            "returns_usd_ha": {e.name: e.returns.tolist() for e in evaluated},
            "returns_shape": "training runs x seasons x noise seeds", "rows": set_rows,
            "units_s": round(sum(r.seconds for _, r in mine), 1),
            "oracle_units_s": round(sum(r.seconds for u, r in mine if u.policy == ORACLE), 1)})
    curves = (learning_curve_rows(groups, curve_inputs[1], lambda key: returns_of(curve_inputs[0], key))
              if with_curves else [])
    wall["total_s"] = round(time.perf_counter() - started, 1)
    result = {
        "task": task.name, "command": "crop-sim " + " ".join(sys.argv[1:]),
        "arguments": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
                      if not k.startswith("_") and k != "func"},
        "regret": ("oracle return - policy return, USD/ha" if args.oracle
                   else "NO ORACLE: gap to the best evaluated policy per (season, noise seed), USD/ha; not a regret"),
        "seeds": {"far_weather_seed": args.far_seed, "terms_seed_base": args.terms_seed,
                  "noise_seeds": list(range(args.noise_seeds)), "bootstrap_seed": args.bootstrap_seed,
                  "bootstrap_resamples": args.bootstrap, "oracle_noise_seed": 0},
        "rule": {**rule_info, **rule.describe()},
        **({"paced_rule": {**paced_info, **paced.describe()}} if paced is not None else {}),
        "agents": {group: [{"directory": str(run.directory), "training_seed": run.seed,
                            "checkpoints": [[steps, str(path)] for steps, path in run.checkpoints]} for run in runs]
                   for group, runs in groups.items()},
        "sets": report_sets, "learning_curves": curves, "versions": _versions(), "wall_s": wall,
        "execution": execution_record(where, cluster_nodes, units, results, sets)}
    write_outputs(out, result, rows, curves)
    log(f"wrote {out}/table.md, table.csv, table.json, regret.png"
        + (", learning_curves.csv, learning_curves.png" if curves else "") + f" in {wall['total_s']:.0f} s")
    return result


def execution_record(address: str | None, cluster_nodes: list[dict], units: list[Unit], results: list[UnitResult],
                     sets: list[EvaluationSet]) -> dict:
    """Where the units ran (for ``table.json`` only: the tables are the same wherever they ran)."""
    here = {"node": "this process", "pid": os.getpid()}
    unit_log = [{"set": sets[u.set_index].name, "policy": u.policy, "noise_seed": u.noise_seed,
                 "seasons": [u.start, u.stop], "node": (r.node or here)["node"], "pid": (r.node or here)["pid"],
                 "seconds": round(r.seconds, 2)} for u, r in zip(units, results)]
    per_node: dict[str, int] = {}
    for entry in unit_log:
        per_node[entry["node"]] = per_node.get(entry["node"], 0) + 1
    return {"address": address or "none: every unit in this process, no Ray", "ray_nodes": cluster_nodes,
            "units": len(units), "units_per_node": per_node,
            "oracle_seasons_per_unit": ORACLE_SEASONS_PER_UNIT, "unit_log": unit_log}


def learning_curve_rows(groups: dict, reference: np.ndarray, returns_of) -> list[dict]:
    """Each run's mean regret (or gap) on heldout-real at every saved checkpoint, by environment steps
    (``returns_of(path)``: the checkpoint's (M, K) returns there)."""
    rows = []
    for group, runs in groups.items():
        for run in runs:
            for steps, path in run.checkpoints:
                returns = returns_of(str(path))
                rows.append({"group": group, "run": str(run.directory), "training_seed": run.seed,
                             "checkpoint": path.name, "timesteps": steps,
                             "return_usd_ha": float(returns.mean()),
                             "regret_usd_ha": float((reference - returns).mean())})
    return rows


def _log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# --- outputs --------------------------------------------------------------------------------------------

def write_outputs(out: Path, result: dict, rows: list[dict], curves: list[dict]) -> None:
    from .summary import recorded_runs, write_summary
    table = _plain(result)
    write_json_atomic(out / "table.json", table, allow_nan=False)
    # the leaderboard's compact copy (results/summaries/<evaluation>.json is this file)
    write_summary(out / "summary.json", table, recorded_runs(table))
    write_csv_atomic(out / "table.csv", CSV_COLUMNS, rows)
    write_text_atomic(out / "table.md", markdown(result))
    plot_regret(out / "regret.png", result)
    if curves:
        write_csv_atomic(out / "learning_curves.csv", list(curves[0]), curves)
        rule_regret = next(r for s in result["sets"] if s["name"] == HELD_OUT_REAL for r in s["rows"]
                           if r["kind"] == "rule")["regret_usd_ha"]
        plot_learning_curves(out / "learning_curves.png", curves, rule_regret, result)


def _plain(value):
    """``value`` as strict JSON: numpy scalars and arrays as numbers and lists, NaN and infinities as null
    (an undefined ratio; a rule parameter that never acts), paths as strings."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if value is None or isinstance(value, str):
        return value
    return str(value)


def markdown(result: dict) -> str:
    with_oracle = result["sets"][0]["reference"] == "oracle"
    word = "regret" if with_oracle else "gap to best"
    lines = [f"# Evaluation of {result['task']}", ""]
    if not with_oracle:
        lines += ["**No oracle**: every 'gap' below is the gap to the best evaluated policy on each (season, noise "
                  "seed), not a regret.", ""]
    lines += [f"Returns and {word} in USD/ha; [95 % bootstrap CI] over training seeds x seasons x noise seeds "
              f"({result['seeds']['bootstrap_resamples']} resamples). Ratio to rule: agent {word} / rule {word}, "
              "paired resamples, against the strongest rule of each set (the rule row with the lower mean "
              f"{word}, named per set; the other rule is a weaker baseline); paired wins: share of (training "
              "seed, season, noise seed) where the policy's return is above that rule's. Budget rule: "
              + f"`{result['rule']['file']}`"
              + (" (tuned by this run)" if result["rule"]["tuned_now"] else "") + ".", ""]
    reference = "oracle" if with_oracle else "best"
    for s in result["sets"]:
        lines += [f"## {s['name']}: {s['role']}", "",
                  f"{len(s['seasons'])} seasons x {len(result['seeds']['noise_seeds'])} noise seeds; terms seed "
                  f"{s['terms_seed']}; strongest rule (the ratios' reference): "
                  f"`{next((r.get('reference_rule') for r in s['rows'] if r.get('reference_rule')), RULE)}`.", "",
                  f"| policy | return | {word} [95 % CI] | {word} % of {reference} | ratio to rule [95 % CI] | "
                  "paired wins | note |", "|---|---:|---:|---:|---:|---:|---|"]
        for r in s["rows"]:
            runs = (f" ({r['runs']} run{'s' if r['runs'] > 1 else ''})" if r["kind"] in ("agent", "early") else "")
            regret = ("0 (reference)" if r["kind"] == "oracle" else
                      f"{_fmt(r['regret_usd_ha'])} [{_fmt(r['regret_ci_low'])}, {_fmt(r['regret_ci_high'])}]")
            ratio = ("-" if r["kind"] in ("oracle", "rule") else
                     f"{_fmt(r['ratio_to_rule'], 2)} [{_fmt(r['ratio_ci_low'], 2)}, {_fmt(r['ratio_ci_high'], 2)}]")
            wins = "-" if r["kind"] == "rule" else f"{100 * r['paired_wins']:.0f} %"
            lines.append(f"| {r['policy']}{runs} | {_fmt(r['return_usd_ha'])} | {regret} | "
                         f"{_fmt(r['regret_pct_of_reference'], 2)} % | {ratio} | {wins} | {r['note']} |")
        lines.append("")
    if result["learning_curves"]:
        lines += ["Learning curves (held-out real regret against environment steps): `learning_curves.png`, "
                  "`learning_curves.csv`.", ""]
    return "\n".join(lines)


def plot_regret(path: Path, result: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sets = result["sets"]
    word = "regret" if sets[0]["reference"] == "oracle" else "gap to the best evaluated policy"
    fig, axes = plt.subplots(1, len(sets), figsize=(3.2 * len(sets) + 1, 4.2), squeeze=False)
    for ax, s in zip(axes[0], sets):
        rows = [r for r in s["rows"] if r["kind"] != "oracle"]
        x = np.arange(len(rows))
        means = np.array([r["regret_usd_ha"] for r in rows])
        errors = np.array([[m - r["regret_ci_low"], r["regret_ci_high"] - m] for m, r in zip(means, rows)]).T
        colors = ["tab:gray" if r["kind"] == "rule" else "tab:orange" if r["kind"] == "early" else "tab:blue"
                  for r in rows]
        ax.bar(x, means, yerr=np.nan_to_num(errors), color=colors, capsize=3)
        ax.set_xticks(x, [r["policy"] for r in rows], rotation=30, ha="right", fontsize=8)
        ax.set_title(f"{s['name']}\n({len(s['seasons'])} seasons)", fontsize=9)
        ax.axhline(0.0, color="black", lw=0.8)
    axes[0][0].set_ylabel(f"{word}, USD/ha (95 % CI)")
    fig.suptitle(f"{result['task']}: {word} per evaluation set", fontsize=10)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=120)
    plt.close(fig)


def plot_learning_curves(path: Path, curves: list[dict], rule_regret: float, result: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    word = "regret" if result["sets"][0]["reference"] == "oracle" else "gap to the best evaluated policy"
    fig, ax = plt.subplots(figsize=(7, 4.5))
    colors = dict(zip(sorted({c["group"] for c in curves}), plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    labelled = set()
    for run in sorted({c["run"] for c in curves}):
        points = sorted((c for c in curves if c["run"] == run), key=lambda c: c["timesteps"])
        group = points[0]["group"]
        ax.plot([p["timesteps"] for p in points], [p["regret_usd_ha"] for p in points], marker="o",
                color=colors[group], label=None if group in labelled else group)
        labelled.add(group)
    ax.axhline(rule_regret, color="gray", ls="--", label=f"{RULE} ({rule_regret:,.0f})")
    ax.set_xscale("log")
    ax.set_xlabel("environment steps (field-days)")
    ax.set_ylabel(f"{HELD_OUT_REAL} {word}, USD/ha")
    ax.set_title(f"{result['task']}: learning curves on the held-out real seasons", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=120)
    plt.close(fig)


def run(args) -> int:
    run_task(args)
    return 0
