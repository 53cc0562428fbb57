"""``crop-sim bench``: throughput of the crop model (and of the irrigation environments, when present).
``--backend jax`` adds the model and the environment on JAX beside numpy's (:mod:`crop_sim_ros.task.jax_bench`).

Prints field-days per second for one field (array path and scalar path) and for a batch of fields over a
full season. Machines here are shared and noisy: every run first prints the CPU model and the load average,
and every figure is followed by what else ran during its measurement
(:class:`crop_sim_ros.throughput.MachineLoad`). Compare figures from one run, or from runs with the same load.
"""

from __future__ import annotations

import argparse
import os

from .model import DailyWeather, initial_state, step
from .model.simple import SCALAR_MATH, scalar_parameters, scalar_state
from .model_workload import IRRIGATION_MM, SEASON_DAYS, benton_potato, model_run, season_weather
from .throughput import Rate, best_rate, machine_summary, measured
from .usage import check_range


def bench_model(n_fields: int, repeats: int = 3, seed: int = 0, seasons: int = 1) -> Rate:
    """Best-of-``repeats`` field-days per second of the array path for ``n_fields`` over ``seasons``
    seasons (several for a small batch: long enough for the load figures)."""
    return best_rate(*model_run(n_fields, seed, seasons), repeats)


def bench_scalar(repeats: int = 3, seed: int = 0, seasons: int = 1) -> Rate:
    """Best-of-``repeats`` field-days per second of the one-field scalar path over ``seasons`` seasons."""
    params = benton_potato()
    weather = season_weather(SEASON_DAYS, 1, seed)
    days = [DailyWeather(*(float(w[d, 0]) for w in weather)) for d in range(SEASON_DAYS)]
    one_field = scalar_parameters(params)

    def run_once():
        for _ in range(seasons):
            state = scalar_state(initial_state(params))
            for day in days:
                state, _ = step(one_field, state, day, IRRIGATION_MM, xp=SCALAR_MATH)

    return best_rate(run_once, seasons * SEASON_DAYS, repeats)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fields", type=int, default=10_000,
                        help="fields in the batched model and vector environment runs (default 10000, at most 1000000)")
    parser.add_argument("--repeats", type=int, default=3, help="best of this many seasons (default 3, at most 100)")
    parser.add_argument("--model-only", action="store_true", help="skip the environment benchmarks")
    parser.add_argument("--backend", choices=("numpy", "jax"), default="numpy",
                        help="jax: also the model and the environment on JAX beside numpy, float64 and float32, "
                             "interleaved, also with --model-only (needs pip install crop_sim_ros[jax])")


MAX_FIELDS = 1_000_000  # the vector environment's own bound
MAX_REPEATS = 100


def run(args: argparse.Namespace) -> int:
    check_range("--fields", args.fields, 1, MAX_FIELDS)
    check_range("--repeats", args.repeats, 1, MAX_REPEATS)
    print(f"machine: {machine_summary()}")
    print(f"SIMPLE model, {SEASON_DAYS}-day season, one thread, best of {args.repeats}:")
    measured("N = 1 (array path, 20 seasons a run)", lambda: bench_model(1, args.repeats, seasons=20))
    measured("N = 1 (scalar path, 200 seasons a run)", lambda: bench_scalar(args.repeats, seasons=200))
    measured(f"N = {args.fields} (batched)", lambda: bench_model(args.fields, args.repeats))
    if not args.model_only:
        from .task.bench import bench_env  # the environment layer; imported only when asked for
        bench_env(num_fields=args.fields, repeats=args.repeats)
    if args.backend == "jax":
        try:
            from .task.jax_bench import bench_jax, bench_jax_model  # imports jax; only when asked for
        except ImportError as error:
            raise SystemExit(f"--backend jax needs JAX (pip install crop_sim_ros[jax]): {error}") from None
        print("SIMPLE model on JAX and on numpy, interleaved:")
        bench_jax_model(num_fields=args.fields, numpy_fields=args.fields, repeats=args.repeats)
        print("JAX environment and numpy vector environment, interleaved:")
        bench_jax(num_fields=args.fields, repeats=args.repeats)
    print(f"machine after the run: load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0
