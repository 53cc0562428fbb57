"""The causal limit of a task, as a committed summary: ``results/summaries/<task>-planner.json``.

    python -m experiments.planners_summary --table runs/eval-benton-quota/table.json \\
        --runs runs/planner/benton-quota-*.json --out results/summaries/benton-quota-planner.json

Reads one evaluation's ``table.json`` (``crop-sim evaluate --task T``: per season and noise seed the oracle's,
the budget rule's and the paced rule's returns) and the ``--out`` files of ``python -m experiments.planners``
run on whole sets of that evaluation (per season the planner's regret; its CPU seconds), and writes per set
(:func:`set_summary`): the planner's regret with its 95 % interval, its ratio to the set's strongest rule, each
rule's regret and ratio to the strongest, and the headroom (strongest rule's regret - planner's regret, USD/ha
and % of the oracle's mean return) with its interval. ``crop-sim leaderboard`` reads it
(:func:`crop_agent_ros.learning.summary.check_planner_summary`), beside the task's headline evaluation.

Intervals: the protocol's own bootstrap (:class:`~crop_agent_ros.learning.evaluate_task.Resamples` of the set's
position in the protocol, the evaluation's seed and resample count), every figure paired with the rules' on the
same resamples: the planner reads the crop's true state and no noisy value, so its return per season is the
same for every noise seed and is counted once per noise seed. The rule regrets written here are therefore the
evaluation summary's, and the leaderboard refuses a planner summary whose rule regrets differ from its
headline's (a rule re-tuned since: run this command again on a fresh ``table.json``; no re-planning needed).

A run of another task's evaluation (``--runs`` of ``benton-quota`` for ``benton-sensing``, whose sets differ
only in what the agents observe) is accepted when, season by season, its oracle returns are this table's
(same weather and terms) and the two tasks' constants and the run's continuation climate are the set's own:
the summary names the run's task (``planned_on``).
"""

from __future__ import annotations

import argparse
import glob
import json
import shlex
import sys
from pathlib import Path

import numpy as np

from crop_agent_ros.learning.evaluate_task import RULE, Resamples, _ratio, interval, table_set
from crop_agent_ros.learning.summary import (PLANNER_KIND, RATIO_DIGITS, SUMMARY_FORMAT, USD_DIGITS, _interval,
                                             _rounded, check_planner_summary, dumps)

PER_SET_SETTINGS = ("pool_generator", "pools")  # the set's own climate: recorded per set as its continuations
ORACLE_MATCH_USD_HA = 1e-6  # a run's oracle return per season against the table's: the same computation


def _rules(entry: dict) -> dict[str, np.ndarray]:
    """The rule rows of a table's set: name -> returns (1, M, K) USD/ha (the budget rule first)."""
    returns = entry["returns_usd_ha"]
    names = [RULE] + sorted(row["policy"] for row in entry["rows"] if row["kind"] == "rule" and row["policy"] != RULE)
    return {name: np.asarray(returns[name], dtype=float) for name in names}


def _usd_interval(distribution: np.ndarray) -> list:
    return _interval(*interval(distribution), USD_DIGITS)


