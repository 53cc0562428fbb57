"""The asymmetric critic (``crop-sim train --task T --critic-hindsight``): the hindsight values by hand, the actor
blind to them, the training environment's values on every day including a season's last, and policy files that
hold the actor alone."""

from __future__ import annotations

import json

import numpy as np
import pytest

from crop_sim_ros.task import IrrigationVectorEnv, get_scenario
from crop_sim_ros.task.core import scenario_table
from crop_sim_ros.task.hindsight import HINDSIGHT_NAMES, SeasonHindsight
from policy_files import tiny_task_training


def _by_hand(table, season: int, day: int) -> list[float]:
    """The documented values, summed day by day (TMAX, SRAD, rain, ET0 are model_weather rows 0, 2, 3, 4)."""
    n = int(table.n_days[season])
    weather = table.model_weather[:, season, :]

    def total(row, days):
        return sum(weather[row, d] for d in range(day, min(day + days, n)))

    values = [table.potential_yield_t_ha[season]]
    for row in (3, 4, 2):
        values += [total(row, days) for days in (7, 21, 63)]
    seen = [weather[0, d] for d in range(day, min(day + 21, n))]
    values.append(sum(seen) / len(seen) if seen else weather[0, n - 1])
    return values


def test_hindsight_values_are_the_weather_still_to_come_summed_by_hand():
    table = scenario_table(get_scenario("benton-quota"))
    hindsight = SeasonHindsight(table)
    n = int(table.n_days[3])
    # mid-season; a window running past the weather; the last day; past the weather (a truncated field)
    cases = [(3, 0), (3, 40), (3, n - 30), (3, n - 1), (3, n + 1), (917, 12)]
    got = hindsight.values([s for s, _ in cases], [d for _, d in cases])
    assert got.shape == (len(cases), len(HINDSIGHT_NAMES)) == (6, 11)
    for row, (season, day) in zip(got, cases):
        np.testing.assert_allclose(row, _by_hand(table, season, day), rtol=1e-12, atol=1e-9)
    assert got[4, 1:10].tolist() == [0.0] * 9  # nothing is left past the weather
    assert got[4, 10] == table.model_weather[0, 3, n - 1]  # the last day's TMAX
    assert np.all(got[0, 1:4] <= got[0, 2:5].max())  # windows grow: 7 <= 21 <= 63 days of rain
    assert got[0, 1] <= got[0, 2] <= got[0, 3]


def test_the_actor_reads_only_its_inputs_and_the_critic_reads_the_hindsight_too():
    import torch
    from stable_baselines3 import PPO
    from crop_agent_ros.learning.asymmetric import HindsightCriticPolicy, actor_container
    from policy_files import Spaces
    model = PPO(HindsightCriticPolicy, Spaces((7,), (1,)), n_steps=8, batch_size=8, seed=0, device="cpu",
                policy_kwargs={"net_arch": [6, 6], "actor_inputs": 4})
    policy = model.policy
    assert policy.mlp_extractor.policy_net[0].in_features == 4
    assert policy.mlp_extractor.value_net[0].in_features == 7
    x = torch.as_tensor(np.random.default_rng(0).normal(size=(5, 7)), dtype=torch.float32)
    changed = x.clone()
    changed[:, 4:] += 3.0  # other hindsight, the same agent inputs
    with torch.no_grad():
        actions = policy.get_distribution(x).distribution.mean
        assert torch.equal(actions, policy.get_distribution(changed).distribution.mean)
        assert not torch.allclose(policy.predict_values(x), policy.predict_values(changed))
        # the container: a standard PPO on the 4 agent inputs acting exactly as the actor does
        container = actor_container(model, 4, {"net_arch": [6, 6]}, {})
        assert container.policy.observation_space.shape == (4,)
        assert type(container.policy).__name__ == "ActorCriticPolicy"
        torch.testing.assert_close(container.policy.get_distribution(x[:, :4]).distribution.mean, actions,
                                   rtol=0, atol=0)


def test_the_training_environment_appends_each_fields_hindsight_also_to_a_seasons_last_observation():
    from crop_agent_ros.learning.agent import AgentInterface
    from crop_agent_ros.learning.asymmetric import HindsightScaler
    from crop_agent_ros.learning.train_task import fit_scaler, training_env
    task = get_scenario("benton-quota")
    table = scenario_table(task)
    hindsight = HindsightScaler(SeasonHindsight(table), table.n_days)
    interface = AgentInterface(fit_scaler(task, 0, seasons=4), 1, "mm", None, None, None)
    venv = training_env(task, 3, 5, interface, 0.8, 0.2, hindsight)
    k = interface.input_size
    assert venv.observation_space.shape == (k + len(HINDSIGHT_NAMES),)
    fields: IrrigationVectorEnv = venv.fields
    inputs = venv.reset()
    ended = 0
    for _ in range(400):
        season, day = fields.field_seasons, fields.field_days
        np.testing.assert_array_equal(inputs[:, k:], hindsight(season, day))
        inputs, _, dones, infos = venv.step(np.full((3, 1), 0.2))
        for i in np.flatnonzero(dones):
            # the ended season's values on the day it ended (the day after the one it stepped from)
            np.testing.assert_array_equal(infos[i]["terminal_observation"][k:],
                                          hindsight(season[i:i + 1], day[i:i + 1] + 1)[0])
            ended += 1
    assert ended >= 3
    assert np.all(np.abs(hindsight.mean) > 0) and hindsight.record()["names"] == list(HINDSIGHT_NAMES)


def test_a_hindsight_run_writes_policy_files_of_the_actor_alone(tmp_path):
    from crop_agent_ros.learning.agent import LearnedPolicy
    from crop_agent_ros.policies.rollout import run_episodes
    summary, out = tiny_task_training(tmp_path / "run", "benton-quota", 1, "--critic-hindsight"), tmp_path / "run"
    config = json.loads((out / "model.json").read_text())
    assert config["critic_hindsight"]["names"] == list(HINDSIGHT_NAMES)
    assert config["hyper_parameters"]["critic_hindsight"] is True
    policy = LearnedPolicy(out / "model.zip")  # the headline agent's loader: the agent's 29 inputs
    assert policy.model.observation_space.shape == (29,)
    first, second = (run_episodes(policy, "benton-quota", np.arange(2), seed=0).episode_return for _ in range(2))
    np.testing.assert_array_equal(first, second)
    # the final actor moved from the first checkpoint's (training happened through the container)
    import torch
    early, final = (LearnedPolicy(out / name).model.policy.mlp_extractor.policy_net[0].weight
                    for name in ("early_model.zip", "final_model.zip"))
    assert not torch.equal(early, final) and summary["steps_run"] >= 512


@pytest.mark.parametrize("extra, message", [
    (("--algorithm", "es"), "--critic-hindsight: for PPO only, not --algorithm es"),
    (("--algorithm", "td3"), "--critic-hindsight: for PPO only, not --algorithm td3"),
    (("--algorithm", "recurrent-ppo"), "--critic-hindsight: for PPO only, not --algorithm recurrent-ppo"),
    (("--imitate", "x.npz"), "--critic-hindsight: for PPO from a fresh network, not with --imitate")])
def test_a_hindsight_critic_is_refused_where_there_is_no_such_critic(tmp_path, extra, message):
    from crop_sim_ros.usage import UsageError
    with pytest.raises((UsageError, SystemExit), match=message):
        tiny_task_training(tmp_path / "run", "benton-quota", 1, "--critic-hindsight", *extra)
