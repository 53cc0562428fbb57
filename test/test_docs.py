"""The manual in docs/ builds offline with warnings as errors, and what it says matches the code.

Sphinx's -W makes every warning fail the build: a page in no toctree, a broken cross-reference, a
generated table whose source moved (docs/_ext/crop_sim_docs.py), a registered task on no page. The other
checks read the built pages: the CLI reference has every ``crop-sim`` command, every registered task is on a
task page, and the ids and commands the prose names exist.
"""

from __future__ import annotations

import html
import re
import subprocess
import sys
from pathlib import Path

import gymnasium
import pytest

import crop_sim_ros.task  # noqa: F401  (registers the tasks)
from crop_agent_ros.cli import COMMANDS, build_parser

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The manual built into a temporary folder, exactly as CI builds it."""
    out = tmp_path_factory.mktemp("docs-html")
    build = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html", "-q",
                            str(DOCS), str(out)], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, f"sphinx failed ({build.returncode}):\n{build.stderr[-4000:]}"
    return out


def text_of(page: Path) -> str:
    return html.unescape(re.sub(r"<[^>]+>", " ", page.read_text(encoding="utf-8")))


def test_the_manual_builds_with_warnings_as_errors_and_every_page_is_built(site):
    # A page in no toctree would have failed the build (-W); each source page gives one HTML page.
    for page in PAGES:
        assert (site / page.relative_to(DOCS).with_suffix(".html")).is_file(), page


def test_the_cli_page_has_a_section_for_every_crop_sim_command(site):
    cli = (site / "cli.html").read_text(encoding="utf-8")
    sections = set(re.findall(r'<section id="crop-sim-([a-z0-9-]+)"', cli))
    missing = [name for name in COMMANDS if name not in sections]
    assert not missing, f"crop-sim commands missing from the CLI page: {missing}"


def test_every_registered_task_is_on_a_task_page_with_its_id(site):
    task_pages = " ".join(text_of(page) for page in (site / "tasks").glob("*.html"))
    ids = [env_id for env_id, spec in gymnasium.registry.items()
           if str(spec.entry_point).startswith("crop_sim_ros.")]
    assert ids, "crop_sim_ros.task registered no task"
    missing = [env_id for env_id in ids if env_id not in task_pages]
    assert not missing, f"registered tasks on no task page: {missing}"


def shell_blocks(text: str) -> list[str]:
    """The bodies of the page's fenced ``bash`` (or unlabelled) code blocks, fences paired in order."""
    blocks, body, info = [], None, ""
    for line in text.splitlines():
        fence = re.match(r"^(`{3,}|~{3,})(.*)$", line.strip())
        if body is None and fence:
            body, info = [], fence.group(2).strip()
        elif body is not None and fence and not fence.group(2).strip():
            if info in ("", "bash", "console", "sh"):
                blocks.append("\n".join(body))
            body = None
        elif body is not None:
            body.append(line)
    return blocks


def command_lines(text: str) -> list[str]:
    """Each shell command of the page's code blocks: comments dropped, continued lines joined, one entry per
    command of a pipeline or list."""
    commands = []
    for block in shell_blocks(text):
        joined = re.sub(r"\\\n", " ", block)
        for line in joined.splitlines():
            line = re.sub(r"(^|\s)#.*", "", line)  # a comment is prose, not a command
            commands += [part.strip() for part in re.split(r"\||;|&&", line) if part.strip()]
    return commands


def test_the_ids_commands_and_options_the_pages_name_exist():
    subcommands = {action.dest: action for action in build_parser()._actions if action.dest == "command"}
    parsers = subcommands["command"].choices
    named_ids, unknown = set(), []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        named_ids |= set(re.findall(r"crop-sim/[A-Za-z0-9_.-]+-v\d+", text))
        for command in command_lines(text):
            call = re.search(r"(?:crop-sim|\./farm) ([a-z][a-z-]*)(.*)", command)
            if not call or call.group(1) in ("demo", "test", "docs"):
                continue
            name, rest = call.groups()
            if name not in parsers:
                unknown.append(f"{page.name}: crop-sim {name}")
                continue
            options = set(parsers[name]._option_string_actions)
            unknown += [f"{page.name}: crop-sim {name} {option}" for option in re.findall(r"(?<!\S)--[a-z][a-z0-9-]*", rest)
                        if option not in options]
    assert named_ids, "the pages name no Gymnasium id"
    unregistered = sorted(i for i in named_ids if i not in gymnasium.registry)
    assert not unregistered, f"ids named in docs/ but not registered: {unregistered}"
    assert not unknown, f"commands or options named in docs/ that crop-sim does not have: {unknown}"
