"""Evolution strategies on JAX (``--algorithm es --hyperparams backend=jax``, crop_agent_ros.learning.jax_evolution):
evosax's update is the numpy learner's, the JAX population's returns are the numpy population's, and a tiny run
trains, reproduces bit for bit, and its exported agent runs in ``crop-sim evaluate --task`` and in the ROS agent
node exactly as offline. Tiny budgets (CPU, seconds after the compilation)."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("evosax")

import ros_support  # noqa: E402  (private ROS_DOMAIN_ID before any context exists)
from crop_agent_ros.learning import hyperparameters as hp  # noqa: E402
from crop_agent_ros.learning.evolution import (Adam, ActorVector, antithetic_gradient,  # noqa: E402
                                               candidates_episodes, generation_seasons)
from crop_agent_ros.learning.jax_evolution import PopulationRollout, open_es, tell  # noqa: E402
from crop_agent_ros.policies.learned import AgentInterface, LearnedPolicy, ObservationScaler  # noqa: E402
from crop_agent_ros.ros.process import isolated_ros_env  # noqa: E402
from crop_sim_ros.task import get_scenario  # noqa: E402
from crop_sim_ros.task.layout import EXTENDED  # noqa: E402
from crop_sim_ros.task.scenario import ObservationNoise  # noqa: E402
from crop_sim_ros.usage import UsageError  # noqa: E402
from policy_files import Spaces, tiny_task_training  # noqa: E402

TASK = "benton-quota"


@pytest.fixture(scope="module", autouse=True)
def x64():
    """float64, as the learner runs (restored after)."""
    with jax.enable_x64(True):
        yield


def _actor(net_arch=(16,), seed: int = 0) -> ActorVector:
    import torch
    from stable_baselines3 import PPO
    torch.manual_seed(seed)
    model = PPO("MlpPolicy", Spaces((EXTENDED.size,), (1,)), n_steps=8, batch_size=8, seed=seed,
                policy_kwargs={"net_arch": list(net_arch)}, device="cpu")
    return ActorVector(model.policy)


def _settings(**overrides):
    return hp.resolve(TASK, "es", True, {"pairs": 4, "seasons": 3, "backend": "jax", **overrides})


def _scaler(scenario) -> ObservationScaler:
    from crop_agent_ros.learning.train_task import fit_scaler
    return fit_scaler(scenario, 0)


def test_evosax_open_es_steps_as_the_numpy_learner():
    """Given the candidates evosax draws and any fitness, its update (antithetic pairs, centred ranks with tied
    values sharing their rank, Adam at a step size given each generation) is the numpy learner's, generation after
    generation, to rounding."""
    strategy = open_es(_settings(noise_std=0.05), 40)
    params = strategy.default_params
    rng = np.random.default_rng(5)
    theta = rng.normal(size=40)
    state = strategy.init(jax.random.key(0), jax.numpy.asarray(theta), params)
    adam = Adam(40)
    for generation, learning_rate in enumerate([0.02, 0.015, 0.01]):
        population, state = strategy.ask(jax.random.key(generation + 1), state, params)
        population = np.asarray(population)
        noise = (population[:4] - theta) / 0.05
        np.testing.assert_allclose(population[4:], theta - 0.05 * noise, atol=1e-12)  # antithetic
        fitness = rng.normal(size=8).round(1)  # rounded: some ties
        fitness[3] = fitness[6]
        theta = theta + adam.step(antithetic_gradient(fitness, noise, 0.05), learning_rate)
        state = tell(strategy, state, jax.random.key(9), jax.numpy.asarray(population),
                     jax.numpy.asarray(fitness), learning_rate)
        np.testing.assert_allclose(np.asarray(state.mean), theta, rtol=1e-10, atol=1e-12)


def test_the_jax_population_returns_are_the_numpy_populations_without_noise():
    """Every candidate on every season with its terms: the JAX rollout (float32 network, float64 environment)
    gives the numpy learner's season returns and lengths (the task's observation noise set to zero, so both see the
    same observations)."""
    base = get_scenario(TASK)
    quiet = replace(base, noise=ObservationNoise(**{name: 0.0 for name in ObservationNoise.__dataclass_fields__}),
                    weather=replace(base.weather, n_seasons=6))
    actor = _actor()
    interface = AgentInterface(_scaler(quiet))
    rng = np.random.default_rng(2)
    candidates = actor.get() + rng.normal(0, 0.3, (3, actor.size))
    seasons, terms = generation_seasons(np.random.default_rng(1), quiet, 4)
    numpy_episodes = candidates_episodes(actor, candidates, interface, quiet, seasons, terms, seed=0)
    rollout = PopulationRollout(quiet, interface, actor)
    from crop_sim_ros.task import core
    returns, days = jax.jit(rollout)(jax.numpy.asarray(candidates), jax.numpy.asarray(seasons),
                                     core.EpisodeTerms(**terms), jax.random.key(0))
    np.testing.assert_array_equal(np.asarray(days).ravel(), numpy_episodes.days)
    np.testing.assert_allclose(np.asarray(returns).ravel(), numpy_episodes.episode_return, rtol=1e-5)
    assert np.ptp(numpy_episodes.episode_return.reshape(3, 4), axis=0).max() > 100  # the candidates differ


def _noisy_rollout():
    """(rollout, actor, scenario): the JAX rollout of a fresh network on the noisy task."""
    scenario = get_scenario(TASK)
    actor = _actor()
    return PopulationRollout(scenario, AgentInterface(_scaler(scenario)), actor), actor, scenario


def _rollout_arguments(thetas, scenario) -> tuple:
    """The rollout's arguments: ``thetas`` (P, size) on 3 seasons of ``scenario`` with their terms, key 0."""
    from crop_sim_ros.task import core
    seasons, terms = generation_seasons(np.random.default_rng(1), scenario, 3)
    return jax.numpy.asarray(thetas), jax.numpy.asarray(seasons), core.EpisodeTerms(**terms), jax.random.key(0)


