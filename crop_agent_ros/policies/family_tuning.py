"""Tune the water-budget rule (:mod:`crop_agent_ros.policies.family`) of a family task on generated training
seasons only (never the held-out ones), and write ``family_<task>.json`` beside the rules.

    crop-sim tune-rule --task benton-quota [--seasons 0..199] [--seed 0] [--candidates 192] [--rounds 4]

Method: a random search over the rule's parameter box, then rounds of local search around the best few
(Gaussian steps shrinking by half each round). Every candidate x season is one field of one batched
environment run; every candidate meets the same seasons, the same drawn terms (prices, quota) and the same
noise seed (common random numbers), so their differences are the rule's, not the draw's. The score is the
mean return over the seasons.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .family import FarmFacts, RuleParameters, WaterBudgetRule
from .rollout import draw_terms, run_episodes, season_range

HERE = Path(__file__).resolve().parent
# The search box: (low, high) of each parameter, and values outside the box a candidate may take ("never").
SEARCH_BOX = {
    "level_factor": (0.3, 1.3),
    "margin_mm": (-40.0, 40.0),
    "skip_rain_mm": (0.0, 30.0),
    "start_tt_fraction": (0.0, 0.6),
    "stop_tt_fraction": (0.5, 1.1),
    "pace": (0.3, 4.0),
    "value_ratio": (0.0, 0.05),
}
NEVER = {"skip_rain_mm": 1e6, "start_tt_fraction": 0.0, "stop_tt_fraction": 10.0, "pace": np.inf,
         "value_ratio": np.inf}


def training_seasons(scenario, first: int, last: int) -> np.ndarray:
    """Seasons FIRST..LAST of the training pool; for a mixture, FIRST..LAST of each part (so that every
    climate of the mixture is tuned on)."""
    return of_each_part(scenario, np.arange(first, last + 1))


def of_each_part(scenario, seasons: np.ndarray) -> np.ndarray:
    """Indices into ``scenario``'s pool of ``seasons``: themselves, or for a mixture those positions of each
    part (part by part); ValueError if a position is past its part's pool."""
    from crop_sim_ros.task.scenario import generated_parts
    sizes = [part.n_seasons for part in generated_parts(scenario)]
    if len(seasons) and (seasons.min() < 0 or seasons.max() >= min(sizes)):
        raise ValueError(f"--seasons: must lie within 0..{min(sizes) - 1} (of each part of a mixture)")
    offsets = np.cumsum([0] + sizes)
    return np.concatenate([offset + np.asarray(seasons, dtype=np.int64) for offset in offsets[:-1]])


def rule_file(task: str) -> Path:
    """``family_<task>.json`` beside this module: the rule tuned for ``task``."""
    return HERE / f"family_{task}.json"


def candidate_returns(scenario, facts: FarmFacts, candidates: dict, seasons: np.ndarray, seed: int,
                      terms: dict) -> np.ndarray:
    """(C, M) returns of C candidates (name -> (C,) arrays) on M seasons, one batched run."""
    c = len(next(iter(candidates.values())))
    m = len(seasons)
    rule = WaterBudgetRule(facts, {k: np.repeat(np.asarray(v, float), m) for k, v in candidates.items()})
    episodes = run_episodes(rule, scenario, np.tile(seasons, c), seed=seed,
                            terms={k: np.tile(v, c) for k, v in terms.items()})
    return episodes.episode_return.reshape(c, m)


def _random_candidates(rng: np.random.Generator, n: int, names: tuple[str, ...]) -> dict:
    out = {}
    for name in names:
        low, high = SEARCH_BOX[name]
        values = rng.uniform(low, high, n)
        if name in NEVER:
            values = np.where(rng.random(n) < 0.35, NEVER[name], values)
        out[name] = values
    return out


def _perturb(rng: np.random.Generator, best: list[dict], n: int, scale: float) -> dict:
    out = {name: np.empty(n) for name in best[0]}
    for i in range(n):
        parent = best[i % len(best)]
        for name, value in parent.items():
            low, high = SEARCH_BOX[name]
            if not np.isfinite(value) or value == NEVER.get(name):
                # a "never" value flips into the box now and then, else stays
                out[name][i] = rng.uniform(low, high) if rng.random() < 0.2 else value
            else:
                out[name][i] = np.clip(value + rng.normal(0.0, scale * (high - low)), low, high)
    return out


