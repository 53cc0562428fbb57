#!/usr/bin/env python3
"""Issue 36's GPU checks in one run: the card, the model, the environment, an ES generation and the ES recipe
on benton-quota trained and evaluated, every figure printed (about 8 minutes on an H200 with the oracle cache).

Run on a machine with an NVIDIA GPU (H200 or H100), JAX built for CUDA (``pip install 'jax[cuda12]'`` into the
project's venv; CuPy optional) and no network, from the repository root:

.. code-block:: bash

    .venv/bin/python scripts/gpu_check.py --out runs/gpu-check [--oracle-cache runs/oracle-cache-bq]
    .venv/bin/python scripts/gpu_check.py --tiny --out /tmp/gpu-check     # the same path, tiny sizes (CPU, tests)

1. machine: JAX and its devices (the card), the host's CPU model and load;
2. model: :func:`crop_sim_ros.model.step` on JAX (one jitted ``lax.scan`` over a 183-day season), float64 and
   float32, at 1 M and 4 M fields, beside numpy's 10,000 on the host, and each precision's final biomass against
   numpy's (:func:`crop_sim_ros.task.jax_bench.bench_jax_model`); CuPy (the same step with ``xp=cupy``, one kernel
   per operation) at 1 M fields when CuPy is installed;
3. environment: the JAX environment of benton-generated at 1 M fields, 200 days, float64 and float32, beside the
   numpy vector environment's 10,000 (:func:`crop_sim_ros.task.jax_bench.bench_jax`);
4. one ES generation of the recipe, numpy learner and JAX learner in turn (``crop-sim es-bench``);
5. the ES recipe: ``crop-sim train --task benton-quota --algorithm es --hyperparams backend=jax --seed 0``, its
   wall time measured around the command (compilation, validation checkpoints and start-up included) and the ES
   loop's own time (the train's ``JAX ES on gpu: ...`` line);
6. ``crop-sim evaluate --task benton-quota --agents es-jax=RUN``, and the run's regret per set beside the CPU
   recipe's ES row (``results/summaries/benton-quota-es-paced.json``, 5 seeds) and its 95 % CI.

The evaluation's hindsight oracle is the slow part without a cache: ``--oracle-cache DIR`` reuses its plans (a
copy of a cache filled by an earlier evaluation of the same sets on any machine; the plans depend on the seasons,
terms and oracle code only). ``--evaluate-cpus N`` (default: this machine's CPUs) runs the evaluation's units on a
private Ray instance when N > 2.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout: the package beside this script

TASK = "benton-quota"
CPU_RECIPE_SUMMARY = REPO / "results" / "summaries" / "benton-quota-es-paced.json"
# Sizes: full (a GPU) and tiny (the same code path on a CPU in seconds)
SIZES = {"full": {"model_fields": (1_000_000, 4_000_000), "env_fields": 1_000_000, "numpy_fields": 10_000,
                  "repeats": 3, "es_bench": [], "train": [], "evaluate": []},
         "tiny": {"model_fields": (1_000,), "env_fields": 1_000, "numpy_fields": 1_000, "repeats": 1,
                  "es_bench": ["--pairs", "2", "--seasons", "2"],
                  "train": ["timesteps=20000", "eval_freq=10000", "pairs=2", "seasons=2", "validation_seasons=2",
                            "net_arch=[16]"],
                  "evaluate": ["--no-oracle", "--no-curves", "--noise-seeds", "1", "--far-seasons", "2", "--sets",
                               "far-benton", "--bootstrap", "100"]}}


def section(title: str) -> None:
    print(f"\n== {title} ({time.strftime('%H:%M:%S')}, load average {os.getloadavg()[0]:.2f})", flush=True)


def machine() -> None:
    import jax
    from crop_sim_ros.throughput import machine_summary
    section("machine")
    print(f"host: {machine_summary()}")
    print(f"JAX {jax.__version__}, default backend {jax.default_backend()}: "
          + ", ".join(f"{d.platform}:{d.device_kind}" for d in jax.devices()))


def model(sizes: dict) -> None:
    from crop_sim_ros.task.jax_bench import bench_jax_model
    section("SIMPLE model: JAX (jit + lax.scan over 183 days) beside numpy on the host")
    for fields in sizes["model_fields"]:
        bench_jax_model(num_fields=fields, numpy_fields=sizes["numpy_fields"], repeats=sizes["repeats"])
    cupy_model(sizes["model_fields"][0], sizes["repeats"])


def cupy_model(fields: int, repeats: int) -> None:
    """The same step with ``xp=cupy`` (float64), weather gathered from a pool on the device, if CuPy is here."""
    try:
        import cupy
    except ImportError:
        print("  CuPy: not installed (skipped)")
        return
    from crop_sim_ros import model_workload as workload
    from crop_sim_ros.model import DailyWeather, FieldParameters, initial_state, step
    from crop_sim_ros.task.jax_bench import MODEL_POOL_SEASONS
    from crop_sim_ros.throughput import best_rate
    try:
        pool = min(fields, MODEL_POOL_SEASONS)
        table = cupy.asarray(workload.season_weather(workload.SEASON_DAYS, pool, 0))  # (5, days, pool)
        season = cupy.arange(fields) % pool
        one = workload.benton_potato()
        params = FieldParameters(**{name: cupy.asarray(getattr(one, name))
                                    for name in FieldParameters.__dataclass_fields__})
        first = initial_state(one)

        def run_once():
            state = type(first)(*(cupy.broadcast_to(cupy.asarray(v), (fields,)) for v in first))
            for d in range(workload.SEASON_DAYS):
                state, _ = step(params, state, DailyWeather(*table[:, d, season]), workload.IRRIGATION_MM, xp=cupy)
            cupy.cuda.Device().synchronize()

        run_once()
        rate = best_rate(run_once, fields * workload.SEASON_DAYS, repeats)
        print(f"  SIMPLE model, CuPy {cupy.__version__} float64, N = {fields:,}: {rate.per_s:,.0f} field-days/s")
    except Exception as error:  # report and go on: the JAX figures are the check
        print(f"  CuPy model failed: {type(error).__name__}: {error}")


def environment(sizes: dict) -> None:
    from crop_sim_ros.task.jax_bench import bench_jax
    section("environment: JAX (jit + vmap + scan, 200 days) beside the numpy vector environment on the host")
    bench_jax(num_fields=sizes["env_fields"], repeats=sizes["repeats"], numpy_fields=sizes["numpy_fields"])


def es_generation(sizes: dict) -> None:
    from crop_agent_ros.cli import main
    section("one ES generation of the recipe: numpy learner and JAX learner in turn")
    main(["es-bench", "--task", TASK, "--repeats", str(sizes["repeats"]), *sizes["es_bench"]])


def crop_sim(arguments: list[str], log: Path) -> tuple[int, float]:
    """``crop-sim ARGUMENTS`` in a child process, its output to ``log``: (exit status, wall seconds)."""
    start = time.perf_counter()
    with open(log, "w") as out:
        done = subprocess.run([sys.executable, "-m", "crop_agent_ros.cli", *arguments], cwd=REPO, stdout=out,
                              stderr=subprocess.STDOUT)
    return done.returncode, time.perf_counter() - start


def train(sizes: dict, out: Path) -> Path | None:
    section(f"the ES recipe on {TASK}, backend jax, seed 0")
    run = out / f"{TASK}-es-jax-s0"
    overrides = [item for setting in ["backend=jax", *sizes["train"]] for item in ("--hyperparams", setting)]
    status, wall = crop_sim(["train", "--task", TASK, "--algorithm", "es", "--seed", "0", "--out", str(run),
                             "--no-progress", *overrides], out / "train.log")
    lines = (out / "train.log").read_text().splitlines()
    print("\n".join(f"  {line}" for line in lines if line.startswith(("JAX ES", "ran ", "training starts"))))
    if status != 0:
        print(f"  train failed (exit {status}); its log: {out / 'train.log'}")
        print("\n".join(lines[-15:]))
        return None
    summary = json.loads((run / "summary.json").read_text())
    print(f"  wall {wall:.1f} s around `crop-sim train` (start-up, scaler, compilation, generations, validation "
          f"checkpoints); training {summary['training_wall_s']} s; {summary['steps_run']:,} field-days")
    return run


def evaluate(sizes: dict, out: Path, run: Path, oracle_cache: str | None, cpus: int) -> None:
    section(f"evaluate the run: crop-sim evaluate --task {TASK}")
    arguments = ["evaluate", "--task", TASK, "--agents", f"es-jax={run}", "--out", str(out / "eval"),
                 *sizes["evaluate"]]
    if oracle_cache:
        arguments += ["--oracle-cache", oracle_cache]
    if cpus > 2:
        arguments += ["--address", "local", "--cpus", str(cpus)]
    status, wall = crop_sim(arguments, out / "evaluate.log")
    print(f"  {' '.join(['crop-sim', *arguments])}: exit {status} in {wall:.1f} s")
    if status != 0:
        print("\n".join((out / "evaluate.log").read_text().splitlines()[-15:]))
        return
    compare(json.loads((out / "eval" / "summary.json").read_text()))


def compare(summary: dict) -> None:
    """es-jax's regret per set beside the CPU recipe's ES row and its 95 % CI."""
    cpu = {s["name"]: s for s in json.loads(CPU_RECIPE_SUMMARY.read_text())["sets"]}
    for evaluated in summary["sets"]:
        ours = next(r for r in evaluated["rows"] if r["policy"] == "es-jax")
        reference = next((r for r in cpu.get(evaluated["name"], {}).get("rows", []) if r["policy"] == "es"), None)
        if evaluated.get("reference") != "oracle" or reference is None:
            print(f"  {evaluated['name']}: es-jax return {ours['return_usd_ha']} USD/ha (reference "
                  f"{evaluated.get('reference')}: no regret to compare)")
            continue
        low, high = reference["regret_ci_usd_ha"]
        inside = "within" if low <= ours["regret_usd_ha"] <= high else "OUTSIDE"
        print(f"  {evaluated['name']:<28} es-jax regret {ours['regret_usd_ha']:>7.1f} USD/ha {inside} the CPU "
              f"recipe's ES {reference['regret_usd_ha']:.1f} [{low:.1f}, {high:.1f}] (5 seeds)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="runs/gpu-check", help="folder of the run's files (default runs/gpu-check)")
    parser.add_argument("--tiny", action="store_true", help="tiny sizes: the same path in seconds on a CPU")
    parser.add_argument("--oracle-cache", default=None, help="the evaluation's oracle cache folder (reused)")
    parser.add_argument("--evaluate-cpus", type=int, default=os.cpu_count(),
                        help="CPUs of the evaluation (a private Ray instance when above 2)")
    args = parser.parse_args(argv)
    sizes = SIZES["tiny" if args.tiny else "full"]
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    machine()
    model(sizes)
    environment(sizes)
    es_generation(sizes)
    run = train(sizes, out)
    if run is not None:
        evaluate(sizes, out, run, args.oracle_cache, 1 if args.tiny else args.evaluate_cpus)
    section(f"done in {time.perf_counter() - start:.0f} s")
    return 0 if run is not None else 1


if __name__ == "__main__":
    sys.exit(main())