def test_the_observation_noise_is_common_to_the_candidates():
    """Candidates with the same network on the same season see the same noisy observations (common random
    numbers), so they return the same; the noise is drawn (other keys, other returns)."""
    rollout, actor, scenario = _noisy_rollout()
    returns, days = jax.jit(rollout)(*_rollout_arguments(np.tile(actor.get(), (3, 1)), scenario))
    np.testing.assert_array_equal(returns[1:], np.broadcast_to(returns[0], (2, 3)))
    np.testing.assert_array_equal(days[1:], np.broadcast_to(days[0], (2, 3)))
    noises = [rollout._noise(jax.random.key(k), 2, 3) for k in (0, 1)]
    assert noises[0].shape == (6, rollout.env.task.noise_columns)
    np.testing.assert_array_equal(noises[0][:3], noises[0][3:])
    assert not np.array_equal(noises[0], noises[1]) and float(np.abs(noises[0]).max()) > 0.5


SPLIT_CHECK = """
import jax, numpy as np
jax.config.update("jax_num_cpu_devices", 2)
with jax.enable_x64(True):
    import test_jax_evolution as t
    from crop_agent_ros.learning.jax_evolution import candidates_split
    rollout, actor, scenario = t._noisy_rollout()
    args = t._rollout_arguments(actor.get() + np.random.default_rng(3).normal(0, 0.3, (4, actor.size)), scenario)
    split, parts = candidates_split(rollout, 4)
    assert parts == 2 and len(jax.devices()) == 2
    (one, days_one), (two, days_two) = jax.jit(rollout)(*args), jax.jit(split)(*args)
    np.testing.assert_array_equal(days_one, days_two)
    np.testing.assert_allclose(one, two, rtol=1e-9)
    assert np.ptp(np.asarray(one), axis=0).max() > 1.0  # the candidates differ
    print("split ok")
"""


def test_the_candidates_split_over_two_cpu_devices_return_as_on_one():
    """With two CPU devices (a fresh process: JAX fixes its devices at its first operation) the population runs
    in two parts, one per device, and returns what one device returns."""
    import os
    from pathlib import Path
    test_dir = Path(__file__).parent
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(test_dir), str(test_dir.parent)])}
    done = subprocess.run([sys.executable, "-c", SPLIT_CHECK], capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0 and "split ok" in done.stdout, done.stderr[-2000:]


def _jax_run(tmp_path, name: str):
    out = tmp_path / name
    summary = tiny_task_training(out, TASK, 1, "es", timesteps=120_000, net_arch=(16,), eval_freq=40_000,
                                 noise_std=0.3, backend="jax")
    return summary, out


@pytest.fixture(scope="module")
def jax_run(tmp_path_factory):
    """A tiny JAX ES run of benton-quota (3 pairs, 3 seasons, 120,000 field-days), and the same run again."""
    folder = tmp_path_factory.mktemp("jax-es")
    return _jax_run(folder, "benton-quota-es-jax-s1"), _jax_run(folder, "again")


def _curve(run):
    """The learning curve, every column but the wall time."""
    with open(run / "learning_curve.csv", newline="") as f:
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)]


