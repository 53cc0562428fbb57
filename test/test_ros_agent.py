"""The agent node over ROS 2: reacting to the simulator's observations (someone else steps), and the
README's main job (``python -m crop_agent_ros.run_farm``: sim + agent processes grow a season)."""

from __future__ import annotations

import json
import subprocess
import sys
import uuid

import pytest

pytest.importorskip("rclpy")

import ros_support  # noqa: E402  (private ROS_DOMAIN_ID before any context exists)
from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from crop_agent_ros.ros_client import PrivateRos, call, wait_for_service  # noqa: E402
from crop_agent_ros.ros_process import NodeProcess, isolated_ros_env  # noqa: E402
from crop_sim_ros import ros_interface as ri  # noqa: E402

pytestmark = pytest.mark.slow


def test_reactive_agent_commands_every_day(tmp_path):
    sim, name, log = ros_support.start_sim(tmp_path, params={"seed": 12})
    agent = None
    try:
        with PrivateRos(f"stepper_{uuid.uuid4().hex[:6]}") as ros:
            accepted = []
            status = ros.node.create_subscription(DiagnosticStatus, f"{name}/irrigation_status",
                                                  lambda m: accepted.append(ri.status_values(m)), ri.READER_QOS)
            step = ros.node.create_client(Trigger, f"{name}/step")
            wait_for_service(ros.executor, step, 30)
            ros.spin_until(lambda: status.get_publisher_count() >= 1, 30, "the status topic")
            agent = NodeProcess("crop_agent_ros.agent_node", env=isolated_ros_env(), name="agent_node",
                                log_path=tmp_path / "agent.out",
                                ros_args=["-p", f"sim_node:={name}", "-p", "policy:=constant", "-p", "constant_mm:=7.5"])
            for day in range(10):  # the agent commands each day as soon as it sees the day's observation
                ros.spin_until(lambda: any(a["accepted"] and a["day"] == day for a in accepted), 30,
                               f"the agent's command for day {day}")
                response = call(ros.executor, step, Trigger.Request())
                assert response.success and json.loads(response.message)["irrigation_mm"] == 7.5
        rows = ros_support.read_log(log)
        assert [(int(r["day"]), float(r["irrigation_mm"])) for r in rows] == [(d, 7.5) for d in range(10)]
    finally:
        if agent is not None:
            assert agent.stop() == 0, agent.output()
        assert sim.stop() == 0, sim.output()


@pytest.mark.parametrize("policy", ["refill", "ppo"])
def test_run_farm_grows_a_season_over_ros(tmp_path, policy):
    log = tmp_path / "season.csv"
    done = subprocess.run([sys.executable, "-m", "crop_agent_ros.run_farm", "--policy", policy, "--json",
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
