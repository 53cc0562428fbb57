"""The ament_python package: package.xml, what setup.py installs, the launch file and the parameter file
agree with each other and with the parameters the nodes declare (no ROS 2 installation needed).

The launch file runs under ``ros2 launch`` only: the ``launch`` and ``launch_ros`` packages are not on PyPI, so
they are not installed here. Its tests load it with small recording stand-ins of the launch classes it uses
(each records what it was built with) and check the description it builds and its exit handler's logic:
that a failed agent makes the handler raise, which makes LaunchService.run, and so ``ros2 launch``, return 1.
"""

from __future__ import annotations

import ast
import importlib.util
import os
import sys
import types
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parent.parent


def test_package_xml_is_format_3_ament_python_with_its_dependencies():
    root = ET.parse(REPO / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == "crop_sim_ros"
    assert root.find("export/build_type").text == "ament_python"
    depends = {e.text for e in root if e.tag in ("depend", "exec_depend")}
    for key in ("rclpy", "std_msgs", "std_srvs", "sensor_msgs", "rosgraph_msgs", "diagnostic_msgs",
                "builtin_interfaces", "rcl_interfaces", "python3-numpy", "python3-yaml", "launch_ros"):
        assert key in depends, key
    assert "python3-pytest" in {e.text for e in root if e.tag == "test_depend"}


# rosdep keys of the ROS packages (rosdistro) and of rosdep's python.yaml that package.xml may name: every one
# resolves, so `rosdep install --from-paths src` does not stop at an unknown key (python3-refet-pip has no rule).
ROSDEP_KEYS = {"ament_python", "rclpy", "builtin_interfaces", "std_msgs", "std_srvs", "sensor_msgs", "rosgraph_msgs",
               "diagnostic_msgs", "rcl_interfaces", "ament_index_python", "launch", "launch_ros", "python3-numpy",
               "python3-yaml", "python3-matplotlib", "python3-pytest"}
PIP_ONLY = ("gymnasium", "refet", "stable-baselines3", "pydantic")


def test_package_xml_names_only_rosdep_keys_that_resolve_and_says_what_comes_from_pip():
    root = ET.parse(REPO / "package.xml").getroot()
    keys = {e.text for e in root if e.tag.endswith("depend") and e.get("condition") is None}
    assert keys <= ROSDEP_KEYS, keys - ROSDEP_KEYS
    assert not [key for key in keys if key.endswith("-pip")]
    comments = (REPO / "package.xml").read_text()
    requirements = (REPO / "requirements.txt").read_text()
    docs = (REPO / "docs" / "ros.md").read_text()
    for name in PIP_ONLY:  # named in package.xml's pip comment, pinned in requirements.txt, and in docs/ros.md
        assert name in comments and name in requirements and name in docs, name


def test_setup_installs_what_ros2_run_and_launch_need():
    tree = ast.parse((REPO / "setup.py").read_text())
    text = ast.unparse(tree)
    for needle in ("share/ament_index/resource_index/packages", "resource/{PACKAGE}", "share/{PACKAGE}",
                   "package.xml", "launch/*.py", "config/*.yaml", "lib/{PACKAGE}", "scripts/sim_node",
                   "scripts/agent_node", "sim_node = crop_sim_ros.sim_node:main",
                   "agent_node = crop_agent_ros.ros.agent_node:main"):
        assert needle in text, needle
    assert (REPO / "resource" / "crop_sim_ros").is_file()
    for exe in ("sim_node", "agent_node"):
        assert os.access(REPO / "scripts" / exe, os.X_OK)


def test_launch_file_and_parameter_file_match_the_nodes():
    from crop_agent_ros.ros import agent as agent_node
    from crop_sim_ros import sim_node

    launch = ast.unparse(ast.parse((REPO / "launch" / "farm.launch.py").read_text()))
    assert "generate_launch_description" in launch
    for needle in ("executable='sim_node'", "executable='agent_node'", "name='crop_sim'", "name='crop_agent'",
                   "farm_params.yaml", "package='crop_sim_ros'"):
        assert needle in launch, needle
    params = yaml.safe_load((REPO / "config" / "farm_params.yaml").read_text())
    declared = {"crop_sim": sim_node.PARAMETERS, "crop_agent": agent_node.PARAMETERS}
    assert set(params) == set(declared)
    for node, values in params.items():
        values = values["ros__parameters"]
        assert set(values) <= set(declared[node]), set(values) - set(declared[node])
        for key, value in values.items():  # same type as the declared default
            default = declared[node][key][0]
            assert type(value) is type(default), (node, key, value, default)


class Recorded:
    """A stand-in for a launch class: remembers its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.args}, {self.kwargs})"


LAUNCH_NAMES = {
    "launch": ["LaunchDescription"],
    "launch.actions": ["DeclareLaunchArgument", "EmitEvent", "RegisterEventHandler"],
    "launch.event_handlers": ["OnProcessExit"],
    "launch.events": ["Shutdown"],
    "launch.substitutions": ["LaunchConfiguration", "PathJoinSubstitution"],
    "launch_ros.actions": ["Node"],
    "launch_ros.parameter_descriptions": ["ParameterValue"],
    "launch_ros.substitutions": ["FindPackageShare"],
}


@pytest.fixture()
def launch_file(monkeypatch):
    """farm.launch.py loaded with recording stand-ins of the launch classes."""
    for module_name, class_names in LAUNCH_NAMES.items():
        module = types.ModuleType(module_name)
        for name in class_names:
            setattr(module, name, type(name, (Recorded,), {}))
        monkeypatch.setitem(sys.modules, module_name, module)
    spec = importlib.util.spec_from_file_location("farm_launch", REPO / "launch" / "farm.launch.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def config_name(value) -> str:
    assert type(value).__name__ == "LaunchConfiguration", value
    return value.args[0]


def test_launch_declares_scenario_namespace_seasons_log_path_policy_and_clock_and_passes_them_on(launch_file):
    from crop_sim_ros.sim_parameters import PARAMETERS

    (entities,) = launch_file.generate_launch_description().args
    declared = {e.args[0]: e.kwargs["default_value"] for e in entities
                if type(e).__name__ == "DeclareLaunchArgument"}
    assert set(declared) == {"params_file", "scenario", "policy", "seasons", "namespace", "log_path", "clock_topic"}
    assert (declared["seasons"], declared["namespace"], declared["log_path"]) == ("1", "", "")
    # the simulator's own defaults, as the parameter file has them
    params = yaml.safe_load((REPO / "config" / "farm_params.yaml").read_text())["crop_sim"]["ros__parameters"]
    for name in ("scenario", "clock_topic"):
        assert declared[name] == PARAMETERS[name].default == params[name], name
    sim, agent = [e for e in entities if type(e).__name__ == "Node"]
    assert (sim.kwargs["executable"], agent.kwargs["executable"]) == ("sim_node", "agent_node")
    for node in (sim, agent):
        assert config_name(node.kwargs["namespace"]) == "namespace"
        assert config_name(node.kwargs["parameters"][0]) == "params_file"
    for name in ("scenario", "log_path", "clock_topic"):  # typed: '' and numeric-looking names stay strings
        value = sim.kwargs["parameters"][1][name]
        assert config_name(value.args[0]) == name and value.kwargs == {"value_type": str}, name
    overrides = agent.kwargs["parameters"][1]
    assert overrides["drive"] is True
    assert config_name(overrides["seasons"].args[0]) == "seasons" and overrides["seasons"].kwargs == {"value_type": int}
    assert config_name(overrides["policy"].args[0]) == "policy"
    namespace, suffix = overrides["sim_node"].args[0]  # the simulator in the agent's namespace
    assert config_name(namespace) == "namespace" and suffix == "/crop_sim"


class Exited:
    """What OnProcessExit hands its handler: the process's exit status."""

    def __init__(self, returncode: int):
        self.returncode = returncode


def test_launch_shuts_down_after_the_agent_and_fails_when_the_agent_fails(launch_file):
    (entities,) = launch_file.generate_launch_description().args
    (handler,) = [e.args[0] for e in entities if type(e).__name__ == "RegisterEventHandler"]
    agent = [e for e in entities if type(e).__name__ == "Node"][1]
    assert handler.kwargs["target_action"] is agent
    on_exit = handler.kwargs["on_exit"]
    (action,) = on_exit(Exited(0), context=None)  # done: shut the simulator down, the launch returns 0
    assert type(action).__name__ == "EmitEvent" and type(action.kwargs["event"]).__name__ == "Shutdown"
    for status in (1, 2, -15):  # failed: raising in a handler makes LaunchService.run return 1
        with pytest.raises(launch_file.AgentFailed, match=f"agent_node exited with status {status}"):
            on_exit(Exited(status), context=None)

