"""What it showed: values that average over the weather inside one programme take a causal planner to 0.43
[0.36, 0.51] of the tuned rule's regret on ``benton-quota``'s far Benton seasons (hindsight values: 0.47); with 8
continuations of a held-out climate's own weather it halves the rule's regret there (0.46 [0.34, 0.62] on late-sown
Maricopa), with a training climate's weather it only ties the rule.

A causal controller for the task family whose values average over the weather inside one dynamic programme
(an "expected-value" programme), where :mod:`experiments.planners_hindsight` averages the values of
one programme per weather continuation.

The hindsight planner's value V_j of continuation j knows j's future: when its rain falls, how hot its July is.
Under a quota that knowledge is worth water (it saves the allocation for the very days that need it), so the
mean of those values over-rates the states a causal controller can reach. This controller builds one table
V_d(W, I50B) per day from the same continuations, with the decision inside the mean:

    V_d(W, I50B) = max over amounts a of  mean over the continuations k whose crop still grows on day d of
                   [ growth value_k(d, W, I50B, a) + V_{d+1}(W'_k, I50B'_k) ] - price x a - event cost x (a > 0)

so day d's amount is chosen before day d's weather is known to it, each day's weather drawn from the
continuations' weather of that day (independently of the day before: the weather generator's own memory is
one day). What the state leaves out is averaged too: thermal time (each continuation's own on day d) and the
crop's end (a continuation whose crop has matured adds nothing after).

- The continuations, the known weather, the crop's true state, the quota left and the daily decision are
  :class:`experiments.planners_hindsight.FamilyHindsightPolicy`'s (a subclass: only the re-plan
  differs); the tables are one (a single "guess") instead of one per continuation.
- The senescence state is stored as an offset over a baseline common to the continuations (each day's least
  heat increment among them), so that one table serves them all; each continuation adds its own heat excess
  to the day's shift of the offset.
- The quota's multiplier: of the same grid (7, then 10 between the best's neighbours, on coarser
  programmes), the one whose policy (each day's amount best by these values) returns most on average when
  run on each continuation from the crop's true state: an evaluation of a causal policy, not a hindsight plan.

    python -m experiments.planners --method expected-value --table T.json --set far-benton
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from crop_agent_ros.policies.family_dp import SeasonProgramme, _forward_plans

from experiments.planners_hindsight import FamilyHindsightPolicy, HindsightSettings, _Guess, _kept
from experiments.planners_mpc import spliced


@dataclass(frozen=True)
class ExpectedSettings(HindsightSettings):
    """:class:`HindsightSettings`' fields, and ``programme_amounts``: the levels of water (0 .. the capacity)
    the programme's days choose among (the daily decision and the multiplier's evaluation try ``amounts``)."""

    programme_amounts: int = 9

    def __post_init__(self) -> None:
        super().__post_init__()
        if int(self.programme_amounts) < 2:
            raise ValueError(f"family expected: programme_amounts must be >= 2, got {self.programme_amounts}")


class ExpectedProgramme:
    """One value table per day over the soil water (mm) x senescence offset (degC d) grid of ``programmes``
    (:class:`SeasonProgramme` of one field on each continuation's weather, same grid steps), the day's weather
    drawn from the continuations (module docstring). After construction each programme's water grid and
    baseline are the common ones, so that :func:`family_dp._forward_plans` and a lookup on any of them read
    these tables."""

    def __init__(self, programmes: list[SeasonProgramme], amounts: int):
        self.programmes = programmes
        water = max((p.water for p in programmes), key=len)
        heat = np.min([p.heat_increment for p in programmes], axis=0)
        self.heat_increment = heat  # the common baseline's daily increment (degC d)
        base = programmes[0].p["i50b_degc_d"] + np.concatenate([[0.0, 0.0], np.cumsum(heat)[:-1]])
        for p in programmes:
            p.water, p.base_i50b = water, base
        self.water, self.offsets = water, programmes[0].offsets
        self.last_growth_day = max(p.last_growth_day for p in programmes)
        self.amounts = programmes[0].cap * np.linspace(0.0, 1.0, int(amounts))
        self.event = programmes[0].problem.event_cost

    def _day_terms(self, d: int, kept: dict | None) -> list:
        """For each continuation growing on day d: (growth value (nW, A, nO) of each grid state and amount,
        tomorrow's W (nW, A), the offset's shift (nW,), whether it still grows tomorrow); kept across prices."""
        if kept is not None and d in kept:
            return kept[d]
        terms = []
        for p in self.programmes:
            if d > p.last_growth_day:
                continue
            fsolar, extra = p._state_terms(d)
            shift = extra + p.heat_increment[d - 1] - self.heat_increment[d - 1]
            next_w, transpiration = p._forward(self.water[:, None], self.amounts[None, :], d)
            factor = np.minimum(p.f_heat[d], p._f_water(transpiration, d))
            gain = p.value_per_kg * p.growth_scale[d] * fsolar[:, None, :] * factor[:, :, None]
            terms.append((gain, next_w, shift, d + 1 <= p.last_growth_day))
        if kept is not None:
            kept[d] = terms
        return terms

    def value_tables(self, prices_per_mm, first_day: int, day_terms: dict | None = None) -> list:
        """For M prices per mm: the value tables (M, nW, nO) of days first_day (>= 1) .. last growth day + 1
        (the others None); ``day_terms`` as :meth:`SeasonProgramme.value_tables`'."""
        prices = np.atleast_1d(np.asarray(prices_per_mm, dtype=float))
        last = self.last_growth_day
        tables: list = [None] * max(last + 2, first_day + 1)
        tables[last + 1] = np.zeros((len(prices), len(self.water), len(self.offsets)))
        charge = prices[:, None] * self.amounts[None, :] + self.event * (self.amounts > 0.0)[None, :]  # (M, A)
        lookup = self.programmes[0]._lookup_shifted
        for d in range(last, max(first_day, 1) - 1, -1):
            terms = self._day_terms(d, day_terms)
            total = 0.0
            for gain, next_w, shift, grows_tomorrow in terms:
                total = total + gain[None]
                if grows_tomorrow:
                    total = total + lookup(tables[d + 1], next_w, shift, False)
            tables[d] = (total / len(terms) - charge[:, None, :, None]).max(axis=2)
        return tables


class FamilyExpectedPolicy(FamilyHindsightPolicy):
    """The module docstring's controller."""

    name = "family-expected"

    def __init__(self, constants, pools, settings: ExpectedSettings = ExpectedSettings(), align: str = "day-of-year"):
        super().__init__(constants, pools, settings, align)

    def _programme(self, problems: list, water_step_mm: float, offset_step_degc_d: float) -> ExpectedProgramme:
        return ExpectedProgramme([SeasonProgramme(p, water_step_mm, offset_step_degc_d) for p in problems],
                                 self.settings.programme_amounts)

    def _replan(self, i: int, day: int) -> None:
        began = time.process_time()
        s = self.settings
        truth = self.problems[i]
        problems = [replace(truth, context=spliced(truth.context, continuation, day + 1, self.align))
                    for continuation in self.field_pools[i]]
        fine = self._programme(problems, s.water_step_mm, s.offset_step_degc_d)
        search = fine if s.search_water_step_mm is None else self._programme(
            problems, s.search_water_step_mm, s.search_offset_step_degc_d)
        day_terms: dict = {}  # the search programme's, shared by its two calls
        multiplier = self._search_multiplier(
            i, lambda multipliers: self._best_policy(search, i, day, multipliers, day_terms))[0]
        tables = fine.value_tables([truth.water_cost_per_mm + multiplier], first_day=day + 1)
        self.guesses[i] = [_Guess(fine.programmes[0], multiplier, _kept(tables, day + s.decision_every_days + 1))]
        self.decisions += 1
        self.planning_cpu_s += time.process_time() - began

    def _best_policy(self, programme: ExpectedProgramme, i: int, day: int, multipliers: np.ndarray,
                     day_terms: dict) -> tuple[float, float, None]:
        """Of ``multipliers``, the one whose policy returns most to go from field ``i``'s state on ``day``, on
        average over the continuations (each run on one continuation's weather, within the quota left):
        (multiplier, mean return to go, None)."""
        prices = self.problems[i].water_cost_per_mm + multipliers
        tables = programme.value_tables(prices, first_day=day + 1, day_terms=day_terms)
        returns = np.mean([_forward_plans(p, tables, prices, self.settings.amounts, first_day=day,
                                          state=self.states[i], quota_left_mm=self._quota_left_mm(i, day))[1]
                           for p in programme.programmes], axis=0)
        best = int(np.argmax(returns))
        return float(multipliers[best]), float(returns[best]), None
