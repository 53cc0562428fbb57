"""The family's learned agents: observation scaling, action in mm, history, policy files (tiny budgets only)."""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import replace

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


def test_training_refuses_the_papers_task_and_family_options_without_a_task(tmp_path):
    from crop_agent_ros.learning import train
    from crop_agent_ros.learning.train_task import train_task
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    for task, message in (("benton-generated", "not a family task"),):
        args = parser.parse_args(["--task", task, "--out", str(tmp_path / "x"), "--timesteps", "64"])
        with pytest.raises(SystemExit, match=message):
            train_task(args)
    # the family agent's options on the paper's task (no --task) are refused, not ignored
    from crop_sim_ros.usage import UsageError
    for extra, flag in ((["--paw-filter"], "--paw-filter"), (["--history", "4"], "--history"),
                        (["--imitate", "x.npz"], "--imitate"), (["--outlook"], "--outlook"),
                        (["--training-seasons", "5000"], "--training-seasons"), (["--sde", "0"], "--sde"),
                        (["--critic-warmup", "100"], "--critic-warmup"), (["--log-std-final", "-4"], "--log-std-final"),
                        (["--critic-hindsight"], "--critic-hindsight"),
                        (["--algorithm", "td3"], "--algorithm td3"), (["--gradient-steps", "4"], "--gradient-steps"),
                        (["--algorithm", "es"], "--algorithm es"), (["--es-noise-std", "0.1"], "--es-noise-std")):
        args = parser.parse_args(["--out", str(tmp_path / "x"), "--timesteps", "64", *extra])
        with pytest.raises(UsageError, match=f"{flag}: with --task only"):
            train.run(args)


def test_a_larger_training_pool_extends_the_tasks_own_pool(tmp_path):
    """--training-seasons N: N seasons drawn by the task's generator with its seed (the pool is drawn at once, so
    it is another draw than the task's 1,000); refused for a mixture of pools and outside 1..10,000."""
    from crop_agent_ros.learning.train_task import training_pool
    from crop_sim_ros.task import IrrigationVectorEnv, get_scenario
    from crop_sim_ros.usage import UsageError
    task = get_scenario("benton-quota")
    larger = training_pool(task, 1500)
    assert larger.name == task.name and larger.n_seasons == 1500 and task.n_seasons == 1000
    assert training_pool(task, None) is task
    assert larger.weather == replace(task.weather, n_seasons=1500)
    IrrigationVectorEnv(2, larger).reset(seed=1, options={"season": 1499})  # beyond the task's own pool
    with pytest.raises(UsageError, match="--training-seasons: 'climates-quota' mixes"):
        training_pool(get_scenario("climates-quota"), 2000)
    for count in (0, 10_001):
        with pytest.raises(UsageError, match=f"--training-seasons {count}: must be in 1..10,000"):
            training_pool(task, count)
    summary, out = _train(tmp_path, "--training-seasons", "40")
    assert json.loads((out / "model.json").read_text())["training_seasons"] == 40


def test_state_dependent_exploration_is_recorded_and_its_policy_acts_deterministically(tmp_path):
    """--sde DAYS: gSDE with its noise weights redrawn every DAYS days (0: once per rollout); the saved policy's
    actions are its mean, so two evaluations agree; a negative count is refused."""
    from crop_agent_ros.learning.train_task import exploration
    from crop_agent_ros.policies.rollout import run_episodes
    from crop_sim_ros.usage import UsageError
    assert exploration(None) == {} and exploration(0) == {"use_sde": True, "sde_sample_freq": -1}
    assert exploration(8) == {"use_sde": True, "sde_sample_freq": 8}
    with pytest.raises(UsageError, match="--sde -1: days between noise draws"):
        exploration(-1)
    summary, out = _train(tmp_path, "--sde", "4")
    hyper = json.loads((out / "model.json").read_text())["hyper_parameters"]
    assert hyper["use_sde"] is True and hyper["sde_sample_freq"] == 4
    policy = LearnedPolicy(out / "model.zip")
    first, second = (run_episodes(policy, "benton-sensing", np.arange(2), seed=0).episode_return for _ in range(2))
    np.testing.assert_array_equal(first, second)


