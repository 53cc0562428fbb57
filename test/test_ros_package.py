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
import re
import signal
import subprocess
import sys
import time
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
               "python3-yaml", "python3-matplotlib", "python3-pytest", "ament_cmake", "rosidl_default_generators",
               "rosidl_default_runtime", "action_msgs"}
# packages of this repository: rosdep resolves them from the workspace (`--from-paths ... --ignore-src`)
WORKSPACE_KEYS = {"crop_sim_interfaces"}
PIP_ONLY = ("gymnasium", "refet", "stable-baselines3", "pydantic")


def test_package_xml_names_only_rosdep_keys_that_resolve_and_says_what_comes_from_pip():
    root = ET.parse(REPO / "package.xml").getroot()
    keys = {e.text for e in root if e.tag.endswith("depend") and e.get("condition") is None}
    interfaces = ET.parse(REPO / "crop_sim_interfaces" / "package.xml").getroot()
    keys |= {e.text for e in interfaces if e.tag.endswith("depend")}
    assert keys <= ROSDEP_KEYS | WORKSPACE_KEYS, keys - ROSDEP_KEYS - WORKSPACE_KEYS
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



# --- the typed interfaces: crop_sim_interfaces, an ament_cmake package beside the ament_python one -------------

INTERFACES = REPO / "crop_sim_interfaces"


def interface_files() -> list[Path]:
    return sorted(p for kind in ("msg", "srv", "action") for p in (INTERFACES / kind).iterdir())


def test_interface_package_is_ament_cmake_generating_every_interface_file():
    root = ET.parse(INTERFACES / "package.xml").getroot()
    assert root.findtext("name") == "crop_sim_interfaces" and root.find("export/build_type").text == "ament_cmake"
    assert root.findtext("member_of_group") == "rosidl_interface_packages"
    cmake = (INTERFACES / "CMakeLists.txt").read_text()
    listed = set(re.findall(r'"((?:msg|srv|action)/\w+\.\w+)"', cmake))
    assert listed == {str(p.relative_to(INTERFACES)) for p in interface_files()}
    # crop_sim_ros runs after it: colcon orders the two by this dependency
    depends = {e.text for e in ET.parse(REPO / "package.xml").getroot() if e.tag.endswith("depend")}
    assert "crop_sim_interfaces" in depends


# what a float field's comment names: a unit, the reward's unit, or a fraction's range
UNIT_IN_COMMENT = re.compile(r"(\bmm\b|\bt ha-1|\bdegC\b|\bMJ m-2|\bppm\b|\bhPa\b|\bm s-1|\bUSD\b|\breward_unit\b|"
                             r"\b0\.\.1\b)")


def test_every_interface_field_is_documented_with_its_unit_or_meaning():
    """Each field line of every .msg/.srv/.action carries a comment (its unit, or what it means), except the
    header; a float field's comment names its unit (mm, t ha-1, degC, ..., or reward_unit; a fraction 0..1);
    a stamped message says what its header.stamp and header.frame_id are."""
    for path in interface_files():
        text = path.read_text()
        if "std_msgs/Header header" in text:
            assert "header.stamp" in text and "header.frame_id" in text, f"{path.name}: the header is not described"
        for line in text.splitlines():
            field = line.split("#")[0].strip()
            if not field or field == "---" or field.startswith("std_msgs/Header"):
                continue
            comment = line.partition("#")[2].strip()
            assert comment, f"{path.name}: {line!r} has no comment"
            if re.match(r"float(32|64) ", field):  # a scalar float (the float32[] observation is the env's vector)
                assert UNIT_IN_COMMENT.search(comment), f"{path.name}: {line!r} names no unit"


def test_the_installed_interfaces_match_the_sources():
    """What ./farm built into this environment is these definitions (./farm rebuilds when they change)."""
    from crop_sim_interfaces.msg import CropState
    from crop_sim_interfaces.srv import Step

    assert "biomass_t_ha" in CropState.get_fields_and_field_types()
    assert Step.Request().day == Step.Request.ANY == -1
    share = Path(sys.prefix) / "share" / "crop_sim_interfaces"
    for path in interface_files():
        installed = share / path.relative_to(INTERFACES)
        assert installed.read_text() == path.read_text(), f"{path.name}: rebuild with scripts/build_interfaces.sh"


def test_colcon_builds_both_packages_in_a_workspace_and_the_copy_installed_node_starts(tmp_path, shared_data):
    """The documented colcon route: the repository under src/, the interface package named as a second base
    path (colcon does not look inside a package's folder); a copy install, then the node from install/ with the
    workspace's setup file sourced: it imports the interfaces from install/ and finds the data."""
    from crop_agent_ros.ros.process import isolated_ros_env

    src = tmp_path / "ws" / "src"
    src.mkdir(parents=True)
    (src / "crop_sim_ros").symlink_to(REPO)
    venv = Path(sys.prefix)
    env = {**isolated_ros_env(base={k: v for k, v in os.environ.items() if k != "PYTHONPATH"}), "PATH": f"{venv / 'bin'}{os.pathsep}{os.environ['PATH']}",
           "AMENT_PREFIX_PATH": str(venv), "CMAKE_PREFIX_PATH": str(venv), "CROP_SIM_DATA_DIR": str(shared_data)}
    build = subprocess.run(["colcon", "build", "--base-paths", "src", "src/crop_sim_ros/crop_sim_interfaces",
                            "--event-handlers", "console_cohesion-"], cwd=tmp_path / "ws", env=env,
                           capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    install = tmp_path / "ws" / "install"
    order = re.findall(r"Finished <<< (\w+)", build.stdout)
    assert order == ["crop_sim_interfaces", "crop_sim_ros"], build.stdout[-2000:]
    node = install / "crop_sim_ros" / "lib" / "crop_sim_ros" / "sim_node"
    script = (f"source {install / 'setup.bash'} && python -c 'import crop_sim_interfaces.msg as m; print(m.__file__)'"
              f" && exec {node} --ros-args -p scenario:=benton-2000 -p log_path:={tmp_path / 'log.csv'}"
              f" -r __ns:=/colcon_{os.getpid()}")
    out = tmp_path / "node.out"
    with out.open("w") as sink:
        process = subprocess.Popen(["bash", "-c", script], env=env, stdout=sink, stderr=subprocess.STDOUT,
                                   start_new_session=True)
    try:
        deadline = time.monotonic() + 90
        while "ready:" not in out.read_text() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        text = out.read_text()
        assert str(install / "crop_sim_interfaces") in text.splitlines()[0], text
        assert "ready: scenario 'benton-2000'" in text, text
    finally:
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=30) == 0, out.read_text()


def test_build_script_names_a_missing_tool_in_one_line(tmp_path):
    """scripts/build_interfaces.sh on a machine without cmake: exit 1, one line saying what to install."""
    import shutil

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("dirname", "cc", "c++", "make"):  # everything the script runs before its checks, but cmake
        (bin_dir / tool).symlink_to(shutil.which(tool))
    done = subprocess.run(["/bin/bash", str(REPO / "scripts" / "build_interfaces.sh"), sys.prefix],
                          env={"PATH": str(bin_dir)}, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.splitlines() == ["build_interfaces: cmake not found: install a C/C++ toolchain, cmake and make "
                                        "(Debian/Ubuntu: sudo apt-get install build-essential cmake)"]
