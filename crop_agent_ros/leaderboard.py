"""``crop-sim leaderboard [--check] [--root DIR]``: the results page and the README's excerpt, generated.

Reads ``results/leaderboard.yaml`` (which evaluations appear, per task: the headline evaluation and its
variants, with the commands that train and evaluate their agents) and the compact summaries it names,
``results/summaries/<evaluation>.json`` (:mod:`crop_agent_ros.learning.summary`, written by
``crop-sim evaluate --task``). Writes ``docs/leaderboard.md``: per task and evaluation set, the oracle's return,
the rule's regret (the set's strongest rule, named, where the summary records one: :func:`reference_rule`) and
every agent's regret with its 95 % interval, ratio to that rule, paired wins, final / 1 % checkpoint ratio and
training cost, then each evaluation's commands. Between the lines
``<!-- leaderboard:start -->`` and ``<!-- leaderboard:end -->`` of ``README.md`` (if it has them) it writes the
headline rows the configuration names (``readme_sets``). The output depends only on those files: no dates.

``--check`` writes nothing; it exits 1 with one line naming the file that differs from what it would write
(0 when both are up to date). A malformed configuration or summary is one line and exit status 2.
"""

from __future__ import annotations

import json
from pathlib import Path

from crop_sim_ros.usage import UsageError, user_input

from .learning.summary import SUMMARY_FORMAT, check_planner_summary

CONFIG = Path("results/leaderboard.yaml")
CONFIG_MAX_BYTES = 1 << 20  # 15 times today's
SUMMARIES = Path("results/summaries")
PAGE = Path("docs/leaderboard.md")
README = Path("README.md")
START, END = "<!-- leaderboard:start -->", "<!-- leaderboard:end -->"
OLD_RULE = "budget-rule"  # the project's water-budget rule: a labelled weaker baseline where the paced rule is stronger
HEADROOM_WORTH_LEARNING_PCT = 2.0  # issue 33: a set where a rule leaves less to a causal controller is not
README_ROWS_MAX = 25  # the front page's excerpt stays short; the page holds the rest
NAME_PATTERN = r"^[a-z0-9][a-z0-9._-]*$"  # a task or summary name: a file name, never a path


def add_arguments(parser) -> None:
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 naming the out-of-date file if the page or the README's "
                             "excerpt differs from what would be written")
    parser.add_argument("--root", type=Path, default=Path("."),
                        help="the repository root holding results/ docs/ README.md (default: the current directory)")


# --- the configuration ----------------------------------------------------------------------------------

def _models():
    """The configuration's pydantic models (built on first use: ``crop-sim --help`` does not import pydantic)."""
    from pydantic import BaseModel, ConfigDict, Field, field_validator

    class Training(BaseModel):
        """How one agent group was trained: ``command`` with ``{seed}``, run for each of ``seeds``."""
        model_config = ConfigDict(extra="forbid")
        command: str = Field(min_length=1)
        seeds: list[int] = Field(min_length=1)

        @field_validator("command")
        @classmethod
        def _has_seed(cls, command: str) -> str:
            if not command.startswith("crop-sim train ") or "{seed}" not in command:
                raise ValueError("must be a `crop-sim train ...` command with {seed} for the training seed")
            return command

    class Evaluation(BaseModel):
        """One evaluation: its summary's name, the command that evaluated it, how each agent group trained."""
        model_config = ConfigDict(extra="forbid")
        summary: str = Field(pattern=NAME_PATTERN)
        evaluate: str = Field(pattern=r"^crop-sim evaluate ")
        train: dict[str, Training] = Field(min_length=1)

    class Task(BaseModel):
        model_config = ConfigDict(extra="forbid")
        task: str = Field(pattern=NAME_PATTERN)
        headline: Evaluation
        variants: list[Evaluation] = []
        readme_sets: list[str] = []
        planner: str | None = Field(default=None, pattern=NAME_PATTERN)  # the causal planner's summary

    class Leaderboard(BaseModel):
        model_config = ConfigDict(extra="forbid")
        stronger_rule: str = Field(min_length=1)
        tasks: list[Task] = Field(min_length=1)

    return Leaderboard


