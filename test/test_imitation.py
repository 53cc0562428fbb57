"""Learning from the causal MPC (crop_agent_ros.learning.imitation): demonstrations record the MPC's own
actions, the recorder perturbs only what is executed, behaviour cloning fits the actor (one-sided at the
0 mm bound), bad files are refused with one line, and `crop-sim train --imitate` writes a policy that acts
like its demonstrations. Tiny budgets only."""

from __future__ import annotations

import json

import numpy as np
import pytest

from crop_agent_ros.learning import imitation
from crop_agent_ros.learning.agent import AgentInterface, LearnedPolicy, ObservationScaler
from crop_agent_ros.policies import family_mpc as fm
from crop_agent_ros.policies.family_oracle import TaskConstants
from crop_agent_ros.policies.rollout import run_episodes
from crop_sim_ros.task import IrrigationVectorEnv, get_scenario
from crop_sim_ros.task.layout import EXTENDED
from crop_sim_ros.usage import UsageError
from policy_files import Spaces, tiny_task_training

DAY = EXTENDED.index("days_since_sowing")
CHEAP = fm.MpcSettings(scenarios=1, decision_every_days=30, replan_first_step_mm=2.0, finest_step_mm=1.0)


@pytest.fixture(scope="module")
def demonstrations():
    return imitation.demonstrate("benton-quota", np.array([5]), CHEAP, action_noise_mm=0.0, seed=2)


def test_demonstrations_are_the_mpcs_own_actions_on_live_days(demonstrations):
    scenario = get_scenario("benton-quota")
    mpc = fm.FamilyMpcPolicy(TaskConstants.of_scenario(scenario), fm.continuation_pool(scenario, 1), CHEAP)
    episodes = run_episodes(mpc, scenario, np.array([5]), seed=2, record=True)
    days = int(episodes.days[0])
    np.testing.assert_array_equal(demonstrations["day"], np.arange(days))
    np.testing.assert_array_equal(demonstrations["mm"], episodes.daily["irrigation_mm"][:days, 0])
    assert demonstrations["observations"].shape == (days, EXTENDED.size)
    assert np.all(demonstrations["season"] == 5) and demonstrations["mm"].sum() > 50.0


def test_the_hindsight_planner_demonstrates_its_own_actions():
    from crop_agent_ros.policies.family_hindsight import HindsightSettings
    cheap = HindsightSettings(scenarios=1, decision_every_days=30, water_step_mm=4.0, offset_step_degc_d=80.0,
                              amounts=9, refined_multipliers=2)
    data = imitation.demonstrate("benton-quota", np.array([5]), cheap, action_noise_mm=0.0, seed=2)
    scenario = get_scenario("benton-quota")
    planner = fm.planner(TaskConstants.of_scenario(scenario), fm.continuation_pool(scenario, 1), cheap)
    episodes = run_episodes(planner, scenario, np.array([5]), seed=2, record=True)
    days = int(episodes.days[0])
    np.testing.assert_array_equal(data["mm"], episodes.daily["irrigation_mm"][:days, 0])
    settings = json.loads(str(data["settings"]))
    assert settings["name"] == "family-hindsight" and settings["refined_multipliers"] == 2
    assert data["mm"].sum() > 50.0


def test_the_recorder_perturbs_what_is_executed_not_the_label():
    class FakeMpc:
        live = np.array([True, True, False])

        def act(self, obs):
            return np.array([0.0, 5.0, 3.0])

    recorder = imitation._Recorder(FakeMpc(), noise_mm=1.0, seed=0)
    obs = np.arange(3 * EXTENDED.size, dtype=float).reshape(3, EXTENDED.size)
    executed = recorder.act(obs)
    assert executed[0] == 0.0 and executed[1] != 5.0 and executed[1] >= 0.0 and abs(executed[1] - 5.0) < 5.0
    np.testing.assert_array_equal(recorder.labels[0], [0.0, 5.0])
    np.testing.assert_array_equal(recorder.observations[0], obs[:2])


