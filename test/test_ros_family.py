"""The ROS side carries the task family: the simulator node serves a family scenario (29-value observation
labelled from its layout, ~/farm_terms, rewards in USD/ha, NaN PAW for a missing reading, cut commands
reported, the season log's extra columns), a scenario change at a reset resizes everything, the bridge equals
the offline environment bit for bit on a benton-quota season, and the agent node runs the family's policies
(budget-rule, agent) and refuses a policy that cannot read the simulator's observation."""

from __future__ import annotations

import json
import math
from datetime import date

import numpy as np
import pytest

import ros_support  # noqa: E402  (private ROS_DOMAIN_ID before any context exists)
from crop_sim_interfaces.msg import CropState, FarmTerms, IrrigationStatus, StepResult  # noqa: E402
from std_msgs.msg import Float32MultiArray  # noqa: E402

from crop_agent_ros.ros.bridge import RosIrrigationEnv  # noqa: E402
from crop_agent_ros.ros.spin import PrivateRos  # noqa: E402
from crop_agent_ros.ros.process import NodeProcess, isolated_ros_env  # noqa: E402
from crop_sim_ros import ros_interface as ri  # noqa: E402
from crop_sim_ros.season_log import LOG_COLUMNS  # noqa: E402
from crop_sim_ros.task import IrrigationEnv  # noqa: E402
from crop_sim_ros.task.layout import EXTENDED, PAPER  # noqa: E402
from crop_sim_ros.task.scenario import get_scenario, load_scenario  # noqa: E402
from policy_files import ppo_file  # noqa: E402

pytestmark = pytest.mark.slow

TIMEOUT_S = 120.0  # any one wait: generous, the machine may be loaded


@pytest.fixture(scope="module")
def quota_sim(tmp_path_factory):
    process, name, log = ros_support.start_sim(tmp_path_factory.mktemp("quota"), params={"scenario": "benton-quota"})
    yield name, log
    assert process.stop() == 0, process.output()


@pytest.fixture(scope="module")
def paper_sim(tmp_path_factory):
    process, name, log = ros_support.start_sim(tmp_path_factory.mktemp("paper"))
    yield name, log
    assert process.stop() == 0, process.output()


