"""The README's links hold: every link to one of its sections names a heading it has, and every committed result
it cites (``results/...``: tables, trained policies, demonstrations) is in the repository."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
SEEDS = "sS"  # the README's name for "each training seed" (its commands loop S = 0..4)


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation other than - and _ dropped, spaces -> -."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(markdown: str) -> set[str]:
    prose = re.sub(r"```.*?```", "", markdown, flags=re.S)
    found: set[str] = set()
    for heading in re.findall(r"^#+ (.*)$", prose, flags=re.M):
        anchor = base = github_anchor(heading)
        for n in itertools.count(1):  # GitHub numbers repeated headings
            if anchor not in found:
                break
            anchor = f"{base}-{n}"
        found.add(anchor)
    return found


def cited_results(markdown: str) -> list[tuple[str, str]]:
    """(the path as written, the glob it stands for) for every ``results/...`` path in the README. Notation:
    ``-sS`` each training seed (seed 0 must exist), ``[-x]`` an optional part (both readings must exist),
    ``*`` and ``[0-9]`` as in a glob, and a path cut by a line end or followed by ``{`` is a prefix."""
    cited = []
    for match in re.finditer(r"results/[\w\-./*\[\]]+", markdown):
        written = match.group(0).rstrip(".,")
        following = markdown[match.end():match.end() + 1]
        prefix = following in ("{", "\n") and not written.endswith((".zip", ".json", ".npz", ".csv", ".md", ".png"))
        optional = re.findall(r"\[(-[^\]]*)\]", written)
        for kept in itertools.product((False, True), repeat=len(optional)):
            parts = iter(kept)
            path = re.sub(r"\[(-[^\]]*)\]", lambda m: m.group(1) if next(parts) else "", written)
            if path.endswith("-" + SEEDS) or f"-{SEEDS}/" in path:
                path = path.replace("-" + SEEDS, "-s0")
            cited.append((written, path + ("*" if prefix else "")))
    return cited


def test_the_anchor_rule_is_githubs():
    assert github_anchor("Set-up: two commands") == "set-up-two-commands"
    assert github_anchor("Recurrent agent on `benton-sensing`") == "recurrent-agent-on-benton-sensing"
    assert github_anchor("The seed code's defects") == "the-seed-codes-defects"
    assert anchors("# A\n```\n# not a heading\n```\n## A\n") == {"a", "a-1"}


def test_every_link_to_a_section_names_one_of_its_headings():
    links = re.findall(r"\]\(#([^)\s]+)\)", README)
    assert len(links) >= 30  # the contents list alone links every section
    assert sorted(set(links) - anchors(README)) == []


def test_every_result_the_readme_cites_is_committed():
    cited = cited_results(README)
    assert len(cited) >= 150
    missing = sorted({written for written, pattern in cited if not list(ROOT.glob(pattern))})
    assert missing == []


def test_the_citation_reader_expands_the_notation(tmp_path):
    text = ("see results/a/x-sS/model.zip and results/a/y[-h8]-sS, results/a/demo-{1,2}.npz\n"
            "and results/a/long-\nname.npz, results/a/t*.csv, results/a/d-[0-9]*.npz.")
    assert cited_results(text) == [
        ("results/a/x-sS/model.zip", "results/a/x-s0/model.zip"),
        ("results/a/y[-h8]-sS", "results/a/y-s0"), ("results/a/y[-h8]-sS", "results/a/y-h8-s0"),
        ("results/a/demo-", "results/a/demo-*"), ("results/a/long-", "results/a/long-*"),
        ("results/a/t*.csv", "results/a/t*.csv"), ("results/a/d-[0-9]*.npz", "results/a/d-[0-9]*.npz")]


def test_the_contents_list_every_section():
    prose = re.sub(r"```.*?```", "", README, flags=re.S)
    sections = [github_anchor(h) for h in re.findall(r"^#{2,3} (.*)$", prose, flags=re.M)]
    contents = README.split("Contents:", 1)[1].split("\n## ", 1)[0]
    assert sorted(set(sections) - set(re.findall(r"\]\(#([^)\s]+)\)", contents))) == []