def tune_rule(scenario, seasons: np.ndarray, seed: int = 0, candidates: int = 192, rounds: int = 4,
              names: tuple[str, ...] = RuleParameters.names(), log=print) -> dict:
    """The best rule parameters on ``seasons`` of ``scenario`` (see the module docstring), with its score."""
    facts = FarmFacts.of_scenario(scenario)
    rng = np.random.default_rng(seed)
    terms = draw_terms(scenario, seasons, seed)
    defaults = {k: np.array([getattr(RuleParameters(), k)]) for k in names}
    pool = _random_candidates(rng, candidates - 1, names)
    pool = {k: np.concatenate([defaults[k], pool[k]]) for k in names}
    history = []
    scale = 0.15
    everything = {k: np.empty(0) for k in names}
    scores_all = np.empty(0)
    for round_ in range(rounds + 1):
        scores = candidate_returns(scenario, facts, pool, seasons, seed, terms).mean(axis=1)
        everything = {k: np.concatenate([everything[k], pool[k]]) for k in names}
        scores_all = np.concatenate([scores_all, scores])
        order = np.argsort(scores_all)[::-1]
        best = [{k: float(everything[k][i]) for k in names} for i in order[:8]]
        history.append(float(scores_all[order[0]]))
        log(f"round {round_}: best mean return {scores_all[order[0]]:.4f} of {len(scores_all)} candidates")
        if round_ < rounds:
            pool = _perturb(rng, best, candidates, scale)
            scale /= 2.0
    return {"parameters": best[0], "mean_return": history[-1], "history": history,
            "seasons": [int(s) for s in seasons], "seed": seed, "scenario": scenario.name,
            "facts": {"capacity_mm": facts.capacity_mm, "tsum_degc_d": facts.tsum_degc_d}}


def tuned_rule(task: str) -> WaterBudgetRule:
    """The rule tuned for ``task``; FileNotFoundError says how to tune it."""
    path = rule_file(task)
    if not path.exists():
        raise FileNotFoundError(f"{path} is missing: run `crop-sim tune-rule --task {task}`")
    return rule_from_record(json.loads(path.read_text()))


def _json_parameters(parameters: dict) -> dict:
    """Rule parameters for JSON: an infinite value ("never") is null."""
    return {k: (None if not np.isfinite(v) else float(v)) for k, v in parameters.items()}


def rule_record(rule: WaterBudgetRule) -> dict:
    """A (scalar-parameter) rule as JSON: its ``facts`` and ``parameters`` (null = inf), as in family_<task>.json."""
    return {"facts": {"capacity_mm": rule.facts.capacity_mm, "tsum_degc_d": rule.facts.tsum_degc_d},
            "parameters": _json_parameters({k: float(v) for k, v in rule.parameters.items()})}


def rule_from_record(record: dict) -> WaterBudgetRule:
    """The rule of a record with ``facts`` and ``parameters`` (family_<task>.json, or :func:`rule_record`)."""
    params = {k: (np.inf if v is None else v) for k, v in record["parameters"].items()}
    return WaterBudgetRule(FarmFacts(**record["facts"]), params, name="budget-rule")


def write_tuned(task: str, result: dict) -> Path:
    """Write :func:`tune_rule`'s ``result`` to :func:`rule_file` (an infinite parameter as null)."""
    path = rule_file(task)
    plain = {**result, "parameters": _json_parameters(result["parameters"])}
    path.write_text(json.dumps(plain, indent=1) + "\n")
    return path


def add_arguments(parser) -> None:
    parser.add_argument("--task", required=True, help="a family task (e.g. benton-quota)")
    parser.add_argument("--seasons", default="0..149",
                        help="training seasons FIRST..LAST of the task's pool (of each part of a mixture)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the search, the terms and the noise")
    parser.add_argument("--candidates", type=int, default=128, help="candidates per round (1..10000)")
    parser.add_argument("--rounds", type=int, default=4, help="local-search rounds after the random one (0..50)")


def run(args) -> int:
    from crop_sim_ros.task.scenario import get_scenario
    from crop_sim_ros.usage import UsageError, user_input
    with user_input("--task"):
        scenario = get_scenario(args.task)
    if not scenario.is_family_task or scenario.weather.kind not in ("generator", "mixture"):
        raise UsageError(f"--task {args.task}: the rule is tuned on a family task's generated training seasons")
    with user_input(None, (ValueError,)):  # the messages name --seasons
        seasons = of_each_part(scenario, season_range(str(args.seasons)))
    if not (1 <= args.candidates <= 10_000 and 0 <= args.rounds <= 50):
        raise UsageError("--candidates must be in 1..10000 and --rounds in 0..50")
    result = tune_rule(scenario, seasons, args.seed, args.candidates, args.rounds)
    print(f"tuned {args.task}: {result['parameters']} mean return {result['mean_return']:.2f}; "
          f"wrote {write_tuned(args.task, result)}")
    return 0
