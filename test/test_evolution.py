"""Evolution strategies for the family agent (``--algorithm es``): the numpy actor is SB3's, the gradient
estimate points uphill, candidates act on their own fields, and a tiny run trains, reproduces and loads."""

from __future__ import annotations

import json

import numpy as np
import pytest

from crop_agent_ros.policies.learned import LearnedPolicy
from crop_agent_ros.learning.evolution import (Adam, ActorVector, Population, actor_outputs, antithetic_gradient,
                                               centred_ranks)
from policy_files import Spaces, tiny_task_training


def _ppo(inputs: int, net_arch=(16, 8)):
    import torch
    from stable_baselines3 import PPO
    torch.manual_seed(0)
    return PPO("MlpPolicy", Spaces((inputs,), (1,)), n_steps=8, batch_size=8, seed=0,
               policy_kwargs={"net_arch": list(net_arch)}, device="cpu")


def test_the_numpy_actor_is_the_sb3_mean_action_and_round_trips_its_parameters():
    import torch
    model = _ppo(5)
    actor = ActorVector(model.policy)
    theta = actor.get()
    assert theta.size == 5 * 16 + 16 + 16 * 8 + 8 + 8 * 1 + 1 == actor.size
    inputs = np.random.default_rng(1).normal(size=(40, 5)).astype(np.float32)
    with torch.no_grad():
        mean = model.policy.get_distribution(torch.as_tensor(inputs)).distribution.mean.numpy()[:, 0]
    ours = actor_outputs(actor.unflatten(theta[None, :]), inputs[None].astype(np.float64))[0]
    np.testing.assert_allclose(ours, mean, rtol=1e-5, atol=1e-6)
    # set then get gives the vector back (float32 storage), and SB3 acts with it
    moved = theta + np.random.default_rng(2).normal(0, 0.1, theta.size)
    actor.set(moved)
    np.testing.assert_allclose(actor.get(), moved, atol=1e-6)
    with torch.no_grad():
        mean = model.policy.get_distribution(torch.as_tensor(inputs)).distribution.mean.numpy()[:, 0]
    np.testing.assert_allclose(actor_outputs(actor.unflatten(moved[None, :]), inputs[None].astype(np.float64))[0],
                               mean, rtol=1e-4, atol=1e-5)


def test_candidates_act_on_their_own_fields_with_their_own_parameters():
    from crop_agent_ros.policies.learned import AgentInterface, ObservationScaler, action_to_mm
    from crop_sim_ros.task.layout import EXTENDED
    model = _ppo(EXTENDED.size)
    actor = ActorVector(model.policy)
    theta = actor.get()
    rng = np.random.default_rng(3)
    candidates = np.stack([theta, theta + rng.normal(0, 0.5, theta.size), theta - 1.0])
    scaler = ObservationScaler(tuple([0.0] * EXTENDED.size), tuple([1.0] * EXTENDED.size))
    obs = rng.normal(size=(3 * 4, EXTENDED.size))
    obs[:, EXTENDED.index("days_since_sowing")] = 5.0
    mm = Population(actor, candidates, 4, AgentInterface(scaler)).act(obs)
    for p in range(3):
        alone = actor_outputs(actor.unflatten(candidates[[p]]), scaler(obs[4 * p:4 * p + 4])[None].astype(float))[0]
        np.testing.assert_allclose(mm[4 * p:4 * p + 4], action_to_mm(alone))
    assert not np.allclose(mm[:4], mm[4:8])


