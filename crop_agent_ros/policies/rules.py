"""Hand-made irrigation rules: zero, constant, the refill rule, and their tuned variants.

The tuned values (found by :mod:`crop_agent_ros.policies.tuning` on generated training seasons, never on
the held-out ones) live in JSON files beside this module: ``best_constant_benton.json`` and
``refill_benton.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .base import FORECAST_RAIN_MM, PAW_MM, TODAY_RAIN_MM, BasePolicy

HERE = Path(__file__).resolve().parent
BEST_CONSTANT_FILE = HERE / "best_constant_benton.json"
REFILL_FILE = HERE / "refill_benton.json"


class ZeroPolicy(BasePolicy):
    """Never irrigate (rain-fed)."""

    name = "zero"

    def _act_batch(self, obs):
        return np.zeros(len(obs))


class ConstantPolicy(BasePolicy):
    """The same amount every day (the paper's baseline is 10 mm/day)."""

    def __init__(self, mm_per_day: float = 10.0, name: str | None = None):
        if not 0.0 <= mm_per_day <= 100.0:
            raise ValueError(f"constant irrigation must be in [0, 100] mm/day, got {mm_per_day}")
        self.mm_per_day = float(mm_per_day)
        self.name = name or f"constant{self.mm_per_day:g}"

    def _act_batch(self, obs):
        return np.full(len(obs), self.mm_per_day)

    def describe(self):
        return {"name": self.name, "mm_per_day": self.mm_per_day}


class RefillPolicy(BasePolicy):
    """Refill rule: when the (noisy) plant-available water falls below ``threshold_mm``, irrigate up to
    ``target_mm``, unless tomorrow's forecast rain exceeds ``skip_rain_mm``.

    Today's rain is observed exactly (it is today's weather), so with ``count_today_rain`` the rule
    counts it toward the target: ``mm = max(0, target - PAW - rain_today)``.

    Parameters may be arrays of shape (N,) to run N variants of the rule on N fields at once (used by the
    grid search).
    """

    def __init__(self, threshold_mm=70.0, target_mm=100.0, skip_rain_mm=10.0, count_today_rain: bool = True,
                 name: str = "refill"):
        self.threshold_mm = np.asarray(threshold_mm, dtype=float)
        self.target_mm = np.asarray(target_mm, dtype=float)
        self.skip_rain_mm = np.asarray(skip_rain_mm, dtype=float)
        self.count_today_rain = bool(count_today_rain)
        self.name = name

    def _act_batch(self, obs):
        paw = obs[:, PAW_MM]
        today_rain = obs[:, TODAY_RAIN_MM] if self.count_today_rain else 0.0
        dry = paw < self.threshold_mm
        rain_coming = obs[:, FORECAST_RAIN_MM] > self.skip_rain_mm
        return np.where(dry & ~rain_coming, np.maximum(self.target_mm - paw - today_rain, 0.0), 0.0)

    def describe(self):
        def plain(v):
            return v.tolist() if np.ndim(v) else float(v)
        return {"name": self.name, "threshold_mm": plain(self.threshold_mm), "target_mm": plain(self.target_mm),
                "skip_rain_mm": plain(self.skip_rain_mm), "count_today_rain": self.count_today_rain}


def load_tuned(path: Path) -> dict:
    """The tuned values of a rule, or FileNotFoundError saying how to produce them."""
    if not Path(path).exists():
        raise FileNotFoundError(f"{path} is missing: run `python -m crop_agent_ros.policies.tuning` to tune "
                                "the rules on generated seasons")
    return json.loads(Path(path).read_text())


def best_constant_policy(path: Path = BEST_CONSTANT_FILE) -> ConstantPolicy:
    """The constant rate tuned on generated training seasons."""
    tuned = load_tuned(path)
    return ConstantPolicy(tuned["mm_per_day"], name="best-constant")


def tuned_refill_policy(path: Path = REFILL_FILE) -> RefillPolicy:
    """The refill rule with thresholds tuned on generated training seasons."""
    p = load_tuned(path)["parameters"]
    return RefillPolicy(p["threshold_mm"], p["target_mm"], p["skip_rain_mm"],
                        count_today_rain=p.get("count_today_rain", True), name="refill")


class DemandMarginPolicy(BasePolicy):
    """Refill to today's estimated no-stress level plus a margin: ``mm = ET0/0.096 + margin - PAW - rain``,
    ET0 by FAO-56 Penman-Monteith from today's observed weather (:func:`crop_agent_ros.policies.sb3.
    estimated_et0_mm`). It is what the PPO policy in ``margin`` mode does with a zero action: a reference
    showing how much of PPO's result comes from that design rather than from learning."""

    def __init__(self, margin_mm: float = 4.0, name: str | None = None):
        self.margin_mm = float(margin_mm)
        self.name = name or f"margin{self.margin_mm:g}"

    def _act_batch(self, obs):
        from .sb3 import action_to_mm
        return action_to_mm(np.zeros(len(obs)), obs, "margin", margin_center_mm=self.margin_mm)

    def describe(self):
        return {"name": self.name, "margin_mm": self.margin_mm}
