"""Run a policy on whole seasons of a task scenario, many fields at once (the batched task environment), and
choose those seasons and their terms.

Used by evaluation, by the rule tuning, by the hindsight oracle and by the training's held-out evaluation callback.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .base import SeasonContext


@dataclass
class Episodes:
    """Results of N fields, one episode each (arrays of shape (N,)); ``daily`` (if recorded) holds (D, N)
    arrays: biomass_t_ha (true, start of day), paw_mm (true, start of day), rain_mm, irrigation_mm."""

    season: np.ndarray
    episode_return: np.ndarray
    yield_t_ha: np.ndarray
    water_mm: np.ndarray
    rain_mm: np.ndarray
    potential_yield_t_ha: np.ndarray
    days: np.ndarray
    matured: np.ndarray
    daily: dict | None = None

    @property
    def normalized_return(self) -> np.ndarray:
        return self.episode_return / self.potential_yield_t_ha

    @property
    def water_productivity_kg_m3(self) -> np.ndarray:
        """Yield (kg/ha) per m3/ha of water received (irrigation + rain, sowing to harvest; 1 mm = 10 m3/ha)."""
        return self.yield_t_ha * 1000.0 / ((self.water_mm + self.rain_mm) * 10.0)


def season_range(text: str) -> np.ndarray:
    """Season indices of a command's ``--seasons`` (``'A..B'``, both included, or one index), each below a pool's
    largest size (MAX_GENERATED_SEASONS); ValueError naming --seasons for anything else, before any allocation."""
    from crop_sim_ros.task.scenario import MAX_GENERATED_SEASONS
    from crop_sim_ros.usage import shown
    low_text, dots, high_text = text.partition("..")
    try:
        low, high = int(low_text), int(high_text if dots else low_text)
    except ValueError:
        raise ValueError(f"--seasons: expected 'A..B' or one index, got {shown(text)}") from None
    if not 0 <= low <= high:
        raise ValueError(f"--seasons: {shown(text)} names no season (non-negative, A <= B)")
    if high >= MAX_GENERATED_SEASONS:
        raise ValueError(f"--seasons: {shown(text)} goes past season {MAX_GENERATED_SEASONS - 1}, the last of the "
                         "largest pool")
    return np.arange(low, high + 1)


def draw_terms(scenario, seasons: np.ndarray, seed: int) -> dict:
    """One draw of a family task's episode terms (name -> (M,) arrays: prices, quota, ...) for M ``seasons``, from
    ``seed``: what comparisons on the same terms fix (every rule candidate, the oracle, an evaluation set)."""
    from crop_sim_ros.task import core
    params = core.task_params(scenario, len(seasons))
    terms = core.draw_terms(params, np.random.default_rng([seed, 7919]), len(seasons))
    return terms._asdict()


def scenario_of(scenario):
    from crop_sim_ros.task import Scenario, get_scenario
    return scenario if isinstance(scenario, Scenario) else get_scenario(scenario)


def season_contexts(scenario) -> list[SeasonContext]:
    """The true weather of every season of ``scenario`` (for the hindsight oracle)."""
    from crop_sim_ros.task import core
    scenario = scenario_of(scenario)
    table = core.scenario_table(scenario)
    params = scenario.field_parameters()
    index = {name: i for i, name in enumerate(core.WEATHER_NAMES)}
    contexts = []
    for k in range(len(table)):
        n = int(table.n_days[k])
        w = table.weather[k, :n]
        contexts.append(SeasonContext(
            name=f"{scenario.name}[{k}]", params=params, tmax_degc=w[:, index["tmax_degc"]],
            tmin_degc=w[:, index["tmin_degc"]], srad_mj_m2=w[:, index["srad_mj_m2"]], rain_mm=w[:, index["rain_mm"]],
            et0_mm=table.et0_mm[k, :n], water_cost_per_mm=float(scenario.irrigation_cost_per_mm),
            extra={"source": table.sources[k], "potential_yield_t_ha": float(table.potential_yield_t_ha[k]),
                   "sowing_date": str(table.sowing_dates[k])}))
    return contexts


def contexts_with_terms(contexts: list[SeasonContext], terms: dict) -> list[SeasonContext]:
    """One context per field, each carrying its episode terms in ``extra["terms"]`` (name -> float, the names
    of ``crop_sim_ros.task.core.EpisodeTerms``; ``terms``: name -> (N,) arrays, as the environment's info
    gives them): what the task family's hindsight oracle plans with."""
    from crop_sim_ros.task import core
    return [replace(context, extra={**context.extra, "terms": {name: float(np.asarray(terms[name])[i])
                                                               for name in core.EpisodeTerms._fields}})
            for i, context in enumerate(contexts)]


