"""The layers import only what is before them (shared/spec/ARCHITECTURE.md)."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _loaded_after_import(modules: list[str]) -> set[str]:
    code = ("import sys\n" + "".join(f"import {m}\n" for m in modules)
            + "print(' '.join(sorted({n.split('.')[0] for n in sys.modules})))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    return set(result.stdout.split())


@pytest.mark.parametrize("modules, forbidden", [
    (["crop_sim_ros.model", "crop_sim_ros.weather", "crop_sim_ros.validation"], {"rclpy", "gymnasium", "torch"}),
    (["crop_sim_ros.task", "crop_sim_ros.session"], {"rclpy", "torch", "stable_baselines3", "crop_agent_ros"}),
])
def test_lower_layers_do_not_load_higher_ones(modules, forbidden):
    assert not _loaded_after_import(modules) & forbidden


def test_the_farm_never_imports_its_farmers():
    offenders = []
    for path in (ROOT / "crop_sim_ros").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            offenders += [f"{path.relative_to(ROOT)}: {n}" for n in names if n.startswith("crop_agent_ros")]
    assert not offenders


def test_command_line_help_does_not_load_torch_or_rclpy():
    code = ("import sys\nfrom crop_agent_ros.cli import build_parser\nbuild_parser()\n"
            "print(' '.join(sorted({n.split('.')[0] for n in sys.modules})))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert not set(result.stdout.split()) & {"torch", "rclpy", "stable_baselines3"}


ROS_MODULES = ("rclpy", "std_msgs", "std_srvs", "diagnostic_msgs", "rosgraph_msgs", "rcl_interfaces", "builtin_interfaces")


def test_only_the_ros_subpackage_imports_ros():
    """crop_agent_ros/ros/ holds everything that imports rclpy; policies/, learning/ and scale/ never import it
    (cli.py names its jobs' modules as strings and imports the one asked for)."""
    offenders = []
    for path in (ROOT / "crop_agent_ros").rglob("*.py"):
        if path.parent.name == "ros":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                names = [("." * node.level) + base] + ([f"{'.' * node.level}{a.name}" for a in node.names]
                                                       if not base else [])
            else:
                continue
            offenders += [f"{path.relative_to(ROOT)}: {n}" for n in names
                          if n.split(".")[0] in ROS_MODULES or n.startswith("crop_agent_ros.ros")
                          or n.lstrip(".").split(".")[0] == "ros"]
    assert not offenders