def run_season(env, rng, seed):
    """(observations, rewards, flags, applied mm, clipped) of one season with random actions, some beyond the
    pivot's 8 mm/d and the action bound."""
    obs, _ = env.reset(seed=seed)
    observations, rewards, flags, applied, clipped = [obs], [], [], [], []
    done = False
    while not done:
        action = np.array([rng.choice([0.0, rng.uniform(0, 30), rng.uniform(-5, 130)])], dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        flags.append((terminated, truncated))
        applied.append(info["irrigation_applied_mm"])
        clipped.append(info["irrigation_clipped"])
        done = terminated or truncated
    return np.stack(observations), rewards, flags, applied, clipped


@pytest.mark.parametrize("via", ["topic", "service"])
def test_bridge_equals_offline_on_a_benton_quota_season(quota_sim, via):
    name, _ = quota_sim
    offline = IrrigationEnv("benton-quota")
    env = RosIrrigationEnv(sim_node=name, verify_topics=True, via=via, timeout=TIMEOUT_S,
                           connect_timeout=TIMEOUT_S)
    try:
        assert env.observation_space == offline.observation_space and env.observation_space.shape == (29,)
        ours = run_season(env, np.random.default_rng(5), 5)
    finally:
        env.close()
    theirs = run_season(offline, np.random.default_rng(5), 5)
    assert ours[0].dtype == np.float32 and ours[0].shape[1] == 29
    assert ours[0].tobytes() == theirs[0].tobytes(), "observations bit for bit"
    assert ours[1] == theirs[1], "rewards (USD/ha) exactly"
    assert ours[2] == theirs[2] and (ours[2][-1][0] or ours[2][-1][1])
    assert ours[3] == theirs[3] and ours[4] == theirs[4], "irrigation applied after capacity and quota"
    # the season was limited: some commands within the action bound were cut to the 8 mm/d pivot
    assert any(8.0 == a for a in ours[3]) and max(ours[3]) <= 8.0


def test_observation_and_farm_terms_of_a_family_reset(quota_sim):
    name, _ = quota_sim
    seed = 11
    scenario = get_scenario("benton-quota")
    obs_offline, info = IrrigationEnv(scenario).reset(seed=seed)
    with PrivateRos("family_terms") as ros:
        observations, terms = [], []
        ros.node.create_subscription(Float32MultiArray, f"{name}/{ri.OBSERVATION_TOPIC}",
                                     lambda m: observations.append(m), ri.READER_QOS)
        ros.node.create_subscription(FarmTerms, f"{name}/{ri.FARM_TERMS_TOPIC}", terms.append, ri.READER_QOS)
        client = ros_support.connect(ros, name, timeout=TIMEOUT_S)
        obs, summary = client.reset(seed=seed)
        episode = summary["episode"]
        ros.spin_until(lambda: any(m.episode == episode for m in terms) and observations, TIMEOUT_S,
                       "the reset's farm terms and observation")
    assert obs.tobytes() == obs_offline.tobytes() and client.layout is EXTENDED
    message = observations[-1]
    assert message.layout.dim[0].label.split(",") == list(EXTENDED.labels) and message.layout.dim[0].size == 29
    assert np.asarray(message.data, np.float32).tobytes() == obs_offline.tobytes()
    term = next(m for m in terms if m.episode == episode)
    dmf = scenario.economics.tuber_dry_matter_fraction
    expected = dict(zip(ri.TERM_FIELDS, (info["yield_value_per_t"] * dmf, info["water_cost_per_mm"], 0.0,
                                         info["quota_mm"], 8.0)))
    assert {name: getattr(term, name) for name in ri.TERM_FIELDS} == expected
    assert (term.scenario, term.seed, term.reward_unit, term.sowing_date) == ("benton-quota", seed, "USD/ha",
                                                                              info["date"])
    assert term.header.stamp.sec == ri.sim_time(date.fromisoformat(info["date"]), 0).sec
    assert 150.0 <= term.tuber_price_usd_per_t <= 300.0 and 150.0 <= term.quota_mm <= 450.0  # the YAML's ranges
    # the observation carries the same terms (float32)
    for column, value in (("tuber_price_usd_per_t", term.tuber_price_usd_per_t),
                          ("water_cost_usd_per_mm", term.water_cost_usd_per_mm),
                          ("quota_remaining_mm", term.quota_mm), ("capacity_mm_per_day", 8.0)):
        assert obs[EXTENDED.index(column)] == np.float32(value), column
    assert summary["reward_unit"] == "USD/ha" and summary["observation_size"] == 29
    assert summary["farm_terms"] == expected


def test_scenario_changes_at_reset_resize_everything(tmp_path):
    """paper -> a YAML family task with a 10 mm quota -> benton-sensing -> paper, in one simulator: the
    observation (size, labels), step results' labels, farm terms, cut reports, NaN PAW, and the season log."""
    tight = tmp_path / "tight-quota.yaml"
    tight.write_text("base: benton-quota\nname: tight-quota\nlimits:\n  quota_mm: 10\n")
    process, name, log = ros_support.start_sim(tmp_path, params={"scenario": "benton-generated"})
    try:
        with PrivateRos("family_switch") as ros:
            got = {"obs": [], "result": [], "terms": [], "status": [], "crop": []}
            for topic, kind, key in ((ri.OBSERVATION_TOPIC, Float32MultiArray, "obs"),
                                     (ri.STEP_RESULT_TOPIC, StepResult, "result"),
                                     (ri.FARM_TERMS_TOPIC, FarmTerms, "terms"),
                                     (ri.CROP_STATE_TOPIC, CropState, "crop")):
                ros.node.create_subscription(kind, f"{name}/{topic}", lambda m, k=key: got[k].append(m),
                                             ri.READER_QOS)
            ros.node.create_subscription(IrrigationStatus, f"{name}/{ri.IRRIGATION_STATUS_TOPIC}",
                                         got["status"].append, ri.COMMAND_QOS)
            client = ros_support.connect(ros, name, via="service", verify_topics=True, timeout=TIMEOUT_S)

            def season(scenario, seed, actions):
                """Reset with ``scenario`` and step ``actions``: (observations, summaries) through ROS."""
                client.set_parameters(scenario=scenario)
                obs, summary = client.reset(seed=seed)
                observations, summaries = [obs], [summary]
                for mm in actions:
                    obs, _, _, _, step = client.step(mm)
                    observations.append(obs)
                    summaries.append(step)
                return np.stack(observations), summaries

            paper_obs, paper = season("benton-generated", 2, [5.0, 5.0])
            tight_obs, tight_run = season(str(tight), 3, [20.0, 20.0, 5.0])
            sensing_obs, sensing = season("benton-sensing", 4, [0.0] * 15)
            back_obs, back = season("benton-generated", 2, [5.0])
            days = 3 + 4 + 16 + 2  # of the four seasons, their reset days included
            last = float(back[-1]["day"])  # the last season's last day: the last PAW and step result published
            ros.spin_until(lambda: len(got["crop"]) >= days and len(got["result"]) >= days and len(got["terms"]) >= 4
                           and got["crop"][-1].day == last and got["result"][-1].day == last
                           and sum(1 for m in got["status"] if m.fate == IrrigationStatus.CUT) >= 3,
                           TIMEOUT_S, "every day's PAW and step result, the farm terms and the cut reports")
    finally:
        assert process.stop() == 0, process.output()

    # observations: each season's layout, and bit for bit the offline environment's
    def offline(scenario, seed, actions):
        env = IrrigationEnv(scenario)
        observations = [env.reset(seed=seed)[0]]
        applied = []
        for mm in actions:
            obs, _, _, _, info = env.step(mm)
            observations.append(obs)
            applied.append(info["irrigation_applied_mm"])
        return np.stack(observations), applied

    tight_scenario = load_scenario(tight)
    assert paper_obs.shape == (3, 20) and back_obs.shape == (2, 20) and tight_obs.shape == (4, 29)
    assert paper_obs.tobytes() == offline("benton-generated", 2, [5.0, 5.0])[0].tobytes()
    tight_offline, tight_applied = offline(tight_scenario, 3, [20.0, 20.0, 5.0])
    assert tight_obs.tobytes() == tight_offline.tobytes()
    assert tight_applied == [8.0, 2.0, 0.0]  # the pivot's 8 mm/d, then the 10 mm quota's 2 mm left, then none
    assert [s["irrigation_mm"] for s in tight_run[1:]] == [8.0, 2.0, 0.0]
    assert [s["reward_unit"] for s in (paper[0], tight_run[0], sensing[0], back[0])] == \
        ["t/ha", "USD/ha", "USD/ha", "t/ha"]
    sensing_offline, _ = offline("benton-sensing", 4, [0.0] * 15)
    assert sensing_obs.tobytes() == sensing_offline.tobytes()

    # topic labels follow the layout; step results carry the reward's unit. A volatile reader may also get the
    # start's latched day: the four seasons are the last messages.
    for key in ("obs", "result", "crop"):
        got[key] = got[key][-days:]
    got["terms"] = [m for m in got["terms"] if m.episode >= paper[0]["episode"]]
    labels = [m.layout.dim[0].label.split(",") for m in got["obs"]]
    assert [len(x) for x in labels] == [20] * 3 + [29] * 4 + [29] * 16 + [20] * 2
    assert labels[3] == list(EXTENDED.labels) and labels[0] == labels[-1] == list(PAPER.labels)
    units = [m.reward_unit for m in got["result"]]
    assert units == ["t/ha"] * 3 + ["USD/ha"] * 4 + ["USD/ha"] * 16 + ["t/ha"] * 2

    # farm terms at each reset: NaN money and no quota for the paper task, the YAML's quota for the tight one
    terms = got["terms"]
    assert [t.episode for t in terms] == [s[0]["episode"] for s in (paper, tight_run, sensing, back)]
    paper_terms, tight_terms = terms[0], terms[1]
    assert all(math.isnan(getattr(paper_terms, name)) for name in ri.TERM_FIELDS[:3])
    assert (paper_terms.quota_mm, paper_terms.capacity_mm_per_day) == (math.inf, 100.0)
    assert (tight_terms.event_cost_usd, tight_terms.quota_mm, tight_terms.capacity_mm_per_day) == (0.0, 10.0, 8.0)

    # cut commands are reported (CUT) with the command, the mm applied and why, stamped with the day after
    cuts = [m for m in got["status"] if m.fate == IrrigationStatus.CUT]
    assert [(c.command.day, c.command.irrigation_mm, c.applied_mm, c.current_day) for c in cuts] == [
        (0, 20.0, 8.0, 1), (1, 20.0, 2.0, 2), (2, 5.0, 0.0, 3)]
    assert "capacity" in cuts[0].message and "quota" in cuts[1].message and "quota" in cuts[2].message
    tight_sowing = date.fromisoformat(tight_run[0]["date"])
    assert [c.header.stamp.sec for c in cuts] == [ri.sim_time(tight_sowing, day).sec for day in (1, 2, 3)]

    # ~/crop_state: PAW NaN (paw_observed false) exactly on the days the sensing task's reading is missing, else
    # the observation's PAW
    observed = sensing_offline[:, EXTENDED.index("paw_observed")]
    assert 0 < observed.sum() < len(observed), "the 15 days hold readings and dropouts"
    # the sensing season's PAW messages: after the paper season's 3 and the tight season's 4
    sensing_paw = got["crop"][3 + 4:3 + 4 + 16]
    assert [reading.day for reading in sensing_paw] == list(range(16))
    for reading, obs in zip(sensing_paw, sensing_offline):
        if obs[EXTENDED.index("paw_observed")] == 0.0:
            assert math.isnan(reading.paw_mm) and not reading.paw_observed, reading.day
        else:
            assert reading.paw_mm == float(obs[EXTENDED.index("paw_mm")]) and reading.paw_observed, reading.day

    # the season log: one header, the family's columns filled only in family rows
    rows = ros_support.read_log(log)
    with open(log, newline="") as handle:
        assert handle.readline().rstrip("\r\n") == ",".join(LOG_COLUMNS)
    by_episode = {}
    for row in rows:
        by_episode.setdefault(int(row["episode"]), []).append(row)
    paper_rows, tight_rows, sensing_rows, back_rows = (by_episode[s[0]["episode"]]
                                                       for s in (paper, tight_run, sensing, back))
    assert all(r["obs_et0_mm"] == "" and r["reward_unit"] == "t/ha" and r["term_tuber_price_usd_per_t"] == "nan"
               and r["term_quota_mm"] == "inf" for r in paper_rows + back_rows)
    assert [(float(r["irrigation_requested_mm"]), float(r["irrigation_mm"])) for r in tight_rows] == \
        [(20.0, 8.0), (20.0, 2.0), (5.0, 0.0)]
    assert all(r["reward_unit"] == "USD/ha" and float(r["term_quota_mm"]) == 10.0 for r in tight_rows)
    for row, obs in zip(tight_rows + sensing_rows, np.concatenate([tight_offline[:-1], sensing_offline[:-1]])):
        assert [np.float32(row[f"obs_{n}"]) for n in EXTENDED.names] == list(obs)


# --- the agent node -------------------------------------------------------------------------------------------

def drive(tmp_path, sim_name: str, label: str, *params: str) -> tuple[int, str]:
    agent = NodeProcess("crop_agent_ros.ros.agent_node", env=isolated_ros_env(), name=label,
                        log_path=tmp_path / f"{label}.out",
                        ros_args=["-p", f"sim_node:={sim_name}", "-p", "drive:=true", "-p", f"timeout:={TIMEOUT_S}",
                                  *params])
    try:
        status = agent.wait(600)
    finally:
        agent.stop()
    return status, agent.output()


def offline_season(policy, scenario: str, seed: int) -> dict:
    env = IrrigationEnv(scenario)
    policy.reset(seed)
    obs, info = env.reset(seed=seed)
    total, water, days, done = 0.0, 0.0, 0, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy.act(obs))
        total += reward
        water += info["irrigation_applied_mm"]
        days += 1
        done = terminated or truncated
    return {"return": total, "irrigation_mm": water, "days": days, "matured": bool(terminated)}