def test_a_critic_warmup_moves_only_the_value_network(tmp_path):
    """--critic-warmup STEPS: PPO's updates inside frozen_actor change the value network and leave the policy (and
    its exploration scale) exactly as it was; afterwards every parameter learns again."""
    import torch
    from stable_baselines3 import PPO
    from crop_agent_ros.learning.train_task import frozen_actor
    model = PPO("MlpPolicy", "Pendulum-v1", n_steps=64, batch_size=32, n_epochs=2, seed=0, device="cpu",
                policy_kwargs={"net_arch": [8]})
    before = {k: v.clone() for k, v in model.policy.state_dict().items()}
    with frozen_actor(model.policy):
        model.learn(128)
    after = model.policy.state_dict()
    actor = [k for k in before if k.startswith(("mlp_extractor.policy_net", "action_net", "log_std"))]
    critic = [k for k in before if k.startswith(("mlp_extractor.value_net", "value_net"))]
    assert actor and critic
    assert all(torch.equal(before[k], after[k]) for k in actor)
    assert any(not torch.equal(before[k], after[k]) for k in critic)
    assert all(p.requires_grad for p in model.policy.parameters())
    summary, out = _train(tmp_path, "--critic-warmup", "256")
    assert json.loads((out / "model.json").read_text())["critic_warmup_steps"] == 256
    assert summary["steps_run"] >= 512
    from crop_sim_ros.usage import UsageError
    with pytest.raises(UsageError, match="--critic-warmup 512: steps in 0..--timesteps"):
        _train(tmp_path, "--critic-warmup", "512")


def test_an_annealed_exploration_follows_its_schedule_and_is_not_learned(tmp_path):
    """--log-std-final: the log std is set at each rollout's start on the line from --log-std-init to the final
    value (4 rollouts of 256 steps: -2, -2.5, -3, -3.5), never by the gradient; recorded in the policy file."""
    import io
    import zipfile
    import torch

    def log_std(path):
        with zipfile.ZipFile(path) as archive:
            return torch.load(io.BytesIO(archive.read("policy.pth")), weights_only=False)["log_std"]

    summary, out = _train(tmp_path, "--sde", "0", "--log-std-init", "-2", "--log-std-final", "-4",
                          "--timesteps", "1024")
    assert json.loads((out / "model.json").read_text())["log_std_final"] == -4.0
    assert torch.all(log_std(out / "final_model.zip") == -3.5)
    checkpoints = sorted(out.glob("checkpoint_*.zip"))
    assert torch.all(log_std(checkpoints[0]) == -2.0)


def test_an_off_policy_td3_agent_trains_loads_and_refuses_ppo_options(tmp_path):
    """--algorithm td3: a deterministic policy with its critic; the saved policy loads as a family agent and acts
    the same twice; PPO's options are refused for it, and its own options for PPO."""
    from crop_agent_ros.policies.rollout import run_episodes
    from crop_sim_ros.usage import UsageError
    summary, out = _train(tmp_path, "--algorithm", "td3", "--gradient-steps", "2", "--action-noise", "0.1")
    config = json.loads((out / "model.json").read_text())
    assert config["algorithm"] == "td3" and summary["steps_run"] >= 512
    assert config["hyper_parameters"]["action_noise"] == 0.1 and config["hyper_parameters"]["gradient_steps"] == 2
    assert "gae_lambda" not in config["hyper_parameters"]
    policy = LearnedPolicy(out / "model.zip")
    first, second = (run_episodes(policy, "benton-sensing", np.arange(2), seed=0).episode_return for _ in range(2))
    np.testing.assert_array_equal(first, second)
    with pytest.raises(UsageError, match="--sde, --critic-warmup: for PPO only, not --algorithm td3"):
        _train(tmp_path, "--algorithm", "td3", "--sde", "0", "--critic-warmup", "100")
    with pytest.raises(UsageError, match="--action-noise: for --algorithm td3 only"):
        _train(tmp_path, "--action-noise", "0.3")


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
    summary, out = _train(tmp_path, "--paw-filter", "--history", "2")
    config = json.loads((out / "model.json").read_text())
    assert config["paw_filter"]["sensor_sd_mm"] == 10.0 and config["paw_filter"]["capacity_mm"] > 0
    policy = LearnedPolicy(out / "model.zip")
    assert policy.interface.input_size == 2 * EXTENDED.size + 1
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