def _validation_line(error) -> str:
    """A pydantic ValidationError on one line: the first error's place and message, and how many more."""
    errors = error.errors()
    first = errors[0]
    place = ".".join(str(part) for part in first["loc"]) or "(top)"
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"{place}: {first['msg']}{more}"


def read_config(root: Path):
    """``results/leaderboard.yaml`` of ``root``, validated (UsageError naming the file and the field; read by
    :mod:`crop_sim_ros.safe_yaml`: a regular file of at most CONFIG_MAX_BYTES, no aliases or duplicate keys)."""
    from pydantic import ValidationError

    from crop_sim_ros.safe_yaml import read_yaml
    with user_input(None, (ValueError,)):
        raw = read_yaml(root / CONFIG, max_bytes=CONFIG_MAX_BYTES, source=str(CONFIG))
    try:
        return _models().model_validate(raw)
    except ValidationError as error:
        raise UsageError(f"{CONFIG}: {_validation_line(error)}") from None


def read_summaries(root: Path, config) -> dict[str, dict]:
    """Every summary the configuration names, by name, checked against it: each summary file is named once,
    every file in results/summaries is named, a summary's task and agent groups (with their training seeds)
    are its entry's, and its sets were scored against the oracle (UsageError otherwise)."""
    named = [(task, evaluation) for task in config.tasks for evaluation in (task.headline, *task.variants)]
    names = [evaluation.summary for _, evaluation in named] + [task.planner for task in config.tasks if task.planner]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise UsageError(f"{CONFIG}: summary {repeated[0]!r} is named more than once")
    tasks = [task.task for task in config.tasks]
    if len(set(tasks)) != len(tasks):
        raise UsageError(f"{CONFIG}: task {next(t for t in tasks if tasks.count(t) > 1)!r} is listed more than once")
    unlisted = sorted(path.stem for path in (root / SUMMARIES).glob("*.json") if path.stem not in names)
    if unlisted:
        raise UsageError(f"{CONFIG}: {SUMMARIES / (unlisted[0] + '.json')} is in no task's headline, variants "
                         "or planner (every committed result has a row)")
    summaries = {}
    for task, evaluation in named:
        where = SUMMARIES / f"{evaluation.summary}.json"
        with user_input(str(where), (OSError, UnicodeDecodeError, json.JSONDecodeError)):
            summary = json.loads((root / where).read_text(encoding="utf-8"))
        _check_summary(summary, task.task, evaluation, where)
        summaries[evaluation.summary] = summary
    readme_rows = 0
    for task in config.tasks:
        sets = {s["name"] for s in summaries[task.headline.summary]["sets"]}
        missing = [name for name in task.readme_sets if name not in sets]
        if missing:
            raise UsageError(f"{CONFIG}: {task.task}: readme_sets: {missing[0]!r} is not a set of "
                             f"{task.headline.summary} ({', '.join(sorted(sets))})")
        readme_rows += len(task.readme_sets)
    if readme_rows > README_ROWS_MAX:
        raise UsageError(f"{CONFIG}: readme_sets name {readme_rows} rows; the README's excerpt holds at most "
                         f"{README_ROWS_MAX}")
    return summaries


def read_planners(root: Path, config, summaries: dict[str, dict]) -> dict[str, dict]:
    """The causal planner's summary of each task that names one, by task (:func:`read_planner`)."""
    return {task.task: read_planner(root, task, summaries[task.headline.summary]) for task in config.tasks
            if task.planner}


def read_planner(root: Path, task, headline: dict) -> dict:
    """The causal planner's summary a task names (:func:`~crop_agent_ros.learning.summary.check_planner_summary`),
    checked against its headline evaluation: each of its sets is a set of the headline with the same seasons,
    noise seeds, terms, oracle return, strongest rule and rule regrets (a rule re-tuned since the planner's
    summary was written makes it stale: UsageError saying how to refresh it)."""
    where = SUMMARIES / f"{task.planner}.json"
    with user_input(str(where), (OSError, UnicodeDecodeError, json.JSONDecodeError, ValueError)):
        planner = check_planner_summary(json.loads((root / where).read_text(encoding="utf-8")))
    if planner["task"] != task.task:
        raise UsageError(f"{where}: the planner of {planner['task']!r}, listed under task {task.task!r}")
    sets = {s["name"]: s for s in headline["sets"]}
    for planned in planner["sets"]:
        evaluated = sets.get(planned["name"])
        if evaluated is None:
            raise UsageError(f"{where}: set {planned['name']} is not a set of {task.headline.summary}")
        _check_planned_set(planned, evaluated, where, task.headline.summary)
    return planner


