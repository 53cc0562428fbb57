"""The JAX environment (crop_sim_ros.task.jax_env) equals the numpy vector environment on every registered task.

Given the same seasons, terms, actions and observation noise (the numpy environment's noise recorded as it draws
it), whole seasons of a few fields agree in float64: the observation bit for bit (float32, as numpy makes it),
the reward to 1e-12 relative, termination and truncation exactly. The weather pools are cut small as in
test_task_ids.py, and padded to one size so that the tasks of one shape share one compilation (CPU, fast).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

jax = pytest.importorskip("jax")
jnp = pytest.importorskip("jax.numpy")

import crop_sim_ros.task.env as env_module  # noqa: E402
import crop_sim_ros.task.scenario as scenario_module  # noqa: E402
import crop_sim_ros.task.vector_env as vector_module  # noqa: E402
from crop_sim_ros.task import core, gym_id, scenario_names  # noqa: E402
from crop_sim_ros.task.jax_env import EnvParams, JaxIrrigationEnv, make_jax_env, params_of  # noqa: E402
from scenario_pools import small_pool_loader  # noqa: E402

NAMES = scenario_names()
POOL_SEASONS = 3     # generated seasons per weather source (the registered pools hold 1,000+)
FIELDS = 3
DAYS = 200           # every task's longest season (test_task_ids checks max_episode_steps == 200)
POOL_PAD = 40        # seasons of every padded pool (the largest cut pool, a mixture of real seasons, has 39)
REL = 1e-12


@pytest.fixture(scope="module", autouse=True)
def x64():
    """float64 for this module's JAX computations (restored after)."""
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def small_pools():
    """Every scenario with its generated pools cut to POOL_SEASONS seasons."""
    get_small = small_pool_loader(POOL_SEASONS)

    with pytest.MonkeyPatch.context() as patch:
        for target in (scenario_module, env_module, vector_module):
            patch.setattr(target, "get_scenario", get_small)
        patch.setattr("crop_sim_ros.task.jax_env.get_scenario", get_small)
        yield get_small


class RecordingNormal(vector_module.PrefetchedNormal):
    """The vector environment's noise stream, each block it hands out recorded (the same values)."""

    drawn: list[np.ndarray] = []

    def standard_normal(self, shape, dtype=np.float32):
        block = super().standard_normal(shape, dtype)
        RecordingNormal.drawn.append(block.copy())
        return block


def padded(params: EnvParams) -> EnvParams:
    """``params`` with the pool padded to POOL_PAD seasons and 202 days (copies of the last: never reached)."""
    m = params.n_days.shape[0]
    assert m <= POOL_PAD and params.model_weather.shape[2] <= DAYS + 2

    def pad(array, season_axis, day_axis=None, days=0):
        widths = [(0, 0)] * array.ndim
        widths[season_axis] = (0, POOL_PAD - m)
        if day_axis is not None:
            widths[day_axis] = (0, days - array.shape[day_axis])
        return jnp.pad(array, widths, mode="edge")

    return params._replace(observation_rows=pad(params.observation_rows, 0, 1, DAYS + 1),
                           model_weather=pad(params.model_weather, 1, 2, DAYS + 2),
                           et0_mm=pad(params.et0_mm, 0, 1, DAYS + 2), n_days=pad(params.n_days, 0),
                           potential_yield_t_ha=pad(params.potential_yield_t_ha, 0))


def _season(env, season, terms, noise, actions, params):
    """The first observation and, for each day, (obs, reward, terminated, truncated) of fields that never reset."""
    obs, state = jax.vmap(env.reset_with, in_axes=(0, 0, 0, None))(season, terms, noise[0], params)

    def day(state, inputs):
        action, day_noise = inputs
        obs, state, reward, terminated, truncated, _ = jax.vmap(env.step_with, in_axes=(0, 0, 0, None))(
            state, action, day_noise, params)
        return state, (obs, reward, terminated, truncated)

    return obs, jax.lax.scan(day, state, (actions, noise[1:]))[1]


season_run = jax.jit(_season, static_argnums=0)


