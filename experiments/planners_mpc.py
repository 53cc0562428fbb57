"""What it showed: a causal controller that knows no future weather, re-planning every 7 days on 8 weather
continuations and applying the mean of their plans, removes 37-55 % of the tuned water-budget rule's regret on
``benton-quota`` (0.63 [0.53, 0.74] of it on far Benton, 0.45 [0.25, 0.72] on the held-out real seasons): most of
the rule's regret is not the price of unknown weather. This module is that controller (``mean-plan``) and what
the other two planners (:mod:`experiments.planners_hindsight`, :mod:`experiments.planners_expected`) share.

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

Run it with ``python -m experiments.planners --method mean-plan ...`` (:mod:`experiments.planners`).
"""

from __future__ import annotations

import datetime
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from crop_agent_ros.policies.base import DAYS_SINCE_SOWING, BasePolicy, SeasonContext
from crop_agent_ros.policies.family_oracle import TaskConstants, field_problems, plan_fields, within_quota
from crop_sim_ros.task.layout import EXTENDED

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
    from crop_agent_ros.policies.rollout import season_contexts
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