RULE_REGRET_MATCH_USD_HA = 0.15  # both summaries round to 0.1 USD/ha: the same figures differ by at most that


def _check_planned_set(planned: dict, evaluated: dict, where: Path, headline: str) -> None:
    same = [planned[key] == evaluated[key] for key in ("seasons", "noise_seeds", "terms_seed")]
    rules = {row["policy"]: row["regret_usd_ha"] for row in evaluated["rows"] if row["kind"] == "rule"}
    mine = {row["policy"]: row["regret_usd_ha"] for row in planned["rules"]}
    if not all(same) or abs(planned["oracle_return_usd_ha"] - evaluated["oracle_return_usd_ha"]) > 0.15:
        raise UsageError(f"{where}: set {planned['name']}: other seasons, terms or oracle than {headline}'s")
    if (set(mine) != set(rules) or any(abs(mine[name] - rules[name]) > RULE_REGRET_MATCH_USD_HA for name in rules)
            or planned["strongest_rule"] != reference_rule(evaluated)["policy"]):
        raise UsageError(f"{where}: set {planned['name']}: its rule regrets ({_rule_regrets(mine)}) are not "
                         f"{headline}'s ({_rule_regrets(rules)}): a rule changed since; re-run "
                         f"`python -m experiments.planners_summary --table <a fresh evaluation's table.json> --runs "
                         f"{where} --out {where}` (no re-planning)")


def _rule_regrets(regrets: dict[str, float]) -> str:
    return ", ".join(f"{name} {value:.1f}" for name, value in sorted(regrets.items()))


def _check_summary(summary, task: str, evaluation, where: Path) -> None:
    if not isinstance(summary, dict) or summary.get("format") != SUMMARY_FORMAT:
        raise UsageError(f"{where}: not a format-{SUMMARY_FORMAT} evaluation summary")
    try:
        if summary["task"] != task:
            raise UsageError(f"{where}: an evaluation of {summary['task']!r}, listed under task {task!r}")
        training = summary["training"]
        if set(training) != set(evaluation.train):
            raise UsageError(f"{CONFIG}: {evaluation.summary}: train names groups {sorted(evaluation.train)}; "
                             f"the summary has {sorted(training)}")
        for group, recipe in evaluation.train.items():
            if recipe.seeds != training[group]["seeds"]:
                raise UsageError(f"{CONFIG}: {evaluation.summary}: train {group}: seeds {recipe.seeds}; the "
                                 f"evaluated runs have {training[group]['seeds']}")
        for evaluation_set in summary["sets"]:
            if evaluation_set["reference"] != "oracle" or evaluation_set["oracle_return_usd_ha"] is None:
                raise UsageError(f"{where}: set {evaluation_set['name']} was scored without the oracle (--no-oracle):"
                                 " its gaps are not regrets")
    except (KeyError, TypeError) as error:
        raise UsageError(f"{where}: not an evaluation summary (missing or malformed {error})") from None


# --- formatting -----------------------------------------------------------------------------------------

def _usd(value) -> str:
    return "-" if value is None else f"{value:,.0f}"


def _ratio(value, interval=None) -> str:
    if value is None:
        return "-"
    return f"{value:.2f}" + ("" if interval is None else f" [{interval[0]:.2f}, {interval[1]:.2f}]")


def _regret(row: dict) -> str:
    low, high = row["regret_ci_usd_ha"]
    return f"{_usd(row['regret_usd_ha'])} [{_usd(low)}, {_usd(high)}]"


def _steps(steps: float) -> str:
    if steps >= 1e6:
        return f"{steps / 1e6:.0f} M" if steps >= 1e7 else f"{steps / 1e6:.1f} M"
    return f"{steps / 1e3:.0f} k"


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"


def training_cost(record: dict) -> str:
    """One agent group's training cost per seed (mean steps run and wall time of ``crop-sim train``)."""
    steps, wall = record.get("steps_run"), record.get("wall_s")
    if not steps or not wall or None in steps or None in wall:
        return "not recorded"
    return f"{_steps(sum(steps) / len(steps))} steps, {_duration(sum(wall) / len(wall))}"


