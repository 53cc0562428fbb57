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
    ({"tasks": []}, "tasks must be a non-empty list"),
    ({"seeds": [0, 0]}, "seeds must be a non-empty list of distinct integers"),
    ({"epochs": 3}, "unknown key(s) epochs"),
    ({"train": {"seed": 3}}, "train may not set seed"),
    ({"evaluate": {"agents": "x=y"}}, "evaluate may not set agents"),
    ({"evaluate": {"address": "auto", "cpus": 2}}, "evaluate may not set address, cpus"),
    ({"train": {"timesteps": "many"}}, "hyperparameter timesteps 'many': Input should be a valid integer"),
    ({"train": {"time-steps": 100}}, "hyperparameter time_steps 100: Extra inputs are not permitted"),
    ({"train": {"algorithm": "td3"}}, "argument --algorithm: invalid choice: 'td3'"),
    ({"evaluate": {"noise-seeds": [1, 2]}}, "has value [1, 2]; give a number"),
    ({"grid": {"learning-rate": 3e-4}}, "grid option 'learning-rate' must list its values"),
    ({"grid": {"timesteps": [1, 2]}}, "timesteps set in more than one of train / grid / random"),
    ({"random": {"ent-coef": {"loguniform": [0, 1]}}}, "loguniform needs [low, high] with low < high and low > 0"),
    ({"random": {"ent-coef": {"gauss": [0, 1]}}}, "random option 'ent-coef' must be one of"),
    ({"samples": 3}, "samples 3 without random options"),
    ({"retries": -1}, "retries -1 must be an integer in 0..100"),
    ({"cpus-per-trial": 0}, "cpus-per-trial 0 must be a number in (0, 1024]"),
    ({"seeds": list(range(101)), "grid": {"learning-rate": [1e-4] * 100}}, "trials (tasks x configurations x seeds) is above"),
])
def test_a_bad_configuration_is_refused_naming_what_is_wrong(changes, message):
    with pytest.raises(UsageError) as error:
        spec(**changes)
    assert message in str(error.value)


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
    # a learning rate of 1e30 is a valid setting whose training diverges: its trials fail at run time
    config = write_config(tmp_path, seeds=[0, 1], grid={"learning-rate": [3e-4, 1e30]}, retries=0,
                          evaluate={**TINY_EVALUATE, "oracle": True})
    out = tmp_path / "out"
    with LoopbackNamespace() as ns:
        result = ns.run([CROP_SIM, "sweep", str(config), "--out", str(out), "--cpus", "2"], timeout=600, cwd=tmp_path)
    assert result.returncode == 1, result.stderr[-3000:]       # some trials failed for good
    assert "Traceback" not in result.stderr, result.stderr[-3000:]
    assert "sweep t: 2/4 finished, 0 running, 2 failed" in result.stderr
    table = read_table(out)
    assert list(table) == ["benton-quota-c00-s0", "benton-quota-c00-s1", "benton-quota-c01-s0", "benton-quota-c01-s1"]
    for key in ("benton-quota-c01-s0", "benton-quota-c01-s1"):
        assert table[key]["status"] == "failed"
        assert table[key]["error"], table[key]
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
