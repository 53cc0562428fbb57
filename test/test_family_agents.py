"""The family's learned agents: observation scaling, action in mm, history, policy files (tiny budgets only)."""

from __future__ import annotations

import argparse
import json
import tempfile

import numpy as np
import pytest

from crop_agent_ros.learning.agent import ACTION_SCALE_MM, History, LearnedPolicy, ObservationScaler, action_to_mm
from crop_sim_ros.task.layout import EXTENDED
from policy_files import tiny_task_training


def test_action_maps_minus_one_to_zero_and_one_to_the_scale():
    np.testing.assert_allclose(action_to_mm([-1.0, 0.0, 1.0, 3.0, -7.0]),
                               [0.0, ACTION_SCALE_MM / 2, ACTION_SCALE_MM, ACTION_SCALE_MM, 0.0])


def test_scaler_centres_and_scales_and_floors_constant_columns():
    rng = np.random.default_rng(0)
    obs = rng.normal(5.0, 2.0, (1000, EXTENDED.size))
    obs[:, 3] = 7.0  # a constant column
    scaler = ObservationScaler.fit(obs)
    scaled = scaler(obs)
    assert np.abs(scaled[:, 0].mean()) < 1e-6 and abs(scaled[:, 0].std() - 1.0) < 1e-3
    assert np.all(scaled[:, 3] == 0.0) and scaler.std[3] == 1e-3
    assert scaler(np.full(EXTENDED.size, 1e9)).max() == 10.0


def test_history_shifts_and_restarts_a_new_season():
    history = History(3)
    first = history.push(np.array([[1.0], [10.0]]), np.array([0, 0]))
    np.testing.assert_array_equal(first, [[1, 1, 1], [10, 10, 10]])
    second = history.push(np.array([[2.0], [20.0]]), np.array([1, 1]))
    np.testing.assert_array_equal(second, [[1, 1, 2], [10, 10, 20]])
    # field 1 starts a new season (day 0): its history restarts from its first observation
    third = history.push(np.array([[3.0], [99.0]]), np.array([2, 0]))
    np.testing.assert_array_equal(third, [[1, 2, 3], [99, 99, 99]])


def _train(tmp_path, *extra: str):
    out = tmp_path / "run"
    return tiny_task_training(out, "benton-sensing", 3, *extra), out


@pytest.mark.parametrize("extra, algorithm, history", [(("--history", "4"), "ppo", 4),
                                                       (("--algorithm", "recurrent-ppo"), "recurrent-ppo", 1)])
def test_tiny_training_writes_loadable_policies(tmp_path, monkeypatch, extra, algorithm, history):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))  # where SB3's default logger makes its folder
    summary, out = _train(tmp_path, *extra)
    assert not list(scratch.glob("SB3-*")), "training left an SB3 log folder in the temporary directory"
    assert summary["steps_run"] >= 512 and summary["algorithm"] == algorithm
    config = json.loads((out / "model.json").read_text())
    assert config["history"] == history and len(config["scaler"]["mean"]) == EXTENDED.size
    # the run's policy is its checkpoint with the best validation return (the curve's rows)
    import csv
    with open(out / "learning_curve.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    best = max(rows, key=lambda r: float(r["validation_return"]))
    assert config["timesteps_at_save"] == int(best["timesteps"]) == summary["selected"]["timesteps"]
    assert (out / "final_model.zip").exists() and "best validation return" in config["selected_by"]
    policy = LearnedPolicy(out / "model.zip")
    early = LearnedPolicy(out / "early_model.zip")
    assert json.loads((out / "early_model.json").read_text())["timesteps_at_save"] < summary["steps_run"]
    from crop_agent_ros.policies.rollout import run_episodes
    episodes = run_episodes(policy, "benton-sensing", np.arange(3), seed=0)
    assert np.all(episodes.days > 60) and np.all(np.isfinite(episodes.episode_return))
    assert np.all(episodes.water_mm <= episodes.water_mm.max()) and early.history.k == history
    with pytest.raises(ValueError, match="expected observations of 29 values"):
        policy.act(np.zeros(20))


def test_a_policy_file_with_other_spaces_is_refused_at_load(tmp_path):
    summary, out = _train(tmp_path, "--history", "2")
    config = json.loads((out / "model.json").read_text())
    config["history"] = 3  # the network takes 2 x 29 values
    (out / "model.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"the network takes \(58,\).*needs \(87,\)"):
        LearnedPolicy(out / "model.zip")
    config["algorithm"] = "dqn"
    (out / "model.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match="algorithm 'dqn' is not one of"):
        LearnedPolicy(out / "model.zip")


def test_training_refuses_the_papers_task_and_real_seasons(tmp_path):
    from crop_agent_ros import train
    from crop_agent_ros.learning.train_task import train_task
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    for task, message in (("benton-generated", "not a family task"),):
        args = parser.parse_args(["--task", task, "--out", str(tmp_path / "x"), "--timesteps", "64"])
        with pytest.raises(SystemExit, match=message):
            train_task(args)
