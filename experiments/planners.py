"""What it showed: on ``benton-quota``'s far Benton seasons a causal planner has 0.63 (mean of plans), 0.47
(hindsight values) and 0.43 [0.36, 0.51] (expected values) of the tuned rule's regret; on a climate no training
season comes from (Maricopa, sown late) the expected-value planner halves the rule's regret only when its 8
continuations are that climate's own weather (0.46 [0.34, 0.62]), and ties the rule given a training climate's.

The three causal planners by name (:data:`METHODS`), and the command line that runs one on a set of an
evaluation (``crop-sim evaluate --task T``'s table.json), beside that evaluation's oracle and rule:

    python -m experiments.planners [--method expected-value|hindsight-value|mean-plan] \\
        --table TABLE.json --set heldout-real [--seasons 0..4] [--scenarios K] [--decision-every-days 7] \\
        [--continuations CLIMATE] [--align day-of-year|sowing] [--out FILE.json]

and ``--paired BASE.json OTHER.json`` compares two such runs season by season (:func:`paired_runs`).
``mean-plan`` is :mod:`experiments.planners_mpc`, ``hindsight-value`` :mod:`experiments.planners_hindsight`,
``expected-value`` (the default) :mod:`experiments.planners_expected`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from crop_agent_ros.learning.evaluate_task import RULE, _ratio, interval, table_set
from crop_agent_ros.policies.base import BasePolicy, SeasonContext
from crop_agent_ros.policies.family_oracle import TaskConstants
from crop_agent_ros.policies.rollout import run_episodes, season_range
from crop_sim_ros.weather.generator import GENERATOR_NAMES

from experiments.planners_expected import ExpectedSettings, FamilyExpectedPolicy
from experiments.planners_hindsight import FamilyHindsightPolicy, HindsightSettings
from experiments.planners_mpc import ALIGNMENTS, FamilyMpcPolicy, MpcSettings, continuation_pool

# --- the three causal planners, by name -----------------------------------------------------------------------

METHODS = ("expected-value", "hindsight-value", "mean-plan")  # the first is the default


def planner_settings(method: str, scenarios: int | None = None, decision_every_days: int | None = None):
    """The settings of planner ``method`` (a METHODS entry: ``mean-plan`` is
    :class:`~experiments.planners_mpc.FamilyMpcPolicy`, ``hindsight-value`` :mod:`experiments.planners_hindsight`'s,
    ``expected-value`` :mod:`experiments.planners_expected`'s), with the planner's defaults where an
    argument is None."""
    kinds = {"mean-plan": MpcSettings, "hindsight-value": HindsightSettings, "expected-value": ExpectedSettings}
    if method not in kinds:
        raise ValueError(f"--method: unknown planner {method!r}; known: {', '.join(METHODS)}")
    given = {"scenarios": scenarios, "decision_every_days": decision_every_days}
    return kinds[method](**{name: value for name, value in given.items() if value is not None})


def planner(constants: TaskConstants, pools: dict[str, list[SeasonContext]], settings,
            align: str = "day-of-year") -> BasePolicy:
    """The causal planner that ``settings`` (:class:`MpcSettings`, ``HindsightSettings`` or ``ExpectedSettings``)
    configures, reading its continuations by ``align`` (:func:`experiments.planners_mpc.spliced`)."""
    if isinstance(settings, ExpectedSettings):
        return FamilyExpectedPolicy(constants, pools, settings, align)
    if isinstance(settings, HindsightSettings):
        return FamilyHindsightPolicy(constants, pools, settings, align)
    if isinstance(settings, MpcSettings):
        return FamilyMpcPolicy(constants, pools, settings, align)
    raise TypeError(f"family planner: settings must be MpcSettings or HindsightSettings, got {type(settings).__name__}")


# --- command line: a planner on an evaluated set, beside the oracle and the rule of that evaluation ----------

def continuation_source(task, evaluation_set, asked: str | None = None):
    """(name, generated-weather scenario) whose climatology the MPC draws continuations from on ``evaluation_set``
    (an :class:`~crop_agent_ros.learning.evaluate_task.EvaluationSet` of ``task``): ``asked`` (a climate of the
    task named apart from its generator, e.g. ``benton-early``: Benton sown March 1; else any built-in
    ``<asked>-generated`` scenario: a fitted generator's, or a delta-changed climate no part of the task holds,
    e.g. ``benton-hot-arid-sunny``), else the set's own (its site and sowing date: a far set's part of the task,
    the held-out real seasons' Benton County, the held-out climate's pool sown on the set's date). Asking for
    another climate's shows what a planner that knows only that climate does here (e.g. a training climate's on
    the held-out one). ValueError names the generators and the task's climates for an unknown one."""
    from crop_sim_ros.model import UnknownNameError
    from crop_sim_ros.task.scenario import climates, get_scenario
    if asked is not None:
        parts = climates(task)
        if asked not in GENERATOR_NAMES and asked in parts:
            return asked, parts[asked]  # a part named apart from its generator (benton-early: sown March 1)
        try:
            source = get_scenario(f"{asked}-generated", task.data_dir)
        except UnknownNameError:
            source = None
        if source is None or source.weather.kind != "generator":
            also = [part for part in parts if part not in GENERATOR_NAMES]
            raise ValueError(f"--continuations: no generated-weather scenario {asked + '-generated'!r} (the fitted "
                             f"generators: {', '.join(GENERATOR_NAMES)}"
                             + (f"; the task's climates: {', '.join(also)}" if also else "") + ")")
        return asked, source
    if evaluation_set.continuations is None:
        raise ValueError(f"family MPC: no weather generator known for set {evaluation_set.name!r}")
    return evaluation_set.continuations


