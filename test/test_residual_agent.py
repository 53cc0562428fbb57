"""The residual variant of the family agent: the tuned rule's action + the network's correction (tiny budgets)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from crop_agent_ros.learning.agent import (ACTION_SCALE_MM, RESIDUAL_SPAN_MM, AgentInterface, LearnedPolicy,
                                           ObservationScaler, residual_to_mm)
from crop_agent_ros.policies.family_tuning import draw_terms, rule_file, tuned_rule
from crop_agent_ros.policies.rollout import run_episodes
from crop_sim_ros.task.layout import EXTENDED
from policy_files import tiny_task_training

TASK = "benton-sensing"  # 33 % of PAW readings missing: the rule's checkbook state matters


def _train(out, *extra: str) -> dict:
    return tiny_task_training(out, TASK, 5, "--action", "residual", *extra)


@pytest.fixture(scope="module")
def residual_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("residual") / "run"
    return _train(out), out


def _first_checkpoint(out):
    """The run's checkpoint saved after its first environment step: the zero-initialised network."""
    return sorted(out.glob("checkpoint_*.zip"))[0]


def test_residual_maps_the_correction_onto_the_rule_and_clips():
    rule_mm = np.array([0.0, 5.0, 20.0, 20.0, 3.0, 7.5])
    action = np.array([1.0, -1.0, 0.5, 1.0, 0.0, 4.0])  # the last asks more than the network's range
    # by hand: 0 + 10, 5 - 10 -> 0, 20 + 5 = 25, 20 + 10 -> 25, 3 + 0, 7.5 + 10 (a clipped to 1)
    np.testing.assert_allclose(residual_to_mm(action, rule_mm), [10.0, 0.0, 25.0, 25.0, 3.0, 17.5])
    assert RESIDUAL_SPAN_MM == 10.0 and ACTION_SCALE_MM == 25.0


def test_interface_refuses_an_unknown_kind_or_a_missing_rule():
    scaler = ObservationScaler((0.0,) * EXTENDED.size, (1.0,) * EXTENDED.size)
    with pytest.raises(ValueError, match="action kind 'margin' is not one of mm, residual"):
        AgentInterface(scaler, 1, "margin")
    with pytest.raises(ValueError, match="needs the rule it corrects"):
        AgentInterface(scaler, 1, "residual")
    with pytest.raises(RuntimeError, match="observe the day first"):
        AgentInterface(scaler, 1, "residual", tuned_rule(TASK)).to_mm(np.zeros(2))


def test_zero_correction_reproduces_the_tuned_rule_exactly(residual_run):
    from crop_sim_ros.task.scenario import get_scenario
    summary, out = residual_run
    policy = LearnedPolicy(_first_checkpoint(out))
    assert policy.interface.action_kind == "residual" and policy.describe()["action_kind"] == "residual"
    seasons = np.arange(4)
    terms = draw_terms(get_scenario(TASK), seasons, 11)
    for seed in (0, 3):
        agent = run_episodes(policy, TASK, seasons, seed=seed, terms=terms)
        rule = run_episodes(tuned_rule(TASK), TASK, seasons, seed=seed, terms=terms)
        np.testing.assert_array_equal(agent.episode_return, rule.episode_return)
        np.testing.assert_array_equal(agent.water_mm, rule.water_mm)
        assert rule.water_mm.min() > 50.0  # the rule irrigates: a match is not two policies that never irrigate
    # the run's validation curve starts at the tuned rule's validation return
    import csv
    with open(out / "learning_curve.csv", newline="") as f:
        first = next(csv.DictReader(f))
    assert float(first["validation_return"]) == pytest.approx(summary["tuned_rule_validation_return"], abs=1e-9)


