"""The family's learned agents: observation scaling, action in mm, policy files (tiny budgets only)."""

from __future__ import annotations

import json
import tempfile

import numpy as np
import pytest

from crop_agent_ros.policies.learned import ACTION_SCALE_MM, LearnedPolicy, ObservationScaler, action_to_mm
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


def _train(tmp_path, **settings):
    out = tmp_path / "run"
    return tiny_task_training(out, "benton-sensing", 3, **settings), out


def test_tiny_training_writes_loadable_policies(tmp_path, monkeypatch):
    algorithm = "ppo"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))  # where SB3's default logger makes its folder
    summary, out = _train(tmp_path)
    assert not list(scratch.glob("SB3-*")), "training left an SB3 log folder in the temporary directory"
    assert summary["steps_run"] >= 512 and summary["algorithm"] == algorithm
    config = json.loads((out / "model.json").read_text())
    assert config["history"] == 1 and len(config["scaler"]["mean"]) == EXTENDED.size
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
    assert np.all(episodes.water_mm <= episodes.water_mm.max()) and early.interface.input_size == EXTENDED.size
    with pytest.raises(ValueError, match="expected observations of 29 values"):
        policy.act(np.zeros(20))


def test_a_policy_file_with_other_spaces_is_refused_at_load(tmp_path):
    summary, out = _train(tmp_path)
    config = json.loads((out / "model.json").read_text())
    config["paw_filter"] = {"capacity_mm": 120.0, "sensor_sd_mm": 10.0}  # the network takes 29 values
    (out / "model.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"the network takes \(29,\).*needs \(30,\)"):
        LearnedPolicy(out / "model.zip")
    del config["paw_filter"]
    config["algorithm"] = "dqn"
    (out / "model.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match="algorithm: Input should be 'ppo', "):
        LearnedPolicy(out / "model.zip")


def test_the_papers_task_trains_ppo_only_and_a_recipe_refuses_what_it_does_not_have(tmp_path, capsys):
    from crop_agent_ros.cli import main
    for argv, message in ((["--algorithm", "es"], "--algorithm es: for a family task only"),
                          (["--task", "benton-quota", "--hyperparams", "history=4"],
                           "hyperparameter history 4: Extra inputs are not permitted"),
                          (["--task", "atlantis"], "--task atlantis: ")):
        assert main(["train", *argv, "--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("crop-sim train: ") and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "x").exists()


def _sensing_season(fields: int = 6, days: int = 120):
    """benton-sensing's observations of ``fields`` fields over ``days`` days under 3 mm a day, with the true
    PAW (mm) of each field-day."""
    from crop_sim_ros.task import IrrigationVectorEnv, get_scenario
    env = IrrigationVectorEnv(fields, get_scenario("benton-sensing"))
    obs, info = env.reset(seed=4)
    seen, truth = [obs], [info["true_paw_mm"]]
    for _ in range(days):
        obs, _, _, _, info = env.step(np.full(fields, 3.0))
        seen.append(obs)
        truth.append(info["true_paw_mm"])
    return np.stack(seen), np.stack(truth)


def test_the_soil_water_filter_knowing_the_sensor_error_is_closer_to_the_truth_than_the_readings():
    """On benton-sensing (10 mm noise, a third of the readings missing) the filter that knows the sensor's
    error is at most half the readings' error from the true PAW; with no sensor error it is the rule's
    checkbook: the reading where there is one."""
    from crop_agent_ros.policies.family import FarmFacts, SoilWaterFilter
    from crop_sim_ros.task import get_scenario
    from crop_sim_ros.task.layout import EXTENDED
    obs, truth = _sensing_season()
    paw, seen = EXTENDED.index("paw_mm"), obs[..., EXTENDED.index("paw_observed")] > 0.5
    capacity = FarmFacts.of_scenario(get_scenario("benton-sensing")).capacity_mm
    kalman, checkbook = SoilWaterFilter(capacity, sensor_sd_mm=10.0), SoilWaterFilter(capacity)
    estimates = np.stack([kalman.update(day) for day in obs])
    plain = np.stack([checkbook.update(day) for day in obs])
    reading_error = np.sqrt(np.mean((obs[..., paw][seen] - truth[seen]) ** 2))
    filter_error = np.sqrt(np.mean((estimates - truth) ** 2))
    assert 8.0 < reading_error < 12.0 and filter_error < 0.5 * reading_error
    np.testing.assert_array_equal(plain[seen], obs[..., paw][seen])
    assert np.all(estimates[0] == capacity)  # the sowing day: SIMPLE starts full
    kalman.reset()
    np.testing.assert_array_equal(np.stack([kalman.update(day) for day in obs]), estimates)
    with pytest.raises(ValueError, match="sensor_sd_mm >= 0"):
        SoilWaterFilter(capacity, sensor_sd_mm=-1.0)


def test_an_agent_with_the_soil_water_filter_sees_its_estimate_and_loads_with_it(tmp_path):
    from crop_agent_ros.policies.rollout import run_episodes
    summary, out = _train(tmp_path, paw_filter=True)
    config = json.loads((out / "model.json").read_text())
    assert config["paw_filter"]["sensor_sd_mm"] == 10.0 and config["paw_filter"]["capacity_mm"] > 0
    policy = LearnedPolicy(out / "model.zip")
    assert policy.interface.input_size == EXTENDED.size + 1
    assert policy.describe()["paw_filter"] == config["paw_filter"]
    episodes = run_episodes(policy, "benton-sensing", np.arange(2), seed=0)
    assert np.all(np.isfinite(episodes.episode_return))
    obs, _ = _sensing_season(fields=2, days=3)
    policy.reset()
    inputs = [policy.interface.observe(day)[0] for day in obs]
    from crop_agent_ros.policies.family import SoilWaterFilter
    reference = SoilWaterFilter(**config["paw_filter"])
    for day, seen in zip(obs, inputs):
        np.testing.assert_allclose(seen[:, -1], reference.update(day) / config["paw_filter"]["capacity_mm"] * 2 - 1,
                                   rtol=1e-6)
    config["paw_filter"] = {"capacity_mm": -5.0, "sensor_sd_mm": 10.0}
    (out / "model.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match="paw_filter .*capacity_mm must be > 0"):
        LearnedPolicy(out / "model.zip")
