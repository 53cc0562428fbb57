"""``crop-sim bench``: throughput of the crop model (and of the irrigation environments, when present).

Prints field-days per second for one field (array path and scalar path) and for a batch of fields over a
full season. Machines here are shared and noisy: compare figures from one run, not across runs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from .model import DailyWeather, Management, field_parameters, initial_state, repeat_parameters, step
from .model import zhao2019_library
from .model.simple import SCALAR_MATH, scalar_parameters, scalar_state

SEASON_DAYS = 183


def _season_weather(days: int, n_fields: int, seed: int) -> list[np.ndarray]:
    """Synthetic but realistic Benton-summer weather, (days, n_fields): TMAX, TMIN degC, SRAD MJ m-2,
    rain mm, ET0 mm (the model's cost does not depend on the values)."""
    rng = np.random.default_rng(seed)
    tmax = rng.uniform(15, 35, (days, n_fields))
    return [tmax, tmax - rng.uniform(8, 16, (days, n_fields)), rng.uniform(8, 30, (days, n_fields)),
            rng.exponential(4, (days, n_fields)) * (rng.random((days, n_fields)) < 0.1),
            rng.uniform(2, 9, (days, n_fields))]


def bench_model(n_fields: int, repeats: int = 3, seed: int = 0) -> float:
    """Best-of-``repeats`` field-days per second of the array path for ``n_fields`` over a season."""
    library = zhao2019_library()
    params = repeat_parameters(field_parameters(library.species("potato"),
                                                library.cultivar("potato", "Russet Burbank"),
                                                library.soil("Benton USA potato"), Management(co2_ppm=369.0)),
                               n_fields)
    weather = _season_weather(SEASON_DAYS, n_fields, seed)
    days = [DailyWeather(*(w[d] for w in weather)) for d in range(SEASON_DAYS)]
    irrigation = np.full(n_fields, 5.0)
    best = np.inf
    for _ in range(repeats):
        state = initial_state(params)
        start = time.perf_counter()
        for day in days:
            state, _ = step(params, state, day, irrigation)
        best = min(best, time.perf_counter() - start)
    return n_fields * SEASON_DAYS / best


def bench_scalar(repeats: int = 3, seed: int = 0) -> float:
    """Best-of-``repeats`` field-days per second of the one-field scalar path."""
    library = zhao2019_library()
    params = field_parameters(library.species("potato"), library.cultivar("potato", "Russet Burbank"),
                              library.soil("Benton USA potato"), Management(co2_ppm=369.0))
    weather = _season_weather(SEASON_DAYS, 1, seed)
    days = [DailyWeather(*(float(w[d, 0]) for w in weather)) for d in range(SEASON_DAYS)]
    one_field = scalar_parameters(params)
    best = np.inf
    for _ in range(repeats):
        state = scalar_state(initial_state(params))
        start = time.perf_counter()
        for day in days:
            state, _ = step(one_field, state, day, 5.0, xp=SCALAR_MATH)
        best = min(best, time.perf_counter() - start)
    return SEASON_DAYS / best


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fields", type=int, default=10_000, help="fields in the batched run (default 10000)")
    parser.add_argument("--repeats", type=int, default=3, help="best of this many seasons (default 3)")
    parser.add_argument("--model-only", action="store_true", help="skip the environment benchmarks")


def run(args: argparse.Namespace) -> int:
    print(f"SIMPLE model, {SEASON_DAYS}-day season, one core, best of {args.repeats}:")
    print(f"  N = 1 (array path)        {bench_model(1, args.repeats):>14,.0f} field-days/s")
    print(f"  N = 1 (scalar path)       {bench_scalar(args.repeats):>14,.0f} field-days/s")
    print(f"  N = {args.fields:<6} (batched)    {bench_model(args.fields, args.repeats):>14,.0f} field-days/s")
    if not args.model_only:
        from .task.bench import bench_env  # the environment layer; imported only when asked for
        bench_env()
    return 0
