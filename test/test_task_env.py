"""The Gymnasium environment, its vectorised form and the Stable-Baselines3 adapter."""

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from crop_sim_ros.task import (STATE_INFO_KEYS, STEP_INFO_KEYS, IrrigationEnv, IrrigationVectorEnv, ObservationNoise,
                               get_scenario)
from crop_sim_ros.task import core
from crop_sim_ros.weather import read_agweathernet_csv
from simple_reference import reference_of_table_season

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
BENTON_FILE = DATA / "agweathernet" / "benton_e_2000-04-01_2000-09-30.csv"
needs_data = pytest.mark.usefixtures("shared_data")  # fails, never skips, without the data
COST_PER_MM = -1.25e-4  # the paper's C_I, t/ha per mm
RUSSET_BURBANK_HARVEST_INDEX = 0.90


def noise_free(name: str):
    return replace(get_scenario(name, DATA), noise=ObservationNoise.none())


def run(env, seed, actions, options=None):
    obs, info = env.reset(seed=seed, options=options)
    trace = [(obs, None, False, False, info)]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(np.array([action], dtype=np.float32))
        trace.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            break
    return trace


def test_gymnasium_check_env_passes():
    from gymnasium.utils.env_checker import check_env

    check_env(IrrigationEnv(), skip_render_check=True)


def test_sb3_check_env_passes():
    from stable_baselines3.common.env_checker import check_env

    check_env(IrrigationEnv(), warn=False)


def test_registered_ids_make_the_environment():
    env = gym.make("crop-sim/benton-generated-v0")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and env.action_space.shape == (1,)
    vector = gym.make_vec("crop-sim/benton-generated-v0", num_envs=3)
    assert isinstance(vector.unwrapped, IrrigationVectorEnv)
    assert vector.reset(seed=0)[0].shape == (3, 20)


def test_same_seed_same_actions_same_episode_bit_for_bit():
    actions = np.linspace(0, 20, 200)
    first = run(IrrigationEnv(), 7, actions)
    second = run(IrrigationEnv(), 7, actions)
    assert len(first) == len(second)
    for a, b in zip(first, second):
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:4] == b[1:4] and a[4] == b[4]
    other = run(IrrigationEnv(), 8, actions)
    assert not np.array_equal(first[0][0], other[0][0])


def test_reset_seed_reseeds_the_noise_not_construction():
    env = IrrigationEnv()
    first = run(env, 3, [1.0] * 5)
    run(env, 4, [1.0] * 5)
    again = run(env, 3, [1.0] * 5)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a[0], b[0])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_irrigation_raises(bad):
    env = IrrigationEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([bad], dtype=np.float32))
    env.step(np.array([1.0], dtype=np.float32))  # the state is still valid


@pytest.mark.parametrize("requested, applied", [(-5.0, 0.0), (150.0, 100.0), (40.0, 40.0)])
def test_out_of_range_irrigation_is_clipped_and_flagged(requested, applied):
    env = IrrigationEnv()
    env.reset(seed=0)
    *_, info = env.step(np.array([requested], dtype=np.float32))
    assert info["irrigation_applied_mm"] == applied
    assert info["irrigation_requested_mm"] == requested
    assert info["irrigation_clipped"] == (requested != applied)


def test_step_before_reset_and_after_the_end_raise():
    env = IrrigationEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.array([0.0], dtype=np.float32))
    trace = run(env, 0, [5.0] * 400)
    assert trace[-1][2] or trace[-1][3]
    with pytest.raises(RuntimeError, match="ended"):
        env.step(np.array([0.0], dtype=np.float32))


def test_info_keys_are_the_documented_ones():
    env = IrrigationEnv()
    _, info = env.reset(seed=0)
    assert set(info) == set(STATE_INFO_KEYS)
    *_, info = env.step(np.array([1.0], dtype=np.float32))
    assert set(info) == set(STATE_INFO_KEYS) | set(STEP_INFO_KEYS)


