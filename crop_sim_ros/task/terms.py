"""The farm's terms in the task family: money, water rights, the irrigation system, the soil-water sensor.

A scenario of the paper's task has none of these (reward in t/ha, no quota, no capacity limit below the
action bound, a PAW reading every day). A family scenario sets some of them; its observation is the
extended layout (:mod:`crop_sim_ros.task.layout`) and its reward is net return in USD/ha.

Ranges (``[low, high]`` in YAML, or one number) are drawn uniformly and independently for each field at the
start of each episode, so that one policy trained on the range serves every value in it; the drawn values
are in the observation. A fixed value draws nothing (the random stream is the paper task's).

Economics (:class:`Economics`), defaults for Benton County, WA processing potato; sources in the README:

========================== ========== ============== ====================================================
Name                       Unit       Default        Description
========================== ========== ============== ====================================================
tuber_price_usd_per_t      USD t-1    [150, 300]     price of fresh tubers (WA 2022: 218 USD/t = 9.88
                                                     USD/cwt, USDA NASS)
tuber_dry_matter_fraction  1          0.20           dry matter of fresh Russet Burbank tubers: SIMPLE's
                                                     dry yield / this = fresh yield
water_price_usd_per_mm     USD mm-1   [0, 1]         delivered water, per mm on one ha (10 m3)
pumping_energy_usd_per_mm  USD mm-1   [0.5, 2]       pumping energy per mm on one ha
event_cost_usd             USD        0              fixed cost of each day with irrigation (labour,
                                                     start-up), per ha
========================== ========== ============== ====================================================

Water rights, system and sensing (:class:`FarmLimits`):

========================== ========== ============== ====================================================
Name                       Unit       Default        Description
========================== ========== ============== ====================================================
quota_mm                   mm         none           the season's allocation (a range is drawn per episode)
capacity_mm_per_day        mm d-1     none           the irrigation system's daily maximum (a centre
                                                     pivot's: 6-8 mm/d)
nominal_season_days        d          150            the expected season length the observation's
                                                     ``season_days_left`` counts down
paw_dropout_probability    1          0              chance that a day's PAW reading is missing (flagged)
paw_sensor                 bool       true           false: no PAW reading at all (column 19 is 0, flag 0)
========================== ========== ============== ====================================================
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

# Upper bounds of what a user may set (each refused above it with a clear error).
MAX_PRICE_USD_PER_T = 10_000.0
MAX_WATER_COST_USD_PER_MM = 1_000.0
MAX_EVENT_COST_USD = 100_000.0
MAX_QUOTA_MM = 10_000.0
MAX_NOMINAL_SEASON_DAYS = 366


def check_number(name: str, value: Any, low: float = -np.inf, high: float = np.inf) -> float:
    """``value`` as a finite float in [low, high], or ValueError naming ``name``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not (np.isfinite(number) and low <= number <= high):
        raise ValueError(f"{name}: {value!r} is not a finite number in [{low:g}, {high:g}]")
    return number


def _from_dict(cls, values: dict, where: str):
    """``cls(**values)``, or ValueError naming the first unknown field under ``where``."""
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"{where}.{unknown[0]}: unknown field (known: {', '.join(sorted(known))})")
    return cls(**values)


@dataclass(frozen=True)
class Range:
    """A value drawn uniformly in [low, high] per field and episode (low == high: fixed, nothing drawn)."""

    low: float
    high: float

    @classmethod
    def parse(cls, name: str, value: Any, low: float, high: float) -> "Range":
        """A Range from a number or a two-element list; ValueError names ``name`` and the bounds."""
        if isinstance(value, Range):
            value = [value.low, value.high]
        if isinstance(value, (list, tuple)):
            if len(value) != 2:
                raise ValueError(f"{name}: a range is [low, high], got {value!r}")
            a, b = (check_number(name, v, low, high) for v in value)
            if a > b:
                raise ValueError(f"{name}: range [{a:g}, {b:g}] has low > high")
            return cls(a, b)
        number = check_number(name, value, low, high)
        return cls(number, number)

    @property
    def fixed(self) -> bool:
        return self.low == self.high

    def draw(self, rng: np.random.Generator, n: int | None):
        """``n`` values (or one float for ``n`` None); a fixed range draws nothing from ``rng``."""
        if self.fixed:
            return self.low if n is None else np.full(n, self.low)
        value = rng.uniform(self.low, self.high, n)
        return float(value) if n is None else value

    def to_yaml(self):
        return self.low if self.fixed else [self.low, self.high]


@dataclass(frozen=True)
class Economics:
    """Money terms (see the module table). Reward: net return, USD/ha."""

    tuber_price_usd_per_t: Range = Range(150.0, 300.0)
    tuber_dry_matter_fraction: float = 0.20
    water_price_usd_per_mm: Range = Range(0.0, 1.0)
    pumping_energy_usd_per_mm: Range = Range(0.5, 2.0)
    event_cost_usd: float = 0.0

    def __post_init__(self) -> None:
        for name, high in (("tuber_price_usd_per_t", MAX_PRICE_USD_PER_T),
                           ("water_price_usd_per_mm", MAX_WATER_COST_USD_PER_MM),
                           ("pumping_energy_usd_per_mm", MAX_WATER_COST_USD_PER_MM)):
            object.__setattr__(self, name, Range.parse(f"economics.{name}", getattr(self, name), 0.0, high))
        object.__setattr__(self, "tuber_dry_matter_fraction",
                           check_number("economics.tuber_dry_matter_fraction", self.tuber_dry_matter_fraction, 0.05, 1.0))
        object.__setattr__(self, "event_cost_usd",
                           check_number("economics.event_cost_usd", self.event_cost_usd, 0.0, MAX_EVENT_COST_USD))

    @classmethod
    def from_dict(cls, values: dict) -> "Economics":
        return _from_dict(cls, values, "economics")


@dataclass(frozen=True)
class FarmLimits:
    """Water rights, the irrigation system and the soil-water sensor (see the module table)."""

    quota_mm: Range | None = None
    capacity_mm_per_day: float | None = None
    nominal_season_days: int = 150
    paw_dropout_probability: float = 0.0
    paw_sensor: bool = True

    def __post_init__(self) -> None:
        if self.quota_mm is not None:
            object.__setattr__(self, "quota_mm", Range.parse("limits.quota_mm", self.quota_mm, 0.0, MAX_QUOTA_MM))
        if self.capacity_mm_per_day is not None:
            object.__setattr__(self, "capacity_mm_per_day",
                               check_number("limits.capacity_mm_per_day", self.capacity_mm_per_day, 0.0, 1000.0))
        days = check_number("limits.nominal_season_days", self.nominal_season_days, 1, MAX_NOMINAL_SEASON_DAYS)
        if days != int(days):
            raise ValueError(f"limits.nominal_season_days: {self.nominal_season_days!r} is not a whole number of days")
        object.__setattr__(self, "nominal_season_days", int(days))
        object.__setattr__(self, "paw_dropout_probability",
                           check_number("limits.paw_dropout_probability", self.paw_dropout_probability, 0.0, 1.0))
        if not isinstance(self.paw_sensor, bool):
            raise ValueError(f"limits.paw_sensor: expected true or false, got {self.paw_sensor!r}")

    @classmethod
    def from_dict(cls, values: dict) -> "FarmLimits":
        return _from_dict(cls, values, "limits")
