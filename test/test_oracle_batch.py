"""The oracle's batched search: the same schedules and returns as the one-season search it replaced, and
the batched evaluator against the plain whole-season simulation (``schedule_returns``)."""

from dataclasses import fields, replace

import numpy as np
import pytest

from crop_agent_ros.policies.base import SeasonContext
from crop_sim_ros.model import Management, field_parameters, repeat_parameters, stack_parameters, zhao2019_library


def short_season(name: str, days: int, harvest_day: int) -> SeasonContext:
    """The first ``days`` days of a real season, harvested on ``harvest_day`` (a quick search)."""
    from crop_agent_ros.policies.rollout import season_contexts
    full = season_contexts(name)[0]
    params = replace(full.params, harvest_day=np.array([float(harvest_day)]))
    return SeasonContext(f"{name}-short", params, full.tmax_degc[:days], full.tmin_degc[:days],
                         full.srad_mj_m2[:days], full.rain_mm[:days], full.et0_mm[:days], full.water_cost_per_mm)


@pytest.fixture(scope="module")
def seasons():
    return [short_season("benton-2000", 70, 60), short_season("paterson-1992", 64, 50)]


# Found by the one-season search this batched search replaced (commit 248d31e, finest step 1 mm), on the
# seasons of the fixture: return t/ha, water mm, rounds, candidates scored.
BEFORE = {"benton-2000-short": (2.0542017449894026, 175.27467883028294, 5, 1426),
          "paterson-1992-short": (2.229894282760541, 150.6194061736096, 6, 1319)}


def test_batched_search_finds_what_the_one_season_search_found(seasons):
    from crop_agent_ros.policies.oracle import find_best_schedule, find_best_schedules
    side_by_side = find_best_schedules(seasons, finest_step_mm=1.0)
    for context, result in zip(seasons, side_by_side):
        expected_return, expected_water, rounds, evaluations = BEFORE[context.name]
        assert result.return_value == pytest.approx(expected_return, rel=1e-9)
        assert result.water_mm == pytest.approx(expected_water, rel=1e-9)
        assert (result.rounds, result.evaluations) == (rounds, evaluations)
        # alone or side by side with another season: the same result, bit for bit
        alone = find_best_schedule(context, finest_step_mm=1.0)
        assert alone.return_value == result.return_value
        np.testing.assert_array_equal(alone.schedule_mm, result.schedule_mm)


def candidates_around(base: np.ndarray, rng: np.random.Generator, count: int) -> np.ndarray:
    """Columns: the base, then copies changed on one or two random days (some equal to the base)."""
    days = base.size
    out = np.repeat(base[:, None], count, axis=1)
    for c in range(1, count):
        for day in rng.integers(0, days, size=rng.integers(1, 3)):
            out[day, c] = max(0.0, out[day, c] + rng.choice([-8.0, -1.0, 0.0, 2.0, 16.0]))
    return out


def test_batched_evaluator_scores_like_whole_season_runs(seasons):
    from crop_agent_ros.policies.oracle import _evaluate, _Request, schedule_returns
    rng = np.random.default_rng(7)
    requests = []
    for context in seasons:
        days = len(context.rain_mm)
        base = np.where(rng.random(days) < 0.4, rng.uniform(0.0, 20.0, days), 0.0)
        requests.append(_Request(context, candidates_around(base, rng, 60), record=True))
    # two seasons of different lengths in one batch, each against its own whole-season runs
    scored = _evaluate(requests)
    for request, evaluation in zip(requests, scored):
        expected, run = schedule_returns(request.context, request.schedules_mm)
        np.testing.assert_array_equal(evaluation.returns, expected)
        np.testing.assert_array_equal(evaluation.maturity_day, run.final_state.maturity_day)
        np.testing.assert_array_equal(evaluation.biomass_kg_ha, run.final_state.biomass_kg_ha)
    # columns started from a recorded trajectory on the first day they leave it
    follow_ups = [_Request(r.context, candidates_around(r.schedules_mm[:, 0], rng, 20)[:, 1:], base=e.trajectory)
                  for r, e in zip(requests, scored)]
    for request, evaluation in zip(follow_ups, _evaluate(follow_ups)):
        np.testing.assert_array_equal(evaluation.returns, schedule_returns(request.context, request.schedules_mm)[0])


def test_repeat_parameters_tiles_the_batch_like_stacking_copies():
    library = zhao2019_library()
    one = field_parameters(library.species("potato"), library.cultivar("potato", "Russet Burbank"),
                           library.soil("Benton USA potato"), Management(co2_ppm=369.0))
    two = stack_parameters([one, replace(one, root_zone_depth_mm=np.array([900.0]),
                                         initial_paw_mm=np.array([50.0]))])
    for params, n in ((one, 1), (one, 5), (two, 3)):
        repeated = repeat_parameters(params, n)
        stacked = stack_parameters([params] * n)  # the previous definition
        for f in fields(repeated):
            value = getattr(repeated, f.name)
            assert value.dtype == getattr(stacked, f.name).dtype
            np.testing.assert_array_equal(value, getattr(stacked, f.name), err_msg=f.name)
    # written out: the whole two-field batch, three times in order
    np.testing.assert_array_equal(repeat_parameters(two, 3).root_zone_depth_mm, [1200.0, 900.0] * 3)
    with pytest.raises(ValueError, match="n_fields >= 1"):
        repeat_parameters(one, 0)
