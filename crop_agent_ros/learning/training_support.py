"""What both training paths of ``crop-sim train`` share: a logger that writes nowhere, fresh validation seasons,
the process's age and the package versions a run records."""

from __future__ import annotations

import os
import platform
from dataclasses import replace
from pathlib import Path

import numpy as np


def silent_logger():
    """An SB3 logger that writes nowhere: with ``verbose=0`` SB3's own default still makes an empty
    ``/tmp/SB3-<time>`` folder on every ``learn`` (245 of them after one session's tests and sweeps)."""
    from stable_baselines3.common.logger import Logger
    return Logger(folder=None, output_formats=[])


def validation_scenario(scenario, n_seasons: int, seed: int):
    """Fresh generated seasons: the training scenario's generator with a seed its pool does not use
    (seed + 10,007 + the training seed). A mixture validates on its first part's generator, re-seeded alike."""
    if scenario.weather.kind == "mixture":
        from crop_sim_ros.task.scenario import get_scenario
        first = get_scenario(scenario.weather.mixture[0], scenario.data_dir)
        scenario = replace(scenario, sowing_date=first.sowing_date, max_season_days=first.max_season_days,
                           weather=first.weather)
    return replace(scenario, name=f"{scenario.name}-validation",
                   weather=replace(scenario.weather, seed=scenario.weather.seed + 10_007 + seed, n_seasons=n_seasons))


def seconds_since_launch() -> float:
    """Seconds since this process started (its start time in /proc, 10 ms resolution): the interpreter's
    start-up and imports count too."""
    after_name = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
    start_s = int(after_name[19]) / os.sysconf("SC_CLK_TCK")  # field 22, starttime, in clock ticks since boot
    return float(Path("/proc/uptime").read_text().split()[0]) - start_s


def package_versions() -> dict:
    import gymnasium
    import stable_baselines3
    import torch
    return {"python": platform.python_version(), "numpy": np.__version__, "gymnasium": gymnasium.__version__,
            "stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__,
            "platform": platform.platform()}
