"""Every size a user sets has an upper bound, refused at once with the field's name (a typo must not run for
half a minute and end in a MemoryError)."""

import math

import pytest
import yaml

from crop_sim_ros.task.scenario import (MAX_GENERATED_DAYS, MAX_GENERATED_SEASONS, MAX_SEASON_DAYS, SCENARIO_DIR,
                                        scenario_from_dict)


def generated(**changes) -> dict:
    values = yaml.safe_load((SCENARIO_DIR / "benton-generated.yaml").read_text())
    weather = {**values["weather"], **changes.pop("weather", {})}
    return {**values, **changes, "weather": weather}


def test_the_bounds_are_the_documented_ones():
    assert (MAX_SEASON_DAYS, MAX_GENERATED_SEASONS, MAX_GENERATED_DAYS) == (730, 10_000, 2_000_000)


@pytest.mark.parametrize("days", [20000, MAX_SEASON_DAYS + 1, 0, -5, 2.5, math.inf, math.nan, "200", True])
def test_max_season_days_out_of_bounds_is_refused(days):
    with pytest.raises(ValueError, match=r"^max_season_days: .* is not a whole number in 1\.\.730$"):
        scenario_from_dict(generated(max_season_days=days))


@pytest.mark.parametrize("n", [10**9, MAX_GENERATED_SEASONS + 1, 0, math.inf, "many"])
def test_generator_season_count_out_of_bounds_is_refused(n):
    with pytest.raises(ValueError, match=r"^weather\.n_seasons: .* is not a whole number in 1\.\.10000$"):
        scenario_from_dict(generated(weather={"n_seasons": n}))


def test_generated_days_are_bounded_as_a_product():
    # each size within its own bound, the product over 2,000,000 season-days
    with pytest.raises(ValueError, match=r"^weather\.n_seasons x max_season_days: 10000 x 201 days is over"):
        scenario_from_dict(generated(weather={"n_seasons": 10_000}, max_season_days=201))


def test_sizes_at_their_bounds_are_accepted():
    assert scenario_from_dict(generated(max_season_days=MAX_SEASON_DAYS, weather={"n_seasons": 2000})).max_season_days == 730
    assert scenario_from_dict(generated(weather={"n_seasons": 10_000}, max_season_days=200)).n_seasons == 10_000


@pytest.mark.parametrize("argv, message", [
    (["train", "--task", "benton-quota", "--algorithm", "ppo", "--hyperparams", "timesteps=0"],
     "hyperparameter timesteps 0: Input should be greater than or equal to 1"),
    (["train", "--task", "benton-quota", "--algorithm", "es", "--hyperparams", "timesteps=10000000000"],
     "hyperparameter timesteps 10000000000: Input should be less than or equal to 1000000000"),
    (["train", "--task", "benton-quota", "--algorithm", "ppo", "--hyperparams", "n_envs=10000000"],
     "hyperparameter n_envs 10000000: Input should be less than or equal to 100000"),
])
def test_training_sizes_have_upper_bounds(argv, message, capsys):
    from crop_agent_ros.cli import main
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_vector_env_fields_have_an_upper_bound():
    from crop_sim_ros.task import IrrigationVectorEnv
    with pytest.raises(ValueError, match=r"num_envs must be in 1..1,000,000"):
        IrrigationVectorEnv(2_000_000)