@needs_data
def test_terminated_at_maturity_truncated_when_the_weather_runs_out():
    env = IrrigationEnv(noise_free("benton-2000"))
    trace = run(env, 0, [5.0] * 400)
    obs, reward, terminated, truncated, info = trace[-1]
    assert terminated and not truncated and info["mature"] and len(trace) - 1 < 183
    short = read_agweathernet_csv(BENTON_FILE).window("2000-04-01", 30)
    trace = run(env, 0, [5.0] * 400, options={"weather": short})
    obs, reward, terminated, truncated, info = trace[-1]
    assert truncated and not terminated and not info["mature"] and info["day"] == 30 and len(trace) - 1 == 30
    assert reward == pytest.approx(-1.25e-4 * 5.0)  # no harvest when truncated
    assert info["season"] == -1 and info["weather_source"] == str(BENTON_FILE)


@needs_data
def test_observation_without_noise_matches_the_true_state_in_info():
    env = IrrigationEnv(noise_free("benton-2000"))
    for obs, _, _, _, info in run(env, 0, [3.0] * 60):
        assert obs[0] == np.float32(info["true_biomass_t_ha"])
        assert obs[19] == np.float32(info["true_paw_mm"])
        assert obs[1] == np.float32(info["thermal_time_degc_d"]) and obs[2] == info["day"]
        assert obs[8] == 369.0 and obs[5] == pytest.approx((obs[3] + obs[4]) / 2, abs=1e-5)


@needs_data
def test_reward_on_harvest_day_is_cost_plus_yield():
    env = IrrigationEnv(get_scenario("benton-2000", DATA))
    trace = run(env, 0, [7.0] * 400)
    _, reward, terminated, _, info = trace[-1]
    assert terminated
    assert reward == pytest.approx(COST_PER_MM * 7.0 + info["yield_t_ha"], rel=1e-12)
    # t/ha of dry potato, as the spec's equations give it (test/simple_reference.py), on its maturity day
    expected = reference_of_table_season(core.scenario_table(env.scenario), core.WEATHER_NAMES, 0, 7.0,
                                         co2_ppm=369.0)
    assert info["day"] == expected.maturity_day + 1
    assert info["yield_t_ha"] == pytest.approx(expected.yield_kg_ha / 1000, rel=1e-9)
    rewards = [t[1] for t in trace[1:]]
    assert info["episode_return"] == pytest.approx(sum(rewards))
    assert info["normalized_return"] == pytest.approx(sum(rewards) / info["potential_yield_t_ha"])
    assert 0.9 < info["normalized_return"] <= 1.0


@needs_data
def test_reset_options_pick_a_season():
    env = IrrigationEnv("heldout", DATA)
    dates = [env.reset(seed=0, options={"season": k})[1]["date"] for k in range(5)]
    assert dates == ["2000-04-01", "1992-04-11", "1993-04-06", "1994-04-05", "1995-04-05"]
    _, info = env.reset(options={"season": 1})
    assert any("wind_m_s" in fill for fill in info["weather_filled"])
    with pytest.raises(ValueError, match="season"):
        env.reset(options={"season": 5})


# --- vectorised ------------------------------------------------------------------------------------------

@needs_data
def test_vector_env_equals_single_envs_on_the_same_seasons():
    scenario = noise_free("heldout")
    n = 5
    actions = np.random.default_rng(0).uniform(-5, 120, size=(200, n))
    vector = IrrigationVectorEnv(n, scenario)
    obs, infos = vector.reset(seed=0, options={"season": np.arange(n)})
    singles = [IrrigationEnv(scenario) for _ in range(n)]
    single_obs = [env.reset(seed=0, options={"season": k})[0] for k, env in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack(single_obs))
    running = np.ones(n, dtype=bool)
    for day in range(200):
        obs, rewards, terminated, truncated, infos = vector.step(actions[day])
        for k in np.flatnonzero(running):
            o, r, te, tr, info = singles[k].step(actions[day, k:k + 1])
            np.testing.assert_array_equal(obs[k], o)
            assert (rewards[k], terminated[k], truncated[k]) == (r, te, tr)
            for key in ("true_biomass_t_ha", "true_paw_mm", "irrigation_applied_mm", "irrigation_clipped",
                        "rain_mm", "runoff_mm", "drainage_mm", "transpiration_mm", "et0_mm", "yield_t_ha",
                        "episode_return", "normalized_return"):
                assert infos[key][k] == info[key], key
            running[k] = not (te or tr)
        if not running.any():
            break
    assert not running.any()


