"""The environments refuse what they cannot mean (issue 34, section 5): a season that is not a whole number
(1.7, "3", True became seasons 1, 3 and 1), a weather that is not a WeatherSeries (an AttributeError), unknown
option keys, and vector actions of another shape than one per field ((2, 4) for 8 fields was reshaped)."""

import numpy as np
import pytest

from crop_sim_ros.task import IrrigationEnv, IrrigationVectorEnv


@pytest.fixture(scope="module")
def env():
    return IrrigationEnv("benton-generated")


@pytest.fixture(scope="module")
def vector_env():
    return IrrigationVectorEnv(8, "benton-generated", noise_thread=False)


@pytest.mark.parametrize("season", [1.7, "3", True, np.float64(2.0), np.bool_(True), object])
def test_a_season_that_is_not_a_whole_number_is_refused(env, season):
    with pytest.raises(TypeError, match=r"^season: expected a whole number"):
        env.reset(seed=0, options={"season": season})


@pytest.mark.parametrize("season", [-1, 1000, 2**70, [1]])
def test_a_season_outside_the_pool_is_refused(env, season):
    with pytest.raises((ValueError, TypeError), match=r"^season: "):
        env.reset(seed=0, options={"season": season})


@pytest.mark.parametrize("season", [3, np.int64(3), np.uint8(3)])
def test_whole_number_seasons_are_accepted(env, season):
    _, info = env.reset(seed=0, options={"season": season})
    assert info["season"] == 3


@pytest.mark.parametrize("options, error, message", [
    ({"weather": "x"}, TypeError, r"^weather: expected a WeatherSeries, got str$"),
    ({"weather": 5}, TypeError, r"^weather: expected a WeatherSeries, got int$"),
    ({"seasons": 3}, ValueError, r"^unknown reset options \['seasons'\]; known: weather, season$"),
    ({1: 2, "a": 3}, ValueError, r"^unknown reset options \[1, 'a'\]"),  # keys that do not sort: still one line
    ([("season", 3)], TypeError, r"^reset options must be a dict, got list$"),
])
def test_bad_reset_options_are_refused_by_name(env, options, error, message):
    with pytest.raises(error, match=message):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("shape", [(2, 4), (8, 2), (1, 8), (4,), (16,), ()])
def test_vector_actions_of_another_shape_are_refused(vector_env, shape):
    vector_env.reset(seed=0)
    with pytest.raises(ValueError, match=r"one irrigation amount per field: shape \(8,\) or \(8, 1\), got"):
        vector_env.step(np.full(shape, 3.0))


@pytest.mark.parametrize("shape", [(8,), (8, 1)])
def test_vector_actions_of_one_value_per_field_are_taken(vector_env, shape):
    vector_env.reset(seed=0)
    _, _, _, _, infos = vector_env.step(np.full(shape, 3.0))
    np.testing.assert_array_equal(infos["irrigation_requested_mm"], np.full(8, 3.0))


@pytest.mark.parametrize("options, error, message", [
    ({"season": 1.7}, TypeError, r"^season: expected a whole number"),
    ({"season": [True] * 8}, TypeError, r"^season: expected a whole number"),
    ({"season": np.arange(3)}, ValueError, r"^season: expected one index or an array of shape \(8,\), got shape "
                                           r"\(3,\)"),
    ({"season": np.full(8, 5000)}, ValueError, r"^season: indices must be in 0\.\.999$"),
    ({"weathers": "x" * 8}, TypeError, r"^weathers: expected a list of 8 WeatherSeries, got str$"),
    ({"weathers": ["x"] * 8}, TypeError, r"^weathers\[\]: expected a WeatherSeries, got str$"),
    ({"terms": [1, 2]}, TypeError, r"^terms: expected a dict"),
    ({"field": 1}, ValueError, r"^unknown reset options \['field'\]; known: weathers, season, terms$"),
])
def test_vector_reset_options_are_checked(vector_env, options, error, message):
    with pytest.raises(error, match=message):
        vector_env.reset(seed=0, options=options)


def test_vector_seasons_as_one_index_or_one_per_field(vector_env):
    vector_env.reset(seed=0, options={"season": 4})
    assert vector_env.field_seasons.tolist() == [4] * 8
    vector_env.reset(seed=0, options={"season": np.arange(8, dtype=np.int32)})
    assert vector_env.field_seasons.tolist() == list(range(8))
