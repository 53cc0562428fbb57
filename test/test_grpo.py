"""PPO with group-relative advantages (``crop-sim train --task T --algorithm grpo``): the advantages by hand, the
groups sharing their season and terms, a tiny run's files, determinism, refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from crop_agent_ros.learning.grpo import GRPO_DEFAULTS, group_advantages, group_seasons
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


def _train(tmp_path, *extra):
    out = tmp_path / "run"
    return tiny_task_training(out, "benton-quota", 1, "--algorithm", "grpo", "--grpo-groups", "3",
                              "--grpo-group-size", "4", "--timesteps", "2000", "--eval-freq", "1000",
                              "--log-std-init", "-2", *extra), out


def test_a_tiny_grpo_run_shares_each_groups_season_and_terms_and_writes_loadable_policies(tmp_path, monkeypatch):
    import torch
    from crop_agent_ros.learning.agent import LearnedPolicy
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
    assert hyper["grpo_groups"] == 3 and hyper["grpo_group_size"] == 4 and hyper["log_std_init"] == -2.0
    policy = LearnedPolicy(out / "model.zip")  # the headline agent's container: 29 inputs, one action
    assert policy.model.observation_space.shape == (29,)
    early, final = (LearnedPolicy(out / name).model.policy.action_net.weight for name in ("early_model.zip",
                                                                                          "final_model.zip"))
    assert not torch.equal(early, final)  # the learner's actor was published into the files
    # the same seed gives the same run, bit for bit
    again, out_again = tiny_task_training(tmp_path / "again", "benton-quota", 1, "--algorithm", "grpo",
                                          "--grpo-groups", "3", "--grpo-group-size", "4", "--timesteps", "2000",
                                          "--eval-freq", "1000", "--log-std-init", "-2"), tmp_path / "again"
    first = LearnedPolicy(out / "final_model.zip").model.policy.state_dict()
    second = LearnedPolicy(out_again / "final_model.zip").model.policy.state_dict()
    assert all(torch.equal(first[k], second[k]) for k in first)


def test_grpo_fills_its_own_defaults_and_is_refused_with_what_it_does_not_have(tmp_path):
    import argparse
    from crop_agent_ros.learning import train
    from crop_sim_ros.usage import UsageError
    parser = argparse.ArgumentParser()
    train.add_arguments(parser)
    args = parser.parse_args(["--task", "benton-quota", "--algorithm", "grpo"])
    train.fill_algorithm_defaults(args)
    assert (args.timesteps, args.eval_freq, args.net_arch, args.learning_rate) == (12_000_000, 1_000_000, "64,64", 3e-4)
    assert GRPO_DEFAULTS == {"groups": 16, "group_size": 8}
    for extra, message in ((("--sde", "0"), "--sde: for PPO only, not --algorithm grpo"),
                           (("--critic-hindsight",), "--critic-hindsight: for PPO only, not --algorithm grpo"),
                           (("--imitate", "x.npz"), "--imitate: for PPO and --algorithm es only, not --algorithm grpo"),
                           (("--grpo-group-size", "1"), "--grpo-group-size 1 \\(2..1,000\\): out of range"),
                           (("--grpo-groups", "1001"), "--grpo-groups 1001 \\(1..1,000\\)")):
        with pytest.raises(UsageError, match=message):
            _train(tmp_path, *extra)
    with pytest.raises(UsageError, match="--grpo-groups 40: the training pool has 30 seasons"):
        _train(tmp_path, "--grpo-groups", "40", "--training-seasons", "30")
    with pytest.raises(UsageError, match="--grpo-groups: for --algorithm grpo only"):
        tiny_task_training(tmp_path / "ppo", "benton-quota", 1, "--grpo-groups", "4")