WEATHER_ORDER = ("tmax_degc", "tmin_degc", "tavg_degc", "rain_mm", "srad_mj_m2", "co2_ppm", "vap_hpa", "wind_m_s")


def documented_weather(series, day: int) -> list[float]:
    """The 8 weather values of ``day`` in the documented order (TAVG as (TMAX + TMIN) / 2, CO2 369 ppm)."""
    values = {name: getattr(series, name)[day] for name in ("tmax_degc", "tmin_degc", "rain_mm", "srad_mj_m2",
                                                             "vap_hpa", "wind_m_s")}
    values.update(tavg_degc=(values["tmax_degc"] + values["tmin_degc"]) / 2, co2_ppm=369.0)
    return [values[name] for name in WEATHER_ORDER]


@needs_data
def test_observation_order_is_the_documented_one_in_both_environments():
    """Index by index against the weather file read on its own: biomass, TT, day, today's 8, tomorrow's 8,
    PAW (README "Observation")."""
    observed = read_agweathernet_csv(BENTON_FILE)
    scenario = noise_free("benton-2000")
    single, vector = IrrigationEnv(scenario), IrrigationVectorEnv(1, scenario)
    obs, info = single.reset(seed=0)
    vector_obs, _ = vector.reset(seed=0, options={"season": 0})
    for day in range(40):
        np.testing.assert_array_equal(vector_obs[0], obs)
        assert obs[2] == day == info["day"]
        assert obs[0] == np.float32(info["true_biomass_t_ha"]) and obs[1] == np.float32(info["thermal_time_degc_d"])
        np.testing.assert_array_equal(obs[3:11], np.float32(documented_weather(observed, day)))
        np.testing.assert_array_equal(obs[11:19], np.float32(documented_weather(observed, day + 1)))
        assert obs[19] == np.float32(info["true_paw_mm"])
        obs, _, _, _, info = single.step(np.array([3.0], dtype=np.float32))
        vector_obs = vector.step(np.array([3.0]))[0]


@needs_data
def test_vector_env_on_truncated_seasons_pays_no_yield_and_equals_single_envs():
    """Seasons cut at 30, 45 and 60 days end truncated; the truncating step pays the water cost only
    (no yield: the crop is not harvested), in the vector environment as in the single one."""
    scenario = noise_free("benton-2000")
    weather = read_agweathernet_csv(BENTON_FILE)
    lengths = (30, 45, 60)
    short = [weather.window("2000-04-01", n) for n in lengths]
    actions = np.random.default_rng(1).uniform(0, 20, size=(max(lengths), len(lengths)))
    vector = IrrigationVectorEnv(len(lengths), scenario)
    vector.reset(seed=0, options={"weathers": short})
    singles = [IrrigationEnv(scenario) for _ in lengths]
    for env, series in zip(singles, short):
        env.reset(seed=0, options={"weather": series})
    running, ended_on = np.ones(len(lengths), dtype=bool), {}
    for day in range(max(lengths)):
        obs, rewards, terminated, truncated, infos = vector.step(actions[day])
        for k in np.flatnonzero(running):
            o, r, te, tr, info = singles[k].step(actions[day, k:k + 1])
            np.testing.assert_array_equal(obs[k], o)
            assert (rewards[k], terminated[k], truncated[k]) == (r, te, tr)
            for key in ("true_biomass_t_ha", "true_paw_mm", "yield_t_ha", "episode_return", "mature"):
                assert infos[key][k] == info[key], key
            if tr:
                assert not te and not info["mature"]
                assert r == pytest.approx(COST_PER_MM * actions[day, k], rel=1e-12)  # no yield
                ended_on[k] = info["day"]
                running[k] = False
            else:
                assert not te and r == pytest.approx(COST_PER_MM * actions[day, k], rel=1e-12)
    assert ended_on == dict(enumerate(lengths))


