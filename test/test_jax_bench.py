"""The JAX benchmarks' code paths at tiny sizes (figures are the benchmarks' business, not the tests'): the GPU
check script end to end (model, environment, ES generation, the ES recipe trained and evaluated), and the ES
generation benchmark's refusals."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("jax")
pytest.importorskip("evosax")

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_gpu_check_runs_its_whole_path_at_tiny_sizes(tmp_path):
    done = subprocess.run([sys.executable, str(REPO / "scripts" / "gpu_check.py"), "--tiny", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    out = done.stdout
    assert re.search(r"^host: .+ CPUs .*load average", out, re.M) and "JAX 0.10" in out
    # the model: JAX float64 is numpy's to rounding, float32 to single precision
    fidelity = dict(re.findall(r"JAX (float\d\d) / numpy: [\d.]+x \(wall\); final biomass vs numpy float64: "
                               r"largest relative difference (\S+)", out))
    assert float(fidelity["float64"]) < 1e-12 and float(fidelity["float32"]) < 1e-4
    assert len(re.findall(r"JaxIrrigationEnv \(float(32|64), jit\+vmap\+scan\)\s+[\d,]+ field-days/s", out)) == 2
    assert re.search(r"ES generation, JAX learner .*field-days/s", out) and "JAX / numpy:" in out
    assert re.search(r"JAX ES on cpu: \d+ generations, [\d,]+ field-days", out)
    assert re.search(r"crop-sim evaluate --task benton-quota --agents es-jax=\S+ .*: exit 0", out)
    assert re.search(r"far-benton: es-jax return [\d.]+ USD/ha", out)
    assert (tmp_path / "benton-quota-es-jax-s0" / "model.zip").is_file()
    assert (tmp_path / "eval" / "summary.json").is_file()


@pytest.mark.parametrize("argv, message", [
    (["--task", "benton-generated"], "crop-sim es-bench: --task 'benton-generated': not a family task"),
    (["--repeats", "0"], "crop-sim es-bench: --repeats: 0 is not in 1..100"),
    (["--pairs", "0"], "crop-sim es-bench: hyperparameter pairs 0: Input should be greater than or equal to 1"),
])
def test_the_es_benchmark_refuses_bad_input_in_one_line(argv, message):
    done = subprocess.run([str(Path(sys.executable).parent / "crop-sim"), "es-bench", *argv], capture_output=True,
                          text=True, timeout=300, cwd=REPO)
    assert done.returncode == 2 and done.stderr.strip().splitlines()[-1].startswith(message), done.stderr


def _es_bench(*argv: str, timeout: int = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "crop_agent_ros.cli", "es-bench", *argv], capture_output=True,
                          text=True, timeout=timeout, cwd=REPO)


def test_the_whole_recipe_benchmark_trains_with_each_learner_in_turn():
    """Tiny whole runs (2 pairs, 2 seasons, 6,000 field-days): a line per run with its wall and CPU seconds, then
    the ratios."""
    done = _es_bench("--whole-recipe", "--repeats", "1", "--pairs", "2", "--seasons", "2", "--timesteps", "6000",
                     timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    out = done.stdout
    for backend in ("numpy", "jax"):
        assert re.search(rf"round 1, {backend} learner: [\d.]+ s wall, [\d.]+ s CPU \(CPUs busy", out), out
    assert re.search(r"numpy / JAX time: [\d.]+x \(wall\), [\d.]+x \(CPU time\)", out), out


def test_the_es_benchmark_refuses_timesteps_without_the_whole_recipe():
    done = _es_bench("--timesteps", "6000")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1] == (
        "crop-sim es-bench: --timesteps: only with --whole-recipe (a generation's field-days are the recipe's)")