def _bootstrap_mean(values: np.ndarray, rng: np.random.Generator, resamples: int) -> np.ndarray:
    """(resamples, ...) means of ``values`` over seasons (axis 0) drawn with replacement."""
    picks = rng.integers(0, len(values), size=(resamples, len(values)))
    return values[picks].mean(axis=1)


def compare_with_table(table: dict, set_name: str, seasons: np.ndarray | None, settings,
                       resamples: int = 2000, log=print, continuations: str | None = None,
                       align: str = "day-of-year") -> dict:
    """Run a planner (``settings``: :class:`MpcSettings` or ``HindsightSettings``; the summary's keys say
    ``mpc`` for either) on ``set_name`` of an evaluation ``table`` (``crop-sim evaluate --task``'s table.json) with
    that evaluation's terms, and compare it with the table's oracle and rule on the same seasons (USD/ha);
    its continuations are drawn from ``continuations``' generator or the set's own climate
    (:func:`continuation_source`).
    The rule's return per season is its mean over the table's noise seeds (the planners read no noisy value:
    its return does not depend on the noise seed). Intervals: 95 % bootstrap over seasons, paired."""
    from crop_sim_ros.task.scenario import get_scenario
    task = get_scenario(table["task"])
    entry, evaluation_set = table_set(table, set_name)
    index = np.arange(len(entry["seasons"])) if seasons is None else np.asarray(seasons)
    if index.size == 0 or index.max() >= len(entry["seasons"]):
        raise ValueError(f"--seasons: {set_name} has seasons 0..{len(entry['seasons']) - 1}")
    terms = {name: np.asarray(values, dtype=float)[index] for name, values in entry["terms"].items()}
    generator, source = continuation_source(task, evaluation_set, continuations)
    pools = continuation_pool(source, settings.scenarios)
    mpc = planner(TaskConstants.of_scenario(evaluation_set.scenario), pools, settings, align)
    began = time.perf_counter()
    mpc_returns = run_episodes(mpc, evaluation_set.scenario, np.asarray(entry["seasons"])[index], seed=0,
                               terms=terms).episode_return
    wall_s = time.perf_counter() - began
    oracle = np.asarray(entry["oracle_returns_usd_ha"], dtype=float)[index]
    rule = np.asarray(entry["returns_usd_ha"][RULE], dtype=float)[0][index].mean(axis=-1)
    regrets = np.stack([oracle - rule, oracle - mpc_returns], axis=1)  # (M, 2): rule, MPC
    means = _bootstrap_mean(regrets, np.random.default_rng(0), resamples)
    low, high = interval(_ratio(means[:, 1], means[:, 0]))
    rows = [{"season": int(entry["seasons"][i]), "source": str(entry["season_sources"][i]) if "season_sources" in entry
             else "", "oracle_usd_ha": float(o), "rule_regret_usd_ha": float(o - r), "mpc_regret_usd_ha": float(o - m)}
            for i, o, r, m in zip(index, oracle, rule, mpc_returns)]
    summary = {
        "set": set_name, "task": task.name, "seasons": len(index), "oracle_usd_ha": float(oracle.mean()),
        "rule_regret_usd_ha": float(regrets[:, 0].mean()),
        "rule_regret_ci": list(interval(means[:, 0])),
        "mpc_regret_usd_ha": float(regrets[:, 1].mean()),
        "mpc_regret_ci": list(interval(means[:, 1])),
        "mpc_over_rule": float(regrets[:, 1].mean() / regrets[:, 0].mean()), "mpc_over_rule_ci": [low, high],
        "mpc_wins_over_rule": float(np.mean(regrets[:, 1] < regrets[:, 0])),
        "settings": {**mpc.describe(), "pool_generator": generator},
        "decisions": mpc.decisions, "planning_cpu_s": round(mpc.planning_cpu_s, 1), "wall_s": round(wall_s, 1),
        "rows": rows}
    log(f"{'season':>7} {'oracle':>9} {'rule regret':>12} {'planner regret':>15}")
    for row in rows:
        log(f"{row['season']:>7} {row['oracle_usd_ha']:>9,.0f} {row['rule_regret_usd_ha']:>12,.0f} "
            f"{row['mpc_regret_usd_ha']:>15,.0f}")
    log(f"{set_name} ({len(index)} seasons, USD/ha): oracle {summary['oracle_usd_ha']:,.0f}; rule regret "
        f"{summary['rule_regret_usd_ha']:,.0f} [{summary['rule_regret_ci'][0]:,.0f}, {summary['rule_regret_ci'][1]:,.0f}]; "
        f"{mpc.name} regret {summary['mpc_regret_usd_ha']:,.0f} [{summary['mpc_regret_ci'][0]:,.0f}, "
        f"{summary['mpc_regret_ci'][1]:,.0f}]; planner / rule {summary['mpc_over_rule']:.2f} [{low:.2f}, {high:.2f}]; "
        f"planner better on {100 * summary['mpc_wins_over_rule']:.0f} % of seasons; {wall_s:.0f} s")
    return summary


