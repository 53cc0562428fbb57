"""Simulated against observed: matching by treatment and days after planting, RRMSE per crop and overall.

Matching: an observation of treatment (crop, experiment, number) at DAP k compares with the simulated
state at the start of day k (day 0 = sowing day). Where the observation file has a Date column, the day
is Date - sowing, and rows where sowing + DAP disagrees with Date are listed (Obs_maize_UFGA8201.csv
counts the sowing day as DAP 1 throughout). After maturity the crop state is frozen, so an observation
after the maturity day compares with the state at maturity; one after the end of the weather of a field
that did not mature has nothing to compare with and is counted as unmatched.

Which observations count:
- Yield: only the last yield observation of each treatment (the harvest). The model's yield is
  HI * biomass, the harvested yield once mature (SIMPLE_MODEL.md item 10); the files' in-season yields
  (0 before pods or grain form) are not that quantity and are counted as ``in_season_yields``.
- Biomass: an observed biomass below the same row's observed yield is a placeholder, not a measurement
  (Obs_banana_BRBA0503.csv: biomass 1 kg/ha beside a yield of 6700 kg/ha) and is skipped.

RRMSE (%) = 100 * RMSE / mean(observed), over the matched pairs of a crop (or of all crops).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from datetime import timedelta

import numpy as np

from .inputs import OBSERVED_VARIABLES, Observation
from .runner import TreatmentRun

VARIABLES = tuple(OBSERVED_VARIABLES.values())
# Zhao et al. (2019) Table 3: RRMSE (%) over all experiments.
PAPER_TABLE3_RRMSE_PERCENT = {"biomass_kg_ha": 25.7, "yield_kg_ha": 25.4, "fsolar": 29.5}
OVERALL = "overall"


def rrmse_percent(simulated, observed) -> float:
    """100 * sqrt(mean((simulated - observed)^2)) / mean(observed), percent (NaN without pairs)."""
    simulated = np.asarray(simulated, dtype=float)
    observed = np.asarray(observed, dtype=float)
    if observed.size == 0:
        return float("nan")
    return float(100.0 * np.sqrt(np.mean((simulated - observed) ** 2)) / np.mean(observed))


@dataclass(frozen=True)
class Comparison:
    """Matched pairs (simulated, observed) per crop and variable; observations that could not be matched
    (``unmatched``) or do not count (``skipped``: in-season yields, placeholder biomass); Date disagreements."""

    pairs: dict[tuple[str, str], list[tuple[float, float]]]
    unmatched: list[Observation]
    skipped: list[Observation]
    date_mismatches: list[str]

    def rrmse(self) -> dict[str, dict[str, dict[str, float | int]]]:
        """{crop or 'overall': {variable: {'rrmse_percent': ..., 'n': ...}}}."""
        table: dict[str, dict[str, dict[str, float | int]]] = defaultdict(dict)
        crops = sorted({crop for crop, _ in self.pairs})
        for variable in VARIABLES:
            everything = []
            for crop in crops:
                pairs = self.pairs.get((crop, variable), [])
                everything += pairs
                table[crop][variable] = _entry(pairs)
            table[OVERALL][variable] = _entry(everything)
        return dict(table)


def _entry(pairs: list[tuple[float, float]]) -> dict[str, float | int]:
    simulated, observed = (np.array([p[i] for p in pairs]) for i in (0, 1))
    return {"rrmse_percent": rrmse_percent(simulated, observed), "n": len(pairs)}


def _last_yields(observations: list[Observation]) -> set[int]:
    """ids of the last (largest DAP) yield observation of each treatment."""
    last: dict[tuple, Observation] = {}
    for obs in observations:
        key = (obs.crop, obs.experiment, obs.treatment)
        if obs.variable == "yield_kg_ha" and (key not in last or
                                              obs.days_after_planting > last[key].days_after_planting):
            last[key] = obs
    return {id(obs) for obs in last.values()}


def _placeholder_biomass(observations: list[Observation]) -> set[int]:
    """ids of observed biomass values below the observed yield of the same file row."""
    yields = {obs.source: obs.value for obs in observations if obs.variable == "yield_kg_ha"}
    return {id(obs) for obs in observations
            if obs.variable == "biomass_kg_ha" and obs.value < yields.get(obs.source, -np.inf)}


def compare(runs: list[TreatmentRun], observations: list[Observation]) -> Comparison:
    """Match ``observations`` of the treatments in ``runs`` (others are ignored); see the module docstring."""
    by_key = {run.treatment.key: run for run in runs}
    harvests = _last_yields(observations)
    placeholders = _placeholder_biomass(observations)
    pairs: dict[tuple[str, str], list[tuple[float, float]]] = defaultdict(list)
    unmatched, skipped, mismatches = [], [], []
    for obs in observations:
        run = by_key.get((obs.crop, obs.experiment, obs.treatment))
        if run is None:
            continue
        sowing = run.treatment.sowing
        day = obs.days_after_planting
        if obs.observed_on is not None:
            if obs.observed_on != sowing + timedelta(days=day):
                mismatches.append(f"{obs.source}: Date {obs.observed_on} but sowing {sowing} + DAP {day} is "
                                  f"{sowing + timedelta(days=day)}; matched by Date")
            day = (obs.observed_on - sowing).days
        if (obs.variable == "yield_kg_ha" and id(obs) not in harvests) or id(obs) in placeholders:
            skipped.append(obs)
            continue
        if day < 0 or (day >= run.days and not run.matured):
            unmatched.append(obs)
            continue
        simulated = run.series[obs.variable][min(day, run.days - 1)]
        pairs[(obs.crop, obs.variable)].append((float(simulated), obs.value))
    return Comparison(dict(pairs), unmatched, skipped, sorted(set(mismatches)))