def test_the_rule_with_a_soil_water_filter_is_measured_on_a_committed_table(capsys):
    """The check behind the README's 'is the rule handicapped by the sensor?': on benton-sensing's committed
    table the plain tuned rule reproduces the table's returns, and the filtered rule's regret is reported."""
    from pathlib import Path
    from crop_agent_ros.learning import filtered_rule
    table = Path(__file__).resolve().parent.parent / "results/family/benton-sensing-expected4/table.json"
    assert filtered_rule.main([str(table), "--sets", "heldout-real"]) == 0
    out = capsys.readouterr().out
    assert "heldout-real: rule regret 437.6 USD/ha; with a filter at 10 mm" in out
    assert filtered_rule.main([str(table.parent / "missing.json")]) == 2


def test_hidden_columns_scale_to_zero_and_round_trip_through_the_record():
    rng = np.random.default_rng(1)
    obs = rng.normal(5.0, 2.0, (200, EXTENDED.size))
    fitted = ObservationScaler.fit(obs)
    assert "hidden" not in fitted.record()  # a policy file of a network that sees everything is as before
    scaler = replace(fitted, hidden=("days_since_sowing", "season_days_left"))
    day, left = EXTENDED.index("days_since_sowing"), EXTENDED.index("season_days_left")
    scaled, plain = scaler(obs), fitted(obs)
    assert np.all(scaled[:, [day, left]] == 0.0) and np.any(plain[:, [day, left]] != 0.0)
    others = [i for i in range(EXTENDED.size) if i not in (day, left)]
    np.testing.assert_array_equal(scaled[:, others], plain[:, others])
    assert ObservationScaler.from_record(json.loads(json.dumps(scaler.record()))) == scaler
    with pytest.raises(KeyError, match="no observation column 'days'"):
        ObservationScaler(fitted.mean, fitted.std, ("days",))


def test_an_agent_trained_with_hidden_columns_records_them_and_does_not_read_them(tmp_path):
    from crop_sim_ros.usage import UsageError
    with pytest.raises(UsageError, match="--hide days, sowing: no such observation column; columns: biomass_t_ha"):
        _train(tmp_path / "bad", "--hide", "sowing,days_since_sowing,days")
    assert not (tmp_path / "bad").exists()  # refused before any work
    _, out = _train(tmp_path, "--hide", "season_days_left, days_since_sowing")
    config = json.loads((out / "model.json").read_text())
    assert config["scaler"]["hidden"] == ["days_since_sowing", "season_days_left"]  # layout order
    policy = LearnedPolicy(out / "model.zip")
    obs, _ = _sensing_season(fields=3, days=2)
    moved = obs[1].copy()
    moved[:, EXTENDED.index("days_since_sowing")] += 40.0
    moved[:, EXTENDED.index("season_days_left")] -= 40.0
    policy.reset()
    policy.act(obs[0])
    first = policy.act(obs[1])
    policy.reset()
    policy.act(obs[0])
    np.testing.assert_array_equal(policy.act(moved), first)
    changed = obs[1].copy()
    changed[:, EXTENDED.index("thermal_time_degc_d")] += 400.0
    policy.reset()
    policy.act(obs[0])
    assert not np.array_equal(policy.act(changed), first)  # a column it reads still moves its action
