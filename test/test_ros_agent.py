"""The agent node over ROS 2: reacting to the simulator's observations (someone else steps), driving
seasons, stopping cleanly on SIGTERM or SIGINT whenever they land, refusing a policy file made for other
spaces, honouring its timeout, leaving the simulator's parameters alone; and the README's main job
(``python -m crop_agent_ros.ros.farm``: sim + agent processes grow a season, also with a shipped agent)."""

from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

import ros_support  # noqa: E402  (private ROS_DOMAIN_ID before any context exists)
from crop_sim_interfaces.msg import IrrigationStatus  # noqa: E402
from rcl_interfaces.srv import GetParameters  # noqa: E402
from crop_sim_interfaces.srv import Step  # noqa: E402

from crop_agent_ros.ros.spin import PrivateRos, ServiceTimeout, call, wait_for_service  # noqa: E402
from crop_agent_ros.ros.process import NodeProcess, isolated_ros_env  # noqa: E402
from crop_sim_ros import ros_interface as ri  # noqa: E402
from policy_files import ppo_file  # noqa: E402
from ros_support import wait_for  # noqa: E402

pytestmark = pytest.mark.slow


def test_reactive_agent_commands_every_day(tmp_path):
    sim, name, log = ros_support.start_sim(tmp_path, params={"seed": 12})
    agent = None
    try:
        with PrivateRos(f"stepper_{uuid.uuid4().hex[:6]}") as ros:
            statuses: list[IrrigationStatus] = []
            status = ros.node.create_subscription(IrrigationStatus, f"{name}/irrigation_status", statuses.append,
                                                  ri.READER_QOS)
            step = ros.node.create_client(Step, f"{name}/step")
            wait_for_service(ros.executor, step, 30)
            ros.spin_until(lambda: status.get_publisher_count() >= 1, 30, "the status topic")
            agent = NodeProcess("crop_agent_ros.ros.agent_node", env=isolated_ros_env(), name="agent_node",
                                log_path=tmp_path / "agent.out",
                                ros_args=["-p", f"sim_node:={name}", "-p", "policy:=constant", "-p", "constant_mm:=7.5"])
            field = name.rpartition("/")[0].strip("/")
            for day in range(10):  # the agent commands each day as soon as it sees the day's observation
                accepted = lambda: [s for s in statuses  # noqa: E731
                                    if s.fate == IrrigationStatus.ACCEPTED and s.command.day == day]
                ros.spin_until(accepted, 30, f"the agent's command for day {day}")
                # stamped with the day's farm time, for this field and this episode only (from its StepResult)
                command, answer = accepted()[0].command, accepted()[0]
                assert command.header.stamp.sec > 0 and command.header.stamp == answer.header.stamp
                assert command.header.frame_id == field == answer.header.frame_id
                assert command.episode == answer.episode == 1 and command.irrigation_mm == 7.5
                response = call(ros.executor, step, ros_support.pending_step())
                assert response.success and response.result.irrigation_mm == 7.5
                assert response.result.header.stamp.sec == command.header.stamp.sec + 86400
        rows = ros_support.read_log(log)
        assert [(int(r["day"]), float(r["irrigation_mm"])) for r in rows] == [(d, 7.5) for d in range(10)]
    finally:
        if agent is not None:
            assert agent.stop() == 0, agent.output()
        assert sim.stop() == 0, sim.output()


@pytest.mark.parametrize("policy", ["refill", "ppo"])
def test_run_farm_grows_a_season_over_ros(tmp_path, policy):
    log = tmp_path / "season.csv"
    done = subprocess.run([sys.executable, "-m", "crop_agent_ros.ros.farm", "--policy", policy, "--json",
                           "--log", str(log), "--domain-id", str(isolated_ros_env()["ROS_DOMAIN_ID"])],
                          env=isolated_ros_env(), capture_output=True, text=True, timeout=300,
                          cwd=ros_support.REPO)
    assert done.returncode == 0, done.stdout + done.stderr
    (summary,) = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert summary["policy"] == policy and summary["matured"] and summary["yield_t_ha"] > 5
    rows = [r for r in ros_support.read_log(log) if int(r["episode"]) == summary["episode"]]
    assert len(rows) == summary["days"]
    assert sum(float(r["irrigation_mm"]) for r in rows) == pytest.approx(summary["irrigation_mm"], rel=1e-12)
    assert log.with_suffix(".png").stat().st_size > 10_000  # the plot of the season


