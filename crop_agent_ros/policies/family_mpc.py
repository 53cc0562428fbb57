"""A causal model-predictive controller (MPC) for the task family: how much of the tuned rule's regret a
controller can remove without knowing the weather to come.

The hindsight oracle (:mod:`crop_agent_ros.policies.family_oracle`) knows every future day's weather; no
controller can, so part of any controller's regret is the price of not knowing it. This controller knows
what a farm's controller can know on day t, and nothing more:

- SIMPLE and the crop's published parameters, the season's terms (tuber price, water cost, quota: columns of
  the observation), the task's capacity and event cost;
- the weather of days 0..t (today's is in the observation; a weather network publishes it daily) and the
  water applied on days 0..t-1 (the observation's ``irrigation_yesterday_mm``), hence the crop's exact state;
- not the weather after today: in its place ``scenarios`` continuations, seasons of the task's weather
  generator drawn with :data:`POOL_SEED` (no training, validation or evaluation pool uses that seed), each
  aligned with the season by the day of the year of sowing. A task on several climates (a mixture) has one
  pool per generator, and each field draws from its own climate's.

Every ``decision_every_days`` days (and on the sowing day) it re-plans: for each continuation, the oracle's
search finds the best schedule of the rest of the season on the true weather so far followed by the
continuation, with the applied days frozen (``FieldProblem.frozen_days``), warm-started from that
continuation's previous plan (the first plan: the oracle's own starts). Until the next decision it applies,
each day, the mean of the continuations' plans for that day: within the capacity, and within the quota left
(each plan is), so the environment applies it unchanged. It ignores the noisy sensors and the forecast.

What its figures mean: its return is achieved by a causal controller (the environment pays it, and a test
checks that its actions do not depend on the weather after the day they are taken), so oracle - MPC regret
is a measured **upper bound on the least regret a causal controller can reach**. It is not a lower bound:
a better controller (more continuations, conditioning on the forecast, daily decisions) may do better.

This mean of plans (``mean-plan``) is one of three planners (:data:`METHODS`); ``hindsight-value``
(:mod:`crop_agent_ros.policies.family_hindsight`) shares one decision a day across the continuations and
removes more of the rule's regret; ``expected-value`` (:mod:`crop_agent_ros.policies.family_expected`, the
default) makes that decision from values that average over the weather inside one programme and removes more
again. :func:`planner` builds each from its settings; the command line runs one on a set of an evaluation,
beside that evaluation's oracle and rule:

    python -m crop_agent_ros.policies.family_mpc [--method expected-value|hindsight-value|mean-plan] \\
        --table results/family/benton-quota/table.json --set heldout-real [--seasons 0..4] [--scenarios K] \\
        [--decision-every-days 7] [--out FILE.json]

and ``--paired BASE.json OTHER.json`` compares two such runs season by season (:func:`paired_runs`).
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from crop_sim_ros.task.layout import EXTENDED
from crop_sim_ros.weather.generator import GENERATOR_NAMES

from .base import DAYS_SINCE_SOWING, BasePolicy, SeasonContext
from .family_oracle import TaskConstants, field_problems, plan_fields, season_range, within_quota

POOL_SEED = 700_001
WEATHER_SERIES = ("tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm", "et0_mm")
APPLIED_YESTERDAY = EXTENDED.index("irrigation_yesterday_mm")


@dataclass(frozen=True)
class MpcSettings:
    """``scenarios``: weather continuations per decision; ``decision_every_days``: days between re-plans;
    ``replan_first_step_mm`` / ``finest_step_mm``: the oracle search's first and finest step (mm) in a
    re-plan (the first plan uses the oracle's defaults, from 16 mm)."""

    scenarios: int = 8
    decision_every_days: int = 7
    replan_first_step_mm: float = 4.0
    finest_step_mm: float = 0.25

    def __post_init__(self) -> None:
        if int(self.scenarios) < 1 or int(self.decision_every_days) < 1:
            raise ValueError(f"family MPC: scenarios and decision_every_days must be >= 1, got {self.scenarios} "
                             f"and {self.decision_every_days}")
        if not 0 < self.finest_step_mm <= self.replan_first_step_mm:
            raise ValueError(f"family MPC: need 0 < finest_step_mm <= replan_first_step_mm, got "
                             f"{self.finest_step_mm} and {self.replan_first_step_mm}")


def continuation_pool(generator_scenario, scenarios: int, seed: int = POOL_SEED) -> dict[str, list[SeasonContext]]:
    """Climate name (:func:`crop_sim_ros.task.scenario.climates`: the generator's, or the part's where two parts
    share one) -> ``scenarios`` generated seasons of that climate with ``seed``: one entry for a scenario on one
    weather generator, one per part for a mixture (each part with its own sowing date)."""
    from crop_sim_ros.task.scenario import climates, reseeded
    from .rollout import season_contexts
    try:
        parts = climates(generator_scenario)
    except ValueError as error:
        raise ValueError(f"family MPC: continuations need a weather generator; {error}") from None
    return {name: season_contexts(reseeded(part, seed, scenarios)) for name, part in parts.items()}


def _climate_key(context: SeasonContext) -> tuple:
    """(weather generator, sowing month and day) of a season: what tells the climates of a mixture apart."""
    from crop_sim_ros.weather.generator import generator_of_source
    return generator_of_source(str(context.extra.get("source", ""))), str(context.extra.get("sowing_date", ""))[5:]


def climate_of(context: SeasonContext, pools: dict) -> str:
    """The pool a field draws its continuations from: the only one, or the one of its weather generator and
    sowing date."""
    if len(pools) == 1:
        return next(iter(pools))
    key = _climate_key(context)
    found = [name for name, pool in pools.items() if _climate_key(pool[0]) == key]
    if len(found) != 1:
        raise ValueError(f"family MPC: season {context.name} ({context.extra.get('source')}, sown "
                         f"{context.extra.get('sowing_date')}) has no continuation pool (pools: {', '.join(pools)})")
    return found[0]


def _day_of_year(context: SeasonContext) -> int:
    return datetime.date.fromisoformat(context.extra["sowing_date"]).timetuple().tm_yday


# How a continuation's days stand in for a season's days to come: the same days of the year (the default: a
# climate's calendar), or the same days after sowing (a crop's own calendar; for a climate sown on another date).
ALIGNMENTS = ("day-of-year", "sowing")


def _checked_alignment(align: str) -> str:
    """``align`` if it is one of :data:`ALIGNMENTS`, else ValueError naming them."""
    if align not in ALIGNMENTS:
        raise ValueError(f"family MPC: align must be one of {', '.join(ALIGNMENTS)}, got {align!r}")
    return align


def spliced(truth: SeasonContext, continuation: SeasonContext, known_days: int,
            align: str = "day-of-year") -> SeasonContext:
    """``truth``'s weather on days 0..known_days-1, then ``continuation``'s on the same days of the year (``align``
    "day-of-year") or the same days after sowing ("sowing"), its first or last day repeated outside it, over
    ``truth``'s length: what the controller plans on."""
    by_day_of_year = _checked_alignment(align) == "day-of-year"
    offset = _day_of_year(truth) - _day_of_year(continuation) if by_day_of_year else 0
    days = np.arange(len(truth.rain_mm))
    source = np.clip(days + offset, 0, len(continuation.rain_mm) - 1)
    series = {}
    for name in WEATHER_SERIES:
        known, guessed = np.asarray(getattr(truth, name), dtype=float), np.asarray(getattr(continuation, name))
        series[name] = np.where(days < known_days, known, guessed[source])
    return replace(truth, name=f"{truth.name}|{continuation.name}@{known_days}", **series)


class ContinuationPlanner(BasePolicy):
    """What the causal planners share: the first ``settings.scenarios`` seasons of each continuation pool, and
    for a season (:meth:`begin_season`: one :class:`SeasonContext` per field with its episode terms, as
    :func:`crop_agent_ros.policies.rollout.run_episodes` gives them) each field's problem, its climate's pool,
    the water applied so far (mm per day) and whether its episode is over. After each act, ``live`` marks the
    fields acted on (what a recorder of the planner's labels keeps)."""

    observation_sizes = (EXTENDED.size,)

    def __init__(self, constants: TaskConstants, pools: dict[str, list[SeasonContext]], settings,
                 align: str = "day-of-year"):
        self.align = _checked_alignment(align)  # refused here, before any planning
        if not pools or min(len(pool) for pool in pools.values()) < settings.scenarios:
            raise ValueError(f"{self.name}: {settings.scenarios} scenarios need as many seasons in every pool, got "
                             f"{ {name: len(pool) for name, pool in pools.items()} }")
        self.constants = constants
        self.pools = {name: list(pool[:settings.scenarios]) for name, pool in pools.items()}
        self.settings = settings
        self.contexts: list[SeasonContext] = []
        self.decisions = 0
        self.planning_cpu_s = 0.0

    def begin_season(self, context) -> None:
        self.contexts = list(context) if isinstance(context, (list, tuple)) else [context]
        self.problems = field_problems(self.contexts, self.constants)
        self.field_pools = [self.pools[climate_of(c, self.pools)] for c in self.contexts]
        self.applied = [np.zeros(len(c.rain_mm)) for c in self.contexts]
        self.last_day = np.full(len(self.contexts), -1)
        self.done = np.zeros(len(self.contexts), dtype=bool)

    def describe(self):
        described = {"name": self.name, "pool_seed": POOL_SEED, "pools": sorted(self.pools), **asdict(self.settings)}
        return described if self.align == "day-of-year" else {**described, "align": self.align}

    def _check_batch(self, obs) -> None:
        if not self.contexts or len(self.contexts) != len(obs):
            raise ValueError(f"{self.name}: begin_season with one context per field first ({len(self.contexts)} "
                             f"contexts for {len(obs)} observations)")


class FamilyMpcPolicy(ContinuationPlanner):
    """The module docstring's controller; the policy reads a field's weather only up to the day it acts on
    (``days_since_sowing`` of the observation)."""

    name = "family-mpc"

    def __init__(self, constants: TaskConstants, pools: dict[str, list[SeasonContext]],
                 settings: MpcSettings = MpcSettings(), align: str = "day-of-year"):
        super().__init__(constants, pools, settings, align)

    def begin_season(self, context) -> None:
        super().begin_season(context)
        n, k = len(self.contexts), self.settings.scenarios
        self.plans = [[None] * k for _ in range(n)]
        self.block = [np.zeros(len(c.rain_mm)) for c in self.contexts]

    def _replan(self, fields: list[int], day: int) -> None:
        began = time.process_time()
        k = self.settings.scenarios
        problems, starts = [], []
        for i in fields:
            truth = self.problems[i]
            for j, continuation in enumerate(self.field_pools[i]):
                context = spliced(truth.context, continuation, day + 1, self.align)
                problems.append(replace(truth, context=context, frozen_days=day))
                if day > 0:
                    start = np.concatenate([self.applied[i][:day], self.plans[i][j][day:]])
                    starts.append(within_quota(start, truth.quota_mm))
        if day == 0:
            results = plan_fields(problems, finest_step_mm=self.settings.finest_step_mm)
        else:
            results = plan_fields(problems, starts=[starts], first_step_mm=self.settings.replan_first_step_mm,
                                  finest_step_mm=self.settings.finest_step_mm)
        for slot, i in enumerate(fields):
            mine = results[slot * k:(slot + 1) * k]
            for j, result in enumerate(mine):
                self.plans[i][j] = result.schedule_mm
            self.block[i] = np.mean([r.schedule_mm for r in mine], axis=0)
        self.decisions += 1
        self.planning_cpu_s += time.process_time() - began

    def _act_batch(self, obs):
        self._check_batch(obs)
        days = np.rint(obs[:, DAYS_SINCE_SOWING]).astype(int)
        self.done |= days < self.last_day  # a field that restarted (its episode ended) is not planned again
        for i in np.flatnonzero(~self.done & (days > 0)):
            self.applied[i][days[i] - 1] = obs[i, APPLIED_YESTERDAY]
        self.last_day = np.where(self.done, self.last_day, days)
        live = [i for i in np.flatnonzero(~self.done) if days[i] < len(self.applied[i])]
        deciding = [i for i in live if days[i] % self.settings.decision_every_days == 0]
        for day in sorted({int(days[i]) for i in deciding}):
            self._replan([i for i in deciding if days[i] == day], day)
        self.live = np.zeros(len(obs), dtype=bool)
        self.live[live] = True
        out = np.zeros(len(obs))
        for i in live:
            out[i] = self.block[i][days[i]]
        return out



# --- the three causal planners, by name -----------------------------------------------------------------------

METHODS = ("expected-value", "hindsight-value", "mean-plan")  # the first is the default


def planner_settings(method: str, scenarios: int | None = None, decision_every_days: int | None = None):
    """The settings of planner ``method`` (a METHODS entry: ``mean-plan`` is this module's
    :class:`FamilyMpcPolicy`, ``hindsight-value`` :mod:`crop_agent_ros.policies.family_hindsight`'s,
    ``expected-value`` :mod:`crop_agent_ros.policies.family_expected`'s), with the planner's defaults where an
    argument is None."""
    from .family_expected import ExpectedSettings
    from .family_hindsight import HindsightSettings
    kinds = {"mean-plan": MpcSettings, "hindsight-value": HindsightSettings, "expected-value": ExpectedSettings}
    if method not in kinds:
        raise ValueError(f"--method: unknown planner {method!r}; known: {', '.join(METHODS)}")
    given = {"scenarios": scenarios, "decision_every_days": decision_every_days}
    return kinds[method](**{name: value for name, value in given.items() if value is not None})


def planner(constants: TaskConstants, pools: dict[str, list[SeasonContext]], settings,
            align: str = "day-of-year") -> BasePolicy:
    """The causal planner that ``settings`` (:class:`MpcSettings`, ``HindsightSettings`` or ``ExpectedSettings``)
    configures, reading its continuations by ``align`` (:func:`spliced`)."""
    from .family_expected import ExpectedSettings, FamilyExpectedPolicy
    from .family_hindsight import FamilyHindsightPolicy, HindsightSettings
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
    from crop_agent_ros.learning.evaluate_task import RULE, _ratio, interval, table_set
    from .rollout import run_episodes
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
    from crop_agent_ros.learning.evaluate_task import interval
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
    parser = argparse.ArgumentParser(prog="python -m crop_agent_ros.policies.family_mpc",
                                     description="the causal MPC on a set of an evaluation, beside its oracle and rule")
    parser.add_argument("--table", help="table.json of `crop-sim evaluate --task T` (required unless --paired)")
    parser.add_argument("--set", help="evaluation set name (e.g. heldout-real, far-benton; required unless --paired)")
    parser.add_argument("--seasons", help="positions in the set 'A..B' (default: all)")
    parser.add_argument("--method", default=METHODS[0], choices=METHODS,
                        help="expected-value (default): the amount best by values that average over the weather "
                             "(family_expected); hindsight-value: each day the amount best on average over the "
                             "continuations' hindsight values (family_hindsight); mean-plan: the mean of each "
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
                from crop_agent_ros.learning.evaluate_task import table_set
                continuation_source(get_scenario(str(table["task"])), table_set(table, args.set)[1],
                                    args.continuations)
            summary = compare_with_table(table, args.set, seasons, settings, continuations=args.continuations,
                                         align=args.align)
    except (OSError, ValueError, KeyError) as error:
        print(f"family_mpc: {str(error).strip(chr(39))}", file=sys.stderr)
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
