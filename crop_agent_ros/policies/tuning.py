"""Tune the hand-made rules by grid search on generated training seasons (never the held-out ones).

    python -m crop_agent_ros.policies.tuning [--task benton-generated] [--seasons 200] [--seed 0]

writes ``best_constant_benton.json``, ``refill_benton.json`` and ``demand_margin_benton.json`` (the fixed
margin of the demand-aware refill, the centre of the PPO policy's margin action) beside the rules. Every grid point runs on
the same seasons with the same noise seed; the score is the mean return. All grid points x seasons run as
fields of one batched environment.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np

from crop_sim_ros.output import write_json_atomic

from .rules import BEST_CONSTANT_FILE, REFILL_FILE, ConstantPolicy, DemandMarginPolicy, RefillPolicy
from .rollout import run_episodes, scenario_of

CONSTANT_GRID_MM = tuple(np.round(np.arange(2.0, 12.01, 0.25), 2))
REFILL_THRESHOLDS_MM = (50, 60, 70, 75, 80, 85, 88, 90, 92, 95, 98, 100, 105, 110)
REFILL_TARGETS_MM = (70, 80, 85, 88, 90, 92, 95, 98, 100, 105, 110, 120)
REFILL_SKIP_RAIN_MM = (1, 2, 3, 5, 8, 10, 20, 1000)
MARGIN_GRID_MM = (0, 1, 2, 3, 4, 5, 6, 8, 10, 12, 15)
MARGIN_FILE = REFILL_FILE.with_name("demand_margin_benton.json")


def _grid_scores(make, grid: list, scenario, seasons: np.ndarray, seed: int) -> np.ndarray:
    """Mean return of each grid point over ``seasons`` (one batched run)."""
    g, m = len(grid), len(seasons)
    policy = make(grid, m)
    episodes = run_episodes(policy, scenario, np.tile(seasons, g), seed=seed)
    return episodes.episode_return.reshape(g, m).mean(axis=1)


def _best_of(key: str, grid: list, scores: np.ndarray) -> dict:
    """The best value of a one-parameter grid under ``key``, its mean return, and every grid point's."""
    best = int(np.argmax(scores))
    return {key: float(grid[best]), "mean_return": float(scores[best]),
            "grid": {f"{v:g}": float(s) for v, s in zip(grid, scores)}}


def tune_constant(scenario, seasons, seed: int = 0) -> dict:
    grid = list(CONSTANT_GRID_MM)

    def make(grid, m):
        class Batch(ConstantPolicy):
            def _act_batch(self, obs):
                return np.repeat(np.asarray(grid, dtype=float), m)
        return Batch(0.0, name="grid")

    return _best_of("mm_per_day", grid, _grid_scores(make, grid, scenario, seasons, seed))


def tune_margin(scenario, seasons, seed: int = 0) -> dict:
    """The fixed margin of the demand-aware refill (the centre of the PPO policy's margin action)."""
    grid = list(MARGIN_GRID_MM)

    def make(grid, m):
        class Batch(DemandMarginPolicy):
            def _act_batch(self, obs):
                from .sb3 import action_to_mm
                return action_to_mm(np.zeros(len(obs)), obs, "margin",
                                    margin_center_mm=np.repeat(np.asarray(grid, dtype=float), m))
        return Batch(0.0, name="grid")

    return _best_of("margin_mm", grid, _grid_scores(make, grid, scenario, seasons, seed))


def tune_refill(scenario, seasons, seed: int = 0) -> dict:
    grid = [(th, tg, sk) for th, tg, sk in itertools.product(REFILL_THRESHOLDS_MM, REFILL_TARGETS_MM,
                                                            REFILL_SKIP_RAIN_MM) if tg > th - 1e-9]

    def make(grid, m):
        th, tg, sk = (np.repeat(np.asarray(col, dtype=float), m) for col in zip(*grid))
        return RefillPolicy(th, tg, sk, count_today_rain=True, name="grid")

    scores = _grid_scores(make, grid, scenario, seasons, seed)
    order = np.argsort(scores)[::-1]
    th, tg, sk = grid[int(order[0])]
    return {"parameters": {"threshold_mm": float(th), "target_mm": float(tg), "skip_rain_mm": float(sk),
                           "count_today_rain": True},
            "mean_return": float(scores[order[0]]),
            "top10": [{"threshold_mm": grid[i][0], "target_mm": grid[i][1], "skip_rain_mm": grid[i][2],
                       "mean_return": float(scores[i])} for i in order[:10]],
            "grid_size": len(grid)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="benton-generated", help="a task with generated weather")
    parser.add_argument("--seasons", type=int, default=200, help="first N seasons of the scenario's pool")
    parser.add_argument("--seed", type=int, default=0, help="observation-noise seed")
    parser.add_argument("--out-dir", type=Path, default=REFILL_FILE.parent)
    args = parser.parse_args(argv)
    scenario = scenario_of(args.task)
    if scenario.name != "benton-generated" and "generat" not in scenario.name:
        print(f"warning: tuning on {scenario.name}, not on generated seasons")
    seasons = np.arange(args.seasons)
    common = {"tuned_on": {"scenario": scenario.name, "seasons": f"0..{args.seasons - 1}", "noise_seed": args.seed},
              "score": "mean return (yield t/ha + C_I * irrigation mm) over the tuning seasons"}
    t = time.perf_counter()
    constant = tune_constant(scenario, seasons, args.seed)
    write_json_atomic(args.out_dir / BEST_CONSTANT_FILE.name, {**common, **constant}, indent=2)
    print(f"best constant: {constant['mm_per_day']} mm/day, mean return {constant['mean_return']:.4f}")
    refill = tune_refill(scenario, seasons, args.seed)
    write_json_atomic(args.out_dir / REFILL_FILE.name, {**common, **refill}, indent=2)
    print(f"refill: {refill['parameters']}, mean return {refill['mean_return']:.4f} "
          f"({refill['grid_size']} grid points, {time.perf_counter() - t:.0f} s)")
    margin = tune_margin(scenario, seasons, args.seed)
    write_json_atomic(args.out_dir / MARGIN_FILE.name, {**common, **margin}, indent=2)
    print(f"demand margin: {margin['margin_mm']} mm, mean return {margin['mean_return']:.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