def _seeds(seeds: list[int]) -> str:
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"S = {seeds[0]}..{seeds[-1]}"
    return "S = " + ", ".join(str(seed) for seed in seeds)


def reference_rule(evaluation_set: dict) -> dict:
    """The rule row an evaluation set's agent ratios are against: the set's strongest rule where its summary
    records one (``strongest_rule``, evaluations with the paced rule beside the budget rule), else its (only)
    rule row."""
    rules = [row for row in evaluation_set["rows"] if row["kind"] == "rule"]
    named = evaluation_set.get("strongest_rule")
    return next((row for row in rules if row["policy"] == named), rules[0])


def _rule_names(summaries: dict[str, dict]) -> str:
    return ", ".join(f"`{name}`" for name in sorted({s["rule"]["name"] for s in summaries.values()}))


# --- the page -------------------------------------------------------------------------------------------

def _entries(task, summaries: dict[str, dict]) -> list[tuple[str, object, dict]]:
    """(role, configuration entry, summary) of a task's evaluations: the headline, then its variants by name."""
    variants = sorted(task.variants, key=lambda evaluation: evaluation.summary)
    return ([("headline", task.headline, summaries[task.headline.summary])]
            + [("variant", evaluation, summaries[evaluation.summary]) for evaluation in variants])


def _set_names(entries) -> list[str]:
    """The task's set names: the headline's in its order, then the variants' others as they first appear."""
    names: list[str] = []
    for _, _, summary in entries:
        names += [s["name"] for s in summary["sets"] if s["name"] not in names]
    return names


def _set_table(task_name: str, set_name: str, entries, limit: list[str] = ()) -> list[str]:
    headline_rows, variant_rows, described = [], [], None
    for role, evaluation, summary in entries:
        evaluation_set = next((s for s in summary["sets"] if s["name"] == set_name), None)
        if evaluation_set is None:
            continue
        described = described or evaluation_set
        rule = reference_rule(evaluation_set)
        for row in evaluation_set["rows"]:
            if row["kind"] != "agent":
                continue
            final = row.get("final_over_1pct")
            cells = [f"**{evaluation.summary}**" if role == "headline" else evaluation.summary, row["policy"],
                     _usd(evaluation_set["oracle_return_usd_ha"]), rule["policy"], _regret(rule), _regret(row),
                     f"{row['regret_pct_of_reference']:.2f} %", _ratio(row["ratio_to_rule"], row["ratio_to_rule_ci"]),
                     f"{100 * row['paired_wins']:.0f} %",
                     _ratio(final, row.get("final_over_1pct_ci")) if final is not None else "-",
                     training_cost(summary["training"][row["group"]])]
            (headline_rows if role == "headline" else variant_rows).append((row["regret_usd_ha"], cells))
    shapes = sorted({(s["seasons"], s["noise_seeds"]) for _, _, summary in entries for s in summary["sets"]
                     if s["name"] == set_name})
    shape = "; ".join(f"{seasons} seasons x {noise} noise seeds" for seasons, noise in shapes)
    lines = [f"### {task_name}, {set_name}", "", f"{described['role']}; {shape}.", "", *limit,
             "| evaluation | agent | oracle return | rule | rule regret [95 % CI] | regret [95 % CI] | regret % of "
             "oracle | ratio to rule [95 % CI] | paired wins | final / 1 % [95 % CI] | training per seed |",
             "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---|"]
    # the headline first as evaluated; the variants by regret, best first
    for _, cells in headline_rows + sorted(variant_rows, key=lambda item: (item[0], item[1][0], item[1][1])):
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def _planned_set(planner: dict | None, set_name: str) -> dict | None:
    return None if planner is None else next((s for s in planner["sets"] if s["name"] == set_name), None)


def _planning_cost(planned: dict) -> str:
    per_season = planned["planning_cpu_s"] / planned["seasons"]
    return f"{_duration(planned['planning_cpu_s'])} CPU ({per_season:.0f} s CPU a season)"