def set_summary(entry: dict, position: int, seeds: dict, planner_returns: np.ndarray) -> dict:
    """One set's figures (USD/ha): ``entry`` is the table's set, ``position`` its place in the protocol (its
    resamples' seed), ``seeds`` the table's, ``planner_returns`` (M,) the planner's return per season."""
    oracle = np.asarray(entry["oracle_returns_usd_ha"], dtype=float)
    rules = _rules(entry)
    m, k = oracle.size, next(iter(rules.values())).shape[-1]
    if planner_returns.shape != (m,):
        raise ValueError(f"{entry['name']}: {planner_returns.size} planner returns for {m} seasons")
    resamples = Resamples.draw(seeds["bootstrap_seed"], position, m, k, {}, seeds["bootstrap_resamples"])
    reference = np.broadcast_to(oracle[None, :, None], (1, m, k))
    regret = {name: reference - returns for name, returns in rules.items()}
    regret["planner"] = reference - np.broadcast_to(planner_returns[None, :, None], (1, m, k))
    means = {name: float(values.mean()) for name, values in regret.items()}
    dist = {name: resamples.means(values) for name, values in regret.items()}
    strongest = min(rules, key=lambda name: means[name])  # the protocol's choice (evaluate_task.compare)
    oracle_mean = float(oracle.mean())
    headroom = dist[strongest] - dist["planner"]

    def ratio(name: str) -> dict:
        return {"ratio_to_strongest_rule": _rounded(means[name] / means[strongest], RATIO_DIGITS)
                if means[strongest] > 0 else None,
                "ratio_to_strongest_rule_ci": _interval(*interval(_ratio(dist[name], dist[strongest])), RATIO_DIGITS)}

    return {
        "name": entry["name"], "role": entry["role"], "seasons": m, "noise_seeds": k,
        "terms_seed": entry["terms_seed"], "oracle_return_usd_ha": _rounded(oracle_mean, USD_DIGITS),
        "strongest_rule": strongest,
        "planner": {"return_usd_ha": _rounded(planner_returns.mean(), USD_DIGITS),
                    "regret_usd_ha": _rounded(means["planner"], USD_DIGITS),
                    "regret_ci_usd_ha": _usd_interval(dist["planner"]),
                    "regret_pct_of_reference": _rounded(100 * means["planner"] / oracle_mean, RATIO_DIGITS),
                    **ratio("planner"),
                    "paired_wins": _rounded(np.mean(regret["planner"] < regret[strongest]), RATIO_DIGITS)},
        "rules": [{"policy": name, "regret_usd_ha": _rounded(means[name], USD_DIGITS),
                   "regret_ci_usd_ha": _usd_interval(dist[name]), **ratio(name)} for name in rules],
        "headroom_usd_ha": _rounded(means[strongest] - means["planner"], USD_DIGITS),
        "headroom_ci_usd_ha": _usd_interval(headroom),
        "headroom_pct_of_oracle": _rounded(100 * (means[strongest] - means["planner"]) / oracle_mean, RATIO_DIGITS),
        "headroom_pct_ci": _interval(*interval(100 * headroom / oracle_mean), RATIO_DIGITS),
        # per season [season, oracle return, planner regret], unrounded: a later summary re-pairs them with
        # re-tuned rules exactly (:func:`runs_of`)
        "per_season_usd_ha": [[int(season), float(o), float(r)]
                              for season, o, r in zip(entry["seasons"], oracle, regret["planner"][0, :, 0])],
    }


def _planner_returns(run: dict, entry: dict) -> np.ndarray:
    """(M,) the planner's return per season of the table's set, from a run over the whole set whose oracle
    returns are the table's season by season (ValueError otherwise)."""
    by_season = {row["season"]: row for row in run["rows"]}
    seasons = [int(season) for season in entry["seasons"]]
    missing = [season for season in seasons if season not in by_season]
    if missing or len(by_season) != len(seasons):
        raise ValueError(f"{entry['name']}: the run planned {len(by_season)} of the set's {len(seasons)} seasons "
                         f"(plan the whole set)")
    oracle = np.asarray(entry["oracle_returns_usd_ha"], dtype=float)
    run_oracle = np.array([by_season[season]["oracle_usd_ha"] for season in seasons])
    if np.max(np.abs(run_oracle - oracle)) > ORACLE_MATCH_USD_HA:
        raise ValueError(f"{entry['name']}: the run's oracle returns are not the table's (other seasons, terms or "
                         f"task)")
    return oracle - np.array([by_season[season]["mpc_regret_usd_ha"] for season in seasons])


def runs_of(document: dict) -> list[dict]:
    """The planner runs a ``--runs`` file holds: a run of ``python -m experiments.planners --out``, or each set of
    a planner summary written before (its seasons' oracle returns and planner regrets, as the run had them):
    what lets a rule re-tuned since be paired with the planner again without re-planning."""
    if document.get("kind") != PLANNER_KIND:
        return [document]
    check_planner_summary(document)
    return [{"task": s["planned_on"], "set": s["name"], "command": shlex.split(s["command"])[2:],
             "settings": {**document["planner"], "pool_generator": s["continuations"]},
             "planning_cpu_s": s["planning_cpu_s"], "wall_s": s["wall_s"], "decisions": s["decisions"],
             "rows": [{"season": season, "oracle_usd_ha": oracle, "mpc_regret_usd_ha": regret}
                      for season, oracle, regret in s["per_season_usd_ha"]]}
            for s in document["sets"]]


