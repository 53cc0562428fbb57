"""The README is a front page: short, its example runs as written, and its links lead somewhere."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def python_blocks(markdown: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", markdown, flags=re.S)


def test_the_readme_is_a_front_page_of_at_most_200_lines():
    assert len(README.splitlines()) <= 200


def test_the_gymnasium_and_sb3_example_runs_verbatim(tmp_path):
    (example,) = python_blocks(README)
    assert len(example.strip().splitlines()) <= 15
    done = subprocess.run([sys.executable, "-c", example], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    match = re.fullmatch(r"yield (\d+\.\d) t/ha, return (-?\d+) USD/ha\n", done.stdout)
    assert match, done.stdout[-500:]
    assert 0.0 < float(match.group(1)) < 40.0  # a grown potato crop, dry tuber yield


def test_every_relative_link_names_a_file_of_the_repository():
    links = [link for link in re.findall(r"\]\(([^)\s]+)\)", README) if not re.match(r"[a-z]+://", link)]
    assert links
    missing = [link for link in links if not (ROOT / link.split("#")[0]).exists()]
    assert not missing


def test_the_readme_cites_no_research_files():
    cited = re.findall(r"results/[\w\-./*]+", README)
    assert all(path.startswith("results/summaries") for path in cited), cited


def test_the_leaderboard_excerpt_is_generated_in_place():
    start, end = "<!-- leaderboard:start -->", "<!-- leaderboard:end -->"
    assert README.count(start) == 1 and README.count(end) == 1
    excerpt = README.split(start)[1].split(end)[0]
    assert "|" in excerpt  # a table, written by `crop-sim leaderboard` (test_leaderboard checks it is current)
