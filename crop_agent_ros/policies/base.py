"""The one interface every irrigation policy implements, and the observation layout it reads.

A policy maps the task's 20-value observation (``shared/spec/IRRIGATION_TASK.md``) to an irrigation
amount in mm for today, in [0, 100]:

    policy.reset(seed)                    # before each episode (seeds any randomness of its own)
    policy.begin_season(context)          # optional: what the policy may know before the season starts
    mm = policy.act(observation)          # (20,) -> float, or (N, 20) -> (N,) for N fields

``context`` is a :class:`SeasonContext`; ordinary policies ignore it. Only the hindsight oracle reads its
true weather (it is an upper bound, not a farmer).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from crop_sim_ros.task.layout import EXTENDED, PAPER

# Observation layout (IRRIGATION_TASK.md, "Observation, each day").
OBS_SIZE = 20
BIOMASS_T_HA = 0
THERMAL_TIME = 1
DAYS_SINCE_SOWING = 2
TODAY = slice(3, 11)            # TMAX, TMIN, TAVG, RAIN, SRAD, CO2, VAP, WIND
TODAY_RAIN_MM = 6
TOMORROW = slice(11, 19)        # forecast, same 8 variables
FORECAST_RAIN_MM = 14
PAW_MM = 19

ACTION_LOW_MM = 0.0
ACTION_HIGH_MM = 100.0


@dataclass
class SeasonContext:
    """What the evaluation knows about the season before it starts.

    ``params`` (FieldParameters, one field), the true daily weather arrays (length D) the model runs on,
    and the water cost C_I (per mm). ``name`` identifies the season in tables and plots.
    """

    name: str
    params: Any
    tmax_degc: np.ndarray
    tmin_degc: np.ndarray
    srad_mj_m2: np.ndarray
    rain_mm: np.ndarray
    et0_mm: np.ndarray
    water_cost_per_mm: float = -1.25e-4
    extra: dict = field(default_factory=dict)

    def weather_on(self, day: int):
        """Day ``day``'s weather as SIMPLE's step reads it (``crop_sim_ros.model.DailyWeather``)."""
        from crop_sim_ros.model import DailyWeather
        return DailyWeather(self.tmax_degc[day], self.tmin_degc[day], self.srad_mj_m2[day], self.rain_mm[day],
                            self.et0_mm[day])


@runtime_checkable
class Policy(Protocol):
    """Every policy: a name, ``reset(seed)`` and ``act(observation) -> mm``."""

    name: str

    def reset(self, seed: int | None = None) -> None: ...

    def act(self, observation: np.ndarray) -> np.ndarray | float: ...


class BasePolicy:
    """Shape handling for policies: subclasses implement ``_act_batch((N, 20)) -> (N,)`` mm."""

    name = "policy"
    # The observation layouts the policy reads (crop_sim_ros.task.layout): the paper's 20 values, and the task
    # family's 29 (which start with the same 20).
    observation_sizes = (PAPER.size, EXTENDED.size)

    def reset(self, seed: int | None = None) -> None:
        self._seed = seed

    def begin_season(self, context: SeasonContext) -> None:
        """Most policies know nothing in advance."""

    def act(self, observation: np.ndarray) -> np.ndarray | float:
        obs = np.asarray(observation, dtype=float)
        if obs.ndim not in (1, 2) or obs.shape[-1] not in self.observation_sizes:
            raise ValueError(f"{self.name}: expected observations of {' or '.join(map(str, self.observation_sizes))} "
                             f"values, shape (size,) or (N, size), got {obs.shape}")
        batch = np.clip(np.asarray(self._act_batch(np.atleast_2d(obs)), dtype=float).reshape(-1),
                        ACTION_LOW_MM, ACTION_HIGH_MM)
        return float(batch[0]) if obs.ndim == 1 else batch

    def _act_batch(self, obs: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> dict:
        """Parameters worth printing in a report."""
        return {"name": self.name}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.describe()})"