def test_a_tiny_jax_es_run_improves_and_reproduces_bit_for_bit(jax_run):
    (summary, out), (_, again) = jax_run
    config = json.loads((out / "model.json").read_text())
    assert config["algorithm"] == "es" and config["hyper_parameters"]["backend"] == "jax"
    assert summary["steps_run"] >= 120_000
    rows = _curve(out)
    assert int(rows[0]["timesteps"]) == 0 and len(rows) >= 4
    # the deterministic policy's validation return rises from the untrained network's
    assert max(float(r["validation_return"]) for r in rows[1:]) > float(rows[0]["validation_return"]) + 500
    assert 1_200 <= json.loads((out / "early_model.json").read_text())["timesteps_at_save"] < 40_000
    # the same seed gives the same run and the same exported network
    assert _curve(again) == rows
    first, second = (ActorVector(LearnedPolicy(run / "model.zip").model.policy) for run in (out, again))
    np.testing.assert_array_equal(first.get(), second.get())


def test_the_exported_jax_agent_runs_in_crop_sim_evaluate(jax_run, tmp_path):
    from crop_agent_ros.cli import main
    (_, run), _ = jax_run
    out = tmp_path / "eval"
    status = main(["evaluate", "--task", TASK, "--agents", f"es-jax={run}", "--no-oracle", "--no-curves",
                   "--noise-seeds", "1", "--far-seasons", "2", "--sets", "far-benton", "--bootstrap", "100",
                   "--out", str(out)])
    assert status == 0
    with open(out / "table.csv", newline="") as f:
        rows = {r["policy"]: r for r in csv.DictReader(f)}
    assert rows["es-jax"]["kind"] == "agent" and np.isfinite(float(rows["es-jax"]["return_usd_ha"]))


def test_the_exported_jax_agent_drives_the_ros_agent_node_as_offline(jax_run, tmp_path):
    """``crop-sim farm --policy agent --policy-file RUN/model.zip``: the agent node runs the JAX-trained network
    over ROS and irrigates exactly as the same file does offline on the same season."""
    (_, run), _ = jax_run
    done = subprocess.run([sys.executable, "-m", "crop_agent_ros.ros.farm", "--task", TASK, "--policy", "agent",
                           "--policy-file", str(run / "model.zip"), "--seasons", "1", "--json", "--no-plot",
                           "--domain-id", str(isolated_ros_env()["ROS_DOMAIN_ID"])],
                          env=isolated_ros_env(), capture_output=True, text=True, timeout=300, cwd=ros_support.REPO)
    assert done.returncode == 0, done.stdout + done.stderr
    (summary,) = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    total, water, weather = offline_season(LearnedPolicy(run / "model.zip"), TASK)
    assert summary["weather"] == weather and summary["policy"] == "agent"
    assert (summary["return"], summary["irrigation_mm"]) == (total, water) and water > 0


def offline_season(policy, task: str) -> tuple[float, float, str]:
    """The season ``crop-sim farm --seasons 1`` grows (the environment's seed 0) run offline by ``policy``:
    its return, its irrigation (mm, summed day by day as the farm sums them) and its weather's source."""
    from crop_sim_ros.task import IrrigationEnv
    env = IrrigationEnv(task)
    policy.reset(None)
    obs, info = env.reset(seed=0)
    days, ended = [], False
    while not ended:
        obs, reward, terminated, truncated, step = env.step(policy.act(obs))
        days.append((reward, step["irrigation_applied_mm"]))
        ended = terminated or truncated
    return sum(reward for reward, _ in days), sum(mm for _, mm in days), info["weather_source"]


def test_backend_jax_refuses_the_soil_water_filter_and_an_unknown_backend_in_one_line():
    with pytest.raises(UsageError, match="^hyperparameters: backend jax has no soil-water filter"):
        hp.resolve(TASK, "es", True, {"backend": "jax", "paw_filter": True})
    with pytest.raises(UsageError, match="hyperparameter backend 'torch': Input should be 'numpy' or 'jax'"):
        hp.resolve(TASK, "es", True, {"backend": "torch"})