def headroom(planned: dict) -> str:
    """The strongest rule's headroom over the causal planner: USD/ha and % of the oracle's return, with their
    intervals, and whether it reaches the 2 % that makes a set worth learning (issue 33)."""
    low, high = planned["headroom_ci_usd_ha"]
    pct_low, pct_high = planned["headroom_pct_ci"]
    reaches = "reaches" if planned["headroom_pct_of_oracle"] >= HEADROOM_WORTH_LEARNING_PCT else "under"
    return (f"{_usd(planned['headroom_usd_ha'])} [{_usd(low)}, {_usd(high)}] USD/ha, "
            f"{planned['headroom_pct_of_oracle']:.2f} % [{pct_low:.2f}, {pct_high:.2f}] of the oracle's return: "
            f"{reaches} {HEADROOM_WORTH_LEARNING_PCT:.0f} %")


def _limit_table(task, planned: dict, headline: dict) -> list[str]:
    """A set's causal-limit table: the oracle, the causal planner, the rules (strongest first) and the headline's
    agents, each with its regret and ratio to the strongest rule, then the rule's headroom over the planner."""
    evaluated = next(s for s in headline["sets"] if s["name"] == planned["name"])
    rows = {row["policy"]: row for row in evaluated["rows"]}
    strongest = planned["strongest_rule"]
    rules = sorted(planned["rules"], key=lambda rule: rule["policy"] != strongest)
    name, oracle = task.headline.summary, planned["oracle_return_usd_ha"]
    cells = [["oracle (knows the season's weather)", name, _usd(oracle), "0", "0.00 %", "-", "-"],
             ["causal planner (knows the weather so far and its climate)", task.planner,
              _usd(planned["planner"]["return_usd_ha"]), _regret(planned["planner"]),
              f"{planned['planner']['regret_pct_of_reference']:.2f} %",
              _ratio(planned["planner"]["ratio_to_strongest_rule"], planned["planner"]["ratio_to_strongest_rule_ci"]),
              _planning_cost(planned)]]
    for rule in rules:
        label = ("strongest rule" if rule["policy"] == strongest
                 else "old rule" if rule["policy"] == OLD_RULE else "weaker rule")
        cells.append([f"{rule['policy']} ({label})", name, _usd(rows[rule["policy"]]["return_usd_ha"]), _regret(rule),
                      f"{rows[rule['policy']]['regret_pct_of_reference']:.2f} %",
                      _ratio(rule["ratio_to_strongest_rule"], rule["ratio_to_strongest_rule_ci"]), "-"])
    for row in evaluated["rows"]:
        if row["kind"] == "agent":
            cells.append([f"{row['policy']} (agent)", name, _usd(row["return_usd_ha"]), _regret(row),
                          f"{row['regret_pct_of_reference']:.2f} %", _ratio(row["ratio_to_rule"], row["ratio_to_rule_ci"]),
                          training_cost(headline["training"][row["group"]]) + " per seed"])
    borrowed = ("" if planned["planned_on"] == task.task else
                f" Planned on `{planned['planned_on']}`'s evaluation: the same seasons, terms and oracle returns, the "
                "same task constants and continuations (the planner reads the true state, not the observation).")
    return ["| policy | summary | return | regret [95 % CI] | regret % of oracle | ratio to strongest rule "
            "[95 % CI] | cost |", "|---|---|---:|---:|---:|---:|---|"] + ["| " + " | ".join(c) + " |" for c in cells] + [
        "", f"Headroom ({strongest}'s regret - the causal planner's): {headroom(planned)}. The planner's "
        f"continuations: `{planned['continuations']}`'s weather.{borrowed}", ""]


def _commands(task_name: str, entries) -> list[str]:
    lines = [f"### {task_name}: how each result was made", ""]
    for role, evaluation, summary in entries:
        lines.append(f"- **{evaluation.summary}** ({role}; evaluated in {_duration(summary['evaluation_wall_s'])}): "
                     f"`{evaluation.evaluate}`")
        for group, recipe in evaluation.train.items():
            lines.append(f"  - {group} ({len(recipe.seeds)} seeds, {training_cost(summary['training'][group])} per "
                         f"seed): `{recipe.command.replace('{seed}', 'S')}`, {_seeds(recipe.seeds)}")
    return lines + [""]


