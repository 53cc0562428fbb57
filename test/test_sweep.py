"""``crop-sim sweep``: the configuration (checked before Ray starts) and real sweeps on Ray Tune.

Every Ray process runs inside a loopback-only network namespace (test/ray_support.py); the pytest process
never imports Ray. Trials use tiny budgets: the tests check the machinery (table, retries, resume, placement on
two nodes), never a learning result.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from crop_agent_ros.scale.sweep import SweepSpec
from crop_sim_ros.usage import UsageError
from ray_support import LoopbackNamespace

ROOT = Path(__file__).resolve().parents[1]
CROP_SIM = str(Path(sys.executable).parent / "crop-sim")

TINY_TRAIN = {"timesteps": 1024, "n-envs": 4, "n-steps": 64, "batch-size": 128, "eval-freq": 512,
              "validation-seasons": 3, "no-progress": True}
TINY_EVALUATE = {"sets": "heldout-real", "noise-seeds": 1, "bootstrap": 100, "oracle": False, "curves": False}


def spec(**changes) -> SweepSpec:
    raw = {"name": "t", "tasks": ["benton-quota"], "seeds": [0], "train": dict(TINY_TRAIN),
           "evaluate": dict(TINY_EVALUATE), **changes}
    return SweepSpec.from_dict(raw, "test.yaml")


# --- the configuration ------------------------------------------------------------------------------------

def test_configurations_are_the_grid_times_seeded_random_draws():
    raw = dict(grid={"learning-rate": [3e-4, 1e-4]}, samples=3, seeds=[0, 1],
               random={"log-std-init": {"uniform": [-1.5, -0.5]}, "n-epochs": {"randint": [5, 6]},
                       "ent-coef": {"loguniform": [1e-4, 1e-2]}, "net-arch": {"choice": [[64, 64], [32]]}})
    one, again, other = spec(**raw), spec(**raw), spec(**raw, **{"search-seed": 1})
    assert len(one.configurations) == 6
    assert one.configurations == again.configurations
    assert one.configurations != other.configurations
    assert [c["learning-rate"] for c in one.configurations] == [3e-4] * 3 + [1e-4] * 3
    for c in one.configurations:
        assert -1.5 <= c["log-std-init"] <= -0.5 and 1e-4 <= c["ent-coef"] <= 1e-2
        assert c["n-epochs"] in (5, 6) and isinstance(c["n-epochs"], int) and c["net-arch"] in ([64, 64], [32])
    # 200 draws of a loguniform: about half below the geometric mean (a plain uniform would put ~1 % there)
    many = spec(random={"ent-coef": {"loguniform": [1e-4, 1e-2]}}, samples=200).configurations
    below = np.mean([c["ent-coef"] < 1e-3 for c in many])
    assert 0.35 < below < 0.65
    trials = one.trials()
    assert [t.key for t in trials[:3]] == ["benton-quota-c00-s0", "benton-quota-c00-s1", "benton-quota-c01-s0"]
    assert len(trials) == 12
    first = trials[0]
    assert first.train_argv[:4] == ("--task", "benton-quota", "--seed", "0")
    assert "learning_rate=0.0003" in first.train_argv and "--no-progress" in first.train_argv
    assert first.train_argv[first.train_argv.index("learning_rate=0.0003") - 1] == "--hyperparams"
    assert first.evaluate_argv == ("--task", "benton-quota", "--sets", "heldout-real", "--noise-seeds", "1",
                                   "--bootstrap", "100", "--no-oracle", "--no-curves")


@pytest.mark.parametrize("changes, message", [
    ({"tasks": []}, "tasks: List should have at least 1 item"),
    ({"seeds": [0, 0]}, "seeds: 0 named more than once"),
    ({"epochs": 3}, "epochs: unknown key; known: name, tasks, seeds"),
    ({"train": {"seed": 3}}, "train: may not set seed"),
    ({"evaluate": {"agents": "x=y"}}, "evaluate: may not set agents"),
    ({"evaluate": {"address": "auto", "cpus": 2}}, "evaluate: may not set address, cpus"),
    ({"train": {"timesteps": "many"}}, "hyperparameter timesteps 'many': Input should be a valid integer"),
    ({"train": {"time-steps": 100}}, "hyperparameter time_steps 100: Extra inputs are not permitted"),
    ({"train": {"algorithm": "td3"}}, "argument --algorithm: invalid choice: 'td3'"),
    ({"evaluate": {"noise-seeds": [1, 2]}}, "evaluate.noise-seeds: has value [1, 2]; give a number"),
    ({"grid": {"learning-rate": 3e-4}}, "grid.learning-rate: Input should be a valid list"),
    ({"grid": {"timesteps": [1, 2]}}, "timesteps set in more than one of train / grid / random"),
    ({"random": {"ent-coef": {"loguniform": [0, 1]}}}, "random.ent-coef.loguniform.0: Input should be greater than 0"),
    ({"random": {"ent-coef": {"uniform": [1, 1]}}}, "random.ent-coef.uniform: needs [low, high] with low < high"),
    ({"random": {"ent-coef": {"gauss": [0, 1]}}}, "random.ent-coef: must be one of {uniform: [...]}"),
    ({"samples": 3}, "samples 3 without random options"),
    ({"retries": -1}, "retries: Input should be greater than or equal to 0"),
    ({"cpus-per-trial": 0}, "cpus-per-trial: Input should be greater than 0"),
    ({"seeds": list(range(101)), "grid": {"learning-rate": [1e-4] * 100}}, "trials (tasks x configurations x seeds) is above"),
    # issue 34: a task twice (one key, one folder for two trials), a path as a task, an unknown or non-family
    # task, timesteps 0 and unbounded distributions refused before Ray, each with its path
    ({"tasks": ["benton-quota", "benton-quota"]}, "tasks: benton-quota named more than once"),
    ({"tasks": ["../benton-quota"]}, "tasks.0: '../benton-quota' is not a task's name (lower-case letters, digits "
                                     "and '-'; no '/' or other path characters)"),
    ({"tasks": ["benton-quota", "no-such-task"]}, "tasks.1: unknown task 'no-such-task'; known: benton-2000"),
    ({"tasks": ["benton-generated"]}, "evaluate on task benton-generated: --task: 'benton-generated' is not a family"),
    ({"train": {**TINY_TRAIN, "timesteps": 0}}, "hyperparameter timesteps 0: Input should be greater than or equal to 1"),
    ({"train": {**TINY_TRAIN, "learning-rate": float("inf")}}, "train.learning-rate: has value inf; give a number"),
    ({"random": {"ent-coef": {"uniform": [-float("inf"), float("inf")]}}},
     "random.ent-coef.uniform.0: Input should be a finite number; random.ent-coef.uniform.1: Input should be a finite"),
    ({"random": {"n-epochs": {"randint": [0, 2**80]}}}, "random.n-epochs.randint.1: Input should be less than or equal"),
    ({"evaluate": {**TINY_EVALUATE, "noise-seeds": 0}}, "evaluate on task benton-quota: --noise-seeds: 0 is not in"),
    ({"evaluate": {**TINY_EVALUATE, "sets": "nowhere"}}, "evaluate on task benton-quota: --sets: nowhere unknown"),
])
def test_a_bad_configuration_is_refused_naming_what_is_wrong(changes, message):
    with pytest.raises(UsageError) as error:
        spec(**changes)
    assert message in str(error.value)


def test_every_problem_of_a_configuration_is_listed_in_one_error_with_its_path():
    with pytest.raises(UsageError) as error:
        spec(tasks=["benton-quota", "x/y"], seeds=[-1], retries="a", random={"z": 5})
    message = str(error.value)
    assert message.startswith("sweep configuration test.yaml: 4 problems: ") and "\n" not in message
    for part in ("tasks.1: 'x/y' is not a task's name", "seeds.0: Input should be greater than or equal to 0",
                 "random.z: must be one of", "retries: Input should be a valid integer"):
        assert part in message, message
    # every configuration's bad training setting, not only the first
    with pytest.raises(UsageError) as error:
        spec(grid={"learning-rate": [1e-4, -1.0, 0.0]})
    assert "2 problems: configuration c01 on task benton-quota" in str(error.value)
    assert "configuration c02 on task benton-quota" in str(error.value)


def test_the_trial_count_is_checked_before_any_configuration_is_built(monkeypatch):
    """Three grid options of 1,000 values are 10**9 configurations: refused at once, by arithmetic."""
    built = []
    monkeypatch.setattr(SweepSpec, "_draw_configurations", lambda self: built.append(1) or ())
    started = time.perf_counter()
    with pytest.raises(UsageError) as error:
        spec(grid={name: list(range(1000)) for name in ("a", "b", "c")})
    assert time.perf_counter() - started < 2.0 and not built
    assert "1,000,000,000 trials (tasks x configurations x seeds) is above 10,000" in str(error.value)
    with pytest.raises(UsageError) as error:
        spec(random={"ent-coef": {"uniform": [0.0, 1.0]}}, samples=10_000, seeds=[0, 1])
    assert "20,000 trials" in str(error.value) and not built


def test_trial_keys_are_unique():
    planned = spec(tasks=["benton-quota", "benton-sensing"], seeds=[0, 1], grid={"learning-rate": [3e-4, 1e-4]})
    keys = [t.key for t in planned.trials()]
    assert len(keys) == 8 and len(set(keys)) == 8


class _Result:
    """What the table takes of a Ray Tune result: its metrics and its error."""

    def __init__(self, stage: str, error=None):
        self.metrics, self.error = {"stage": stage, "validation_return_usd_ha": 1.0}, error


def test_a_trial_is_finished_only_when_its_evaluation_wrote_its_table(tmp_path):
    """Issue 34: a trial whose evaluation failed was counted finished (exit 0); now its row is failed, the last
    line counts it and the exit status is 1."""
    from crop_agent_ros.scale.sweep import summary_line, table_rows
    trials = spec(seeds=[0, 1, 2, 3]).trials()
    tables = [tmp_path / "trials" / t.key / "eval" / "table.json" for t in trials]
    for path in tables:
        path.parent.mkdir(parents=True)
    tables[0].write_text(json.dumps({"sets": []}))
    tables[1].write_text("")                         # a torn or empty table
    tables[2].write_text(json.dumps(["not", "a", "table"]))
    # tables[3]: none written
    rows = table_rows(trials, {t.key: _Result("evaluated") for t in trials}, tmp_path)
    assert [r["status"] for r in rows] == ["finished", "failed", "failed", "failed"]
    assert "table.json is unreadable" in rows[1]["error"] and "holds no table" in rows[2]["error"]
    assert "wrote no table (table.json is missing)" in rows[3]["error"]
    line, status = summary_line("t", rows, tmp_path)
    assert status == 1 and "\n" not in line
    assert line.startswith("sweep t: 1/4 trials finished; 3 FAILED: benton-quota-c00-s1, benton-quota-c00-s2, ")
    everything, status = summary_line("t", rows[:1], tmp_path)
    assert status == 0 and everything.startswith("sweep t: 1/1 trials finished; wrote ")


def test_the_command_refuses_a_bad_configuration_or_address_in_one_line_before_starting_ray(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("tasks: [benton-quota]\ntrain: {timesteps: many}\n")
    good = tmp_path / "good.yaml"
    good.write_text(yaml.safe_dump({"tasks": ["benton-quota"], "train": TINY_TRAIN, "evaluate": TINY_EVALUATE}))
    for argv, message in (([str(bad)], "timesteps 'many': Input should be a valid integer"),
                          ([str(tmp_path / "none.yaml")], "none.yaml"),
                          ([str(good), "--address", "not an address"], "neither 'auto' nor HOST:PORT"),
                          ([str(good), "--address", f"127.0.0.1:{_free_port()}"], "no Ray cluster answers there"),
                          ([str(good), "--address", "auto", "--cpus", "2"], "a cluster's CPUs are its nodes'"),
                          ([str(good), "--cpus", "0"], "--cpus 0: must be >= 1"),
                          ([str(good), "--resume", "--out", str(tmp_path / "o")], "holds no sweep to resume")):
        result = subprocess.run([CROP_SIM, "sweep", *argv], capture_output=True, text=True, cwd=tmp_path, timeout=120)
        assert result.returncode == 2, result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("crop-sim sweep: ") and message in lines[0], result.stderr
        assert not (tmp_path / "runs").exists()


def test_a_sweep_file_is_read_bounded_refusing_aliases_and_non_regular_files(tmp_path, capsys):
    """Issue 34: a few hundred bytes of nested aliases exhausted memory; a FIFO hung the reader."""
    from crop_agent_ros.cli import main
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n" for p, c in zip("abcdefgh", "bcdefghi"))
        + "tasks: [benton-quota]\ntrain: {timesteps: *i}\n")
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    for path, message in ((bomb, "YAML anchors and aliases (& and *) are not allowed"),
                          (fifo, "not a regular file")):
        started = time.perf_counter()
        assert main(["sweep", str(path)]) == 2
        err = capsys.readouterr().err
        assert time.perf_counter() - started < 5.0
        assert err.count("\n") == 1 and err.startswith(f"crop-sim sweep: sweep configuration {path}") and message in err


# --- real sweeps on Ray (inside a loopback-only namespace) -----------------------------------------------

def write_config(tmp_path: Path, **changes) -> Path:
    path = tmp_path / "sweep.yaml"
    raw = {"name": "t", "tasks": ["benton-quota"], "seeds": [0], "train": dict(TINY_TRAIN),
           "evaluate": dict(TINY_EVALUATE), **changes}
    path.write_text(yaml.safe_dump(raw))
    return path


def read_table(out: Path) -> dict[str, dict]:
    with open(out / "table.csv", newline="") as f:
        return {row["trial"]: row for row in csv.DictReader(f)}


def wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f"waited {timeout:.0f} s for {what}")
        time.sleep(0.5)


@pytest.mark.slow
def test_a_sweep_on_a_local_instance_writes_a_row_per_trial_finished_or_failed(tmp_path):
    # configuration c01's trials fail at run time: a file stands where their training's folder goes
    config = write_config(tmp_path, seeds=[0, 1], grid={"learning-rate": [3e-4, 1e-4]}, retries=0,
                          evaluate={**TINY_EVALUATE, "oracle": True})
    out = tmp_path / "out"
    for seed in (0, 1):
        (out / "trials" / f"benton-quota-c01-s{seed}").mkdir(parents=True)
        (out / "trials" / f"benton-quota-c01-s{seed}" / "run").write_text("not a folder\n")
    with LoopbackNamespace() as ns:
        result = ns.run([CROP_SIM, "sweep", str(config), "--out", str(out), "--cpus", "2"], timeout=600, cwd=tmp_path)
    assert result.returncode == 1, result.stderr[-3000:]       # some trials failed for good
    assert "Traceback" not in result.stderr, result.stderr[-3000:]
    assert "sweep t: 2/4 finished, 0 running, 2 failed" in result.stderr
    table = read_table(out)
    assert list(table) == ["benton-quota-c00-s0", "benton-quota-c00-s1", "benton-quota-c01-s0", "benton-quota-c01-s1"]
    for key in ("benton-quota-c01-s0", "benton-quota-c01-s1"):
        assert table[key]["status"] == "failed"
        assert "crop-sim train: --out: " in table[key]["error"] and "is a file, not a folder" in table[key]["error"]
        assert table[key]["attempts"] == "1"
    for key, seed in (("benton-quota-c00-s0", 0), ("benton-quota-c00-s1", 1)):
        row = table[key]
        assert row["status"] == "finished" and row["error"] == "" and row["attempts"] == "1"
        trial = out / "trials" / key
        summary = json.loads((trial / "run" / "summary.json").read_text())
        assert summary["seed"] == seed and (trial / "run" / "model.zip").is_file()
        assert float(row["validation_return_usd_ha"]) == summary["selected"]["validation_return"]
        evaluation = json.loads((trial / "eval" / "table.json").read_text())
        agent = next(r for r in evaluation["sets"][0]["rows"] if r["kind"] == "agent")
        assert float(row["heldout-real/agent_regret_usd_ha"]) == pytest.approx(agent["regret_usd_ha"], rel=1e-12)
        assert float(row["heldout-real/agent_return_usd_ha"]) == pytest.approx(agent["return_usd_ha"], rel=1e-12)
        assert row["node"] and row["node_address"] == "127.0.0.1"
        assert "ran 1024 steps (1024 asked)" in (trial / "trial.log").read_text()   # the trial's own output
    # the trials share the oracle's plan of the 5 held-out seasons: one cached file, the same oracle return
    assert len(list((out / "oracle-cache").glob("*.json"))) == 1
    assert table["benton-quota-c00-s0"]["heldout-real/oracle_return_usd_ha"] == \
        table["benton-quota-c00-s1"]["heldout-real/oracle_return_usd_ha"] != ""
    report = json.loads((out / "table.json").read_text())
    assert report["best"]["benton-quota"]["config"] == "c00"
    assert report["best"]["benton-quota"]["seeds"] == [0, 1]
    assert report["best"]["benton-quota"]["mean_validation_return_usd_ha"] == pytest.approx(
        np.mean([float(table[k]["validation_return_usd_ha"]) for k in ("benton-quota-c00-s0", "benton-quota-c00-s1")]))
    assert (out / "sweep.png").stat().st_size > 5000 and (out / "table.md").is_file()


@pytest.mark.slow
def test_a_trial_whose_worker_is_killed_mid_training_is_retried_and_finishes(tmp_path):
    config = write_config(tmp_path, seeds=[3], train={**TINY_TRAIN, "timesteps": 30000, "n-envs": 8}, retries=1)
    out = tmp_path / "out"
    trial = out / "trials" / "benton-quota-c00-s3"
    with LoopbackNamespace() as ns:
        sweep = ns.popen([CROP_SIM, "sweep", str(config), "--out", str(out), "--cpus", "1"], cwd=tmp_path,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_for(lambda: "training starts" in _text(trial / "trial.log"), 300, "the trial's training to start")
        first_pid = int((trial / "worker.pid").read_text())
        os.kill(first_pid, signal.SIGKILL)
        _, stderr = sweep.communicate(timeout=600)
    assert sweep.returncode == 0, stderr[-3000:]
    assert "trial benton-quota-c00-s3 failed (attempt 1); retrying it" in stderr
    assert "Traceback" not in stderr
    attempts = (trial / "attempts.log").read_text().splitlines()
    assert len(attempts) == 2 and f"pid {first_pid} " in attempts[0] and f"pid {first_pid} " not in attempts[1]
    row = read_table(out)["benton-quota-c00-s3"]
    assert row["status"] == "finished" and row["attempts"] == "2"
    assert json.loads((trial / "run" / "summary.json").read_text())["steps_run"] >= 30000


@pytest.mark.slow
def test_an_interrupted_sweep_resumes_without_redoing_finished_trials(tmp_path):
    config = write_config(tmp_path, seeds=[3, 4])
    out = tmp_path / "out"
    first, second = (out / "trials" / f"benton-quota-c00-s{s}" for s in (3, 4))
    with LoopbackNamespace() as ns:
        sweep = ns.popen([CROP_SIM, "sweep", str(config), "--out", str(out), "--cpus", "1"], cwd=tmp_path,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_for(lambda: (first / "eval" / "table.json").is_file() and (second / "attempts.log").is_file(), 300,
                 "the first trial to finish and the second to start")
        os.killpg(sweep.pid, signal.SIGINT)    # Ctrl-C
        _, stderr = sweep.communicate(timeout=300)
        assert sweep.returncode == 130, stderr[-3000:]
        assert "interrupted, unfinished: benton-quota-c00-s4 (continue with --resume)" in stderr
        interrupted = read_table(out)
        assert interrupted["benton-quota-c00-s3"]["status"] == "finished"
        assert interrupted["benton-quota-c00-s4"]["status"] == "unfinished"
        again = ns.run([CROP_SIM, "sweep", str(config), "--out", str(out)], timeout=60, cwd=tmp_path)
        assert again.returncode == 2 and "already holds a sweep; add --resume" in again.stderr
        resumed = ns.run([CROP_SIM, "sweep", str(config), "--out", str(out), "--cpus", "1", "--resume"],
                         timeout=600, cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    table = read_table(out)
    assert [table[k]["status"] for k in table] == ["finished", "finished"]
    assert len((first / "attempts.log").read_text().splitlines()) == 1      # not redone
    assert table["benton-quota-c00-s3"]["validation_return_usd_ha"] == interrupted["benton-quota-c00-s3"][
        "validation_return_usd_ha"]


@pytest.mark.slow
def test_a_sweep_joins_a_two_node_cluster_and_places_trials_on_both(tmp_path):
    config = write_config(tmp_path, seeds=[0, 1])
    out = tmp_path / "out"
    port = 20000 + os.getpid() % 20000
    with LoopbackNamespace() as ns:
        ns.start_ray_node(1, port=port)
        ns.start_ray_node(1, head_address=f"127.0.0.1:{port}")
        result = ns.run([CROP_SIM, "sweep", str(config), "--out", str(out), "--address", f"127.0.0.1:{port}"],
                        timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((out / "table.json").read_text())
    assert len(report["nodes"]) == 2 and {n["cpus"] for n in report["nodes"]} == {1.0}
    table = read_table(out)
    assert [row["status"] for row in table.values()] == ["finished", "finished"]
    assert {row["node"] for row in table.values()} == {n["node"] for n in report["nodes"]}
    assert f"127.0.0.1:{port}: 2 node(s)" in result.stderr


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _text(path: Path) -> str:
    try:
        return path.read_text()
    except FileNotFoundError:
        return ""


def test_the_scaling_benchmark_runs_a_valid_sweep_in_a_loopback_only_namespace():
    from crop_agent_ros.scale import bench
    planned = SweepSpec.from_dict(bench.sweep_config(4, 20000), "bench").trials()
    assert [t.seed for t in planned] == [0, 1, 2, 3]
    assert "--no-oracle" in planned[0].evaluate_argv and "timesteps=20000" in planned[0].train_argv
    seen = subprocess.run([*bench.loopback_prefix(), "ip", "-o", "link", "show", "up"], capture_output=True,
                          text=True, timeout=30)
    assert seen.returncode == 0 and [line.split(":")[1].strip() for line in seen.stdout.splitlines()] == ["lo"]


def test_the_documented_example_configuration_plans_the_trials_it_says():
    text = (ROOT / "docs" / "scale.md").read_text()
    block = next(b.split("```", 1)[0] for b in text.split("```yaml\n")[1:] if b.startswith("# quota-lr.yaml"))
    planned = SweepSpec.from_dict(yaml.safe_load(block), "docs/scale.md quota-lr.yaml")
    assert "2 tasks x (2 learning rates x 2 random draws) x 5 seeds = 40 trials" in text
    assert len(planned.configurations) == 4 and len(planned.trials()) == 40


def test_the_benchmark_counts_the_cpu_of_its_namespace_and_not_of_the_rest_of_the_machine():
    """A child of the namespaced process burns about 1 CPU-s (parented like Ray's workers: not by us); a busy
    process outside the namespace runs as long and must not be counted."""
    from crop_agent_ros.scale import bench
    burn = "import time\nend = time.process_time() + 1.0\nwhile time.process_time() < end: pass\n"
    outside = subprocess.Popen([sys.executable, "-c", burn])
    inside = subprocess.Popen([*bench.loopback_prefix(), "sh", "-c", f"{sys.executable} -c '{burn}' & wait"])
    try:
        counter = bench.NamespaceCpu(inside.pid, interval_s=0.05)
        assert inside.wait(timeout=60) == 0
        seen_cpu_s = counter.stop()
    finally:
        outside.wait(timeout=60)
    assert 0.8 <= seen_cpu_s <= 1.5, seen_cpu_s
