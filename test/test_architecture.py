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
    (["crop_sim_ros.task", "crop_sim_ros.session"], {"rclpy", "torch", "stable_baselines3", "crop_agent_ros", "jax"}),
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


# --- the static import graph ------------------------------------------------------------------------------------

PACKAGES = ("crop_sim_ros", "crop_agent_ros")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _package_modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the two packages."""
    return {_module_name(path): path for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py"))}


def imported_names(name: str, path: Path) -> set[str]:
    """Every dotted name the module ``name`` (file ``path``) imports, anywhere in it (functions included):
    relative imports resolved against its package, ``from P import X`` as ``P.X`` (X may be a module or a name in
    P: :func:`import_graph` keeps the longest prefix of it that is a module)."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the package modules it imports (an imported name resolved to its longest prefix that is one)."""
    graph = {}
    for name, path in modules.items():
        targets = set()
        for imported in imported_names(name, path):
            while imported and imported not in modules:
                imported = imported.rpartition(".")[0]
            if imported and imported != name:
                targets.add(imported)
        graph[name] = targets
    return graph


def strongly_connected_components(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm, iterative: each component's modules, sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(graph[successor]))))
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    components.append(sorted(component))
    return components


def test_the_import_graph_finds_a_cycle_through_a_function_level_import(tmp_path):
    """The checker itself: a cycle closed by an import inside a function, through `from . import module` and
    `import pkg.a as alias`; `from pkg import c` is the module pkg.c, a name of a module is the module."""
    texts = {"pkg": "", "pkg.a": "from . import b\n", "pkg.b": "def f():\n    from .c import thing\n",
             "pkg.c": "import pkg.a as alias\n", "pkg.d": "from pkg import c\nfrom pkg.c import thing\n"}
    paths = {}
    for name, text in texts.items():
        path = (tmp_path / "pkg" / "__init__.py" if name == "pkg"
                else tmp_path.joinpath(*name.split(".")).with_suffix(".py"))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        paths[name] = path
    graph = import_graph(paths)
    assert graph == {"pkg": set(), "pkg.a": {"pkg.b"}, "pkg.b": {"pkg.c"}, "pkg.c": {"pkg.a"}, "pkg.d": {"pkg.c"}}
    assert [c for c in strongly_connected_components(graph) if len(c) > 1] == [["pkg.a", "pkg.b", "pkg.c"]]


def test_no_import_cycles():
    """No two modules of crop_sim_ros and crop_agent_ros import each other, directly or through others
    (function-level imports count: a cycle is a design knot even where it does not fail at import time)."""
    cycles = [c for c in strongly_connected_components(import_graph(_package_modules())) if len(c) > 1]
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_policies_never_import_learning():
    """A policy is run by the evaluation, the ROS agent and the training; the training is never needed to run one."""
    graph = import_graph(_package_modules())
    offenders = [f"{module} imports {target}" for module, targets in sorted(graph.items())
                 if module.startswith("crop_agent_ros.policies") for target in sorted(targets)
                 if target.startswith("crop_agent_ros.learning")]
    assert not offenders, "\n".join(offenders)


def test_the_packages_never_import_experiments():
    """experiments/ holds investigations that import the package; the package never imports them."""
    offenders = [f"{name}: {imported}" for name, path in sorted(_package_modules().items())
                 for imported in sorted(imported_names(name, path)) if imported.split(".")[0] == "experiments"]
    assert not offenders, "\n".join(offenders)
