"""Result files are written whole or not at all (:mod:`crop_sim_ros.output`), and every command checks its output
folder before any work (issue 34: a full disk left a truncated ``table.json`` where a valid one stood; an
``--out`` under a file, read-only or in /proc ended in a traceback).

A full disk is a file-size limit (``RLIMIT_FSIZE``, with ``SIGXFSZ`` ignored so that a write past it fails with
EFBIG as on a full disk) set in a forked child: the pytest process itself is never limited.
"""

from __future__ import annotations

import io
import json
import multiprocessing
import os
import resource
import signal
import sys
import tempfile
from pathlib import Path

import pytest

from crop_agent_ros.cli import main
from crop_sim_ros.output import (WriteError, check_output_directory, check_output_file, replace_atomically,
                                 save_figure_atomic, write_csv_atomic, write_json_atomic, write_text_atomic)
from crop_sim_ros.usage import UsageError

LIMIT_BYTES = 4096
TINY_EVALUATE = ["--sets", "heldout-real", "--noise-seeds", "1", "--bootstrap", "100", "--no-oracle", "--no-curves"]


def _child(queue, limit_bytes, uid, function, args):
    """In a forked child: the limits, then ``function(*args)``; its result, or the error it raised, to ``queue``."""
    try:
        if limit_bytes is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        if uid is not None:
            os.setgid(uid)
            os.setuid(uid)
        queue.put(("returned", function(*args)))
    except BaseException as error:  # noqa: BLE001 - everything is the parent's to judge
        queue.put((type(error).__name__, str(error)))


def in_child(function, *args, limit_bytes: int | None = None, uid: int | None = None):
    """``(outcome, value)`` of ``function(*args)`` run in a forked child under a file-size limit and/or as
    another user: ("returned", its result) or (the exception's class name, its message)."""
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_child, args=(queue, limit_bytes, uid, function, args))
    child.start()
    try:
        outcome = queue.get(timeout=120)
    finally:
        child.join(timeout=30)
    return outcome


def cli_in_child(argv: list[str]) -> tuple[int, str]:
    """``crop-sim argv`` in this (forked) process: (exit status, stderr)."""
    stderr, saved = io.StringIO(), sys.stderr
    sys.stderr = stderr
    try:
        status = main(argv)
    finally:
        sys.stderr = saved
    return status, stderr.getvalue()


def no_temporaries(folder: Path) -> bool:
    return not [p for p in folder.iterdir() if p.name.startswith(".") and ".tmp" in p.name]


# --- the writers ------------------------------------------------------------------------------------------

def test_an_atomic_write_replaces_the_whole_file_and_keeps_its_permissions(tmp_path):
    path = tmp_path / "table.json"
    write_json_atomic(path, {"a": [1, 2]})
    assert json.loads(path.read_text()) == {"a": [1, 2]} and path.read_text().endswith("\n")
    assert path.stat().st_mode & 0o777 == 0o666 & ~_umask()     # not mkstemp's 0o600
    path.chmod(0o640)
    write_text_atomic(path, "short\n")
    assert path.read_text() == "short\n" and path.stat().st_mode & 0o777 == 0o640
    write_csv_atomic(tmp_path / "rows.csv", ["x", "y"], [{"x": 1, "y": 2}, {"x": 3, "y": 4}])
    write_csv_atomic(tmp_path / "lists.csv", ["x", "y"], [[1, 2]])
    assert (tmp_path / "rows.csv").read_bytes() == b"x,y\r\n1,2\r\n3,4\r\n"
    assert (tmp_path / "lists.csv").read_bytes() == b"x,y\r\n1,2\r\n"
    assert no_temporaries(tmp_path)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def test_a_failed_write_leaves_the_old_file_and_no_temporary_file(tmp_path):
    path = tmp_path / "model.zip"
    path.write_bytes(b"old model")

    def fails(temporary: Path) -> None:
        temporary.write_bytes(b"half a mod")
        raise OSError(28, "No space left on device")

    with pytest.raises(WriteError) as error:
        replace_atomically(path, fails)
    assert str(error.value) == (f"cannot write {path}: [Errno 28] No space left on device (any previous model.zip "
                                "is unchanged)")
    assert path.read_bytes() == b"old model" and no_temporaries(tmp_path)
    with pytest.raises(ValueError):          # a value JSON refuses: nothing written at all
        write_json_atomic(path.with_suffix(".json"), {"x": float("nan")}, allow_nan=False)
    assert not path.with_suffix(".json").exists() and no_temporaries(tmp_path)
    with pytest.raises(WriteError, match=r"cannot write .*missing/x.json: \[Errno 2\]"):
        write_json_atomic(tmp_path / "missing" / "x.json", {})


