"""The units of ``crop-sim evaluate --task``: what one piece of an evaluation is and how it runs.

A unit is a policy on a set of seasons with one noise seed, or the hindsight oracle on a chunk of a set's
seasons. :func:`run_unit` computes one, the same function in this process (:mod:`.evaluate_task`) or on a Ray
worker (:mod:`crop_agent_ros.scale.evaluate_units`); both import the units from here, so neither imports the
other's caller.
"""

from __future__ import annotations

import hashlib
import tempfile
import time
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from crop_sim_ros.usage import user_input

ORACLE = "oracle"


def load_agent(path: Path, name: str):
    """A trained policy file as a policy (UsageError if it is missing, corrupt or made for other spaces)."""
    from ..policies.learned import LearnedPolicy
    with user_input(f"--agents {name}", (ValueError, KeyError, OSError, zipfile.BadZipFile)):
        return LearnedPolicy(path, name=name)


@dataclass(frozen=True)
class AgentFile:
    """A saved agent as data, as it goes to a Ray worker (a cluster's machines need not share a disk): the
    bytes of its ``.zip`` and of the ``.json`` beside it; ``path``: where this process read them."""

    path: str
    name: str
    model_zip: bytes
    model_json: bytes

    @classmethod
    def read(cls, path: Path, name: str) -> "AgentFile":
        with user_input(f"--agents {name}", (OSError,)):
            return cls(str(path), name, path.read_bytes(), path.with_suffix(".json").read_bytes())

    def policy(self, loaded: dict):
        """The policy, loaded once per content into ``loaded`` (a worker keeps its agents for its next units)."""
        digest = hashlib.sha256(self.model_json + b"\0" + self.model_zip).hexdigest()
        if digest not in loaded:
            with tempfile.TemporaryDirectory(prefix="crop-sim-agent-") as directory:
                path = Path(directory) / "model.zip"
                path.write_bytes(self.model_zip)
                path.with_suffix(".json").write_bytes(self.model_json)
                loaded[digest] = load_agent(path, self.name)
        return loaded[digest]


@dataclass(frozen=True)
class Unit:
    """One piece of the evaluation: policy ``policy`` (RULE, ORACLE or an agent file's path) on the seasons at
    positions ``start:stop`` of set ``set_index`` with noise seed ``noise_seed`` (the oracle: 0). A policy's
    unit is its whole set (one noise stream per batch); the oracle's, a chunk of it."""

    set_index: int
    policy: str
    noise_seed: int
    start: int
    stop: int


@dataclass(frozen=True)
class UnitResult:
    """A unit's returns ((stop - start,) USD/ha), the oracle's plan summaries (else None), its compute time
    (s) and where it ran (None: this process; on Ray, :func:`crop_agent_ros.scale.cluster.this_node`)."""

    returns: np.ndarray
    plans: list | None
    seconds: float
    node: dict | None = None


def run_unit(unit: Unit, evaluation_set, terms: dict, policy) -> UnitResult:
    """The unit's returns: ``policy`` (None for the oracle) on its seasons and noise seed under the set's terms
    (one draw per season, for the whole set). The one function of a unit, in this process or on a worker."""
    from ..policies.rollout import run_episodes
    started = time.perf_counter()
    if unit.policy == ORACLE:
        part = replace(evaluation_set, seasons=evaluation_set.seasons[unit.start:unit.stop])
        returns, plans = oracle_returns(part, {name: values[unit.start:unit.stop] for name, values in terms.items()})
    else:
        returns, plans = run_episodes(policy, evaluation_set.scenario, evaluation_set.seasons, seed=unit.noise_seed,
                                      terms=terms).episode_return, None
    return UnitResult(returns, plans, time.perf_counter() - started)


def oracle_returns(evaluation_set, terms: dict) -> tuple[np.ndarray, list[dict]]:
    """(M,) returns (USD/ha) of the hindsight oracle's plan of each season under its terms, run in the
    environment with noise seed 0 (the plan does not read the observation), and each plan's summary."""
    from ..policies.family_oracle import FamilyOraclePolicy
    from ..policies.rollout import run_episodes
    oracle = FamilyOraclePolicy.for_scenario(evaluation_set.scenario)
    returns = run_episodes(oracle, evaluation_set.scenario, evaluation_set.seasons, seed=0, terms=terms).episode_return
    plans = [{"planned_return_usd_ha": r.return_value, "potential_bound_usd_ha": r.potential_bound,
              "water_mm": r.water_mm, "start": r.start, "last_gain_usd_ha": r.last_gain} for r in oracle.results]
    return returns, plans