@needs_data
def test_vector_env_given_weathers_and_autoreset_next_step():
    scenario = noise_free("benton-2000")
    short = read_agweathernet_csv(BENTON_FILE).window("2000-04-01", 10)
    vector = IrrigationVectorEnv(2, scenario)
    vector.reset(seed=0, options={"weathers": [short, short.window("2000-04-01", 5)]})
    for day in range(5):
        obs, rewards, terminated, truncated, infos = vector.step(np.zeros(2))
    assert truncated.tolist() == [False, True] and infos["day"].tolist() == [5, 5]
    obs, rewards, terminated, truncated, infos = vector.step(np.array([0.0, 50.0]))
    # Field 1 restarted on the scenario's season: day 0, reward 0, its action ignored.
    assert infos["day"].tolist() == [6, 0] and rewards[1] == 0.0 and not truncated[1]
    assert infos["_irrigation_applied_mm"].tolist() == [True, False]
    assert infos["season"][1] == 0 and obs[1, 2] == 0


def test_vector_env_same_step_autoreset_keeps_the_final_observation():
    vector = IrrigationVectorEnv(16, "benton-generated", autoreset_mode=AutoresetMode.SAME_STEP)
    vector.reset(seed=1)
    for _ in range(250):
        obs, rewards, terminated, truncated, infos = vector.step(np.full((16, 1), 4.0))
        ended = terminated | truncated
        if ended.any():
            k = np.flatnonzero(ended)[0]
            assert infos["_final_obs"][k] and infos["final_obs"][k, 2] > 100 and obs[k, 2] == 0
            final = infos["final_info"]
            assert final["mature"][k]
            # The ending step itself pays the harvest: yield = HI x biomass, minus the day's water.
            assert rewards[k] == pytest.approx(
                RUSSET_BURBANK_HARVEST_INDEX * final["true_biomass_t_ha"][k] + COST_PER_MM * 4.0, rel=1e-12)
            return
    pytest.fail("no field ended")


def test_vector_env_rejects_non_finite_actions():
    vector = IrrigationVectorEnv(3)
    vector.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        vector.step(np.array([1.0, np.nan, 2.0]))


def test_vector_env_is_deterministic_per_seed():
    def episode(seed):
        vector = IrrigationVectorEnv(4)
        out = [vector.reset(seed=seed)[0]]
        out += [vector.step(np.full(4, 2.0))[0] for _ in range(20)]
        return np.stack(out)

    np.testing.assert_array_equal(episode(5), episode(5))
    assert not np.array_equal(episode(5), episode(6))


def test_sb3_vec_env_runs_and_reports_terminal_observations():
    from crop_sim_ros.task.sb3_vec import make_sb3_vec_env

    venv = make_sb3_vec_env("benton-generated", n_envs=4, seed=0)
    obs = venv.reset()
    assert obs.shape == (4, 20)
    for _ in range(250):
        obs, rewards, dones, infos = venv.step(np.full((4, 1), 4.0, dtype=np.float32))
        if dones.any():
            k = np.flatnonzero(dones)[0]
            assert infos[k]["terminal_observation"].shape == (20,) and obs[k, 2] == 0
            assert "normalized_return" in infos[k] and infos[k]["TimeLimit.truncated"] is False
            return
    pytest.fail("no field ended")


def test_task_layer_imports_neither_torch_nor_rclpy():
    code = ("import sys, crop_sim_ros.task, crop_sim_ros.task.bench; "
            "bad = [m for m in ('torch', 'rclpy', 'crop_agent_ros', 'stable_baselines3') if m in sys.modules]; "
            "print(bad); sys.exit(bool(bad))")
    result = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[1],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_prefetched_noise_is_the_plain_stream_whatever_the_threads():
    from crop_sim_ros.task.vector_env import PrefetchedNormal

    rows = PrefetchedNormal.MIN_ROWS_TO_PREFETCH
    for n in (rows, rows - 1):  # prefetched on the worker thread, and drawn in place
        noise = PrefetchedNormal(7, n, 10)
        plain = np.random.Generator(np.random.SFC64(7))
        first, second = noise.standard_normal((n, 10)), noise.standard_normal((3, 10))  # a partial block
        np.testing.assert_array_equal(first, plain.standard_normal((n, 10), np.float32))
        np.testing.assert_array_equal(second, plain.standard_normal((n, 10), np.float32)[:3])
    with pytest.raises(ValueError, match="noise of shape"):
        noise.standard_normal((n + 1, 10))