def _observations(seasons: int = 24) -> np.ndarray:
    env = IrrigationVectorEnv(seasons, get_scenario("benton-quota"))
    obs, _ = env.reset(seed=0)
    seen = [obs]
    for _ in range(100):
        obs, *_ = env.step(np.full(seasons, 3.0))
        seen.append(obs)
    return np.concatenate(seen)


def test_cloning_fits_the_actor_and_reaches_the_zero_bound_one_sidedly():
    from stable_baselines3 import PPO

    obs = _observations()
    day = obs[:, DAY]
    mm = np.clip(0.3 * (day - 40.0), 0.0, 20.0)  # nothing before day 40, then a ramp to 20 mm
    data = {"observations": obs, "mm": mm, "season": np.tile(np.arange(24), len(obs) // 24), "day": day,
            "file": np.zeros(len(obs), dtype=int), "files": ["synthetic"]}
    interface = AgentInterface(ObservationScaler.fit(obs), 1, "mm")
    model = PPO("MlpPolicy", Spaces((EXTENDED.size,), (1,)), policy_kwargs={"net_arch": [32, 32]}, seed=0, device="cpu")
    report = imitation.clone(model, interface, data, epochs=60, seed=0, log=lambda *a, **k: None)
    assert report["error_on"].startswith("held-out") and report["held_out_samples"] > 0
    assert report["abs_error_mm"] < 0.25 * report["abs_error_mm_before"]
    assert report["abs_error_mm"] < 1.5
    action, _ = model.predict(interface.scaler(obs[day < 30]).astype(np.float32), deterministic=True)
    assert np.mean((action + 1.0) / 2.0 * 25.0) < 0.5  # the 0 mm days: the clipped action is at the bound
    with pytest.raises(UsageError, match="fits the mm action"):
        imitation.clone(model, AgentInterface(interface.scaler, 1, "residual", rule=object()), data, epochs=1, seed=0)


def test_cloning_can_keep_the_epoch_of_least_held_out_error():
    """Labels with noise of their own (as a noisy sensor makes them look to the network): the fit learns the
    training seasons' noise and the held-out error rises after its best epoch. With keep_best the actor ends
    with that epoch's weights: its held-out error, recomputed here from the model, is the least of the run, below
    the last epoch's (the same run without keep_best)."""
    import torch
    from stable_baselines3 import PPO
    obs = _observations(12)
    day = obs[:, DAY]
    season = np.tile(np.arange(12), len(obs) // 12)
    mm = np.clip(0.3 * (day - 40.0), 0.0, 20.0) + np.random.default_rng(5).uniform(0.0, 6.0, len(obs))
    data = {"observations": obs, "mm": mm, "season": season, "day": day,
            "file": np.zeros(len(obs), dtype=int), "files": ["synthetic"]}
    interface = AgentInterface(ObservationScaler.fit(obs), 1, "mm")
    reports, models = {}, {}
    for keep_best in (False, True):
        torch.manual_seed(0)
        models[keep_best] = PPO("MlpPolicy", Spaces((EXTENDED.size,), (1,)), policy_kwargs={"net_arch": [64, 64]},
                                seed=0, device="cpu")
        reports[keep_best] = imitation.clone(models[keep_best], interface, data, epochs=40, seed=0, batch_size=32,
                                             learning_rate=3e-3, log=lambda *a, **k: None, keep_best=keep_best)
    assert reports[False]["kept_epoch"] == 40 and 1 <= reports[True]["kept_epoch"] < 40
    assert reports[True]["abs_error_mm"] < reports[False]["abs_error_mm"]
    held = np.isin(season, reports[True]["held_out_seasons"])
    action, _ = models[True].predict(interface.scaler(obs[held]).astype(np.float32), deterministic=True)
    recomputed = np.mean(np.abs((np.clip(action[:, 0], -1, 1) + 1.0) / 2.0 * 25.0 - np.clip(mm[held], 0, 25)))
    assert recomputed == pytest.approx(reports[True]["abs_error_mm"], abs=2e-3)


def test_with_a_history_the_inputs_are_the_stacks_the_agent_sees():
    """Demonstrations of 3 seasons from 2 files, shuffled: each sample's input is what an agent with a
    3-day history computes when it meets that season's observations day by day."""
    obs = _observations(seasons=3)[:3 * 20]
    season, day = np.tile([7, 8, 7], 20), obs[:, DAY]
    file = np.tile([0, 0, 1], 20)  # season 7 in two files: two episodes
    data = {"observations": obs, "mm": day, "season": season, "day": day.astype(int), "file": file,
            "files": ["a.npz", "b.npz"]}
    shuffle = np.random.default_rng(0).permutation(len(obs))
    shuffled = {k: (v[shuffle] if isinstance(v, np.ndarray) else v) for k, v in data.items()}
    scaler = ObservationScaler.fit(obs)
    inputs, order = imitation.network_inputs(AgentInterface(scaler, 3, "mm"), shuffled)
    assert inputs.shape == (len(obs), 3 * EXTENDED.size)
    agent = AgentInterface(scaler, 3, "mm")
    expected = np.concatenate([agent.observe(obs[3 * t:3 * t + 3])[0] for t in range(20)])  # rows: day-major
    for position, row in enumerate(shuffle[order]):
        np.testing.assert_array_equal(inputs[position], expected[row])
    gap = {**shuffled, "day": np.where(shuffled["day"] == 5, 6, shuffled["day"])}
    with pytest.raises(UsageError, match="does not hold consecutive days from day 0"):
        imitation.network_inputs(AgentInterface(scaler, 3, "mm"), gap)


def test_with_the_soil_water_filter_the_inputs_are_what_the_agent_computes_day_by_day():
    """The same shuffled demonstrations with a filter (and no history): each sample's last input is the
    filter's estimate after that season's observations up to its day, as the agent computes it online;
    seasons of different lengths run side by side."""
    from crop_agent_ros.policies.family import SoilWaterFilter
    obs = _observations(seasons=3)[:3 * 20]
    season, day = np.tile([7, 8, 7], 20), obs[:, DAY]
    file = np.tile([0, 0, 1], 20)
    keep = ~((season == 8) & (day >= 15))  # season 8 ends early
    data = {"observations": obs[keep], "mm": day[keep], "season": season[keep], "day": day[keep].astype(int),
            "file": file[keep], "files": ["a.npz", "b.npz"]}
    shuffle = np.random.default_rng(1).permutation(int(keep.sum()))
    shuffled = {k: (v[shuffle] if isinstance(v, np.ndarray) else v) for k, v in data.items()}
    scaler = ObservationScaler.fit(obs)
    paw_filter = SoilWaterFilter(120.0, sensor_sd_mm=10.0)
    inputs, order = imitation.network_inputs(AgentInterface(scaler, 1, "mm", paw_filter=paw_filter), shuffled)
    assert inputs.shape == (int(keep.sum()), EXTENDED.size + 1)
    agent = AgentInterface(scaler, 1, "mm", paw_filter=SoilWaterFilter(120.0, sensor_sd_mm=10.0))
    expected = np.concatenate([agent.observe(obs[3 * t:3 * t + 3])[0] for t in range(20)])[keep]
    for position, row in enumerate(shuffle[order]):
        np.testing.assert_allclose(inputs[position], expected[row], rtol=1e-6)
    gap = {**shuffled, "day": np.where(shuffled["day"] == 5, 6, shuffled["day"])}
    with pytest.raises(UsageError, match="the soil-water filter needs them"):
        imitation.network_inputs(AgentInterface(scaler, 1, "mm", paw_filter=paw_filter), gap)


def test_a_task_with_more_weather_parts_takes_the_demonstrations_of_one_with_fewer(tmp_path, demonstrations):
    # climates3-quota = climates-quota's two parts + early-planted Benton (benton-early-quota's only part)
    assert imitation.serves("climates-quota", "climates3-quota")
    assert imitation.serves("benton-early-quota", "climates3-quota")
    assert not imitation.serves("climates3-quota", "climates-quota")  # a part the smaller task does not hold
    assert not imitation.serves("climates-quota", "benton-quota")
    assert not imitation.serves("benton-early-quota", "benton-sensing")  # another sensor: other observations
    # another pivot (5.5 mm/d, the observation's capacity column says so) on a part the task holds: served
    assert imitation.serves("benton-early-pivot", "climates3-quota")
    assert imitation.serves("benton-early-pivot", "benton-early-quota")
    assert not imitation.serves("benton-early-pivot", "climates-quota")  # its part is not climates-quota's
    assert not imitation.serves("benton-money", "benton-quota")  # no quota: not only the capacity differs
    early = tmp_path / "early.npz"
    np.savez_compressed(early, **{**demonstrations, "task": "benton-early-quota"})
    assert len(imitation.load_demonstrations([str(early)], "climates3-quota")["mm"]) == len(demonstrations["mm"])
    with pytest.raises(UsageError, match="demonstrations of 'benton-early-quota'"):
        imitation.load_demonstrations([str(early)], "climates-quota")


def test_a_column_the_training_task_holds_constant_is_scaled_over_the_demonstrations_too():
    capacity, quota = EXTENDED.index("capacity_mm_per_day"), EXTENDED.index("quota_remaining_mm")
    rng = np.random.default_rng(3)
    task_obs = rng.uniform(1.0, 2.0, (200, EXTENDED.size))
    task_obs[:, capacity], task_obs[:, 22] = 8.0, 0.0  # one pivot; no event cost
    demos = rng.uniform(1.0, 2.0, (300, EXTENDED.size))
    demos[:, capacity], demos[:, 22] = 5.5, 0.0  # another pivot
    own, widened = ObservationScaler.fit(task_obs), ObservationScaler.fit(task_obs, demos)
    both = np.concatenate([task_obs, demos])
    assert widened.mean[capacity] == pytest.approx(both[:, capacity].mean())  # 6.5
    assert widened.std[capacity] == pytest.approx(both[:, capacity].std())
    # the demonstrations' pivot was at the -10 clip under the task's own scaling, and is not now
    assert own(demos[:1])[0, capacity] == -10.0
    assert -3.0 < widened(demos[:1])[0, capacity] < 0.0 < widened(task_obs[:1])[0, capacity] < 3.0
    # columns the task varies keep its scaling; a column constant in both stays at the floor
    assert widened.mean[quota] == own.mean[quota] and widened.std[quota] == own.std[quota]
    assert widened.std[22] == own.std[22] == 1e-3
    assert ObservationScaler.fit(task_obs, task_obs[:50]) == own


def test_bad_demonstration_files_are_refused(tmp_path, demonstrations):
    good = tmp_path / "good.npz"
    np.savez_compressed(good, **demonstrations)
    loaded = imitation.load_demonstrations([str(tmp_path / "*.npz")], "benton-quota")
    assert len(loaded["mm"]) == len(demonstrations["mm"]) and loaded["files"] == [str(good)]
    with pytest.raises(UsageError, match="demonstrations of 'benton-quota', a task that differs from 'benton-sensing'"):
        imitation.load_demonstrations([str(good)], "benton-sensing")
    with pytest.raises(UsageError, match="no demonstration file matches"):
        imitation.load_demonstrations([str(tmp_path / "none-*.npz")], "benton-quota")
    np.savez_compressed(tmp_path / "bad.npz", **{**demonstrations, "mm": -demonstrations["mm"] - 1.0})
    with pytest.raises(UsageError, match="mm >= 0"):
        imitation.load_demonstrations([str(tmp_path / "bad.npz")], "benton-quota")
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(UsageError, match="junk.npz"):
        imitation.load_demonstrations([str(tmp_path / "junk.npz")], "benton-quota")


def test_train_imitate_writes_a_policy_that_acts_like_its_demonstrations(tmp_path, demonstrations):
    np.savez_compressed(tmp_path / "demo.npz", **demonstrations)
    out = tmp_path / "run"
    summary = tiny_task_training(out, "benton-quota", 1, "--imitate", str(tmp_path / "demo.npz"),
                                 "--imitation-epochs", "200", timesteps=256, net_arch="32,32")
    assert summary["imitation"]["samples"] + summary["imitation"]["held_out_samples"] == len(demonstrations["mm"])
    first = LearnedPolicy(sorted(out.glob("checkpoint_*.zip"))[0])  # after cloning, before any PPO update
    assert json.loads(first.path.with_suffix(".json").read_text())["imitation"]["epochs"] == 200
    assert summary["imitation"]["kept_epoch"] == 200  # without --imitation-keep-best: the last epoch
    error = np.abs(first.act(demonstrations["observations"].astype(float)) - demonstrations["mm"])
    assert error.mean() < 1.0, error.mean()  # one season's 140 days, fitted 200 epochs: memorised
    # the run's 1 % policy: after 2 of the 200 cloning epochs, further from the demonstrations
    early = LearnedPolicy(out / "early_model.zip")
    early_config = json.loads((out / "early_model.json").read_text())
    assert early_config["timesteps_at_save"] == 0 and "after 2 of 200" in early_config["imitation"]["early_model"]
    early_error = np.abs(early.act(demonstrations["observations"].astype(float)) - demonstrations["mm"])
    assert early_error.mean() > 2.0 * error.mean()


def test_es_after_cloning_starts_from_the_cloned_network_and_keeps_the_clonings_1_percent_policy(tmp_path,
                                                                                               demonstrations):
    """--imitate with --algorithm es: the same cloning as PPO's (same seed), then ES moves the cloned network."""
    from crop_agent_ros.learning.evolution import ActorVector
    np.savez_compressed(tmp_path / "demo.npz", **demonstrations)
    cloning = ("--imitate", str(tmp_path / "demo.npz"), "--imitation-epochs", "20")
    tiny_task_training(tmp_path / "ppo", "benton-quota", 1, *cloning, timesteps=256, net_arch="16")
    tiny_task_training(tmp_path / "es", "benton-quota", 1, *cloning, "--algorithm", "es", "--es-pairs", "3",
                       "--es-seasons", "3", "--es-noise-std", "0.3", "--eval-freq", "40000", timesteps=60_000,
                       net_arch="16")

    def actor(path):
        return ActorVector(LearnedPolicy(path).model.policy).get()

    first = {run: sorted((tmp_path / run).glob("checkpoint_*.zip"))[0] for run in ("ppo", "es")}
    assert first["es"].name == "checkpoint_000000000.zip"
    np.testing.assert_array_equal(actor(first["es"]), actor(first["ppo"]))  # the cloned network
    np.testing.assert_array_equal(actor(tmp_path / "es" / "early_model.zip"),  # the cloning's 1 % policy
                                  actor(tmp_path / "ppo" / "early_model.zip"))
    assert "after 1 of 20" in json.loads((tmp_path / "es" / "early_model.json").read_text())["imitation"]["early_model"]
    assert not np.array_equal(actor(tmp_path / "es" / "final_model.zip"), actor(first["es"]))  # ES moved it


def test_a_smaller_pivots_demonstrations_train_the_task_and_set_the_capacity_columns_scaling(tmp_path):
    # the planner on a 5.5 mm/d pivot plans within it; its file trains the 8 mm/d task, whose own seasons
    # hold the capacity column constant: the run's scaler takes that column from the demonstrations
    small = imitation.demonstrate("benton-early-pivot", np.array([5]), CHEAP, action_noise_mm=0.0, seed=2)
    capacity = EXTENDED.index("capacity_mm_per_day")
    assert np.all(small["observations"][:, capacity] == 5.5) and small["mm"].max() <= 5.5
    assert small["mm"].sum() > 50.0
    np.savez_compressed(tmp_path / "small.npz", **small)
    out = tmp_path / "run"
    tiny_task_training(out, "benton-early-quota", 1, "--imitate", str(tmp_path / "small.npz"),
                       "--imitation-epochs", "2", timesteps=256)
    config = json.loads((out / "model.json").read_text())
    mean, std = config["scaler"]["mean"][capacity], config["scaler"]["std"][capacity]
    assert 5.5 < mean < 8.0 and std > 0.1  # the task's 8 mm/d days and the file's 5.5 together
    policy = LearnedPolicy(out / "model.zip")
    assert np.all(np.abs(policy.interface.scaler(small["observations"])[:, capacity]) < 10.0)


@pytest.mark.parametrize("arguments, message", [
    (["--task", "benton-generated", "--seasons", "0..1"], "is not a family task"),
    (["--task", "benton-quota", "--seasons", "5..1"], "--seasons: '5..1' names no season"),
    (["--task", "benton-quota", "--seasons", "0..1000"], "must lie within 0..999"),
    (["--task", "climates-quota", "--seasons", "999..1000"], "must lie within 0..999 (of each part"),
    (["--task", "benton-quota", "--seasons", "0..1", "--action-noise-mm", "-1"], "--action-noise-mm: expected"),
    (["--task", "benton-quota", "--seasons", "0..1", "--scenarios", "0"], "scenarios and decision_every_days"),
])
def test_demonstrate_refuses_bad_input_with_one_line(tmp_path, capsys, arguments, message):
    from crop_agent_ros.cli import main
    assert main(["demonstrate", *arguments, "--out", str(tmp_path / "d.npz")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("crop-sim demonstrate: ") and message in err, err
    assert not (tmp_path / "d.npz").exists()


def test_with_a_behaviour_policy_the_agent_acts_and_the_mpc_labels(demonstrations, tmp_path):
    from crop_agent_ros.policies.rollout import run_episodes as run
    np.savez_compressed(tmp_path / "demo.npz", **demonstrations)
    tiny_task_training(tmp_path / "run", "benton-quota", 0, "--imitate", str(tmp_path / "demo.npz"),
                       "--imitation-epochs", "3", timesteps=64, net_arch="8")
    agent = tmp_path / "run" / "model.zip"
    dagger = imitation.demonstrate("benton-quota", np.array([5]), CHEAP, action_noise_mm=0.0, seed=2,
                                   behaviour_path=str(agent))
    applied = run(LearnedPolicy(agent), "benton-quota", np.array([5]), seed=2, record=True)
    days = int(applied.days[0])
    # the states are the agent's (its applied water shows in the next day's observation) ...
    yesterday = EXTENDED.index("irrigation_yesterday_mm")
    np.testing.assert_allclose(dagger["observations"][1:days, yesterday], applied.daily["irrigation_mm"][:days - 1, 0],
                               atol=1e-4)
    # ... and the labels are not the agent's actions (a 3-epoch clone is far from the planner)
    assert np.abs(dagger["mm"][:days] - applied.daily["irrigation_mm"][:days, 0]).mean() > 0.5
    with pytest.raises(UsageError, match="trained on 'benton-quota', not 'benton-sensing'"):
        imitation.demonstrate("benton-sensing", np.array([5]), CHEAP, 0.0, 2, behaviour_path=str(agent))


def test_a_mixture_is_demonstrated_on_each_climate_with_its_own_continuations():
    """climates-quota: position 3 of each climate is pool seasons 3 (Benton) and 1003 (Gainesville); the
    Gainesville field's labels are those of an MPC that has only Gainesville's continuations."""
    data = imitation.demonstrate("climates-quota", np.array([3]), CHEAP, action_noise_mm=0.0, seed=4)
    assert sorted(np.unique(data["season"])) == [3, 1003]
    scenario = get_scenario("climates-quota")
    gainesville_only = fm.FamilyMpcPolicy(TaskConstants.of_scenario(scenario),
                                          {"gainesville": fm.continuation_pool(get_scenario("gainesville-generated"), 1)["gainesville"]},
                                          CHEAP)
    both = run_episodes(gainesville_only, scenario, np.array([3, 1003]), seed=4, record=True)
    days = int(both.days[1])
    mine = data["season"] == 1003
    np.testing.assert_array_equal(data["day"][mine], np.arange(days))
    np.testing.assert_array_equal(data["mm"][mine], both.daily["irrigation_mm"][:days, 1])
    assert data["mm"][mine].sum() > 0.0


def test_a_sensing_task_is_demonstrated_with_the_quota_tasks_labels_without_planning(tmp_path):
    """The planners read no PAW sensor and benton-sensing draws benton-quota's weather and terms, so re-running
    a benton-quota file on benton-sensing (--labels-from) gives what planning on benton-sensing gives: the same
    labels, the executed noise drawn the same way, the sensing task's own observations."""
    quota = imitation.demonstrate("benton-quota", np.array([5, 6]), CHEAP, action_noise_mm=1.0, seed=3)
    np.savez_compressed(tmp_path / "quota.npz", **quota)
    planned = imitation.demonstrate("benton-sensing", np.array([5, 6]), CHEAP, action_noise_mm=1.0, seed=3)
    replayed = imitation.demonstrate_with_labels_of("benton-sensing", str(tmp_path / "quota.npz"))
    for key in ("observations", "mm", "season", "day", "episode_return_usd_ha"):
        np.testing.assert_array_equal(replayed[key], planned[key], err_msg=key)
    paw_observed = EXTENDED.index("paw_observed")
    assert 0 < replayed["observations"][:, paw_observed].mean() < 1  # the sensing task's dropouts ...
    assert np.all(quota["observations"][:, paw_observed] == 1)        # ... where the quota task reads every day
    made = json.loads(str(replayed["settings"]))
    assert made["labels_from"] == str(tmp_path / "quota.npz") and made["seed"] == 3 and made["seasons"] == [5, 6]


def test_labels_are_taken_only_from_a_file_whose_states_this_task_reaches(tmp_path, demonstrations):
    np.savez_compressed(tmp_path / "quota.npz", **demonstrations)
    with pytest.raises(UsageError, match=r"season 5, day 0: quota_remaining_mm is 1000 here and [0-9.]+ in the file"):
        imitation.demonstrate_with_labels_of("benton-capacity", str(tmp_path / "quota.npz"))
    longer = dict(demonstrations, observations=np.r_[demonstrations["observations"], demonstrations["observations"][-1:]],
                  mm=np.r_[demonstrations["mm"], 3.0], season=np.r_[demonstrations["season"], 5],
                  day=np.r_[demonstrations["day"], 900])
    np.savez_compressed(tmp_path / "longer.npz", **longer)
    with pytest.raises(UsageError, match=f"reached {len(demonstrations['mm'])} of the file's {len(demonstrations['mm']) + 1} field-days"):
        imitation.demonstrate_with_labels_of("benton-quota", str(tmp_path / "longer.npz"))
    settings = json.loads(str(demonstrations["settings"]))
    np.savez_compressed(tmp_path / "dagger.npz", **dict(demonstrations, settings=json.dumps({**settings, "behaviour": "a.zip"})))
    with pytest.raises(UsageError, match="visited reading its own task's observations"):
        imitation.demonstrate_with_labels_of("benton-sensing", str(tmp_path / "dagger.npz"))


def test_demonstrate_labels_from_refuses_a_teacher_of_its_own(tmp_path, capsys, demonstrations):
    from crop_agent_ros.cli import main
    np.savez_compressed(tmp_path / "quota.npz", **demonstrations)
    assert main(["demonstrate", "--task", "benton-sensing", "--labels-from", str(tmp_path / "quota.npz"),
                 "--seasons", "0..1", "--method", "mean-plan", "--out", str(tmp_path / "d.npz")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the seasons, seed, noise and teacher are the file's; drop --seasons, --method" in err, err
    assert main(["demonstrate", "--task", "benton-sensing", "--labels-from", str(tmp_path / "quota.npz"),
                 "--out", str(tmp_path / "d.npz")]) == 0
    with np.load(tmp_path / "d.npz") as written:
        np.testing.assert_array_equal(written["mm"], demonstrations["mm"])
        assert str(written["task"]) == "benton-sensing"


def test_the_default_teacher_is_the_expected_value_planner(tmp_path, monkeypatch, demonstrations):
    from crop_agent_ros.cli import main
    from crop_agent_ros.policies.family_expected import ExpectedSettings
    taught = {}

    def record(task, seasons, settings, noise_mm, seed, behaviour):
        taught.update(settings=settings, noise_mm=noise_mm, seed=seed)
        return demonstrations

    monkeypatch.setattr(imitation, "demonstrate", record)
    assert main(["demonstrate", "--task", "benton-quota", "--seasons", "0..1", "--out", str(tmp_path / "d.npz")]) == 0
    assert taught == {"settings": ExpectedSettings(), "noise_mm": 1.0, "seed": 0}
