"""``crop-sim evaluate --task T --address ...``: the evaluation's units as Ray tasks, with the same tables as the
run in one process, bit for bit.

Every Ray process runs inside a loopback-only network namespace (test/ray_support.py); the pytest process
never imports Ray. The agents are two runs (final and 1 % checkpoint each) made in a temporary directory from
the shipped benton-quota ES agent, each of the four networks with its weights scaled differently so that a mix-up
of runs or checkpoints shows; the rule is the committed tuned rule of benton-quota.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from crop_agent_ros.learning import evaluate_task as et
from crop_agent_ros.learning.evaluation_units import oracle_returns
from crop_agent_ros.policies.family_tuning import tuned_rule
from crop_agent_ros.policies.learned import algorithm_class
from crop_agent_ros.policies.rollout import run_episodes
from ray_support import LoopbackNamespace

ROOT = Path(__file__).resolve().parents[1]
CROP_SIM = str(Path(sys.executable).parent / "crop-sim")
TASK = "benton-quota"
AGENT_RUNS = ("benton-quota-es-s0", "benton-quota-es-s1")
SHIPPED = ROOT / "crop_agent_ros" / "agents" / TASK / "es" / "model.zip"
# The weight scale of each run's (final, 1 % checkpoint) network: four different policies.
WEIGHT_SCALES = {"benton-quota-es-s0": (1.0, 0.5), "benton-quota-es-s1": (0.9, 0.25)}
NOISE_SEEDS = 2
SMALL = ["--sets", "heldout-real", "--noise-seeds", str(NOISE_SEEDS), "--bootstrap", "100", "--no-curves"]


@pytest.fixture(scope="module")
def agents(tmp_path_factory) -> Path:
    """Two training runs (model.zip/json, early_model.zip/json) made from the shipped agent (WEIGHT_SCALES)."""
    import torch

    root = tmp_path_factory.mktemp("agents")
    config = json.loads(SHIPPED.with_suffix(".json").read_text())
    for seed, name in enumerate(AGENT_RUNS):
        (root / name).mkdir()
        for stem, scale in zip(("model", "early_model"), WEIGHT_SCALES[name]):
            model = algorithm_class("es").load(str(SHIPPED), device="cpu")
            with torch.no_grad():
                for parameter in model.policy.parameters():
                    parameter.mul_(scale)
            model.save(str(root / name / f"{stem}.zip"))
            (root / name / f"{stem}.json").write_text(json.dumps({**config, "seed": seed}))
    return root


def evaluate_argv(agents: Path, out: Path, *extra: str) -> list[str]:
    return [CROP_SIM, "evaluate", "--task", TASK, "--agents", f"es={agents}/{TASK}-es-s*", *SMALL,
            "--out", str(out), *extra]


@pytest.fixture(scope="module")
def local_and_cluster(agents, tmp_path_factory):
    """The small evaluation in one process (no Ray) and on a two-node loopback cluster (1 CPU each)."""
    base = tmp_path_factory.mktemp("runs")
    local = subprocess.run(evaluate_argv(agents, base / "local"), capture_output=True, text=True, timeout=300,
                           cwd=base)
    assert local.returncode == 0, local.stderr[-3000:]
    port = 20000 + (os.getpid() + 7) % 20000
    with LoopbackNamespace() as ns:
        ns.start_ray_node(1, port=port)
        ns.start_ray_node(1, head_address=f"127.0.0.1:{port}")
        cluster = ns.run(evaluate_argv(agents, base / "cluster", "--address", f"127.0.0.1:{port}"), timeout=400,
                         cwd=base)
    assert cluster.returncode == 0, cluster.stderr[-3000:]
    return base / "local", base / "cluster", port, cluster.stderr


def read_json(out: Path) -> dict:
    return json.loads((out / "table.json").read_text())


@pytest.mark.slow
def test_a_two_node_cluster_gives_the_same_tables_bit_for_bit(local_and_cluster):
    local, cluster, port, stderr = local_and_cluster
    for name in ("table.csv", "table.md"):
        assert (local / name).read_bytes() == (cluster / name).read_bytes(), name
    here, there = read_json(local), read_json(cluster)
    for key in ("returns_usd_ha", "oracle_returns_usd_ha", "oracle_plans", "terms", "rows"):
        assert here["sets"][0][key] == there["sets"][0][key], key
    assert f"127.0.0.1:{port}: 2 node(s)" in stderr


@pytest.mark.slow
def test_the_table_records_where_each_unit_ran(local_and_cluster):
    local, cluster, port, _ = local_and_cluster
    # heldout-real: one oracle unit (5 seasons <= 10), and the two rules (budget, paced) + 2 runs x (final, 1 %)
    # per noise seed
    units = 1 + (2 + 2 * len(AGENT_RUNS)) * NOISE_SEEDS
    here, there = read_json(local)["execution"], read_json(cluster)["execution"]
    assert here["units"] == there["units"] == len(there["unit_log"]) == units
    assert here["ray_nodes"] == [] and here["units_per_node"] == {"this process": units}
    assert there["address"] == f"127.0.0.1:{port}"
    nodes = {n["node"] for n in there["ray_nodes"]}
    assert len(nodes) == 2 and {n["cpus"] for n in there["ray_nodes"]} == {1.0}
    assert set(there["units_per_node"]) == nodes                 # units ran on both nodes
    assert sum(there["units_per_node"].values()) == units
    logged = [(u["policy"], u["noise_seed"]) for u in there["unit_log"]]
    assert logged == [(u["policy"], u["noise_seed"]) for u in here["unit_log"]]
    assert logged.count(("oracle", 0)) == 1 and logged.count(("budget-rule", 1)) == 1
    assert logged.count(("paced-rule", 1)) == 1


@pytest.mark.slow
def test_a_private_local_instance_gives_the_same_returns(local_and_cluster, agents, tmp_path):
    """``--address local --cpus 1`` (without the oracle, to stay short): every policy's returns as in one process."""
    local, _, _, _ = local_and_cluster
    with LoopbackNamespace() as ns:
        result = ns.run(evaluate_argv(agents, tmp_path / "instance", "--no-oracle", "--address", "local", "--cpus",
                                      "1"), timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    saved = read_json(tmp_path / "instance")
    assert saved["sets"][0]["returns_usd_ha"] == {name: returns for name, returns in
                                                  read_json(local)["sets"][0]["returns_usd_ha"].items()
                                                  if name != et.ORACLE}
    assert saved["execution"]["address"] == "local" and len(saved["execution"]["ray_nodes"]) == 1
    assert saved["execution"]["units_per_node"] == {saved["execution"]["ray_nodes"][0]["node"]:
                                                   (2 + 2 * len(AGENT_RUNS)) * NOISE_SEEDS}


@pytest.mark.slow
def test_the_local_run_equals_each_policy_run_directly(local_and_cluster, agents):
    """What the evaluation computed before it was cut into units: each policy through run_episodes on all the
    set's seasons, once per noise seed, with the set's terms; the oracle planned on the whole set."""
    local, _, _, _ = local_and_cluster
    saved = read_json(local)["sets"][0]
    heldout = et.evaluation_sets(et._task(TASK), far_seasons=1)[0]
    assert saved["name"] == heldout.name == et.HELD_OUT_REAL
    terms = et.set_terms(heldout, et.TERMS_SEED)

    def direct(policy) -> list:
        return np.stack([run_episodes(policy, heldout.scenario, heldout.seasons, seed=seed, terms=terms)
                         .episode_return for seed in range(NOISE_SEEDS)], axis=1).tolist()

    import torch
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as the evaluation runs its units (more threads may round a network differently)
    try:
        assert saved["returns_usd_ha"][et.RULE] == [direct(tuned_rule(TASK))]
        finals = [direct(et.load_agent(agents / run / "model.zip", "es")) for run in AGENT_RUNS]
        earlies = [direct(et.load_agent(agents / run / "early_model.zip", "es-1%")) for run in AGENT_RUNS]
    finally:
        torch.set_num_threads(threads)
    assert saved["returns_usd_ha"]["es"] == finals
    assert saved["returns_usd_ha"]["es, 1 % checkpoint"] == earlies
    assert finals != earlies                                      # two different networks
    oracle, plans = oracle_returns(heldout, terms)
    assert saved["oracle_returns_usd_ha"] == oracle.tolist()
    assert saved["oracle_plans"] == json.loads(json.dumps(plans))


def test_the_oracle_in_season_chunks_equals_the_oracle_on_the_whole_set():
    far = et.evaluation_sets(et._task(TASK), far_seasons=2)[1]
    terms = et.set_terms(far, et.TERMS_SEED + 1)
    units = et.plan_units([far], [], [], noise_seeds=1, with_oracle=True, oracle_seasons_per_unit=1)
    chunks = [u for u in units if u.policy == et.ORACLE]
    assert [(u.start, u.stop) for u in chunks] == [(0, 1), (1, 2)]
    results = [et.run_unit(u, far, terms, None) for u in chunks]
    whole, plans = oracle_returns(far, terms)
    assert np.concatenate([r.returns for r in results]).tolist() == whole.tolist()
    assert [p for r in results for p in r.plans] == plans


def test_an_agent_sent_as_bytes_acts_as_the_file_it_came_from(agents):
    far = et.evaluation_sets(et._task(TASK), far_seasons=2)[1]
    terms = et.set_terms(far, et.TERMS_SEED + 1)
    path = agents / AGENT_RUNS[0] / "model.zip"
    agent_file = et.AgentFile.read(path, "es")
    loaded: dict = {}
    policy = agent_file.policy(loaded)
    assert agent_file.policy(loaded) is policy and len(loaded) == 1       # loaded once per process
    unit = et.Unit(0, str(path), 1, 0, len(far.seasons))
    from_bytes = et.run_unit(unit, far, terms, policy).returns
    expected = run_episodes(et.load_agent(path, "es"), far.scenario, far.seasons, seed=1, terms=terms).episode_return
    assert from_bytes.tolist() == expected.tolist()


@pytest.mark.parametrize("extra, message", [
    (["--address", "not an address"], "--address: 'not an address' is neither 'auto' nor HOST:PORT"),
    (["--address", "127.0.0.1:6379", "--cpus", "2"], "--cpus: sets the CPUs of the private Ray instance"),
    (["--address", "local", "--cpus", "0"], "--cpus: 0 is not a positive number of CPUs"),
])
def test_bad_address_or_cpus_is_one_line_and_exit_2(agents, tmp_path, extra, message):
    result = subprocess.run(evaluate_argv(agents, tmp_path / "out", *extra), capture_output=True, text=True,
                            timeout=120, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.startswith(f"crop-sim evaluate: {message}") and result.stderr.count("\n") == 1, \
        result.stderr
    assert not (tmp_path / "out").exists()


def test_address_without_task_is_refused(tmp_path):
    result = subprocess.run([CROP_SIM, "evaluate", "--policies", "zero", "--address", "auto"], capture_output=True,
                            text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr == ("crop-sim evaluate: --address: Ray runs the family protocol (--task TASK); this "
                             "evaluation (--policies) runs in this process\n")
