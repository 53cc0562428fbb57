"""Helpers of the ROS tests (test_ros_*.py): isolation, node processes, a private rclpy context per test, and
the simulator's clients that the tests share (connect, step_client, raw_step, set_parameter, status_reader).

Isolation: importing this module gives the test process its own ROS_DOMAIN_ID (from the pid, so pytest-xdist
workers differ) and keeps discovery on this machine; child processes inherit both. Every node a test starts
runs under its own namespace too, and is stopped by the test (NodeProcess removes the /dev/shm files of a
process it killed, and only those).
"""

from __future__ import annotations

import csv
import os
import time
import uuid
from pathlib import Path

import pytest

from crop_agent_ros.ros.process import NodeProcess, isolated_ros_env, pick_domain_id

os.environ["ROS_DOMAIN_ID"] = str(pick_domain_id(salt=int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or 0)))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_LOCALHOST_ONLY", None)

# rclpy reads the two variables above when a context starts; these imports start none
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue  # noqa: E402
from rcl_interfaces.srv import GetParameters, SetParameters  # noqa: E402
from crop_sim_interfaces.msg import StepResult  # noqa: E402
from crop_sim_interfaces.srv import Reset, Step  # noqa: E402

from crop_agent_ros.ros.spin import PrivateRos, call, wait_for_service  # noqa: E402
from crop_agent_ros.ros.sim_client import SimClient  # noqa: E402
from crop_sim_ros import ros_interface as ri  # noqa: E402

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


def wait_for(condition, timeout: float, what: str, step: float = 0.01) -> None:
    """Poll ``condition`` every ``step`` seconds; TimeoutError naming ``what`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(step)


def read_log(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def summary(response) -> dict:
    """A typed Step or Reset reply as a dict: ``success``; on success the result's (or the terms') fields as
    ri.step_summary / ri.reset_summary give them; else ``error`` (the reason) and the current episode and day."""
    if not response.success:
        result = getattr(response, "result", None)
        where = {"episode": result.episode, "day": result.day} if result is not None else {}
        return {"success": False, "error": response.message, **where}
    if isinstance(response, Reset.Response):
        return {"success": True, **ri.reset_summary(response.terms, response.observation)}
    return {"success": True, **ri.step_summary(response.result, response.observation),
            **({"log_error": response.message} if response.message else {})}


def pending_step() -> Step.Request:
    """A ~/step request that applies the command accepted on ~/irrigation (none: 0 mm)."""
    return Step.Request(use_pending_command=True)


# --- clients of a simulator (these import rclpy) ------------------------------------------------------------

def connect(ros, name, **kwargs) -> SimClient:
    client = SimClient(ros.node, ros.executor, name, **kwargs)
    client.connect(30)
    return client


def step_client(ros, name):
    """A ~/step client that the simulator has surely discovered: wait for the service, then one idempotent
    round trip (get_parameters) from the same node, whose endpoints all exist already. It keeps every response
    (ri.SERVICE_CLIENT_QOS): with the default depth of 10, a client starved of CPU while another client of the
    same simulator got more than 10 answers lost its own (the day was stepped, the call timed out: 5 of 60 runs
    of the two-client test with the other core loaded, 0 of 25 with this QoS)."""
    step = ros.node.create_client(Step, f"{name}/step", qos_profile=ri.SERVICE_CLIENT_QOS)
    probe = ros.node.create_client(GetParameters, f"{name}/get_parameters")
    wait_for_service(ros.executor, step, 30)
    wait_for_service(ros.executor, probe, 30)
    call(ros.executor, probe, GetParameters.Request(names=["mode"]))
    ros.node.destroy_client(probe)
    return step


def set_parameter(ros, name, **values):
    client = ros.node.create_client(SetParameters, f"{name}/set_parameters")
    wait_for_service(ros.executor, client, 20)
    request = SetParameters.Request()
    for key, value in values.items():
        if isinstance(value, str):
            v = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
        elif isinstance(value, float):
            v = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
        else:
            v = ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
        request.parameters.append(Parameter(name=key, value=v))
    # setting the same values again is harmless, and a request sent right after discovery can be lost in DDS
    # (the server's reader had not matched this new client yet; ROS 2 services never resend): try again
    for attempt in range(4):
        try:
            response = call(ros.executor, client, request, timeout=5.0)
            break
        except TimeoutError:
            if attempt == 3:
                raise
    ros.node.destroy_client(client)
    return response.results


def raw_step(ros, name, timeout: float = 5.0) -> dict:
    """One ~/step call (the pending command of ~/irrigation) from ``ros``'s node, while no other client steps
    this simulator.

    A service request sent just after discovery can be lost in DDS (the server's reader had not yet matched
    the new client's writer; ROS 2 services have no retry). So if no response comes, this looks at the
    latched ~/step_result: the day did not advance -> the request was lost, send it again; it advanced -> the
    response was lost, the step_result is the outcome. Never steps twice."""
    cache = ros.__dict__.setdefault("_raw_step", {})
    if name not in cache:
        latest: list = []
        ros.node.create_subscription(StepResult, f"{name}/step_result", latest.append, ri.LATCHED_READER_QOS)
        cache[name] = (step_client(ros, name), latest)
        ros.spin_until(lambda: latest, 20, "the latched step result")
    client, latest = cache[name]
    before = (latest[-1].episode, latest[-1].day)
    for _ in range(5):
        future = client.call_async(pending_step())
        try:
            ros.spin_until(future.done, timeout, "the step response")
            return summary(future.result())
        except TimeoutError:
            client.remove_pending_request(future)
            if (latest[-1].episode, latest[-1].day) != before:  # stepped, the response was lost
                return {"success": True, **ri.step_summary(latest[-1])}
    raise TimeoutError(f"no step of {name} after 5 attempts")


def status_reader(ros, name) -> list[dict]:
    """A list that fills with the status of the simulator ``name`` on /diagnostics (ri.node_status_values), the
    latest last; latched, so the current status arrives at once. Other nodes' statuses are left out."""
    statuses: list[dict] = []
    ros.node.create_subscription(DiagnosticArray, ri.DIAGNOSTICS_TOPIC,
                                 lambda m: statuses.extend(ri.node_statuses(m, name)), ri.LATCHED_READER_QOS)
    ros.spin_until(lambda: statuses, 20, f"the latched status of {name} on /diagnostics")
    return statuses


@pytest.fixture
def ros():
    """A private rclpy context and node for one test (closed after it); import it into a test module to use."""
    client = PrivateRos(f"test_client_{uuid.uuid4().hex[:8]}")
    yield client
    client.close()
