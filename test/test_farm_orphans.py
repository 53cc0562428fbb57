"""No orphaned nodes: SIGKILL of ``crop-sim farm`` (which can run no clean-up) still ends its sim_node and
agent_node, through the parent-death signal that NodeProcess asks the kernel for (issue 34, section 2)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from crop_agent_ros.ros.process import isolated_ros_env, pick_domain_id

import ros_support  # noqa: F401  (a private ROS_DOMAIN_ID and localhost discovery for this process and its children)

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and PR_SET_PDEATHSIG: Linux")

NODE_MODULES = ("crop_sim_ros.sim_node", "crop_agent_ros.ros.agent_node")


def _children(pid: int) -> dict[int, str]:
    """The live child processes of ``pid`` (from /proc/*/stat), with their command lines."""
    children = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            command = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) ": state, ppid, ...
        if int(fields[1]) == pid and fields[0] != "Z":
            children[int(entry)] = command
    return children


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return state[state.rindex(")") + 2:].split()[0] != "Z"


def test_sigkill_of_the_farm_leaves_no_node_running(tmp_path):
    env = isolated_ros_env(pick_domain_id(salt=77))
    crop_sim = Path(sys.executable).with_name("crop-sim")
    farm = subprocess.Popen([str(crop_sim), "farm", "--task", "benton-generated", "--seasons", "50", "--no-plot",
                             "--log", str(tmp_path / "season.csv")],
                            env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    nodes: dict[int, str] = {}
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and farm.poll() is None:
            nodes = {pid: command for pid, command in _children(farm.pid).items()
                     if any(module in command for module in NODE_MODULES)}
            if len(nodes) == 2:
                break
            time.sleep(0.1)
        assert len(nodes) == 2, f"the farm did not start both nodes (exit {farm.poll()}): {nodes}"
        log = tmp_path / "season.csv"  # the agent drives the season: both nodes are past their start-up
        while time.monotonic() < deadline and farm.poll() is None and not (
                log.exists() and log.read_bytes().count(b"\n") >= 3):
            time.sleep(0.1)
        assert farm.poll() is None and log.exists(), f"the farm grew no day (exit {farm.poll()})"
        farm.send_signal(signal.SIGKILL)
        farm.wait(10)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(_alive(pid) for pid in nodes):
            time.sleep(0.1)
        left = {pid: command for pid, command in nodes.items() if _alive(pid)}
        assert not left, f"orphaned after SIGKILL of the farm: {left}"
    finally:
        if farm.poll() is None:
            farm.kill()
            farm.wait()
        for pid in nodes:
            if _alive(pid):
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