def season_summary(output: str) -> dict:
    (line,) = [line for line in output.splitlines() if line.startswith("season summary: ")]
    return json.loads(line.removeprefix("season summary: "))


def test_budget_rule_agent_drives_a_family_season_like_offline(tmp_path, quota_sim):
    """policy:=budget-rule without a task: the tuned rule of the simulator's scenario (benton-quota)."""
    from crop_agent_ros.policies.family_tuning import tuned_rule

    name, _ = quota_sim
    status, output = drive(tmp_path, name, "agent_rule", "-p", "policy:=budget-rule", "-p", "seed:=21")
    assert status == 0, output
    summary = season_summary(output)
    expected = offline_season(tuned_rule("benton-quota"), "benton-quota", 21)
    assert summary["policy"] == "budget-rule" and summary["reward_unit"] == "USD/ha"
    assert {k: summary[k] for k in expected} == expected
    assert expected["irrigation_mm"] > 0


@pytest.fixture(scope="module")
def family_agent_file(tmp_path_factory):
    """An untrained family agent file: a PPO network on 29 values and its model.json (scaler fitted on a
    season's observations, so that its actions vary)."""
    from crop_agent_ros.policies.learned import ObservationScaler

    path = ppo_file(tmp_path_factory.mktemp("agent") / "model.zip", (EXTENDED.size,))
    env = IrrigationEnv("benton-quota")
    observations = [env.reset(seed=0)[0]]
    done = False
    while not done:
        obs, _, terminated, truncated, _ = env.step(3.0)
        observations.append(obs)
        done = terminated or truncated
    scaler = ObservationScaler.fit(np.stack(observations))
    path.with_suffix(".json").write_text(json.dumps({"algorithm": "ppo", "history": 1, "task": "benton-quota",
                                                     "scaler": {"mean": scaler.mean, "std": scaler.std}}))
    return path


