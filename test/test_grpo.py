"""PPO with group-relative advantages (``crop-sim train --task T --algorithm grpo``): the advantages by hand, the
groups sharing their season and terms, a tiny run's files, determinism, refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from crop_agent_ros.learning.grpo import group_advantages, group_seasons
from policy_files import tiny_task_training


def test_a_fields_advantage_is_its_return_minus_its_groups_mean_over_the_spread_of_those():
    returns = np.array([1.0, 3.0, 10.0, 14.0, 7.0, 7.0])  # three groups of two
    centred = np.array([-1.0, 1.0, -2.0, 2.0, 0.0, 0.0])
    np.testing.assert_allclose(group_advantages(returns, 2), centred / (np.sqrt(10.0 / 6.0) + 1e-8))
    # the weather's share (a group's common level) does not reach the advantages
    np.testing.assert_allclose(group_advantages(returns + np.repeat([500.0, -300.0, 9e3], 2), 2),
                               group_advantages(returns, 2), atol=1e-12)
    assert np.all(group_advantages(np.full(4, 7.0), 2) == 0.0)


def test_groups_run_distinct_seasons_each_repeated_for_its_fields():
    seasons = group_seasons(np.random.default_rng(0), 1000, 16, 8)
    assert seasons.shape == (128,)
    per_group = seasons.reshape(16, 8)
    assert np.all(per_group == per_group[:, :1]) and len(set(per_group[:, 0])) == 16


def _train(tmp_path, **settings):
    out = tmp_path / "run"
    return tiny_task_training(out, "benton-quota", 1, "grpo", timesteps=2000, eval_freq=1000, **settings), out


def test_a_tiny_grpo_run_shares_each_groups_season_and_terms_and_writes_loadable_policies(tmp_path, monkeypatch):
    import torch
    from crop_agent_ros.policies.learned import LearnedPolicy
    from crop_sim_ros.task import IrrigationVectorEnv
    resets = []
    reset = IrrigationVectorEnv.reset

    def recording_reset(self, *, seed=None, options=None):
        resets.append(options)
        return reset(self, seed=seed, options=options)

    monkeypatch.setattr(IrrigationVectorEnv, "reset", recording_reset)
    summary, out = _train(tmp_path)
    iterations = [o for o in resets if o and len(o.get("season", ())) == 12]
    assert len(iterations) >= 2  # 2,000 field-days of 12 fields' whole seasons
    for options in iterations:
        seasons = np.asarray(options["season"]).reshape(3, 4)
        assert np.all(seasons == seasons[:, :1]) and len(set(seasons[:, 0])) == 3
        for values in options["terms"].values():
            values = np.asarray(values).reshape(3, 4)
            assert np.all(values == values[:, :1])
    assert summary["algorithm"] == "grpo" and summary["steps_run"] >= 2000
    config = json.loads((out / "model.json").read_text())
    hyper = config["hyper_parameters"]
    assert hyper["groups"] == 3 and hyper["group_size"] == 4 and hyper["log_std_init"] == -2.0
    policy = LearnedPolicy(out / "model.zip")  # the headline agent's container: 29 inputs, one action
    assert policy.model.observation_space.shape == (29,)
    early, final = (LearnedPolicy(out / name).model.policy.action_net.weight for name in ("early_model.zip",
                                                                                          "final_model.zip"))
    assert not torch.equal(early, final)  # the learner's actor was published into the files
    # the same seed gives the same run, bit for bit
    again, out_again = _train(tmp_path / "again")
    first = LearnedPolicy(out / "final_model.zip").model.policy.state_dict()
    second = LearnedPolicy(out_again / "final_model.zip").model.policy.state_dict()
    assert all(torch.equal(first[k], second[k]) for k in first)


def test_grpo_refuses_settings_out_of_range_or_of_another_algorithm(tmp_path):
    from crop_sim_ros.usage import UsageError
    for settings, message in (({"group_size": 1}, "hyperparameter group_size 1: Input should be greater than or equal to 2"),
                              ({"groups": 1001}, "hyperparameter groups 1001: Input should be less than or equal to 1000"),
                              ({"gae_lambda": 0.9}, "hyperparameter gae_lambda 0.9: Extra inputs are not permitted")):
        with pytest.raises(UsageError, match=message):
            _train(tmp_path, **settings)
    with pytest.raises(UsageError, match="hyperparameter groups 4: Extra inputs are not permitted"):
        tiny_task_training(tmp_path / "ppo", "benton-quota", 1, "ppo", groups=4)
    assert not (tmp_path / "run").exists() and not (tmp_path / "ppo").exists()