def test_a_plot_is_written_to_a_temporary_name_in_its_format_then_renamed(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    save_figure_atomic(fig, tmp_path / "curve.png", dpi=50)
    plt.close(fig)
    assert (tmp_path / "curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and no_temporaries(tmp_path)


def _write_big_json(path: str) -> str:
    write_json_atomic(path, {"rows": ["x" * 100] * 200})   # about 21 kB, over the limit
    return "written"


def test_a_full_disk_leaves_the_old_valid_table_and_says_the_write_failed(tmp_path):
    path = tmp_path / "table.json"
    path.write_text(json.dumps({"sets": [], "old": True}))
    outcome, message = in_child(_write_big_json, str(path), limit_bytes=LIMIT_BYTES)
    assert outcome == "WriteError", (outcome, message)
    assert message.startswith(f"cannot write {path}: [Errno 27] File too large") and "\n" not in message
    assert json.loads(path.read_text()) == {"sets": [], "old": True}
    assert no_temporaries(tmp_path)


def _evaluation_outputs(out: str) -> str:
    """``crop-sim evaluate --task``'s writer with a table of about 60 kB (its first file is table.json)."""
    from crop_agent_ros.learning.evaluate_task import write_outputs
    write_outputs(Path(out), {"task": "benton-quota", "sets": [], "padding": ["x" * 100] * 600}, [], [])
    return "written"


def test_evaluate_tasks_writer_on_a_full_disk_keeps_the_previous_table(tmp_path):
    """Issue 34's case: the old writer left 4,096 bytes of invalid JSON where a valid table stood."""
    (tmp_path / "table.json").write_text(json.dumps({"task": "benton-quota", "sets": [], "old": True}))
    outcome, message = in_child(_evaluation_outputs, str(tmp_path), limit_bytes=LIMIT_BYTES)
    assert outcome == "WriteError" and message.startswith(f"cannot write {tmp_path / 'table.json'}: "), message
    assert json.loads((tmp_path / "table.json").read_text())["old"] is True
    assert no_temporaries(tmp_path)


def test_simulate_on_a_full_disk_ends_in_one_line_and_keeps_the_previous_files(tmp_path, capsys):
    out = tmp_path / "sim"
    argv = ["simulate", "--task", "benton-2000", "--out", str(out), "--no-plot"]
    assert main(argv) == 0
    before = {name: (out / name).read_bytes() for name in ("summary.json", "season.csv")}
    assert len(before["season.csv"]) > LIMIT_BYTES
    outcome, (status, stderr) = in_child(cli_in_child, argv, limit_bytes=LIMIT_BYTES)
    assert outcome == "returned" and status == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"crop-sim simulate: cannot write {out}/season.csv: "), stderr
    assert "File too large" in lines[0] and "unchanged" in lines[0]
    assert {name: (out / name).read_bytes() for name in before} == before
    assert no_temporaries(out)


# --- output folders checked before any work ---------------------------------------------------------------

def test_the_output_folder_checks_name_what_is_wrong(tmp_path):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    for path, message in ((a_file, "is a file, not a folder"),
                          (a_file / "out", f"lies under {a_file}, which is a file, not a folder"),
                          (Path("/proc/self/out"), "is in a kernel file system (/proc, /sys, /dev)"),
                          (Path("/dev/shm/../null/out"), "kernel file system")):
        with pytest.raises(UsageError, match=r"^--out: .*" + message.replace("(", r"\(").replace(")", r"\)")):
            check_output_directory(path)
    assert check_output_directory(tmp_path / "new" / "deeper") == tmp_path / "new" / "deeper"
    assert not (tmp_path / "new").exists()     # checked, not created
    with pytest.raises(UsageError, match="--root: .* is a folder, not a file"):
        check_output_file(tmp_path, "--root")


def test_a_read_only_folder_is_refused_in_one_line():
    base = Path(tempfile.mkdtemp())
    try:
        base.chmod(0o755)
        read_only = base / "ro"
        read_only.mkdir(mode=0o555)
        read_only.chmod(0o555)
        uid = 65534 if os.geteuid() == 0 else None     # root writes anywhere: check as nobody
        outcome, message = in_child(check_output_directory, read_only / "out", uid=uid)
        assert outcome == "UsageError" and message == f"--out: cannot write in {read_only} (read-only or no permission)"
    finally:
        (base / "ro").chmod(0o755)
        (base / "ro").rmdir()
        base.rmdir()


@pytest.mark.parametrize("command", [
    ["simulate", "--task", "benton-2000"],
    ["evaluate", "--seasons", "benton-2000", "--policies", "never"],
    ["evaluate", "--task", "benton-quota", *TINY_EVALUATE],
    ["train", "--task", "benton-quota", "--algorithm", "ppo"],
])
def test_every_command_refuses_a_bad_out_in_one_line_before_any_work(tmp_path, capsys, command):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    for out, message in ((a_file, "is a file, not a folder"), (a_file / "sub", "which is a file, not a folder"),
                         ("/proc/1/x", "kernel file system")):
        assert main([*command, "--out", str(out)]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"crop-sim {command[0]}: --out: ") and message in lines[0], lines
    assert a_file.read_text() == "x" and sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_the_sweep_refuses_a_bad_out_before_starting_ray(tmp_path, capsys, monkeypatch):
    from crop_agent_ros.scale import cluster
    monkeypatch.setattr(cluster, "connect", lambda *a: pytest.fail("Ray was started"))
    config = tmp_path / "sweep.yaml"
    config.write_text("tasks: [benton-quota]\ntrain: {timesteps: 1024, n-envs: 4, n-steps: 64, batch-size: 128}\n")
    a_file = tmp_path / "file"
    a_file.write_text("x")
    assert main(["sweep", str(config), "--out", str(a_file / "sweep")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("crop-sim sweep: --out: ") and "which is a file" in err
    assert not (tmp_path / "runs").exists()


def test_the_leaderboard_refuses_a_folder_where_its_page_goes_and_writes_nothing(tmp_path, capsys):
    from test_leaderboard import small_tree
    root = small_tree(tmp_path)
    readme = (root / "README.md").read_text()
    (root / "docs" / "leaderboard.md").mkdir(parents=True)
    assert main(["leaderboard", "--root", str(root)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("crop-sim leaderboard: --root: ") and "is a folder, not a file" in err
    assert (root / "README.md").read_text() == readme        # nothing written when one file cannot be
    (root / "docs" / "leaderboard.md").rmdir()
    assert main(["leaderboard", "--root", str(root)]) == 0
    assert no_temporaries(root / "docs") and no_temporaries(root)


def test_the_tuned_rule_is_written_atomically(tmp_path, monkeypatch):
    from crop_agent_ros.policies import family_tuning
    monkeypatch.setattr(family_tuning, "HERE", tmp_path)
    written = family_tuning.write_tuned("x", {"parameters": {"pace": float("inf"), "margin_mm": 1.0}})
    assert json.loads(written.read_text())["parameters"] == {"pace": None, "margin_mm": 1.0}
    assert no_temporaries(tmp_path)