@pytest.mark.parametrize("bias", [0.3, -0.5])
def test_a_loaded_residual_policy_adds_its_correction_to_an_independent_rule(residual_run, tmp_path, bias):
    import shutil
    import torch
    from stable_baselines3 import PPO
    from crop_sim_ros.task import IrrigationVectorEnv
    _, out = residual_run
    source = _first_checkpoint(out)
    model = PPO.load(str(source), device="cpu")
    with torch.no_grad():
        model.policy.action_net.bias.fill_(bias)  # the weights are zero: a = bias on every field, every day
    model.save(tmp_path / "shifted.zip")
    shutil.copyfile(source.with_suffix(".json"), tmp_path / "shifted.json")
    policy = LearnedPolicy(tmp_path / "shifted.zip")
    reference = tuned_rule(TASK)  # fed the same observations; its state is its own
    env = IrrigationVectorEnv(3, TASK)
    obs, _ = env.reset(seed=2, options={"season": np.array([0, 1, 2])})
    policy.reset(2)
    reference.reset(2)
    clipped = shifted = 0
    for _ in range(90):
        mm = policy.act(obs)
        rule_mm = reference.act(obs)
        expected = np.clip(rule_mm + 10.0 * bias, 0.0, 25.0)
        np.testing.assert_allclose(mm, expected, rtol=0, atol=1e-5)
        clipped += int(np.sum(rule_mm + 10.0 * bias < 0.0))
        shifted += int(np.sum((rule_mm + 10.0 * bias > 0.0) & (rule_mm > 0.0)))
        obs, *_ = env.step(mm)
    assert shifted > 0 and (clipped > 0) == (bias < 0)  # both branches met (the rule asks 0..8 mm)


def test_training_env_feeds_the_rule_every_observation_and_restarts_it_per_field():
    """The training wrapper's residual with a = 0 sends, field by field, what a rule of its own (reset at each
    of the field's season starts, as a rollout resets a policy) asks for the same observations, while the
    fields start new seasons at different steps; a season's last observation is bootstrapped with the rule's
    proposal for it."""
    import copy
    from crop_agent_ros.learning.train_task import fit_scaler, training_env
    from crop_sim_ros.task.scenario import get_scenario
    scenario = get_scenario(TASK)
    interface = AgentInterface(fit_scaler(scenario, 0, seasons=4), 2, "residual", tuned_rule(TASK))
    venv = training_env(scenario, 3, 7, interface, 0.9, 0.2)
    inner = venv.venv
    sent, raws, raw_infos = [], [], []
    step_async, step_wait, reset = inner.step_async, inner.step_wait, inner.reset

    def recording_async(actions):
        sent.append(np.array(actions, dtype=float).reshape(-1))
        step_async(actions)

    def recording_wait():
        raw, rewards, dones, infos = step_wait()
        raws.append(np.array(raw, dtype=float))
        raw_infos.append([dict(info) for info in infos])  # before the wrapper replaces terminal observations
        return raw, rewards, dones, infos

    def recording_reset():
        raw = reset()
        raws.append(np.array(raw, dtype=float))
        return raw

    inner.step_async, inner.step_wait, inner.reset = recording_async, recording_wait, recording_reset
    inputs = venv.reset()
    assert inputs.shape == (3, 2 * EXTENDED.size + 1)
    wrapped_infos = []
    for _ in range(330):
        venv.step_async(np.zeros((3, 1), dtype=np.float32))
        inputs, _, _, infos = venv.step_wait()
        wrapped_infos.append(infos)
    day = EXTENDED.index("days_since_sowing")
    restarts = [[t for t in range(1, len(raws)) if raws[t][j][day] < 0.5] for j in range(3)]
    assert all(len(r) >= 2 for r in restarts) and len({r[0] for r in restarts}) > 1  # restarts at other steps
    for j in range(3):
        rule = tuned_rule(TASK)
        for t, raw in enumerate(raws):
            obs = raw[j]
            if obs[day] < 0.5:
                if t > 0:  # the season that just ended: its last observation's input holds the rule's proposal
                    last = raw_infos[t - 1][j]["terminal_observation"]
                    proposal = copy.deepcopy(rule).act(last)
                    assert wrapped_infos[t - 1][j]["terminal_observation"][-1] == np.float32(proposal / 10.0)
                rule.reset()
            proposal = rule.act(obs)
            if t < len(sent):
                assert sent[t][j] == proposal, (j, t)
        assert inputs[j, -1] == np.float32(proposal / 10.0)
    assert np.max(sent) > 0.0