def numpy_season(name: str, seed: int):
    """A whole season of FIELDS fields of the numpy vector env: its first obs and infos, the actions, the
    (obs, reward, terminated, truncated) of each day, which fields were still in their first season, the noise."""
    RecordingNormal.drawn = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(vector_module, "PrefetchedNormal", RecordingNormal)
        env = vector_module.IrrigationVectorEnv(FIELDS, name, max_episode_steps=DAYS)
        obs0, info = env.reset(seed=seed, options={"season": np.arange(FIELDS) % len(env.seasons)})
        rng = np.random.default_rng(seed)
        # Below 0 and above the bound (clipped), zero, and amounts that exhaust quotas and exceed capacities.
        actions = rng.choice([-3.0, 0.0, 2.5, 7.0, 12.0, 150.0], size=(DAYS, FIELDS))
        days, first_season, ended = [], [], np.zeros(FIELDS, dtype=bool)
        for t in range(DAYS):
            first_season.append(~ended)
            obs, reward, terminated, truncated, _ = env.step(actions[t])
            days.append((obs, reward, terminated, truncated))
            ended |= terminated | truncated
    assert ended.all(), f"{name}: a field's season lasted more than {DAYS} days"
    noise = RecordingNormal.drawn
    columns = env.params.noise_columns
    if env.params.noisy:
        assert len(noise) == DAYS + 1 and noise[0].shape == (FIELDS, columns)
        noise = np.stack(noise)
    else:
        noise = np.zeros((DAYS + 1, FIELDS, columns), np.float32)
    outputs = [np.stack(values) for values in zip(*days)]
    return env, obs0, info, actions, outputs, np.array(first_season), noise


@pytest.mark.usefixtures("shared_data", "small_pools")
@pytest.mark.parametrize("name", NAMES)
def test_every_task_equals_the_numpy_vector_env_over_whole_seasons_given_the_same_noise(name):
    np_env, obs0, info, actions, (obs, reward, terminated, truncated), live, noise = numpy_season(name, seed=7)
    env = make_jax_env(name, table=np_env.seasons)
    params = padded(env.default_params)
    assert params.model_weather.dtype == jnp.float64
    terms = core.EpisodeTerms(*(jnp.asarray(info[key]) for key in core.EpisodeTerms._fields))
    jobs0, (jobs, jreward, jterminated, jtruncated) = season_run(env, jnp.asarray(info["season"]), terms,
                                                                 jnp.asarray(noise), jnp.asarray(actions), params)
    assert jobs0.dtype == np.float32 and jreward.dtype == np.float64
    np.testing.assert_array_equal(np.asarray(jobs0), obs0)
    # Every field's first season, its ending day included (after it the numpy env resets the field).
    np.testing.assert_array_equal(np.asarray(jobs)[live], obs[live])
    np.testing.assert_allclose(np.asarray(jreward)[live], reward[live], rtol=REL, atol=0.0)
    np.testing.assert_array_equal(np.asarray(jterminated)[live], terminated[live])
    np.testing.assert_array_equal(np.asarray(jtruncated)[live], truncated[live])
    assert (terminated | truncated)[live].sum() == FIELDS  # each field's season ended within the run


