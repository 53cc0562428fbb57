"""The compact summary of a family-task evaluation: what the leaderboard shows, from ``table.json``.

``crop-sim evaluate --task`` writes ``summary.json`` beside ``table.json`` (:func:`summary` of that table, with
the ``summary.json`` of each agent run it evaluated); the committed copies in ``results/summaries/`` are what
``crop-sim leaderboard`` reads. A summary keeps, per evaluation set, its size (seasons, noise seeds), the
oracle's return and each policy row (the rule and every agent group): return, regret with its 95 % bootstrap
interval, regret as a percentage of the reference's return (the oracle's; ``reference`` says which), and for
an agent its training seeds, the paired ratio to the rule with its interval, paired wins and, where the runs
kept a 1 % checkpoint, the final / 1 % regret ratio with its interval; per agent group its training record
(seeds, steps, wall seconds, the command with ``{seed}``); the rule's parameters, the seeds and the package
versions. It drops what only the full table needs (per-season returns and terms, oracle plans, return
intervals, the 1 % checkpoint's own row, notes, the unit log, learning curves): a few kB per evaluation.

Money in USD/ha (``_usd_ha`` in the key), shares in % (``_pct``), seconds in ``_s``; ratios and paired wins
(a share of 0..1) unitless. Numbers are rounded (:data:`USD_DIGITS`, :data:`RATIO_DIGITS`) so that a
re-evaluation that differs only in float noise writes the same file.
"""

from __future__ import annotations

import json
import math
import shlex
from collections.abc import Mapping
from pathlib import Path

SUMMARY_FORMAT = 1
USD_DIGITS = 1  # USD/ha to 0.1: the bootstrap intervals are tens of USD/ha wide
RATIO_DIGITS = 3  # ratios, shares and percentages
RULE_PARAMETER_DIGITS = 6  # significant digits of a tuned rule parameter
# flags of a recorded training command that say where and how it ran, not what it trained
_RUN_ONLY_FLAGS = {"--out": 1, "--no-progress": 0}


def _rounded(value, digits: int):
    """``value`` rounded to ``digits`` decimals (None stays None; -0.0 becomes 0.0 so files do not flicker)."""
    if value is None or value == "":
        return None
    return round(float(value), digits) + 0.0


def _interval(low, high, digits: int) -> list | None:
    return None if low is None or high is None else [_rounded(low, digits), _rounded(high, digits)]


def _significant(value):
    if isinstance(value, float) and math.isfinite(value) and value != 0.0:
        return float(f"{value:.{RULE_PARAMETER_DIGITS}g}")
    return value


def _integers(text) -> list[int]:
    """The space-separated integers of a table cell ('0 1 2 3 4'; '' for none)."""
    return [int(part) for part in str(text).split()]


def _policy_row(row: dict) -> dict:
    """One rule or agent row of a set: the leaderboard's numbers, rounded. An agent row adds its training
    seeds, ratio to the rule, paired wins and, where the runs kept a 1 % checkpoint, the final / 1 % ratio."""
    summarised = {
        "policy": row["policy"], "kind": row["kind"],
        "return_usd_ha": _rounded(row["return_usd_ha"], USD_DIGITS),
        "regret_usd_ha": _rounded(row["regret_usd_ha"], USD_DIGITS),
        "regret_ci_usd_ha": _interval(row["regret_ci_low"], row["regret_ci_high"], USD_DIGITS),
        "regret_pct_of_reference": _rounded(row["regret_pct_of_reference"], RATIO_DIGITS),
    }
    if row["kind"] == "rule":  # its ratio to itself and wins against itself say nothing
        return summarised
    summarised.update({
        "group": row["group"], "training_seeds": _integers(row["training_seeds"]),
        "ratio_to_rule": _rounded(row["ratio_to_rule"], RATIO_DIGITS),
        "ratio_to_rule_ci": _interval(row["ratio_ci_low"], row["ratio_ci_high"], RATIO_DIGITS),
        "paired_wins": _rounded(row["paired_wins"], RATIO_DIGITS),
    })
    if row.get("final_over_early") is not None:
        summarised["final_over_1pct"] = _rounded(row["final_over_early"], RATIO_DIGITS)
        summarised["final_over_1pct_ci"] = _interval(row["final_over_early_ci_low"], row["final_over_early_ci_high"],
                                                     RATIO_DIGITS)
    return summarised


def _set_summary(evaluation_set: dict) -> dict:
    rows = evaluation_set["rows"]
    oracle = next((row for row in rows if row["kind"] == "oracle"), None)
    return {
        "name": evaluation_set["name"], "role": evaluation_set["role"], "scenario": evaluation_set["scenario"],
        "seasons": len(evaluation_set["seasons"]), "noise_seeds": rows[0]["noise_seeds"],
        "terms_seed": evaluation_set["terms_seed"], "reference": evaluation_set["reference"],
        "oracle_return_usd_ha": None if oracle is None else _rounded(oracle["return_usd_ha"], USD_DIGITS),
        **_strongest_rule(rows),
        # the 1 % checkpoint's own row is left out: its regret enters as the agent row's final / 1 % ratio
        "rows": [_policy_row(row) for row in rows if row["kind"] in ("rule", "agent")],
    }