def tiny_filter_agent(folder: Path) -> Path:
    """An untrained family agent (a tiny PPO network) that also sees the soil-water filter's PAW estimate: its
    model.zip with the model.json beside it (identity scaling; 29 observation values + the estimate)."""
    from crop_sim_ros.task.layout import EXTENDED

    model = ppo_file(folder / "model.zip", (EXTENDED.size + 1,))
    config = {"task": "benton-sensing", "algorithm": "ppo", "history": 1, "action_kind": "mm",
              "scaler": {"mean": [0.0] * EXTENDED.size, "std": [1.0] * EXTENDED.size},
              "paw_filter": {"capacity_mm": 120.0, "sensor_sd_mm": 10.0}}
    (folder / "model.json").write_text(json.dumps(config))
    return model


def test_run_farm_grows_a_family_season_with_an_agent_file(tmp_path):
    """`crop-sim farm --policy agent`: a family agent file that also sees the soil-water filter's estimate drives a
    benton-sensing season over ROS; the agent node feeds the filter from the readings it receives (a missing one
    as NaN), and the season stays within the farm's quota."""
    log = tmp_path / "season.csv"
    agent = tiny_filter_agent(tmp_path)
    done = subprocess.run([sys.executable, "-m", "crop_agent_ros.ros.farm", "--policy", "agent", "--policy-file",
                           str(agent), "--task", "benton-sensing", "--json", "--no-plot", "--log", str(log),
                           "--domain-id", str(isolated_ros_env()["ROS_DOMAIN_ID"])],
                          env=isolated_ros_env(), capture_output=True, text=True, timeout=300, cwd=ros_support.REPO)
    assert done.returncode == 0, done.stdout + done.stderr
    (summary,) = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert summary["policy"] == "agent" and summary["matured"]
    rows = [r for r in ros_support.read_log(log) if int(r["episode"]) == summary["episode"]]
    assert len(rows) == summary["days"] and 0.0 < summary["irrigation_mm"] <= float(rows[0]["term_quota_mm"]) + 1e-6
    assert any(float(r["obs_paw_observed"]) == 0.0 for r in rows)  # the agent met missing readings


@pytest.mark.parametrize("name", ["es", "es-residual"])
def test_farm_grows_a_season_with_the_shipped_agent_of_the_task_as_offline(tmp_path, name):
    """`crop-sim farm --task benton-quota --policy es --seasons 1`: the agent node resolves ``es`` (and
    ``es-residual``, the paced rule inside it) to the shipped agent of the simulator's task and irrigates exactly as
    that agent does offline on the same season."""
    from crop_agent_ros.policies import PolicyArguments, build_policy
    from crop_sim_ros.task import IrrigationEnv

    done = subprocess.run([sys.executable, "-m", "crop_agent_ros.ros.farm", "--task", "benton-quota", "--policy", name,
                           "--seasons", "1", "--json", "--no-plot",
                           "--domain-id", str(isolated_ros_env()["ROS_DOMAIN_ID"])],
                          env=isolated_ros_env(), capture_output=True, text=True, timeout=300, cwd=ros_support.REPO)
    assert done.returncode == 0, done.stdout + done.stderr
    (summary,) = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert (summary["policy"], summary["scenario"], summary["reward_unit"]) == (name, "benton-quota", "USD/ha")
    policy = build_policy(name, PolicyArguments(task="benton-quota"))
    env = IrrigationEnv("benton-quota")
    policy.reset(None)
    obs, info = env.reset(seed=0)
    total, water, done_ = 0.0, 0.0, False
    while not done_:
        obs, reward, terminated, truncated, step = env.step(policy.act(obs))
        total, water, done_ = total + reward, water + step["irrigation_applied_mm"], terminated or truncated
    assert summary["weather"] == info["weather_source"]
    assert summary["matured"] and (summary["return"], summary["irrigation_mm"]) == (total, water) and water > 0
    assert summary["yield_t_ha"] == step["yield_t_ha"] > 10


def catches_sigterm(pid: int) -> bool:
    """The process has a handler for SIGTERM (/proc's SigCgt mask): the agent's main has installed its own.
    Before that no code of ours runs (the interpreter is still starting), and SIGTERM's default ends it."""
    with open(f"/proc/{pid}/status") as status:
        caught = next(int(line.split()[1], 16) for line in status if line.startswith("SigCgt:"))
    return bool(caught & (1 << (signal.SIGTERM - 1)))


