"""The crop model's benchmark workload (``crop-sim bench``'s and the JAX model benchmark's,
:mod:`crop_sim_ros.task.jax_bench`): one Benton potato field, synthetic seasons of weather, the batched array path
over a season."""

from __future__ import annotations

import numpy as np

from .model import DailyWeather, Management, field_parameters, initial_state, repeat_parameters, step
from .model import zhao2019_library

SEASON_DAYS = 183
IRRIGATION_MM = 5.0  # applied every day of the model runs


def season_weather(days: int, n_fields: int, seed: int) -> list[np.ndarray]:
    """Synthetic but realistic Benton-summer weather, (days, n_fields): TMAX, TMIN degC, SRAD MJ m-2,
    rain mm, ET0 mm (the model's cost does not depend on the values)."""
    rng = np.random.default_rng(seed)
    tmax = rng.uniform(15, 35, (days, n_fields))
    return [tmax, tmax - rng.uniform(8, 16, (days, n_fields)), rng.uniform(8, 30, (days, n_fields)),
            rng.exponential(4, (days, n_fields)) * (rng.random((days, n_fields)) < 0.1),
            rng.uniform(2, 9, (days, n_fields))]


def benton_potato():
    """The benchmarks' field: Russet Burbank potato on the Benton soil (one field's parameters)."""
    library = zhao2019_library()
    return field_parameters(library.species("potato"), library.cultivar("potato", "Russet Burbank"),
                            library.soil("Benton USA potato"), Management(co2_ppm=369.0))


def model_run(n_fields: int, seed: int = 0, seasons: int = 1):
    """(run_once, field-days): the array path, ``n_fields`` fields over ``seasons`` synthetic seasons."""
    params = repeat_parameters(benton_potato(), n_fields)
    weather = season_weather(SEASON_DAYS, n_fields, seed)
    days = [DailyWeather(*(w[d] for w in weather)) for d in range(SEASON_DAYS)]
    irrigation = np.full(n_fields, IRRIGATION_MM)

    def run_once():
        for _ in range(seasons):
            state = initial_state(params)
            for day in days:
                state, _ = step(params, state, day, irrigation)

    return run_once, seasons * n_fields * SEASON_DAYS
