"""Simulated against observed: matching by treatment and days after planting, RRMSE per crop and overall.

Matching: an observation of treatment (crop, experiment, number) at DAP k compares with the simulated
state at the start of day k (day 0 = sowing day). After maturity the crop state is frozen, so an
observation after the maturity day compares with the state at maturity; one after the end of the
weather of a field that did not mature has nothing to compare with and is counted as unmatched. Where
the observation file has a Date column, sowing + DAP must equal it; disagreements are listed.

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
    """Matched pairs (simulated, observed) per crop and variable, and what could not be matched."""

    pairs: dict[tuple[str, str], list[tuple[float, float]]]
    unmatched: list[Observation]
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


def compare(runs: list[TreatmentRun], observations: list[Observation]) -> Comparison:
    """Match ``observations`` of the treatments in ``runs`` (others are ignored)."""
    by_key = {run.treatment.key: run for run in runs}
    pairs: dict[tuple[str, str], list[tuple[float, float]]] = defaultdict(list)
    unmatched, mismatches = [], []
    for obs in observations:
        run = by_key.get((obs.crop, obs.experiment, obs.treatment))
        if run is None:
            continue
        planted = run.treatment.sowing + timedelta(days=obs.days_after_planting)
        if obs.observed_on is not None and obs.observed_on != planted:
            mismatches.append(f"{obs.source}: Date {obs.observed_on} but sowing {run.treatment.sowing} + "
                              f"DAP {obs.days_after_planting} is {planted}")
        if obs.days_after_planting < 0 or (obs.days_after_planting >= run.days and not run.matured):
            unmatched.append(obs)
            continue
        day = min(obs.days_after_planting, run.days - 1)
        pairs[(obs.crop, obs.variable)].append((float(run.series[obs.variable][day]), obs.value))
    return Comparison(dict(pairs), unmatched, sorted(set(mismatches)))
