"""When each policy irrigates: mm applied per period after sowing on one evaluation set of a family task.

Showed: on the late-sown held-out climate (maricopa-late-generated) ES irrigates the fast crop too late
(151 mm in days 20-59 where the oracle and the rule spend 194 and 216 mm), which is where it loses to the rule.

    python experiments/irrigation_timing.py --task benton-quota --set maricopa-late-generated \\
        --agent es=crop_agent_ros/agents/benton-quota/es [--agent ...] [--seasons 12] [--period-days 20]

The set's first ``--seasons`` seasons: ``crop-sim evaluate``'s set with its weather and the terms of its position
in the whole protocol (``--far-seasons``, ``--far-seed`` and ``--terms-seed`` as there: a generated pool's first
seasons depend on its size), noise seed 0; the hindsight oracle, the
task's tuned rule (``rule``: the budget rule; ``paced-rule`` where the task has one) and each ``--agent`` (a run directory with ``model.zip``). Prints one row per policy: mean
return (USD/ha), water (mm), dry yield (t/ha) and days to the season's end, then the mean irrigation (mm) in
each period of ``--period-days`` days after sowing and the mean true plant-available water (mm) over it. How the
late-sown held-out climate's failure was read (docs/findings.md).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from crop_sim_ros.usage import UsageError, user_input

from crop_agent_ros.learning.evaluate_task import FAR_SEASONS, FAR_SEED, TERMS_SEED, evaluation_sets, set_terms


@dataclass(frozen=True)
class Timing:
    """One policy's figures on the seasons (means over seasons; per period: mm irrigated, mean PAW in mm)."""

    policy: str
    return_usd_ha: float
    water_mm: float
    yield_t_ha: float
    days: float
    irrigation_mm_by_period: tuple[float, ...]
    paw_mm_by_period: tuple[float, ...]


def timings(task_name: str, set_name: str, agents: dict[str, Path], seasons: int, period_days: int,
            far_seasons: int = FAR_SEASONS, far_seed: int = FAR_SEED, terms_seed: int = TERMS_SEED) -> list[Timing]:
    """The oracle's, the tuned rule's and each agent's :class:`Timing` on the first ``seasons`` seasons of
    evaluation set ``set_name`` as ``crop-sim evaluate --far-seasons far_seasons`` builds it (ValueError naming the
    task's sets if it has no such set)."""
    from crop_sim_ros.task.scenario import get_scenario
    from crop_agent_ros.policies import family_tuning
    from crop_agent_ros.policies.family_oracle import FamilyOraclePolicy
    from crop_agent_ros.policies.rollout import run_episodes
    from crop_agent_ros.policies.learned import LearnedPolicy
    task = get_scenario(task_name)
    sets = evaluation_sets(task, far_seasons, far_seed)
    position = next((i for i, s in enumerate(sets) if s.name == set_name), None)
    if position is None:
        raise ValueError(f"no set {set_name!r} in {task_name}'s protocol (sets: {', '.join(s.name for s in sets)})")
    chosen = sets[position]
    all_terms = set_terms(chosen, terms_seed + position)
    chosen = replace(chosen, seasons=chosen.seasons[:seasons])
    terms = {name: values[:len(chosen.seasons)] for name, values in all_terms.items()}
    policies = {"oracle": FamilyOraclePolicy.for_scenario(chosen.scenario), "rule": family_tuning.tuned_rule(task_name)}
    if family_tuning.family_file(task_name, "paced-rule").exists():
        policies["paced-rule"] = family_tuning.tuned_rule(task_name, "paced-rule")
    for name, directory in agents.items():
        policies[name] = LearnedPolicy(Path(directory) / "model.zip", name=name)
    result = []
    for name, policy in policies.items():
        episodes = run_episodes(policy, chosen.scenario, chosen.seasons, seed=0, terms=terms, record=True)
        irrigation = np.array(episodes.daily["irrigation_mm"])   # (days, seasons), NaN after a season's end
        paw = np.array(episodes.daily["paw_mm"])
        starts = range(0, irrigation.shape[0], period_days)
        result.append(Timing(
            name, float(episodes.episode_return.mean()), float(episodes.water_mm.mean()),
            float(episodes.yield_t_ha.mean()), float(episodes.days.mean()),
            tuple(float(np.nansum(irrigation[a:a + period_days], axis=0).mean()) for a in starts),
            tuple(float(np.nanmean(paw[a:a + period_days])) if np.isfinite(paw[a:a + period_days]).any()
                  else float("nan") for a in starts)))
    return result


def _agents(specs: list[str]) -> dict[str, Path]:
    agents = {}
    for spec in specs:
        name, _, directory = spec.partition("=")
        if not name or not directory:
            raise UsageError(f"--agent {spec!r}: give NAME=RUN_DIRECTORY")
        if not (Path(directory) / "model.zip").is_file():
            raise UsageError(f"--agent {name}: {directory}/model.zip does not exist")
        if name in agents or name in ("oracle", "rule", "paced-rule"):
            raise UsageError(f"--agent {name}: the name is taken")
        agents[name] = Path(directory)
    return agents


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python experiments/irrigation_timing.py",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", required=True, help="a family task (e.g. benton-quota)")
    parser.add_argument("--set", required=True, help="an evaluation set of crop-sim evaluate --task (e.g. far-benton)")
    parser.add_argument("--agent", action="append", default=[], metavar="NAME=RUN_DIRECTORY")
    parser.add_argument("--seasons", type=int, default=12, help="the set's first N seasons")
    parser.add_argument("--period-days", type=int, default=20)
    parser.add_argument("--far-seasons", type=int, default=FAR_SEASONS,
                        help="seasons of each far generated set, as crop-sim evaluate's (default: its default)")
    parser.add_argument("--far-seed", type=int, default=FAR_SEED)
    parser.add_argument("--terms-seed", type=int, default=TERMS_SEED)
    args = parser.parse_args(argv)
    try:
        for name, value, high in (("--seasons", args.seasons, 1000), ("--period-days", args.period_days, 200),
                                  ("--far-seasons", args.far_seasons, 10_000)):
            if not 1 <= value <= high:
                raise UsageError(f"{name}: {value} is not in 1..{high}")
        agents = _agents(args.agent)
        with user_input(None, (ValueError, KeyError)):
            rows = timings(args.task, args.set, agents, args.seasons, args.period_days, args.far_seasons,
                           args.far_seed, args.terms_seed)
    except UsageError as error:
        print(f"irrigation_timing: {error}", file=sys.stderr)
        return 2
    periods = len(rows[0].irrigation_mm_by_period)
    names = [f"d{a}-{a + args.period_days - 1}" for a in range(0, periods * args.period_days, args.period_days)]
    print(f"{args.task}, {args.set}: first {args.seasons} seasons, noise seed 0 (USD/ha, mm, t/ha; per period after "
          "sowing: mm irrigated / mean PAW mm)")
    print("| policy | return | water | yield | days | " + " | ".join(names) + " |")
    print("|---|---:|---:|---:|---:|" + "---:|" * periods)
    for r in rows:
        cells = [f"{i:.0f} / {p:.0f}" if np.isfinite(p) else "-" for i, p in zip(r.irrigation_mm_by_period,
                                                                              r.paw_mm_by_period)]
        print(f"| {r.policy} | {r.return_usd_ha:,.0f} | {r.water_mm:.0f} | {r.yield_t_ha:.2f} | {r.days:.1f} | "
              + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