def start_driving_agent(tmp_path, sim_name: str, name: str, policy: str = "refill", seasons: int = 1000,
                        extra: tuple[str, ...] = ()) -> NodeProcess:
    return NodeProcess("crop_agent_ros.ros.agent_node", env=isolated_ros_env(), name=name,
                       log_path=tmp_path / f"{name}.out",
                       ros_args=["-p", f"sim_node:={sim_name}", "-p", f"policy:={policy}", "-p", "drive:=true",
                                 "-p", f"seasons:={seasons}", "-p", "timeout:=30.0", *extra])


@pytest.fixture(scope="module")
def shared_sim(tmp_path_factory):
    sim, name, log = ros_support.start_sim(tmp_path_factory.mktemp("signals"))
    yield name, log
    assert sim.stop() == 0, sim.output()


def log_rows(log) -> int:
    return len(ros_support.read_log(log)) if log.exists() else 0


# 20 trials, each with its own seed: even ones land during the start-up (rclpy, the task, the policy loading;
# PPO's torch on every fourth), odd ones while the agent drives seasons (after the simulator logged its days).
@pytest.mark.parametrize("trial", range(20))
def test_sigterm_at_a_random_moment_exits_0_without_traceback(tmp_path, shared_sim, trial):
    sim_name, log = shared_sim
    rng = random.Random(1000 + trial)
    policy = "ppo" if trial % 4 == 0 else "refill"
    agent = start_driving_agent(tmp_path, sim_name, f"agent_{trial}", policy=policy)
    try:
        wait_for(lambda: agent.poll() is not None or catches_sigterm(agent.pid), 30, "the agent's signal handlers")
        if trial % 2 == 0:
            delay = rng.uniform(0.0, 2.5)
        else:
            rows = log_rows(log)
            wait_for(lambda: log_rows(log) > rows + 2, 120, "the agent driving", step=0.05)
            delay = rng.uniform(0.0, 1.0)
        time.sleep(delay)
        agent.process.send_signal(signal.SIGTERM)
        status = agent.wait(60)
    finally:
        agent.stop()
    output = agent.output()
    assert status == 0 and "Traceback" not in output, (f"delay {delay:.3f} s", status, output)


@pytest.mark.parametrize("trial", range(3))
def test_two_sigints_while_driving_exit_0_without_traceback(tmp_path, shared_sim, trial):
    """Ctrl-C to a process group that a launcher also stops with SIGINT: the second lands in the clean-up."""
    sim_name, log = shared_sim
    rng = random.Random(2000 + trial)
    agent = start_driving_agent(tmp_path, sim_name, f"agent_int_{trial}")
    try:
        rows = log_rows(log)
        wait_for(lambda: log_rows(log) > rows + 2, 120, "the agent driving", step=0.05)
        time.sleep(rng.uniform(0.0, 0.5))
        agent.process.send_signal(signal.SIGINT)
        time.sleep(rng.uniform(0.0, 0.05))
        agent.process.send_signal(signal.SIGINT)
        status = agent.wait(60)
    finally:
        agent.stop()
    output = agent.output()
    assert status == 0 and "Traceback" not in output and "stopped by SIGINT" in output, (status, output)


def test_drive_leaves_the_simulators_seed_parameter_as_it_was(tmp_path):
    sim, name, log = ros_support.start_sim(tmp_path, params={"seed": 0})
    agent = None
    try:
        agent = start_driving_agent(tmp_path, name, "agent_seed", seasons=2, extra=("-p", "seed:=5"))
        assert agent.wait(300) == 0, agent.output()
        with PrivateRos(f"inspector_{uuid.uuid4().hex[:6]}") as ros:
            client = ros.node.create_client(GetParameters, f"{name}/get_parameters")
            wait_for_service(ros.executor, client, 30)
            values = ros.call(client, GetParameters.Request(names=["seed", "weather_season"])).values
        assert (values[0].integer_value, values[1].integer_value) == (0, -1)
        seeds = {}
        for row in ros_support.read_log(log):
            seeds.setdefault(int(row["episode"]), row["seed"])
        assert list(seeds.values()) == ["5", ""]  # season 1 seeded with 5, season 2 continued the stream
    finally:
        if agent is not None:
            agent.stop()
        assert sim.stop() == 0, sim.output()


