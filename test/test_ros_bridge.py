"""The Gymnasium bridge over ROS equals the offline environment: same seed and actions -> the same
observations (bit for bit), rewards, terminated and truncated flags, for whole seasons."""

from __future__ import annotations

import numpy as np
import pytest

import ros_support  # noqa: E402  (private ROS_DOMAIN_ID before any context exists)

from crop_agent_ros.ros.bridge import RosIrrigationEnv  # noqa: E402
from crop_sim_ros.task import IrrigationEnv  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    process, name, log = ros_support.start_sim(tmp_path_factory.mktemp("bridge"))
    yield name, log
    assert process.stop() == 0, process.output()


@pytest.fixture(scope="module", params=["topic", "service"])
def bridge(sim, request):
    """The bridge both ways: stepping commands answered on topics, and command + acknowledgement + ~/step
    service (whose observations are checked against the observation topic bit for bit)."""
    name, _ = sim
    env = RosIrrigationEnv(sim_node=name, verify_topics=True, via=request.param)
    yield env
    env.close()


def run_season(env, rng, seed, options=None):
    """(observations, rewards, terminated, truncated) of one season with random actions (some outside the
    action space, clipped by both environments)."""
    obs, _ = env.reset(seed=seed, options=options)
    observations, rewards, flags = [obs], [], []
    done = False
    while not done:
        action = np.array([rng.choice([0.0, rng.uniform(0, 30), rng.uniform(-5, 130)])], dtype=np.float32)
        obs, reward, terminated, truncated, _ = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        flags.append((terminated, truncated))
        done = terminated or truncated
    return np.stack(observations), rewards, flags


def test_spaces_are_the_offline_spaces(bridge):
    offline = IrrigationEnv()
    assert bridge.observation_space == offline.observation_space
    assert bridge.action_space == offline.action_space


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bridge_equals_offline_for_whole_seasons(bridge, seed):
    offline = IrrigationEnv()
    ours = run_season(bridge, np.random.default_rng(seed), seed)
    theirs = run_season(offline, np.random.default_rng(seed), seed)
    assert ours[0].dtype == theirs[0].dtype == np.float32
    assert ours[0].tobytes() == theirs[0].tobytes(), "observations bit for bit"
    assert ours[1] == theirs[1], "rewards exactly"
    assert ours[2] == theirs[2], "terminated / truncated"
    assert ours[2][-1][0] or ours[2][-1][1]


def test_unseeded_resets_continue_the_stream_like_gymnasium(bridge):
    offline = IrrigationEnv()
    rng_a, rng_b = np.random.default_rng(7), np.random.default_rng(7)
    a = [run_season(bridge, rng_a, 5)] + [run_season(bridge, rng_a, None) for _ in range(2)]
    b = [run_season(offline, rng_b, 5)] + [run_season(offline, rng_b, None) for _ in range(2)]
    for ours, theirs in zip(a, b):
        assert ours[0].tobytes() == theirs[0].tobytes() and ours[1] == theirs[1] and ours[2] == theirs[2]


def test_chosen_weather_season(bridge):
    offline = IrrigationEnv()
    ours = run_season(bridge, np.random.default_rng(3), 3, options={"season": 17})
    theirs = run_season(offline, np.random.default_rng(3), 3, options={"season": 17})
    assert ours[0].tobytes() == theirs[0].tobytes() and ours[1] == theirs[1]
    with pytest.raises(ValueError):
        bridge.reset(options={"weather": None})
    with pytest.raises(ValueError):
        bridge.step(np.array([np.nan]))


def test_bridge_on_a_real_weather_scenario(tmp_path, shared_data):
    """The paper's season (AgWeatherNet Benton E. 2000): the simulator switches scenario at reset."""
    offline = IrrigationEnv("benton-2000")
    process, name, _ = ros_support.start_sim(tmp_path)
    try:
        env = RosIrrigationEnv(sim_node=name, scenario="benton-2000")
        try:
            ours = run_season(env, np.random.default_rng(1), 1)
            theirs = run_season(offline, np.random.default_rng(1), 1)
        finally:
            env.close()
        assert ours[0].tobytes() == theirs[0].tobytes() and ours[1] == theirs[1] and ours[2] == theirs[2]
    finally:
        assert process.stop() == 0, process.output()