@pytest.mark.usefixtures("shared_data", "small_pools")
def test_the_gymnax_api_jits_and_vmaps_with_same_step_resets():
    env = make_jax_env("benton-quota")
    params = env.default_params
    n = 64

    @jax.jit
    def seasons(key):
        """n fields reset, then DAYS days of env.step (vmapped) in a scan."""
        keys = jax.random.split(key, n)
        obs, state = jax.vmap(env.reset, in_axes=(0, None))(keys, params)

        def day(carry, key):
            state = carry
            obs, new_state, reward, done, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(key, n), state, jnp.full(n, 6.0), params)
            return new_state, (obs, reward, done, info["terminated"] | info["truncated"],
                               state.crop.days_since_sowing, new_state.crop.days_since_sowing)

        return obs, state, jax.lax.scan(day, state, jax.random.split(key, DAYS))[1]

    obs0, state0, (obs, reward, done, ended, days_before, days_after) = seasons(jax.random.key(0))
    assert obs0.shape == (n, 29) and obs0.dtype == jnp.float32 and state0.crop.biomass_kg_ha.dtype == jnp.float64
    assert bool(jnp.all(state0.crop.days_since_sowing == 0))
    assert bool(jax.vmap(env.observation_space(params).contains)(obs0).all())
    quota = np.asarray(state0.terms.quota_mm)
    assert quota.min() >= env.task.quota_mm.low and quota.max() <= env.task.quota_mm.high and np.ptp(quota) > 0
    assert obs.shape == (DAYS, n, 29) and reward.dtype == jnp.float64
    done, days_before, days_after = np.asarray(done), np.asarray(days_before), np.asarray(days_after)
    assert np.array_equal(done, np.asarray(ended))
    # A field that ended starts a new season on the same step (day 0 in state and observation); the others went
    # on by one day.
    assert (days_after[done] == 0).all() and (np.asarray(obs)[..., 2][done] == 0).all()
    assert (days_after[~done] == days_before[~done] + 1).all()
    returns = np.asarray(reward).sum(axis=0)
    assert done.any(axis=0).all() and np.isfinite(returns).all() and returns.max() > 0  # harvested and paid


@pytest.mark.usefixtures("shared_data", "small_pools")
def test_one_compilation_serves_every_task_of_one_shape():
    a, b = make_jax_env("benton-generated"), make_jax_env("paterson-1993")
    assert a == b and hash(a) == hash(b) and a != make_jax_env("benton-quota")
    traces = []

    def first_reward(env, params):
        traces.append(env.scenario.name)
        obs, state = env.reset(jax.random.key(1), params)
        return env.step(jax.random.key(2), state, 5.0, params)[2]

    run = jax.jit(first_reward, static_argnums=0)
    run(a, padded(a.default_params)), run(b, padded(b.default_params))
    assert traces == ["benton-generated"]


@pytest.mark.parametrize("bad", ["atlantis", "benton-quota.yaml", "", "crop-sim/atlantis-v0", 7])
def test_a_name_that_is_no_registered_task_is_refused(bad):
    with pytest.raises(ValueError, match="is not (a built-in task|the id of a built-in task)"):
        make_jax_env(bad)


def test_the_gymnasium_id_names_the_same_task():
    assert make_jax_env(gym_id("benton-money")).scenario.name == "benton-money"
    assert isinstance(make_jax_env("benton-money"), JaxIrrigationEnv)


@pytest.mark.usefixtures("shared_data", "small_pools")
def test_float32_when_x64_is_off():
    with jax.enable_x64(False):
        env = make_jax_env("benton-capacity")
        params = env.default_params
        noise = jnp.zeros(env.task.noise_columns, jnp.float32)

        @jax.jit
        def first_day(terms):
            obs, state = env.reset_with(0, terms, noise, params)
            return env.step_with(state, 3.0, noise, params)

        obs, state, reward, *_ = first_day(core.EpisodeTerms(1.0, 1.0, jnp.inf))
        assert obs.dtype == jnp.float32 and reward.dtype == jnp.float32
        assert state.crop.biomass_kg_ha.dtype == jnp.float32 and env.default_params.model_weather.dtype == jnp.float32


@pytest.mark.usefixtures("shared_data")
def test_params_of_a_given_table_match_its_arrays():
    table = core.season_table(scenario_module.get_scenario("benton-2000"),
                              scenario_module.get_scenario("benton-2000").load_seasons())
    env = JaxIrrigationEnv("benton-2000", table=table)
    params = params_of(table, env.max_steps_in_episode, env.task)
    np.testing.assert_array_equal(np.asarray(params.model_weather), table.model_weather)
    assert int(params.max_steps_in_episode) == 200


def test_the_quickstarts_jax_example_runs_as_written():
    text = (Path(__file__).resolve().parents[1] / "docs" / "quickstart.md").read_text()
    example = text.split("## JAX")[1].split("```python\n")[1].split("```")[0]
    done = subprocess.run([sys.executable, "-c", example], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    shape, mean_reward = done.stdout.split(") ")
    assert shape == "(64, 29" and float(mean_reward) < 0.0  # 5 mm on day 0 costs water, no yield yet