def test_agent_without_a_simulator_gives_up_after_its_timeout(tmp_path):
    timeout_s = 2.0
    agent = start_driving_agent(tmp_path, f"/nobody_{uuid.uuid4().hex[:8]}/crop_sim", "agent_alone",
                                extra=("-p", f"timeout:={timeout_s}"))
    status = agent.wait(120)
    output = agent.output()
    # rclpy's log lines carry their time: from the node's start line to its error line
    stamps = {level: float(stamp) for level, stamp in re.findall(r"^\[(INFO|ERROR)\] \[([0-9.]+)\]", output, re.M)}
    assert status == 1 and "no simulator" in output, output
    waited = stamps["ERROR"] - stamps["INFO"]
    assert timeout_s <= waited <= timeout_s + 3.0, (waited, output)


def test_agent_help_prints_usage_and_starts_no_node():
    done = subprocess.run([sys.executable, "-m", "crop_agent_ros.ros.agent_node", "--help"], capture_output=True,
                          text=True, timeout=120, env=isolated_ros_env(), cwd=ros_support.REPO)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert done.stdout.splitlines()[2] == "usage: agent_node [--help] [--ros-args -p NAME:=VALUE ...]"
    for name in ("policy", "policy_file", "drive", "seasons", "seed", "timeout"):
        assert f"\n  {name} (default " in done.stdout
    assert "[INFO]" not in done.stdout  # no node was made


@pytest.fixture(scope="module")
def wrong_shape_policy(tmp_path_factory):
    return ppo_file(tmp_path_factory.mktemp("policy") / "observes_5.zip", (5,))


def test_agent_refuses_a_policy_of_other_spaces_at_load(tmp_path, wrong_shape_policy):
    agent = NodeProcess("crop_agent_ros.ros.agent_node", env=isolated_ros_env(), name="agent_policy",
                        log_path=tmp_path / "agent.out",
                        ros_args=["-p", "policy:=ppo", "-p", f"policy_file:={wrong_shape_policy}", "-p", "drive:=true"])
    status = agent.wait(120)
    (line,) = [line for line in agent.output().splitlines() if line.strip()]
    assert status == 2 and "cannot start: PolicyFileError: " in line, (status, line)
    assert f"{wrong_shape_policy}: its network observes Box of shape (5,)" in line


def test_farm_refuses_a_policy_of_other_spaces_in_one_line(tmp_path, wrong_shape_policy):
    done = subprocess.run([sys.executable, "-m", "crop_agent_ros.ros.farm", "--policy-file", str(wrong_shape_policy),
                           "--log", str(tmp_path / "season.csv")], env=isolated_ros_env(), capture_output=True,
                          text=True, timeout=300, cwd=ros_support.REPO)
    (line,) = done.stderr.splitlines()
    assert done.returncode == 2 and done.stdout == "", (done.returncode, done.stdout, done.stderr)
    assert line.startswith("crop-sim farm: agent_node: cannot start: PolicyFileError: policy file "
                           f"{wrong_shape_policy}: its network observes Box of shape (5,)"), line
    assert not (tmp_path / "season.csv").exists() or log_rows(tmp_path / "season.csv") == 0  # no day was grown