def _strongest_rule(rows: list[dict]) -> dict:
    """``strongest_rule``: the rule the agents' ratios and paired wins are against (the set's rule row with the
    lower regret; recorded by evaluations that had more than one rule row, absent before)."""
    names = {row.get("reference_rule") for row in rows if row.get("reference_rule")}
    return {"strongest_rule": names.pop()} if len(names) == 1 else {}


def seed_command(command: str, seed: int) -> str:
    """A recorded ``crop-sim train`` command with its ``--seed`` as ``{seed}`` and the flags that only say
    where it ran (``--out``, ``--no-progress``) left out: the same text for every seed of a group."""
    words = shlex.split(command)
    kept, index = [], 0
    while index < len(words):
        word = words[index]
        if word in _RUN_ONLY_FLAGS:
            index += 1 + _RUN_ONLY_FLAGS[word]
            continue
        if word == "--seed" and index + 1 < len(words) and words[index + 1] == str(seed):
            kept += ["--seed", "{seed}"]
            index += 2
            continue
        kept.append(word)
        index += 1
    # shlex quotes the braces; the placeholder is meant to be filled in, not typed
    return shlex.join(kept).replace(shlex.quote("{seed}"), "{seed}")


def _training(table: dict, run_summaries: Mapping[str, dict]) -> dict:
    """Per agent group: its seeds, the steps of each seed's selected policy (from the table), and where the
    run's own ``summary.json`` is given, the steps it ran, its wall seconds (the whole ``crop-sim train``
    run; demonstrations recorded beforehand are not in it) and its command."""
    selected = {}
    for evaluation_set in table["sets"]:
        for row in evaluation_set["rows"]:
            if row["kind"] == "agent":
                selected.setdefault(row["group"], _integers(row["timesteps"]))
    training = {}
    for group, runs in table["agents"].items():
        records = [run_summaries.get(run["directory"].rstrip("/")) for run in runs]
        recorded = [record for record in records if record is not None]
        complete = len(recorded) == len(runs)
        training[group] = {
            "algorithm": recorded[0].get("algorithm") if recorded else None,
            "seeds": [run["training_seed"] for run in runs],
            "timesteps_selected": selected.get(group, []),
            "steps_run": [record.get("steps_run") for record in recorded] if complete else None,
            "wall_s": ([_rounded(record.get("total_wall_s", record.get("training_wall_s")), 1) for record in recorded]
                       if complete else None),
            "commands": sorted({seed_command(record["command"], run["training_seed"])
                                for run, record in zip(runs, records) if record and record.get("command")}),
        }
    return training


def summary(table: dict, run_summaries: Mapping[str, dict] | None = None) -> dict:
    """The compact summary of an evaluation's ``table`` (its ``table.json``, read). ``run_summaries`` maps an
    agent run's directory as the table names it to that run's ``summary.json`` (read), for the training cost
    and command; runs not in it have none recorded."""
    run_summaries = run_summaries or {}
    rule = table["rule"]
    return {
        "format": SUMMARY_FORMAT,
        "task": table["task"],
        "command": table["command"],
        "regret": table["regret"],
        "seeds": {key: table["seeds"][key] for key in ("noise_seeds", "terms_seed_base", "far_weather_seed",
                                                       "bootstrap_resamples", "bootstrap_seed")},
        "rule": {"name": rule["name"], "file": Path(rule["file"]).name, "tuned_now": rule["tuned_now"],
                 "parameters": {key: _significant(value) for key, value in rule.items()
                                if key not in ("name", "file", "tuned_now")}},
        **({"paced_rule": {"name": table["paced_rule"]["name"], "file": Path(table["paced_rule"]["file"]).name,
                           "parameters": {key: _significant(value) for key, value in table["paced_rule"].items()
                                          if key not in ("name", "file", "tuned_now")}}}
           if isinstance(table.get("paced_rule"), dict) and "file" in table["paced_rule"] else {}),
        "sets": [_set_summary(evaluation_set) for evaluation_set in table["sets"]],
        "training": _training(table, run_summaries),
        "evaluation_wall_s": _rounded(table["wall_s"]["total_s"], 1),
        "versions": table["versions"],
    }


def recorded_runs(table: dict) -> dict[str, dict]:
    """The ``summary.json`` of each agent run of ``table`` whose directory holds one (read where the table
    names it: as ``crop-sim evaluate --task`` found the run), by directory."""
    found = {}
    for runs in table["agents"].values():
        for run in runs:
            path = Path(run["directory"]) / "summary.json"
            if path.is_file():
                found[run["directory"].rstrip("/")] = json.loads(path.read_text(encoding="utf-8"))
    return found


def _is_flat(value) -> bool:
    """A value written on one line: a scalar, or a list or mapping of scalars and lists of scalars."""
    items = value.values() if isinstance(value, dict) else value if isinstance(value, list) else ()
    return all(not isinstance(item, dict) and not (isinstance(item, list) and not _is_flat(item)) for item in items)


