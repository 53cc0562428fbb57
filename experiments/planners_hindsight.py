"""What it showed: deciding each day by the mean of the continuations' hindsight values, not applying the mean
of their plans, takes a causal planner from 0.63 to 0.47 [0.41, 0.54] of the tuned rule's regret on
``benton-quota``'s far Benton seasons (lower on 46 of 50 seasons).

A causal controller for the task family that decides each day by the mean of hindsight values
("hindsight optimisation"): one decision shared by every guess of the weather to come, not the mean of the
guesses' own plans.

:class:`experiments.planners_mpc.FamilyMpcPolicy` applies the mean of the plans that are best for
each weather continuation. Each of those plans knows its own future (when its rain falls), and their mean
is a schedule no continuation would choose: under a binding quota it starts irrigating later than the
hindsight oracle (measured on far Benton seasons). This controller asks another question each day: which
amount today is best when the rest of the season may be any of the continuations?

- It knows what :mod:`experiments.planners_mpc` knows (SIMPLE and the crop's parameters, the
  season's terms, the weather up to today and the water applied so far, hence the crop's exact state), and
  draws its continuations from the same pools (:func:`experiments.planners_mpc.continuation_pool`).
- Every ``decision_every_days`` days (and at sowing) it builds, for each continuation j, the dynamic
  programme of the rest of the season on the true weather so far followed by continuation j
  (:class:`crop_agent_ros.policies.family_dp.SeasonProgramme`: soil water x senescence offset, with the
  quota priced by a multiplier lambda). For each continuation it keeps the multiplier lambda_j whose plan,
  from the crop's true state and the quota left, returns most on that continuation (each plan holds the
  quota; a first grid of multipliers, then a finer one between the best's neighbours, searched on coarser
  programmes), and the value tables V_j of that multiplier.
- Each day it applies, of ``amounts`` levels between 0 and the most it may apply (capacity, quota left),
  the one that maximises today's reward on today's true weather + the mean over continuations of
  V_j(tomorrow's state) - lambda_j x amount (lambda_j: continuation j's shadow price of the quota).

What its figures mean: like the MPC's, its return is achieved by a causal controller (it reads no weather
after the day it acts on), so oracle - its return bounds from above the least regret a causal controller can
reach; the values V_j still know their continuation's future, so it is not optimal either.

    python -m experiments.planners --method hindsight-value --table T.json --set far-benton
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from crop_sim_ros import model

from crop_agent_ros.policies.base import DAYS_SINCE_SOWING, SeasonContext
from crop_agent_ros.policies.family_dp import SeasonProgramme, _forward_plans
from crop_agent_ros.policies.family_oracle import TaskConstants

from experiments.planners_mpc import APPLIED_YESTERDAY, ContinuationPlanner, spliced


@dataclass(frozen=True)
class HindsightSettings:
    """``scenarios``: weather continuations; ``decision_every_days``: days between new value tables;
    ``water_step_mm`` / ``offset_step_degc_d``: the programme's grids (soil water, mm; senescence offset,
    degC d); ``amounts``: levels of water tried each day (0 .. the most allowed); ``multipliers_per_value``:
    the quota's multipliers tried first, as fractions of the yield value per t (reward units per mm per reward
    unit per t ha-1); ``refined_multipliers``: how many more are tried, evenly between the best first one's
    neighbours (the quota's price must be precise: with the true weather as the only continuation, on two
    seasons with a 250 mm quota, the 7 first multipliers alone leave 1.5-1.9 % of the oracle's return, with
    10 refined 0.1-0.2 %). ``search_water_step_mm`` / ``search_offset_step_degc_d``: the grids of the
    programmes that choose the multiplier (coarser and cheaper: only the chosen multiplier's tables are
    built on the fine grids; None: the fine grids throughout)."""

    scenarios: int = 4
    decision_every_days: int = 7
    water_step_mm: float = 2.0
    offset_step_degc_d: float = 80.0
    amounts: int = 33
    multipliers_per_value: tuple = (0.0, 0.005, 0.01, 0.015, 0.02, 0.03, 0.05)
    refined_multipliers: int = 10
    search_water_step_mm: float | None = 4.0
    search_offset_step_degc_d: float = 80.0

    def __post_init__(self) -> None:
        if int(self.scenarios) < 1 or int(self.decision_every_days) < 1 or int(self.amounts) < 2:
            raise ValueError(f"family hindsight: scenarios and decision_every_days must be >= 1 and amounts >= 2, "
                             f"got {self.scenarios}, {self.decision_every_days} and {self.amounts}")
        search = (1.0, 1.0) if self.search_water_step_mm is None else (self.search_water_step_mm,
                                                                       self.search_offset_step_degc_d)
        if not (self.water_step_mm > 0 and self.offset_step_degc_d > 0 and min(search) > 0):
            raise ValueError(f"family hindsight: the grid steps must be > 0, got {self.water_step_mm} mm and "
                             f"{self.offset_step_degc_d} degC d (search: {search[0]} mm, {search[1]} degC d)")
        if not self.multipliers_per_value or min(self.multipliers_per_value) < 0 or int(self.refined_multipliers) < 0:
            raise ValueError(f"family hindsight: multipliers_per_value must be >= 0 and not empty, and "
                             f"refined_multipliers >= 0, got {self.multipliers_per_value} and {self.refined_multipliers}")


@dataclass
class _Guess:
    """One continuation's programme, its chosen multiplier (reward units per mm) and its value tables
    (1, nW, nO) by day (None where not needed)."""

    programme: SeasonProgramme
    multiplier: float
    tables: list


def _kept(tables: list, last_day: int) -> list:
    """The value tables of days up to ``last_day`` (the others None: a field keeps only what it reads before
    its next decision)."""
    return [t if d <= last_day else None for d, t in enumerate(tables)]


class FamilyHindsightPolicy(ContinuationPlanner):
    """The module docstring's controller; :meth:`begin_season` as :class:`ContinuationPlanner`'s. It follows
    each field's crop state by stepping SIMPLE on the true weather of each day past with the water the
    environment applied (``irrigation_yesterday_mm`` of the observation)."""

    name = "family-hindsight"

    def __init__(self, constants: TaskConstants, pools: dict[str, list[SeasonContext]],
                 settings: HindsightSettings = HindsightSettings(), align: str = "day-of-year"):
        super().__init__(constants, pools, settings, align)

    def begin_season(self, context) -> None:
        super().begin_season(context)
        self.states = [model.initial_state(c.params) for c in self.contexts]
        self.guesses: list[list[_Guess]] = [[] for _ in self.contexts]

    def _quota_left_mm(self, i: int, day: int) -> float:
        return self.problems[i].quota_mm - float(self.applied[i][:day].sum())

    def _search_multiplier(self, i: int, best_of) -> tuple:
        """The quota's multiplier (reward units per mm) of most return for field ``i``: ``best_of(multipliers)``
        gives the best of some as (multiplier, return, anything kept with it); tried on the first grid (the
        settings' fractions of the yield value per t; 0 alone without a quota), then on ``refined_multipliers``
        evenly between the best first one's neighbours. Returns ``best_of``'s tuple of the best."""
        s, truth = self.settings, self.problems[i]
        first = truth.yield_value_per_t * np.asarray(sorted(s.multipliers_per_value), dtype=float)
        if not np.isfinite(truth.quota_mm):
            first = np.zeros(1)
        best = best_of(first)
        if len(first) > 1 and s.refined_multipliers:
            k = int(np.searchsorted(first, best[0]))
            between = np.linspace(first[max(k - 1, 0)], first[min(k + 1, len(first) - 1)],
                                  s.refined_multipliers + 2)[1:-1]
            best = max(best, best_of(between), key=lambda b: b[1])
        return best

    def _replan(self, i: int, day: int) -> None:
        began = time.process_time()
        s = self.settings
        truth = self.problems[i]
        keep_until = day + s.decision_every_days + 1  # the tables the days to the next decision read
        guesses = []
        for continuation in self.field_pools[i]:
            problem = replace(truth, context=spliced(truth.context, continuation, day + 1, self.align))
            programme = SeasonProgramme(problem, s.water_step_mm, s.offset_step_degc_d)
            search = programme if s.search_water_step_mm is None else SeasonProgramme(
                problem, s.search_water_step_mm, s.search_offset_step_degc_d)
            day_terms: dict = {}  # the search programme's, shared by its two calls
            best = self._search_multiplier(
                i, lambda multipliers: self._best_multiplier(search, i, day, multipliers, day_terms))
            tables = best[2]
            if search is not programme:  # the chosen multiplier's tables on the fine grids
                _, tables = programme.value_tables([truth.water_cost_per_mm + best[0]], rounding=False,
                                                   first_day=day + 1)
            guesses.append(_Guess(programme, best[0], _kept(tables, keep_until)))
        self.guesses[i] = guesses
        self.decisions += 1
        self.planning_cpu_s += time.process_time() - began

    def _best_multiplier(self, programme: SeasonProgramme, i: int, day: int, multipliers: np.ndarray,
                         day_terms: dict) -> tuple[float, float, list]:
        """Of ``multipliers``, the one whose plan from field ``i``'s state on ``day`` returns most on the
        programme's weather: (multiplier, return to go, its value tables); ``day_terms`` as
        :meth:`SeasonProgramme.value_tables`'."""
        prices = self.problems[i].water_cost_per_mm + multipliers
        _, tables = programme.value_tables(prices, rounding=False, first_day=day + 1, day_terms=day_terms)
        _, returns = _forward_plans(programme, tables, prices, self.settings.amounts, first_day=day,
                                    state=self.states[i], quota_left_mm=self._quota_left_mm(i, day))
        best = int(np.argmax(returns))
        return float(multipliers[best]), float(returns[best]), [None if t is None else t[best:best + 1] for t in tables]

    def _decide(self, i: int, day: int) -> float:
        """Today's amount (mm) of field ``i``: the module docstring's daily choice."""
        state, problem, context = self.states[i], self.problems[i], self.contexts[i]
        if bool(state.mature[0]):
            return 0.0
        top = max(min(problem.capacity_mm_per_day, self._quota_left_mm(i, day) - 1e-6), 0.0)
        amounts = top * np.linspace(0.0, 1.0, self.settings.amounts)
        n = len(amounts)
        batch = model.CropState(*(np.repeat(a, n) for a in state))
        after, _ = model.step(model.repeat_parameters(context.params, n), batch, context.weather_on(day), amounts)
        score = (self.guesses[i][0].programme.value_per_kg * (after.biomass_kg_ha - batch.biomass_kg_ha)
                 - problem.water_cost_per_mm * amounts - problem.event_cost * (amounts > 0.0))
        later = np.zeros(n)
        for guess in self.guesses[i]:
            later -= guess.multiplier * amounts
            if day + 1 < len(guess.tables) and guess.tables[day + 1] is not None:
                offset = (state.i50b_degc_d - guess.programme.base_i50b[day + 1])[:, None]
                later += guess.programme._lookup(guess.tables[day + 1], after.plant_available_water_mm[None, :],
                                                 offset, False)[0, 0, :, 0]
        return float(amounts[int(np.argmax(score + later / len(self.guesses[i])))])

    def _act_batch(self, obs):
        self._check_batch(obs)
        days = np.rint(obs[:, DAYS_SINCE_SOWING]).astype(int)
        self.done |= days < self.last_day  # a field that restarted (its episode ended) is not planned again
        out = np.zeros(len(obs))
        self.live = np.zeros(len(obs), dtype=bool)  # the fields acted on (what a recorder of its labels keeps)
        for i in np.flatnonzero(~self.done):
            day, context = int(days[i]), self.contexts[i]
            if day >= len(self.applied[i]):
                continue
            self.live[i] = True
            if day != self.last_day[i] + 1:
                raise ValueError(f"family hindsight: field {i} is on day {day} after day {self.last_day[i]}; "
                                 f"it follows a season day by day from sowing")
            if day > 0:  # yesterday: the water the environment applied, on yesterday's true weather
                self.applied[i][day - 1] = obs[i, APPLIED_YESTERDAY]
                self.states[i], _ = model.step(context.params, self.states[i], context.weather_on(day - 1),
                                               self.applied[i][day - 1:day])
            self.last_day[i] = day
            if day % self.settings.decision_every_days == 0 or not self.guesses[i]:
                self._replan(i, day)
            out[i] = self._decide(i, day)
        return out