def processes_tagged(tag: str) -> list[tuple[int, str]]:
    """Live processes (pid, command line) whose environment has FARM_TEST_TAG=``tag``: the farm passes its
    environment on to its nodes."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as environ:
                if f"FARM_TEST_TAG={tag}".encode() not in environ.read().split(b"\0"):
                    continue
            with open(f"/proc/{entry}/cmdline", "rb") as cmdline:
                found.append((int(entry), cmdline.read().replace(b"\0", b" ").decode(errors="replace")))
        except OSError:
            continue
    return found


def test_ctrl_c_to_the_farm_stops_both_nodes_without_traceback(tmp_path):
    tag = uuid.uuid4().hex
    log = tmp_path / "season.csv"
    farm = subprocess.Popen([sys.executable, "-m", "crop_agent_ros.ros.farm", "--policy", "refill", "--seasons", "100",
                             "--log", str(log), "--no-plot"], env={**isolated_ros_env(), "FARM_TEST_TAG": tag},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ros_support.REPO,
                            start_new_session=True)
    try:
        wait_for(lambda: log_rows(log) > 20, 180, "the farm growing days", step=0.1)
        assert len(processes_tagged(tag)) == 3  # the farm and its two nodes
        os.killpg(farm.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole process group
        stdout, stderr = farm.communicate(timeout=60)
    finally:
        if farm.poll() is None:
            farm.kill()
            farm.communicate()
    assert farm.returncode == 128 + signal.SIGINT and "Traceback" not in stdout + stderr, (stdout, stderr)
    assert processes_tagged(tag) == []  # both nodes stopped (each runs in a session of its own)


def test_run_season_action_grows_a_season_with_feedback_every_day(tmp_path):
    """~/run_season of a reactive agent: a goal (seed, policy constant) grows one season through the simulator's
    typed services; one feedback per day, in day order, the water so far; the result agrees with the season
    log. A goal with an unknown policy is aborted with the reason."""
    from crop_sim_interfaces.action import RunSeason
    from rclpy.action import ActionClient

    sim, name, log = ros_support.start_sim(tmp_path, params={"seed": 12})
    agent_name = name.rsplit("/", 1)[0] + "/crop_agent"
    agent = NodeProcess("crop_agent_ros.ros.agent_node", env=isolated_ros_env(), name="agent_node",
                        log_path=tmp_path / "agent.out",
                        ros_args=["-r", f"__ns:={name.rsplit('/', 1)[0]}", "-p", f"sim_node:={name}",
                                  "-p", "policy:=zero"])
    try:
        with PrivateRos(f"goal_{uuid.uuid4().hex[:6]}") as ros:
            client = ActionClient(ros.node, RunSeason, f"{agent_name}/run_season",
                                  feedback_sub_qos_profile=ri.COMMAND_SUBSCRIPTION_QOS)
            ros.spin_until(client.server_is_ready, 60, "the run_season action server")
            # rclpy's ActionClient drops feedback it takes after the goal's result (it forgets the goal's callback),
            # and under load the result can overtake a season's burst of feedback: read the feedback topic itself.
            feedback_topic = f"{agent_name}/run_season/_action/feedback"
            published = []
            ros.node.create_subscription(RunSeason.Impl.FeedbackMessage, feedback_topic, published.append,
                                         ri.COMMAND_SUBSCRIPTION_QOS)
            ros.spin_until(lambda: ros.node.count_publishers(feedback_topic) >= 1, 60, "the feedback writer")

            def run(goal):
                # A goal sent right after discovery can be lost, or its answer (CI waited 30 s for one, once), and
                # ROS 2 does not resend it. Send it once more, under a new id: were the first accepted after all,
                # its season runs first, and the checks below read only this goal's feedback and rows.
                sent = client.send_goal_async(goal)
                try:
                    ros.spin_until(sent.done, 15, "the goal's acceptance")
                except ServiceTimeout:
                    sent = client.send_goal_async(goal)
                    ros.spin_until(sent.done, 90, "the resent goal's acceptance")
                handle = sent.result()
                assert handle.accepted
                done = handle.get_result_async()
                ros.spin_until(done.done, 120, "the season")
                days = done.result().result.days

                def feedback():
                    return [m.feedback for m in published if bytes(m.goal_id.uuid) == bytes(handle.goal_id.uuid)]
                ros.spin_until(lambda: len(feedback()) >= days, 30, "every day's feedback")  # a topic: may trail
                return done.result(), feedback()

            answer, feedback = run(RunSeason.Goal(seed=5, policy="constant"))
            result = answer.result
            assert answer.status == 4 and result.success, result.message  # SUCCEEDED
            assert [f.step.day for f in feedback] == list(range(1, result.days + 1))
            assert all(f.step.irrigation_mm == 10.0 and f.water_mm == 10.0 * f.step.day for f in feedback)
            assert result.water_mm == 10.0 * result.days and result.yield_t_ha > 0 and result.reward_unit == "t/ha"
            rows = [r for r in ros_support.read_log(log) if int(r["episode"]) == result.episode]
            assert len(rows) == result.days and all(r["seed"] == "5" for r in rows)
            assert float(rows[-1]["episode_return"]) == result.episode_return
            assert float(rows[-1]["end_yield_t_ha"]) == result.yield_t_ha

            refused, feedback = run(RunSeason.Goal(policy="no-such-policy"))
            assert refused.status == 6 and not refused.result.success and not feedback  # ABORTED
            assert "no-such-policy" in refused.result.message
    finally:
        assert agent.stop() == 0, agent.output()
        assert sim.stop() == 0, sim.output()
