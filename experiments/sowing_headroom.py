"""How much a family task's tuned rule leaves to learn on a climate sown on other dates: the headroom.

Showed: the rule's headroom on generated Maricopa seasons grows with the sowing date (0.69 % of the
oracle's return sown December 15, 2.42 % February 28), which chose maricopa-late-* (February 28) as a set.

    python experiments/sowing_headroom.py --task benton-quota --scenario maricopa-generated \\
        --sowing-dates 2000-12-15,2001-01-15,2001-02-15,2001-02-28 [--seasons 50] [--noise-seeds 3]

For each sowing date: ``--scenario``'s weather generator with the far evaluation seed (``--weather-seed``,
900,001 as ``crop-sim evaluate``'s far sets), sown on that date, under the task's terms (one draw per season,
``--terms-seed``, the same for every date); the hindsight oracle's plan and the tuned rule (noise seeds
0..K-1) on each season. Prints, per date, the mean oracle and rule returns (USD/ha), the rule's regret and its
share of the oracle's return: a set is worth evaluating learned agents on if that share is at least
``HEADROOM_PCT`` (2 %). How the held-out climate's late sowing date (``maricopa-late-generated``) was chosen.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, replace
from datetime import date

import numpy as np

from crop_sim_ros.usage import UsageError, user_input

from crop_agent_ros.learning.evaluate_task import FAR_SEED, HEADROOM_PCT, TERMS_SEED, EvaluationSet, set_terms
from crop_agent_ros.learning.evaluation_units import oracle_returns


@dataclass(frozen=True)
class Headroom:
    """One sowing date's figures (USD/ha, means over the seasons; the rule's also over the noise seeds)."""

    sowing_date: date
    oracle_usd_ha: float
    rule_usd_ha: float

    @property
    def regret_usd_ha(self) -> float:
        return self.oracle_usd_ha - self.rule_usd_ha

    @property
    def headroom_pct(self) -> float:
        """The rule's regret as a share of the oracle's return (%)."""
        return 100.0 * self.regret_usd_ha / self.oracle_usd_ha


def sowing_headroom(task_name: str, scenario_name: str, sowing_date: date, seasons: int, noise_seeds: int,
                    weather_seed: int = FAR_SEED, terms_seed: int = TERMS_SEED) -> Headroom:
    """The oracle's and the tuned rule's mean returns on ``seasons`` generated seasons of ``scenario_name``'s
    generator (seed ``weather_seed``) sown on ``sowing_date``, under ``task_name``'s terms."""
    from crop_sim_ros.task.scenario import get_scenario, reseeded, with_weather_of
    from crop_agent_ros.policies import family_tuning
    from crop_agent_ros.policies.rollout import run_episodes
    task = get_scenario(task_name)
    source = get_scenario(scenario_name)
    if source.weather.kind != "generator":
        raise ValueError(f"--scenario {scenario_name!r} is not on generated weather (its weather is "
                         f"{source.weather.kind!r})")
    weather = replace(reseeded(source, weather_seed, seasons), sowing_date=sowing_date)
    evaluation_set = EvaluationSet(f"{scenario_name}-sown-{sowing_date}", f"sown {sowing_date}",
                                   with_weather_of(task, weather), np.arange(seasons))
    terms = set_terms(evaluation_set, terms_seed)
    oracle, _ = oracle_returns(evaluation_set, terms)
    rule = family_tuning.tuned_rule(task_name)
    rule_returns = [run_episodes(rule, evaluation_set.scenario, evaluation_set.seasons, seed=seed,
                                 terms=terms).episode_return for seed in range(noise_seeds)]
    return Headroom(sowing_date, float(np.mean(oracle)), float(np.mean(rule_returns)))


def _dates(text: str) -> list[date]:
    try:
        dates = [date.fromisoformat(part.strip()) for part in text.split(",") if part.strip()]
    except ValueError as error:
        raise UsageError(f"--sowing-dates: {error} (give YYYY-MM-DD,YYYY-MM-DD,...)") from None
    if not dates:
        raise UsageError("--sowing-dates: no date given")
    return dates


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python experiments/sowing_headroom.py",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", required=True, help="a family task with a tuned rule (e.g. benton-quota)")
    parser.add_argument("--scenario", default="maricopa-generated", help="a generated-weather scenario")
    parser.add_argument("--sowing-dates", required=True, help="comma-separated YYYY-MM-DD")
    parser.add_argument("--seasons", type=int, default=50)
    parser.add_argument("--noise-seeds", type=int, default=3)
    parser.add_argument("--weather-seed", type=int, default=FAR_SEED)
    parser.add_argument("--terms-seed", type=int, default=TERMS_SEED)
    args = parser.parse_args(argv)
    try:
        dates = _dates(args.sowing_dates)
        for name, value in (("--seasons", args.seasons), ("--noise-seeds", args.noise_seeds)):
            if not 1 <= value <= 1000:
                raise UsageError(f"{name}: {value} is not in 1..1000")
        print(f"task {args.task}, {args.scenario}'s generator (seed {args.weather_seed}), {args.seasons} seasons, "
              f"rule on noise seeds 0..{args.noise_seeds - 1}, terms seed {args.terms_seed} (USD/ha)")
        print("| sown | oracle | rule | rule's regret | % of oracle |")
        print("|---|---:|---:|---:|---:|")
        for sowing_date in dates:
            with user_input("--task / --scenario", (ValueError, KeyError, FileNotFoundError)):
                h = sowing_headroom(args.task, args.scenario, sowing_date, args.seasons, args.noise_seeds,
                                    args.weather_seed, args.terms_seed)
            mark = "" if h.headroom_pct >= HEADROOM_PCT else f" (under {HEADROOM_PCT:g} %)"
            print(f"| {sowing_date:%B} {sowing_date.day} | {h.oracle_usd_ha:,.0f} | {h.rule_usd_ha:,.0f} | "
                  f"{h.regret_usd_ha:,.0f} | {h.headroom_pct:.2f} %{mark} |", flush=True)
    except UsageError as error:
        print(f"sowing_headroom: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
