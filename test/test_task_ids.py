"""One name per task: the Gymnasium id derived from the task name by one rule (and back), every built-in task
registered with ``max_episode_steps``, and episodes that end by it (``gymnasium.make`` and ``make_vec``)."""

from dataclasses import replace
from datetime import date

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import parse_env_id
from gymnasium.wrappers import TimeLimit

import crop_sim_ros.task.env as env_module
import crop_sim_ros.task.scenario as scenario_module
from crop_sim_ros.task import IrrigationVectorEnv, get_scenario, gym_id, scenario_names, task_name
from crop_sim_ros.weather.generator import climate_parameters, generate_seasons
from scenario_pools import small_pool_loader

NAMES = scenario_names()
POOL_SEASONS = 3  # generated seasons per weather source in the episode tests (the registered pools hold 1,000+)


def test_the_rule_round_trips_for_every_built_in_task_and_gymnasium_parses_the_id():
    assert len(NAMES) >= 40
    for name in NAMES:
        env_id = gym_id(name)
        assert env_id == f"crop-sim/{name}-v0" and task_name(env_id) == name
        assert parse_env_id(env_id) == ("crop-sim", name, 0)  # gymnasium's id regex reads the name back whole


@pytest.mark.parametrize("bad", ["benton-quota", "crop-sim/benton-quota", "crop-sim/benton-quota-v1",
                                 "crop-sim/atlantis-v0", "SimpleIrrigation-Quota-v0", "other/benton-quota-v0", "", 7])
def test_an_id_the_rule_does_not_make_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match=f"^{bad!r} is not the id of a built-in task "):
        task_name(bad)


@pytest.mark.parametrize("bad", ["atlantis", "crop-sim/benton-quota-v0", "benton-quota.yaml", ""])
def test_a_name_that_is_no_built_in_task_has_no_id(bad):
    with pytest.raises(ValueError, match=f"^{bad!r} is not a built-in task; known: benton-2000, "):
        gym_id(bad)


def test_every_built_in_task_is_registered_with_its_longest_season_as_max_episode_steps():
    registered = {env_id for env_id in gym.registry if env_id.startswith("crop-sim/")}
    assert registered == {gym_id(name) for name in NAMES}
    for name in NAMES:
        spec = gym.spec(gym_id(name))
        scenario = get_scenario(name)  # the Scenario object (no weather loaded): a second reading of the files
        parts = [get_scenario(part) for part in scenario.weather.mixture]
        longest = max(s.max_season_days for s in [scenario, *parts])
        assert spec.max_episode_steps == longest == 200, name
        assert spec.kwargs == {"scenario": name}
        assert spec.vector_entry_point == "crop_sim_ros.task.vector_env:IrrigationVectorEnv"


@pytest.fixture
def small_pools(monkeypatch):
    """Every scenario the environments load, with its generated pools cut to POOL_SEASONS seasons."""
    get_small = small_pool_loader(POOL_SEASONS)
    monkeypatch.setattr(scenario_module, "get_scenario", get_small)  # a mixture's parts
    monkeypatch.setattr(env_module, "get_scenario", get_small)
    monkeypatch.setattr("crop_sim_ros.task.vector_env.get_scenario", get_small)


@pytest.mark.usefixtures("shared_data", "small_pools")
@pytest.mark.parametrize("name", NAMES)
def test_every_registered_id_makes_an_env_whose_episodes_end_by_max_episode_steps(name):
    limit = gym.spec(gym_id(name)).max_episode_steps
    env = gym.make(gym_id(name))
    assert isinstance(env, TimeLimit) and env._max_episode_steps == limit
    assert int(env.unwrapped.seasons.n_days.max()) <= limit  # no season is longer than the limit
    for seed in range(2):
        env.reset(seed=seed)
        for step in range(1, limit + 1):
            *_, terminated, truncated, _ = env.step(np.array([0.0], np.float32))  # rainfed
            if terminated or truncated:
                break
        assert terminated or truncated, (name, seed)
    vector = gym.make_vec(gym_id(name), num_envs=2)
    assert isinstance(vector.unwrapped, IrrigationVectorEnv) and vector.unwrapped.max_episode_steps == limit
    vector.reset(seed=0)
    ended = np.zeros(2, bool)
    for _ in range(limit):
        *_, terminations, truncations, _ = vector.step(np.zeros(2))
        ended |= terminations | truncations
    assert ended.all(), name


def cold_season(days: int):
    """A generated Benton season of ``days`` days from April 1, made too cold (TMAX 3 degC, TMIN -1 degC) for the
    potato to accumulate thermal time: it never matures."""
    (series,) = generate_seasons(climate_parameters("benton"), date(2001, 4, 1), days, 1, 0)
    return replace(series, tmax_degc=np.full(days, 3.0), tmin_degc=np.full(days, -1.0), tavg_degc=np.full(days, 1.0))


def test_a_season_that_never_matures_is_truncated_at_max_episode_steps():
    cold = cold_season(260)  # longer than the limit: the scenario keeps its first 200 days
    env = gym.make("crop-sim/benton-quota-v0")
    env.reset(seed=0, options={"weather": cold})
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated):
        *_, terminated, truncated, info = env.step(np.array([2.0], np.float32))
        steps += 1
    assert (steps, terminated, truncated, info["mature"]) == (200, False, True, False)
    vector = gym.make_vec("crop-sim/benton-quota-v0", num_envs=2)
    vector.reset(seed=0, options={"weathers": [cold, cold]})
    for day in range(1, 201):
        *_, terminations, truncations, _ = vector.step(np.full(2, 2.0))
        assert not terminations.any() and truncations.all() == (day == 200) and not (truncations.any() and day < 200)


def test_the_vector_env_truncates_at_a_given_max_episode_steps_and_autoresets():
    vector = gym.make_vec("crop-sim/benton-generated-v0", num_envs=3, max_episode_steps=5)
    assert vector.unwrapped.max_episode_steps == 5
    vector.reset(seed=0)
    for day in range(1, 6):
        *_, terminations, truncations, infos = vector.step(np.full(3, 4.0))
        assert not terminations.any() and list(infos["day"]) == [day] * 3
    assert truncations.all()
    *_, truncations, infos = vector.step(np.full(3, 4.0))  # NEXT_STEP autoreset: back to the sowing day
    assert not truncations.any() and list(infos["day"]) == [0, 0, 0]
    with pytest.raises(ValueError, match="max_episode_steps must be a whole number of days >= 1 or None, got 0"):
        IrrigationVectorEnv(2, "benton-generated", max_episode_steps=0)