def test_learned_agent_drives_a_family_season_like_offline(tmp_path, quota_sim, family_agent_file):
    from crop_agent_ros.policies.learned import LearnedPolicy

    name, _ = quota_sim
    status, output = drive(tmp_path, name, "agent_learned", "-p", "policy:=agent", "-p",
                           f"policy_file:={family_agent_file}", "-p", "seed:=8")
    assert status == 0, output
    summary = season_summary(output)
    offline = LearnedPolicy(family_agent_file)
    expected = offline_season(offline, "benton-quota", 8)
    assert summary["policy"] == "agent" and {k: summary[k] for k in expected} == expected


def test_reacting_learned_agent_commands_the_offline_agents_amounts(tmp_path, quota_sim, family_agent_file):
    """Reacting, the agent sees observations only (someone else steps): its commands are the offline agent's, day
    by day."""
    from crop_agent_ros.policies.learned import LearnedPolicy

    name, _ = quota_sim
    policy = ("-p", "policy:=agent", "-p", f"policy_file:={family_agent_file}")
    offline = LearnedPolicy(family_agent_file)
    env = IrrigationEnv("benton-quota")
    offline.reset(None)
    obs, _ = env.reset(seed=8)
    requested, expected = [], []
    for _ in range(8):
        requested.append(offline.act(obs))
        obs, _, _, _, info = env.step(requested[-1])
        expected.append(info["irrigation_applied_mm"])
    agent = NodeProcess("crop_agent_ros.ros.agent_node", env=isolated_ros_env(), name="reacting_learned",
                        log_path=tmp_path / "reacting_learned.out", ros_args=["-p", f"sim_node:={name}", *policy])
    try:
        with PrivateRos("learned_stepper") as ros:
            statuses = []
            ros.node.create_subscription(IrrigationStatus, f"{name}/{ri.IRRIGATION_STATUS_TOPIC}", statuses.append,
                                         ri.READER_QOS)
            client = ros_support.connect(ros, name)
            client.reset(seed=8)
            applied = []
            for day in range(8):  # (a status of the previous season's day may still arrive: match the amount)
                ros.spin_until(lambda: any(s.fate == IrrigationStatus.ACCEPTED and s.command.day == day
                                           and s.command.irrigation_mm == requested[day] for s in statuses), 30,
                               f"the agent's command of {requested[day]} mm for day {day}")
                applied.append(ros_support.raw_step(ros, name)["irrigation_mm"])
        assert applied == expected and any(applied), (applied, agent.output())
    finally:
        assert agent.stop() == 0, agent.output()