def test_model_json_round_trips_the_rule_and_the_kind(residual_run):
    summary, out = residual_run
    config = json.loads((out / "model.json").read_text())
    tuned = json.loads(rule_file(TASK).read_text())
    assert config["action_kind"] == "residual" and summary["action_kind"] == "residual"
    # every tuned parameter, and the climatological budget the plain rule does not use (null: inf)
    assert config["rule"]["parameters"] == {**tuned["parameters"], "outlook_pace": None}
    assert config["rule"]["facts"] == tuned["facts"]
    assert config["rule"]["file"] == f"family_{TASK}.json"
    policy = LearnedPolicy(out / "model.zip")
    rule = tuned_rule(TASK)
    for name, value in rule.parameters.items():
        assert policy.interface.rule.parameters[name] == value, name
    assert policy.model.observation_space.shape == (EXTENDED.size + 1,)


def test_a_wrong_action_kind_or_a_residual_without_its_rule_is_refused(residual_run, tmp_path):
    import shutil
    _, out = residual_run
    shutil.copyfile(out / "model.zip", tmp_path / "model.zip")
    config = json.loads((out / "model.json").read_text())
    (tmp_path / "model.json").write_text(json.dumps({**config, "action_kind": "margin"}))
    with pytest.raises(ValueError, match=r"model\.json: action_kind 'margin' is not one of mm, residual"):
        LearnedPolicy(tmp_path / "model.zip")
    (tmp_path / "model.json").write_text(json.dumps({k: v for k, v in config.items() if k != "rule"}))
    with pytest.raises(ValueError, match="action_kind 'residual' needs the rule it corrects"):
        LearnedPolicy(tmp_path / "model.zip")
    # a residual network read as an mm agent takes 30 values, not 29: refused at load
    (tmp_path / "model.json").write_text(json.dumps({**config, "action_kind": "mm"}))
    with pytest.raises(ValueError, match=r"the network takes \(30,\).*needs \(29,\)"):
        LearnedPolicy(tmp_path / "model.zip")


def test_training_a_residual_without_the_tasks_tuned_rule_is_refused(tmp_path, monkeypatch):
    from crop_agent_ros.policies import family_tuning
    from crop_sim_ros.usage import UsageError
    missing = tmp_path / "family_benton-sensing.json"
    monkeypatch.setattr(family_tuning, "rule_file", lambda task, outlook=False: missing)
    with pytest.raises(UsageError, match=r"--action residual corrects the task's tuned rule: .*family_benton-sensing"
                                         r"\.json is missing: run `crop-sim tune-rule --task benton-sensing`"):
        _train(tmp_path / "run")
    assert not (tmp_path / "run" / "model.zip").exists()


def test_evolution_strategies_correct_the_rule_from_the_rule_and_grpo_td3_refuse_it(tmp_path):
    """ES's candidates act through the residual interface: its checkpoint before the first generation is the tuned
    rule, its trained policy corrects it (a labelled variant, as PPO's residual)."""
    from crop_sim_ros.task.scenario import get_scenario
    from crop_sim_ros.usage import UsageError
    out = tmp_path / "es"
    _train(out, "--algorithm", "es", "--es-pairs", "3", "--es-seasons", "3", "--es-noise-std", "0.3",
           "--timesteps", "60000", "--eval-freq", "30000")
    config = json.loads((out / "model.json").read_text())
    assert config["algorithm"] == "es" and config["action_kind"] == "residual" and config["rule"]["parameters"]
    seasons = np.arange(3)
    terms = draw_terms(get_scenario(TASK), seasons, 11)
    rule = run_episodes(tuned_rule(TASK), TASK, seasons, seed=2, terms=terms)
    start = run_episodes(LearnedPolicy(_first_checkpoint(out)), TASK, seasons, seed=2, terms=terms)
    np.testing.assert_array_equal(start.episode_return, rule.episode_return)
    trained = run_episodes(LearnedPolicy(out / "model.zip"), TASK, seasons, seed=2, terms=terms)
    assert not np.array_equal(trained.episode_return, rule.episode_return)  # ES moved the correction off zero
    for algorithm in ("grpo", "td3"):
        with pytest.raises(UsageError, match=f"--action residual: for PPO and --algorithm es only, not --algorithm "
                                             f"{algorithm}"):
            _train(tmp_path / algorithm, "--algorithm", algorithm)