def test_centred_ranks_and_the_antithetic_estimate_point_uphill():
    np.testing.assert_allclose(centred_ranks(np.array([3.0, -1.0, 10.0, 0.0])), [1 / 6, -0.5, 0.5, -1 / 6])
    # ties share their mean rank: candidates that all return the same give no gradient at all
    np.testing.assert_allclose(centred_ranks(np.array([2.0, 5.0, 2.0, 7.0])), [-1 / 3, 1 / 6, -1 / 3, 0.5])
    assert not antithetic_gradient(np.full(6, 4.0), np.ones((3, 5)), 0.1).any()
    # f(theta) = -|theta - target|^2: the estimate from 200 antithetic pairs points towards the target,
    # and Adam's ascent on it gets there
    rng = np.random.default_rng(0)
    target = rng.normal(size=20)
    theta, adam = np.zeros(20), Adam(20)
    first = None
    for _ in range(300):
        noise = rng.standard_normal((200, 20))
        candidates = np.concatenate([theta + 0.1 * noise, theta - 0.1 * noise])
        gradient = antithetic_gradient(-((candidates - target) ** 2).sum(axis=1), noise, 0.1)
        if first is None:
            first = gradient @ target / (np.linalg.norm(gradient) * np.linalg.norm(target))
        theta = theta + adam.step(gradient, 0.05)
    assert first > 0.8
    assert np.linalg.norm(theta - target) < 0.1 * np.linalg.norm(target)


def _es(tmp_path, name: str):
    out = tmp_path / name
    summary = tiny_task_training(out, "benton-quota", 1, "es", timesteps=120_000, net_arch=(16,), eval_freq=40_000,
                                 noise_std=0.3)
    return summary, out


def test_a_tiny_es_run_improves_reproduces_and_loads_as_a_family_agent(tmp_path):
    summary, out = _es(tmp_path, "a")
    config = json.loads((out / "model.json").read_text())
    assert config["algorithm"] == "es" and summary["steps_run"] >= 120_000
    assert config["hyper_parameters"] == {"timesteps": 120_000, "eval_freq": 40_000, "validation_seasons": 2,
                                          "net_arch": [16], "learning_rate": 0.02, "final_learning_rate": 0.002,
                                          "paw_filter": False, "residual": False, "weather_inputs": True, "pairs": 3, "noise_std": 0.3, "seasons": 3,
                                          "backend": "numpy"}
    import csv
    with open(out / "learning_curve.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert int(rows[0]["timesteps"]) == 0 and len(rows) >= 4
    # the deterministic policy's validation return rises from the untrained network's
    assert max(float(r["validation_return"]) for r in rows[1:]) > float(rows[0]["validation_return"]) + 500
    early = json.loads((out / "early_model.json").read_text())["timesteps_at_save"]
    assert 1_200 <= early < 40_000  # the first generation past 1 % of the budget
    policy = LearnedPolicy(out / "model.zip")
    from crop_agent_ros.policies.rollout import run_episodes
    episodes = run_episodes(policy, "benton-quota", np.arange(2), seed=0)
    assert np.all(np.isfinite(episodes.episode_return)) and policy.describe()["algorithm"] == "es"
    # the same seed gives the same policy, bit for bit
    _, again = _es(tmp_path, "b")
    def curve(run):  # every column but the wall time
        with open(run / "learning_curve.csv", newline="") as f:
            return [{k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)]

    assert curve(again) == curve(out)
    first, second = ActorVector(policy.model.policy), ActorVector(LearnedPolicy(again / "model.zip").model.policy)
    np.testing.assert_array_equal(first.get(), second.get())


def test_es_refuses_settings_out_of_range_or_of_another_algorithm(tmp_path):
    from crop_sim_ros.usage import UsageError
    for settings, message in (({"pairs": 0}, "hyperparameter pairs 0: Input should be greater than or equal to 1"),
                              ({"noise_std": -0.1}, "hyperparameter noise_std -0.1: Input should be greater than 0"),
                              ({"n_steps": 64}, "hyperparameter n_steps 64: Extra inputs are not permitted")):
        with pytest.raises(UsageError, match=message):
            tiny_task_training(tmp_path / "x", "benton-quota", 0, "es", **settings)
    assert not (tmp_path / "x" / "model.zip").exists()
