"""The residual agent (``--algorithm es --hyperparams residual=true``): a network correcting the task's tuned
paced rule. It starts at the rule exactly, its file carries the rule, it loads and acts as it trained, and what
it cannot do is refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from crop_agent_ros.policies.family_tuning import paced_rule_record, tuned_rule
from crop_agent_ros.policies.learned import RESIDUAL_SPAN_MM, LearnedPolicy, residual_to_mm
from crop_agent_ros.policies.rollout import draw_terms, run_episodes
from crop_sim_ros.task.layout import EXTENDED
from crop_sim_ros.task.scenario import get_scenario
from policy_files import tiny_task_training


def test_the_residual_corrects_the_rules_mm_within_its_span_and_the_pivots_reach():
    rule_mm = np.array([0.0, 5.0, 5.0, 20.0, 3.0])
    action = np.array([-1.0, 0.0, 0.5, 1.0, -2.0])  # -2: clipped to -1 first
    np.testing.assert_allclose(residual_to_mm(action, rule_mm), [0.0, 5.0, 5.0 + 0.5 * RESIDUAL_SPAN_MM, 25.0, 0.0])


@pytest.fixture(scope="module")
def residual_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("residual") / "run"
    summary = tiny_task_training(out, "benton-quota", 1, "es", timesteps=60_000, net_arch=(16,), eval_freq=20_000,
                                 noise_std=0.3, residual=True)
    return summary, out


def test_a_residual_run_starts_at_the_rule_and_its_file_carries_the_rule(residual_run):
    _, out = residual_run
    rule = tuned_rule("benton-quota", "paced-rule")
    config = json.loads((out / "model.json").read_text())
    assert config["action_kind"] == "residual" and config["hyper_parameters"]["residual"] is True
    assert config["residual_rule"] == json.loads(json.dumps(paced_rule_record(rule)))
    seasons = np.arange(3)
    terms = draw_terms(get_scenario("benton-quota"), seasons, 7)
    by_rule = run_episodes(rule, "benton-quota", seasons, seed=5, terms=terms)
    # the step-0 checkpoint (zero last layer) is the rule, bit for bit
    start = LearnedPolicy(out / "checkpoint_000000000.zip")
    assert start.interface.input_size == EXTENDED.size + 1 and start.describe()["action_kind"] == "residual"
    at_start = run_episodes(start, "benton-quota", seasons, seed=5, terms=terms)
    np.testing.assert_array_equal(at_start.episode_return, by_rule.episode_return)
    np.testing.assert_array_equal(at_start.water_mm, by_rule.water_mm)
    # training moved the network: the final policy is not the rule
    final = run_episodes(LearnedPolicy(out / "final_model.zip"), "benton-quota", seasons, seed=5, terms=terms)
    assert not np.array_equal(final.episode_return, by_rule.episode_return)


def test_the_loaded_residual_sees_the_rules_proposal_and_acts_as_the_rule_plus_its_correction(residual_run):
    _, out = residual_run
    policy = LearnedPolicy(out / "final_model.zip")
    rule = tuned_rule("benton-quota", "paced-rule")
    from crop_sim_ros.task import IrrigationVectorEnv
    env = IrrigationVectorEnv(3, "benton-quota")
    obs, _ = env.reset(seed=11)
    policy.reset()
    rule.reset()
    for _ in range(60):
        inputs, _ = policy.interface.observe(obs)
        proposal = rule.act(obs)
        np.testing.assert_allclose(inputs[:, -1], proposal / RESIDUAL_SPAN_MM, rtol=1e-6)
        action, _ = policy.model.predict(inputs, deterministic=True)
        mm = policy.interface.to_mm(action)
        np.testing.assert_allclose(mm, residual_to_mm(action, proposal))
        obs, *_ = env.step(mm)


def test_what_a_residual_cannot_do_is_refused_in_one_line(tmp_path, residual_run):
    from crop_sim_ros.usage import UsageError
    with pytest.raises(UsageError, match="backend jax has no paced rule inside its rollout"):
        tiny_task_training(tmp_path / "j", "benton-quota", 0, "es", residual=True, backend="jax")
    with pytest.raises(UsageError, match=r"residual=true corrects the task's tuned paced rule: .*family_benton-"
                                         r"capacity-paced\.json is missing: run `crop-sim tune-rule --task "
                                         r"benton-capacity --rule paced-rule`"):
        tiny_task_training(tmp_path / "c", "benton-capacity", 0, "es", residual=True)
    assert not (tmp_path / "j" / "model.zip").exists() and not (tmp_path / "c" / "model.zip").exists()
    # a file whose rule is broken is refused at load, naming the file and the entry
    _, out = residual_run
    broken = tmp_path / "broken"
    broken.mkdir()
    config = json.loads((out / "model.json").read_text())
    config["residual_rule"]["parameters"]["pace"] = "fast"
    (broken / "model.json").write_text(json.dumps(config))
    (broken / "model.zip").write_bytes((out / "model.zip").read_bytes())
    with pytest.raises(ValueError, match=r"model\.json: residual_rule: parameter pace must be a finite number") as e:
        LearnedPolicy(broken / "model.zip")
    assert "\n" not in str(e.value)


def test_without_weather_inputs_the_network_sees_the_climate_columns_at_their_training_mean(tmp_path):
    from crop_agent_ros.policies.learned import CLIMATE_COLUMNS
    out = tmp_path / "blind"
    tiny_task_training(out, "benton-quota", 2, "es", timesteps=20_000, net_arch=(8,), eval_freq=10_000,
                       residual=True, weather_inputs=False)
    config = json.loads((out / "model.json").read_text())
    assert config["weather_inputs"] is False and config["hyper_parameters"]["weather_inputs"] is False
    policy = LearnedPolicy(out / "model.zip")
    assert policy.describe()["weather_inputs"] is False
    from crop_sim_ros.task import IrrigationVectorEnv
    obs, _ = IrrigationVectorEnv(4, "benton-quota").reset(seed=3)
    policy.reset()
    inputs, _ = policy.interface.observe(obs)
    blind = [EXTENDED.index(name) for name in CLIMATE_COLUMNS]
    seen = [i for i in range(EXTENDED.size) if i not in blind]
    assert np.all(inputs[:, blind] == 0.0)
    np.testing.assert_allclose(inputs[:, seen], policy.interface.scaler(obs)[:, seen])
    assert {"rain_mm", "forecast_rain_mm"}.isdisjoint(CLIMATE_COLUMNS) and "et0_mm" in CLIMATE_COLUMNS
    from crop_sim_ros.usage import UsageError
    with pytest.raises(UsageError, match="backend jax sees every observed value"):
        tiny_task_training(tmp_path / "j", "benton-quota", 0, "es", weather_inputs=False, backend="jax")