def dumps(value, indent: int = 0) -> str:
    """``value`` as JSON with one line per flat mapping or list (a policy row, a training record): short and
    easy to diff, unlike ``indent=1``'s one line per number."""
    if _is_flat(value):
        return json.dumps(value, ensure_ascii=False, allow_nan=False)
    pad, inner = " " * indent, " " * (indent + 1)
    if isinstance(value, dict):
        lines = [f"{inner}{json.dumps(key)}: {dumps(item, indent + 1)}" for key, item in value.items()]
        return "{\n" + ",\n".join(lines) + "\n" + pad + "}"
    return "[\n" + ",\n".join(inner + dumps(item, indent + 1) for item in value) + "\n" + pad + "]"


def write_summary(path: Path, table: dict, run_summaries: Mapping[str, dict] | None = None) -> None:
    """Write :func:`summary` of ``table`` to ``path``."""
    from crop_sim_ros.output import write_text_atomic
    write_text_atomic(path, dumps(summary(table, run_summaries)) + "\n")


# --- the causal planner's summary (experiments/planners_summary.py writes it; the leaderboard reads it) -------

PLANNER_KIND = "causal-planner"  # a planner summary's ``kind``; an evaluation summary has none


def _planner_models():
    """The planner summary's pydantic models (built on first use: importing this module needs no pydantic)."""
    from pydantic import BaseModel, ConfigDict, Field

    class Strict(BaseModel):
        model_config = ConfigDict(extra="forbid")

    Interval = list[float]  # [low, high] of a 95 % bootstrap interval

    class RatioToStrongest(Strict):
        ratio_to_strongest_rule: float | None
        ratio_to_strongest_rule_ci: Interval | None = Field(min_length=2, max_length=2)

    class PlannerRow(RatioToStrongest):
        return_usd_ha: float
        regret_usd_ha: float
        regret_ci_usd_ha: Interval = Field(min_length=2, max_length=2)
        regret_pct_of_reference: float
        paired_wins: float = Field(ge=0, le=1)

    class RuleRow(RatioToStrongest):
        policy: str = Field(min_length=1)
        regret_usd_ha: float
        regret_ci_usd_ha: Interval = Field(min_length=2, max_length=2)

    class PlannerSet(Strict):
        name: str = Field(min_length=1)
        role: str
        seasons: int = Field(ge=1)
        noise_seeds: int = Field(ge=1)
        terms_seed: int
        oracle_return_usd_ha: float
        strongest_rule: str = Field(min_length=1)
        planner: PlannerRow
        rules: list[RuleRow] = Field(min_length=1)
        headroom_usd_ha: float
        headroom_ci_usd_ha: Interval = Field(min_length=2, max_length=2)
        headroom_pct_of_oracle: float
        headroom_pct_ci: Interval = Field(min_length=2, max_length=2)
        per_season_usd_ha: list[tuple[int, float, float]] = Field(min_length=1)  # season, oracle return, planner regret
        continuations: str = Field(min_length=1)
        planned_on: str = Field(min_length=1)
        planning_cpu_s: float = Field(ge=0)
        wall_s: float = Field(ge=0)
        decisions: int = Field(ge=0)
        command: str = Field(min_length=1)

    class PlannerSummary(Strict):
        format: int = Field(ge=SUMMARY_FORMAT, le=SUMMARY_FORMAT)
        kind: str = Field(pattern=f"^{PLANNER_KIND}$")
        task: str = Field(min_length=1)
        planner: dict
        evaluation: str = Field(min_length=1)
        rules: dict[str, str]
        bootstrap: dict[str, int]
        sets: list[PlannerSet] = Field(min_length=1)

    return PlannerSummary


def check_planner_summary(value) -> dict:
    """``value`` if it is a planner summary (:data:`PLANNER_KIND`): the schema, one row per season, the
    strongest rule among the rules, distinct sets; else ValueError with one line."""
    from pydantic import ValidationError
    model = _planner_models()
    try:
        model.model_validate(value)
    except ValidationError as error:
        first = error.errors()[0]
        place = ".".join(str(part) for part in first["loc"]) or "(top)"
        raise ValueError(f"not a planner summary ({place}: {first['msg']})") from None
    names = [s["name"] for s in value["sets"]]
    for evaluation_set in value["sets"]:
        rules = [row["policy"] for row in evaluation_set["rules"]]
        if evaluation_set["strongest_rule"] not in rules or names.count(evaluation_set["name"]) > 1:
            raise ValueError(f"set {evaluation_set['name']}: its strongest rule is none of its rules, or "
                             "the set is listed twice")
        if len(evaluation_set["per_season_usd_ha"]) != evaluation_set["seasons"]:
            raise ValueError(f"set {evaluation_set['name']}: {evaluation_set['seasons']} seasons, "
                             f"{len(evaluation_set['per_season_usd_ha'])} rows per season")
    return value