def run_episodes(policy, scenario, seasons, seed: int | None = 0, record: bool = False,
                 contexts: list[SeasonContext] | None = None, terms: dict | None = None) -> Episodes:
    """One episode per entry of ``seasons`` (indices into the scenario's seasons), all fields at once, with
    the environment's noise generator seeded by ``seed``. ``policy.act`` receives the (N, 20) batch.

    ``terms`` (name -> (N,) array, see ``IrrigationVectorEnv.reset``) fixes the family task's drawn terms
    (prices, quota) of each field, for comparisons on the same terms.

    Policies with ``begin_season`` get, after the reset and before the first step, the list of the fields'
    :class:`SeasonContext` (``contexts`` of the scenario, computed if not given), each with the field's episode
    terms (:func:`contexts_with_terms`).
    """
    from gymnasium.vector import AutoresetMode
    from crop_sim_ros.task import IrrigationVectorEnv
    scenario = scenario_of(scenario)
    seasons = np.asarray(seasons, dtype=np.int64)
    n = len(seasons)
    env = IrrigationVectorEnv(n, scenario, autoreset_mode=AutoresetMode.SAME_STEP)
    if hasattr(policy, "reset"):
        policy.reset(seed)
    obs, info = env.reset(seed=seed, options={"season": seasons, **({} if terms is None else {"terms": terms})})
    if hasattr(policy, "begin_season"):
        all_contexts = contexts if contexts is not None else season_contexts(scenario)
        policy.begin_season(contexts_with_terms([all_contexts[k] for k in seasons], info))
    potential = np.asarray(info["potential_yield_t_ha"], dtype=float).copy()
    total = np.zeros(n)
    water = np.zeros(n)
    rain = np.zeros(n)
    yield_t_ha = np.zeros(n)
    days = np.zeros(n, dtype=np.int64)
    matured = np.zeros(n, dtype=bool)
    alive = np.ones(n, dtype=bool)
    daily = {"biomass_t_ha": [], "paw_mm": [], "rain_mm": [], "irrigation_mm": []} if record else None
    state_biomass, state_paw = info["true_biomass_t_ha"].copy(), info["true_paw_mm"].copy()
    while alive.any():
        action = np.clip(np.asarray(policy.act(obs), dtype=float).reshape(n), 0.0, scenario.max_irrigation_mm)
        obs, rewards, terminated, truncated, info = env.step(action)
        applied = np.where(alive, info["irrigation_applied_mm"], 0.0)
        if record:
            daily["biomass_t_ha"].append(np.where(alive, state_biomass, np.nan))
            daily["paw_mm"].append(np.where(alive, state_paw, np.nan))
            daily["rain_mm"].append(np.where(alive, info["rain_mm"], np.nan))
            daily["irrigation_mm"].append(np.where(alive, applied, np.nan))
        total += np.where(alive, rewards, 0.0)
        water += applied
        rain += np.where(alive, info["rain_mm"], 0.0)
        days += alive
        ended = alive & (terminated | truncated)
        if ended.any():
            final = info["final_info"]
            yield_t_ha[ended] = np.where(terminated[ended], final["yield_t_ha"][ended], 0.0)
            matured[ended] = terminated[ended]
        alive &= ~ended
        state_biomass, state_paw = info["true_biomass_t_ha"].copy(), info["true_paw_mm"].copy()
    if record:
        daily = {k: np.array(v) for k, v in daily.items()}
    return Episodes(seasons, total, yield_t_ha, water, rain, potential, days, matured, daily)