def one_error_line(output: str) -> str:
    (line,) = [line for line in output.splitlines() if "[FATAL]" in line or "[ERROR]" in line]
    return line


def test_agent_refuses_a_family_policy_for_a_paper_simulator_at_start(tmp_path, paper_sim, family_agent_file):
    name, log = paper_sim
    for label, params in (("rule", ("-p", "policy:=budget-rule", "-p", "task:=benton-quota")),
                          ("agent", ("-p", "policy:=agent", "-p", f"policy_file:={family_agent_file}"))):
        status, output = drive(tmp_path, name, f"refused_{label}", *params)
        line = one_error_line(output)
        assert status == 2 and "Traceback" not in output, (status, output)
        assert "reads observations of 29 values, but the simulator's scenario 'benton-generated' has 20" in line
    assert not log.exists() or ros_support.read_log(log) == []  # no day was grown


def test_reacting_agent_refuses_an_observation_it_cannot_read(tmp_path, paper_sim, family_agent_file):
    """A reacting agent with its task named does not ask the simulator: the first observation (latched) is
    refused, one line, exit 2."""
    name, _ = paper_sim
    agent = NodeProcess("crop_agent_ros.ros.agent_node", env=isolated_ros_env(), name="reacting",
                        log_path=tmp_path / "reacting.out",
                        ros_args=["-p", f"sim_node:={name}", "-p", "policy:=budget-rule", "-p", "task:=benton-quota"])
    try:
        status = agent.wait(300)
    finally:
        agent.stop()
    output = agent.output()
    line = one_error_line(output)
    assert status == 2 and "Traceback" not in output, (status, output)
    assert f"reads observations of 29 values, but the observation of {name} has 20" in line


def test_budget_rule_of_an_unknown_task_is_one_line_and_exit_2(tmp_path, paper_sim):
    """The paper simulator's scenario has no tuned rule: the agent says how to make one."""
    name, _ = paper_sim
    status, output = drive(tmp_path, name, "no_rule", "-p", "policy:=budget-rule")
    line = one_error_line(output)
    assert status == 2 and "Traceback" not in output, (status, output)
    assert "family_benton-generated.json is missing: run `crop-sim tune-rule --task benton-generated`" in line
