"""The ament_python package: package.xml, what setup.py installs, the launch file and the parameter file
agree with each other and with the parameters the nodes declare (no ROS 2 installation needed)."""

from __future__ import annotations

import ast
import os
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
                "builtin_interfaces", "rcl_interfaces", "python3-numpy", "python3-yaml", "python3-gymnasium-pip",
                "python3-stable-baselines3-pip", "python3-refet-pip", "launch_ros"):
        assert key in depends, key
    assert "python3-pytest" in {e.text for e in root if e.tag == "test_depend"}


def test_setup_installs_what_ros2_run_and_launch_need():
    tree = ast.parse((REPO / "setup.py").read_text())
    text = ast.unparse(tree)
    for needle in ("share/ament_index/resource_index/packages", "resource/{PACKAGE}", "share/{PACKAGE}",
                   "package.xml", "launch/*.py", "config/*.yaml", "lib/{PACKAGE}", "scripts/sim_node",
                   "scripts/agent_node", "sim_node = crop_sim_ros.sim_node:main",
                   "agent_node = crop_agent_ros.agent_node:main"):
        assert needle in text, needle
    assert (REPO / "resource" / "crop_sim_ros").is_file()
    for exe in ("sim_node", "agent_node"):
        assert os.access(REPO / "scripts" / exe, os.X_OK)


def test_launch_file_and_parameter_file_match_the_nodes():
    pytest.importorskip("rclpy")
    from crop_agent_ros import agent_node
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

