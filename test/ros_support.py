"""Helpers of the ROS tests (test_ros_*.py): isolation, node processes, a private rclpy context per test.

Isolation: importing this module gives the test process its own ROS_DOMAIN_ID (from the pid, so pytest-xdist
workers differ) and keeps discovery on this machine; child processes inherit both. Every node a test starts
runs under its own namespace too, and is stopped by the test (NodeProcess removes the /dev/shm files of a
process it killed, and only those).
"""

from __future__ import annotations

import csv
import json
import os
import uuid
from pathlib import Path

from crop_agent_ros.ros_process import NodeProcess, isolated_ros_env, pick_domain_id

os.environ["ROS_DOMAIN_ID"] = str(pick_domain_id(salt=int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or 0)))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_LOCALHOST_ONLY", None)

REPO = Path(__file__).resolve().parent.parent
PARAMS_FILE = REPO / "config" / "farm_params.yaml"


def unique_namespace(prefix: str = "t") -> str:
    return f"/{prefix}_{os.getpid()}_{uuid.uuid4().hex[:6]}"


def start_sim(tmp_path: Path, namespace: str | None = None, params: dict | None = None,
              params_file: Path | None = None, log_name: str = "season.csv") -> tuple[NodeProcess, str, Path]:
    """A sim_node process under a fresh namespace; returns (process, its fully qualified name, log path)."""
    namespace = namespace or unique_namespace("sim")
    log = tmp_path / log_name
    ros_args = ["-r", f"__ns:={namespace}"]
    if params_file:
        ros_args += ["--params-file", str(params_file)]
    for key, value in {"log_path": str(log), **(params or {})}.items():
        ros_args += ["-p", f"{key}:={value}"]
    process = NodeProcess("crop_sim_ros.sim_node", ros_args=ros_args, env=isolated_ros_env(),
                          name="sim_node", log_path=tmp_path / f"sim_node_{uuid.uuid4().hex[:4]}.out")
    return process, f"{namespace}/crop_sim", log


def read_log(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def summary(response) -> dict:
    return json.loads(response.message)
