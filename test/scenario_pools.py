"""Scenarios with their generated weather pools cut short, for tests that make every registered task: the same
task, season length and weather source, but building all 48 environments with their 1,000-6,000-season pools
would take minutes."""

from __future__ import annotations

from dataclasses import replace

import crop_sim_ros.task.scenario as scenario_module


def small_pool_loader(pool_seasons: int):
    """A stand-in for ``get_scenario`` whose generated pools hold at most ``pool_seasons`` seasons."""
    load = scenario_module.get_scenario

    def get_small(name, data_dir=None):
        scenario = load(name, data_dir)
        if scenario.weather.kind != "generator":
            return scenario
        return replace(scenario, weather=replace(scenario.weather,
                                                 n_seasons=min(scenario.weather.n_seasons, pool_seasons)))

    return get_small