def _planner_commands(planner: dict) -> list[str]:
    settings = ", ".join(f"{key} {value}" for key, value in planner["planner"].items())
    lines = [f"Causal planner ({settings}), per set, then `python -m experiments.planners_summary` on the "
             f"evaluation `{planner['evaluation']}`:", ""]
    return lines + [f"- {s['name']} ({_planning_cost(s)}): `{s['command']}`" for s in planner["sets"]] + [""]


def page(config, summaries: dict[str, dict], planners: dict[str, dict]) -> str:
    """The text of docs/leaderboard.md (``planners``: :func:`read_planners`)."""
    agent_rows = sum(1 for s in summaries.values() for es in s["sets"] for row in es["rows"] if row["kind"] == "agent")
    lines = [
        "# Leaderboard", "",
        f"> **Which rule the ratios are against.** Every ratio on this page is an agent's regret over the regret of "
        f"the rule in the `rule` column, paired on the same seasons and noise: where an evaluation scored the paced "
        f"rule (`paced-rule`, issue 33, `crop_agent_ros/policies/family_<task>-paced.json`) beside the project's "
        f"tuned water-budget rule ({_rule_names(summaries)}, `crop_agent_ros/policies/family_<task>.json`), the "
        f"set's strongest of the two (the lower regret on that set; the other is a weaker baseline); in older "
        f"evaluations, the water-budget rule alone. Both are tuned by `crop-sim tune-rule` on generated training "
        f"seasons only. {config.stronger_rule.strip()}",
        "",
        f"Generated by `crop-sim leaderboard` from `{SUMMARIES}/*.json` (one per evaluation, listed in `{CONFIG}`); "
        "`crop-sim leaderboard --check` fails when this page is out of date. Do not edit it by hand.",
        "",
        f"{len(config.tasks)} tasks, {len(summaries)} evaluations, {len(planners)} planner summaries, {agent_rows} agent rows. Money in USD/ha. "
        "Regret: the hindsight oracle's return (it plans knowing the season's weather) minus the policy's, per "
        "training seed, season and noise seed; [95 % CI]: hierarchical bootstrap over training seeds, seasons and "
        "noise seeds. Ratio to rule: agent regret / rule regret on the same resamples. Paired wins: the share of "
        "(training seed, season, noise seed) where the agent's return is above the rule's. Final / 1 %: final "
        "regret / the same runs' 1 % checkpoint regret (learning is real at <= 0.5). Training per seed: mean "
        "environment steps and wall time of one `crop-sim train` run as recorded (demonstrations recorded "
        "beforehand are not in it). Headline: the task's reference evaluation (evolution strategies; on the tasks "
        "with a paced rule also the residual agent, ES correcting that rule); variants: "
        "every other evaluation on the task, best regret first. A `crop-sim train` command runs once per "
        "training seed S; a headline ES command uses the task's recipe defaults, every other command is as its "
        "runs recorded it, with the `crop-sim train` options of that time (options removed since are in the git "
        "history).", "",
        "**The causal limit** (issue 33), on the sets of the tasks whose entry names a planner summary: a table "
        "before the agents' with the oracle, the causal planner, the rules and the headline's agents. The causal "
        "planner (`experiments/planners_expected.py`, expected values over continuations of the set's own "
        "climate) knows the crop's true state, the weather so far and the climate's weather generator, not the "
        "season ahead: its regret is a measured upper bound on what a controller that cannot see the future "
        "reaches (no noise: it reads no noisy value). Ratio to strongest rule: regret / the strongest rule's "
        "regret on the same resamples. Headroom: the strongest rule's regret minus the planner's, in USD/ha and "
        f"as % of the oracle's return; a set is worth learning where it reaches {HEADROOM_WORTH_LEARNING_PCT:.0f} "
        "%. Cost: the planner's CPU seconds of planning on the set.", "",
    ]
    for task in config.tasks:
        entries = _entries(task, summaries)
        lines += [f"## {task.task}", "",
                  f"Headline: `{task.headline.summary}`; {len(entries) - 1} variants.", ""]
        planner = planners.get(task.task)
        for set_name in _set_names(entries):
            planned = _planned_set(planner, set_name)
            limit = [] if planned is None else _limit_table(task, planned, entries[0][2])
            lines += _set_table(task.task, set_name, entries, limit)
        lines += _commands(task.task, entries) + (_planner_commands(planner) if planner else [])
    return "\n".join(lines).rstrip("\n") + "\n"