def paired_runs(base: dict, other: dict, resamples: int = 2000) -> dict:
    """``other`` planner run against ``base`` (two summaries of :func:`compare_with_table`, as ``--out`` writes
    them) on the seasons both ran, which must be of one task and set: each one's mean regret (USD/ha), the mean
    of other - base per season with its 95 % bootstrap interval over seasons, and on how many seasons other's
    regret is lower. What tells two planner settings apart beyond the noise of the seasons."""
    for key in ("task", "set"):
        if base.get(key) != other.get(key):
            raise ValueError(f"--paired: the runs are of {key} {base.get(key)!r} and {other.get(key)!r}; "
                             f"pair runs of one task and set")
    base_regret = {row["season"]: row["mpc_regret_usd_ha"] for row in base["rows"]}
    common = [row for row in other["rows"] if row["season"] in base_regret]
    if not common:
        raise ValueError("--paired: the two runs share no season")
    other_regret = np.array([row["mpc_regret_usd_ha"] for row in common])
    mine = np.array([base_regret[row["season"]] for row in common])
    rule = np.array([row["rule_regret_usd_ha"] for row in common])
    difference = other_regret - mine
    low, high = interval(_bootstrap_mean(difference, np.random.default_rng(0), resamples))
    return {"task": base["task"], "set": base["set"], "seasons": len(common),
            "rule_regret_usd_ha": float(rule.mean()), "base_regret_usd_ha": float(mine.mean()),
            "other_regret_usd_ha": float(other_regret.mean()), "difference_usd_ha": float(difference.mean()),
            "difference_ci": [low, high], "other_lower_on": int(np.sum(difference < 0))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.planners",
                                     description="the causal MPC on a set of an evaluation, beside its oracle and rule")
    parser.add_argument("--table", help="table.json of `crop-sim evaluate --task T` (required unless --paired)")
    parser.add_argument("--set", help="evaluation set name (e.g. heldout-real, far-benton; required unless --paired)")
    parser.add_argument("--seasons", help="positions in the set 'A..B' (default: all)")
    parser.add_argument("--method", default=METHODS[0], choices=METHODS,
                        help="expected-value (default): the amount best by values that average over the weather "
                             "(planners_expected); hindsight-value: each day the amount best on average over the "
                             "continuations' hindsight values (planners_hindsight); mean-plan: the mean of each "
                             "continuation's best plan")
    parser.add_argument("--scenarios", type=int, help="continuations per decision (default: the planner's, 4 or 8)")
    parser.add_argument("--decision-every-days", type=int, help="days between decisions (default: 7)")
    parser.add_argument("--continuations", metavar="CLIMATE",
                        help="draw the continuations from this climate of the task (e.g. benton-early), else from "
                             "the built-in scenario CLIMATE-generated (a site's generator, e.g. gainesville, or a "
                             "delta-changed climate, e.g. benton-hot-arid-sunny) (default: the set's own site, e.g. "
                             "maricopa on maricopa-generated)")
    parser.add_argument("--align", choices=ALIGNMENTS, default="day-of-year",
                        help="read a continuation's weather on the same days of the year as the season's (default) "
                             "or on the same days after sowing (for a climate sown on another date)")
    parser.add_argument("--out", help="write the summary and per-season rows here (JSON)")
    parser.add_argument("--paired", nargs=2, metavar=("BASE", "OTHER"),
                        help="run nothing: compare two --out files of one task and set, season by season")
    args = parser.parse_args(argv)
    try:
        if args.paired:
            base, other = (json.loads(Path(name).read_text()) for name in args.paired)
            if not all(isinstance(run, dict) and "rows" in run for run in (base, other)):
                raise ValueError(f"--paired: {' and '.join(args.paired)} must both be --out files of this command")
            result = paired_runs(base, other)
        elif args.table is None or args.set is None:
            raise ValueError("--table and --set are required (or --paired BASE OTHER)")
        else:
            with open(args.table) as f:
                table = json.load(f)
            if not isinstance(table, dict) or "sets" not in table or "task" not in table:
                raise ValueError(f"--table: {args.table} is not a table.json of `crop-sim evaluate --task`")
            settings = planner_settings(args.method, args.scenarios, args.decision_every_days)
            seasons = None if args.seasons is None else season_range(args.seasons)
            if args.continuations is not None:  # refused before any planning
                from crop_sim_ros.task.scenario import get_scenario
                continuation_source(get_scenario(str(table["task"])), table_set(table, args.set)[1],
                                    args.continuations)
            summary = compare_with_table(table, args.set, seasons, settings, continuations=args.continuations,
                                         align=args.align)
    except (OSError, ValueError, KeyError) as error:
        print(f"planners: {str(error).strip(chr(39))}", file=sys.stderr)
        return 2
    if args.paired:
        low, high = result["difference_ci"]
        print(f"{result['task']} {result['set']}, {result['seasons']} seasons (USD/ha): rule regret "
              f"{result['rule_regret_usd_ha']:,.0f}; {args.paired[0]} {result['base_regret_usd_ha']:,.0f}; "
              f"{args.paired[1]} {result['other_regret_usd_ha']:,.0f}; difference {result['difference_usd_ha']:+,.0f} "
              f"[{low:+,.0f}, {high:+,.0f}]; lower on {result['other_lower_on']} of {result['seasons']} seasons")
        return 0
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"command": sys.argv, **summary}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