def _same_planning_problem(table: dict, run: dict) -> None:
    """A run of another task's evaluation must face this set's problem: the same task constants and the same
    continuation climate (the oracle's returns, checked per season, stand for weather and terms)."""
    if run["task"] == table["task"]:
        return
    from crop_agent_ros.policies.family_oracle import TaskConstants
    from experiments.planners import continuation_source
    from crop_sim_ros.task.scenario import get_scenario
    mine = table_set(table, run["set"])[1]
    theirs = table_set({"task": run["task"], "sets": table["sets"], "arguments": table["arguments"]}, run["set"])[1]
    if TaskConstants.of_scenario(mine.scenario) != TaskConstants.of_scenario(theirs.scenario):
        raise ValueError(f"{run['set']}: a run of {run['task']}, whose constants are not {table['task']}'s")
    own = continuation_source(get_scenario(table["task"]), mine)[0]
    if run["settings"]["pool_generator"] != own:
        raise ValueError(f"{run['set']}: a run of {run['task']} drew continuations from "
                         f"{run['settings']['pool_generator']}, not the set's own climate {own}")


def planner_summary(table: dict, runs: list[dict]) -> dict:
    """The task's planner summary from its evaluation ``table`` and the planner ``runs`` (one per set)."""
    by_set = {}
    for run in runs:
        if run["set"] in by_set:
            raise ValueError(f"--runs: two runs of set {run['set']}")
        by_set[run["set"]] = run
    base = table["seeds"]["terms_seed_base"]
    sets, settings = [], None
    for entry in table["sets"]:
        run = by_set.pop(entry["name"], None)
        if run is None:
            continue
        _same_planning_problem(table, run)
        described = {key: value for key, value in run["settings"].items() if key not in PER_SET_SETTINGS}
        if settings not in (None, described):
            raise ValueError(f"--runs: {entry['name']} was planned with other settings than the sets before it")
        settings = described
        summary = set_summary(entry, entry["terms_seed"] - base, table["seeds"], _planner_returns(run, entry))
        sets.append({**summary, "continuations": run["settings"]["pool_generator"],
                     "planned_on": run["task"], "planning_cpu_s": run["planning_cpu_s"], "wall_s": run["wall_s"],
                     "decisions": run["decisions"],
                     "command": shlex.join(["python", "-m", "experiments.planners", *run["command"][1:]])})
    if by_set:
        raise ValueError(f"--runs: set {next(iter(by_set))} is not in the table")
    if not sets:
        raise ValueError("--runs: no run of a set of this table")
    return check_planner_summary({
        "format": SUMMARY_FORMAT, "kind": PLANNER_KIND, "task": table["task"],
        "planner": settings, "evaluation": table["command"],
        "rules": {"budget-rule": Path(table["rule"]["file"]).name,
                  **({"paced-rule": Path(table["paced_rule"]["file"]).name} if "paced_rule" in table else {})},
        "bootstrap": {key: table["seeds"][key] for key in ("bootstrap_seed", "bootstrap_resamples")},
        "sets": sets})


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.planners_summary",
                                     description="the committed summary of the causal planner's runs on a task")
    parser.add_argument("--table", required=True, help="table.json of `crop-sim evaluate --task T`")
    parser.add_argument("--runs", nargs="+", required=True,
                        help="--out files of `python -m experiments.planners` on sets of that evaluation (globs)")
    parser.add_argument("--out", required=True, help="the summary to write (results/summaries/<task>-planner.json)")
    args = parser.parse_args(argv)
    try:
        table = json.loads(Path(args.table).read_text())
        names = sorted({name for pattern in args.runs for name in (glob.glob(pattern) or [pattern])})
        runs = [run for name in names for run in runs_of(json.loads(Path(name).read_text()))]
        summary = planner_summary(table, runs)
    except (OSError, ValueError, KeyError, TypeError) as error:
        print(f"planners_summary: {str(error).strip(chr(39))}", file=sys.stderr)
        return 2
    Path(args.out).write_text(dumps(summary) + "\n")
    for s in summary["sets"]:
        print(f"{s['name']}: planner {s['planner']['regret_usd_ha']:,.0f} {s['planner']['regret_ci_usd_ha']}; "
              f"{s['strongest_rule']} {s['rules'][[r['policy'] for r in s['rules']].index(s['strongest_rule'])]['regret_usd_ha']:,.0f}; "
              f"headroom {s['headroom_usd_ha']:,.0f} USD/ha, {s['headroom_pct_of_oracle']:.2f} % of the oracle")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