def readme_block(config, summaries: dict[str, dict], planners: dict[str, dict]) -> str:
    """The README's excerpt: per task and set named in ``readme_sets``, the headline's best agent."""
    lines = [
        "Regret in USD/ha (the hindsight oracle's return minus the policy's) with 95 % bootstrap intervals; ratio: "
        "agent regret / the regret of the rule named (the set's strongest rule where the evaluation scored the paced "
        "rule of issue 33, else our tuned water-budget rule); causal planner: the regret of a planner that knows "
        "the weather so far and its climate, not the season ahead; headroom: the rule's regret minus the "
        "planner's, as % of the oracle's return (a set is worth learning at 2 %): see the box at the top of "
        "[the leaderboard](docs/leaderboard.md), which has every result.",
        "",
        "| task | set | rule | rule regret | causal planner regret | headroom | best agent | agent regret [95 % CI] "
        "| ratio to rule [95 % CI] |",
        "|---|---|---|---:|---:|---:|---|---:|---:|",
    ]
    for task in config.tasks:
        summary = summaries[task.headline.summary]
        for set_name in task.readme_sets:
            planned = _planned_set(planners.get(task.task), set_name)
            limit = ("- | -" if planned is None else
                     f"{_usd(planned['planner']['regret_usd_ha'])} | {planned['headroom_pct_of_oracle']:.2f} %")
            evaluation_set = next(s for s in summary["sets"] if s["name"] == set_name)
            rule = reference_rule(evaluation_set)
            best = min((row for row in evaluation_set["rows"] if row["kind"] == "agent"),
                       key=lambda row: (row["regret_usd_ha"], row["policy"]))
            lines.append(f"| {task.task} | {set_name} | {rule['policy']} | {_usd(rule['regret_usd_ha'])} | {limit} | "
                         f"{best['policy']} | "
                         f"{_regret(best)} | {_ratio(best['ratio_to_rule'], best['ratio_to_rule_ci'])} |")
    return "\n".join(lines) + "\n"


def with_block(readme: str, block: str) -> str | None:
    """``readme`` with the text between its markers replaced by ``block``; None if it has neither marker."""
    start, end = readme.find(START), readme.find(END)
    if start < 0 and end < 0:
        return None
    if start < 0 or end < 0 or end < start or readme.count(START) > 1 or readme.count(END) > 1:
        raise UsageError(f"{README}: expected one {START} line followed by one {END} line")
    return readme[:start + len(START)] + "\n" + block + readme[end:]


def outputs(root: Path) -> dict[Path, str]:
    """What the command writes, by path relative to ``root``: the page, and the README if it has markers."""
    config = read_config(root)
    summaries = read_summaries(root, config)
    planners = read_planners(root, config, summaries)
    written = {PAGE: page(config, summaries, planners)}
    readme_path = root / README
    if readme_path.is_file():
        with user_input(str(README), (OSError, UnicodeDecodeError)):
            readme = readme_path.read_text(encoding="utf-8")
        updated = with_block(readme, readme_block(config, summaries, planners))
        if updated is not None:
            written[README] = updated
    return written


def run(args) -> int:
    import sys
    root = args.root
    if not (root / CONFIG).is_file():
        raise UsageError(f"--root: {root / CONFIG} not found (run from the repository root, or give --root)")
    written = outputs(root)
    if args.check:
        stale = [str(path) for path, text in written.items()
                 if not (root / path).is_file() or (root / path).read_text(encoding="utf-8") != text]
        if stale:
            print(f"crop-sim leaderboard: {' and '.join(stale)} out of date; run crop-sim leaderboard",
                  file=sys.stderr)
            return 1
        print(f"up to date: {', '.join(str(path) for path in written)}")
        return 0
    from crop_sim_ros.output import check_output_file, output_directory, write_text_atomic
    for path in written:   # every file checked before any is written
        check_output_file(root / path, "--root")
    for path, text in written.items():
        output_directory((root / path).parent, "--root")
        write_text_atomic(root / path, text)
    print(f"wrote {', '.join(str(path) for path in written)}"
          + ("" if README in written else f" ({README}: no {START} marker, left alone)"))
    return 0
