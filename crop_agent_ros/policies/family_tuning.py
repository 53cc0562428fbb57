"""Tune the water-budget rule (:mod:`crop_agent_ros.policies.family`) of a family task on generated training
seasons only (never the held-out ones), and write ``family_<task>.json`` beside the rules.

    crop-sim tune-rule --task benton-quota [--rule budget-rule|paced-rule] [--seasons 0..199] [--seed 0]
        [--candidates 192] [--rounds 4] [--term-draws 1] [--space full]

Two rule families are tuned the same way (:data:`RULES`): the water-budget rule (``budget-rule``, written to
``family_<task>.json``) and the paced rule (``paced-rule``, :mod:`crop_agent_ros.policies.paced_rule`, written
to ``family_<task>-paced.json``).

Method: a random search over the rule's parameter box, then rounds of local search around the best few
(Gaussian steps shrinking by half each round; the paced rule's, 17 parameters, by 0.7, so that its last rounds
still move). Every candidate x season is one field of one batched environment run; every candidate meets the
same seasons, the same drawn terms (prices, quota) and the same noise seed (common random numbers), so their
differences are the rule's, not the draw's. The score is the mean return over the seasons.

Search spaces (``--space``, :class:`SearchSpace`): which parameters are searched, within which bounds, and which
are held at a value, chosen before tuning from what the rule should not rely on (never from a held-out score);
the file names its space (``search_space``) unless it is the full one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .family import FarmFacts, RuleParameters, WaterBudgetRule
from .paced_rule import PacedFacts, PacedParameters, PacedRule
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


MAX_SEED = 2**32 - 1  # --seed (numpy's generators take any non-negative integer; one bound for every command)

# The paced rule's search box and "never" values (see crop_agent_ros/policies/paced_rule.py).
PACED_SEARCH_BOX = {
    "level_factor": (0.5, 1.4),
    "margin_mm": (-20.0, 60.0),
    "early_factor": (0.0, 1.2),
    "start_offset_degc_d": (-500.0, 600.0),
    "stop_offset_degc_d": (-500.0, 400.0),
    "narrow_degc_d": (0.0, 1500.0),
    "narrow_stop_degc_d": (0.0, 1500.0),
    "pace": (0.5, 3.0),
    "late_factor": (0.0, 1.5),
    "heat_weight": (0.0, 1.0),
    "senescence_weight": (0.0, 2.0),
    "skip_rain_mm": (0.0, 30.0),
    "rate_prior_mm_per_degc_d": (0.15, 0.6),
    "prior_weight_degc_d": (0.0, 3000.0),
    "memory_degc_d": (50.0, 1500.0),
    "bank_days": (0.0, 20.0),
    "bank_threshold": (0.3, 1.2),
}
PACED_NEVER = {"skip_rain_mm": 1e6, "pace": 1e6, "memory_degc_d": 1e6}


@dataclass(frozen=True)
class SearchSpace:
    """A named search space of a rule family, chosen before tuning from what the rule should not rely on (never
    from a held-out score): ``box`` replaces or adds (low, high) bounds of the family's box, ``fixed`` holds
    parameters at a value (not searched)."""

    description: str
    box: dict = field(default_factory=dict)
    fixed: dict = field(default_factory=dict)


FULL = "full"
PACED_SPACES = {
    FULL: SearchSpace("every parameter of PACED_SEARCH_BOX (climates-quota's shipped file)"),
    # Growth is intercepted radiation (SIMPLE's f_Solar): before the canopy closes a mm buys little, whatever the
    # climate; the late reserve already follows the senescing cover, this lets the window follow the rising one.
    "canopy": SearchSpace("the full space and rise_weight: the window's level may follow the rising canopy",
                          box={"rise_weight": (0.0, 1.0)}),
}


@dataclass(frozen=True)
class RuleFamily:
    """A tunable rule family: its facts (from a scenario, to and from JSON), its builder, parameter names and
    defaults, search box, "never" values and the suffix of its file (``family_<task><suffix>.json``)."""

    name: str
    facts_of: Callable
    facts_record: Callable
    facts_from_record: Callable
    build: Callable
    names: tuple[str, ...]
    defaults: object
    box: dict
    never: dict
    suffix: str
    shrink: float = 0.5  # the local search's step scale is multiplied by this each round
    spaces: dict = field(default_factory=lambda: {FULL: SearchSpace("every parameter of the box")})

    def space(self, name: str) -> tuple[dict, dict, dict]:
        """The (box, never, fixed) of search space ``name`` (ValueError naming the known ones)."""
        if name not in self.spaces:
            raise ValueError(f"--space: unknown search space {name!r} of {self.name}; known: {', '.join(self.spaces)}")
        space = self.spaces[name]
        return {**self.box, **space.box}, self.never, dict(space.fixed)


RULES = {
    "budget-rule": RuleFamily(
        "budget-rule", FarmFacts.of_scenario,
        lambda facts: {"capacity_mm": facts.capacity_mm, "tsum_degc_d": facts.tsum_degc_d},
        lambda record: FarmFacts(**record), WaterBudgetRule, RuleParameters.names(), RuleParameters(),
        SEARCH_BOX, NEVER, ""),
    "paced-rule": RuleFamily(
        "paced-rule", PacedFacts.of_scenario, PacedFacts.record, PacedFacts.from_record, PacedRule,
        PacedParameters.names(), PacedParameters(), PACED_SEARCH_BOX, PACED_NEVER, "-paced", shrink=0.7,
        spaces=PACED_SPACES),
}


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


def family_file(task: str, rule: str = "budget-rule") -> Path:
    """The file of ``rule`` (a :data:`RULES` name) tuned for ``task``: :func:`rule_file` of ``task`` + the
    family's suffix (``family_<task>-paced.json`` for the paced rule)."""
    return rule_file(task + _family(rule).suffix)


def _family(rule: str) -> RuleFamily:
    if rule not in RULES:
        raise ValueError(f"unknown rule {rule!r}; known: {', '.join(RULES)}")
    return RULES[rule]


def candidate_returns(scenario, facts, candidates: dict, seasons: np.ndarray, seed: int,
                      terms: dict, rule: str = "budget-rule") -> np.ndarray:
    """(C, M) returns of C candidates (name -> (C,) arrays) on M seasons, one batched run."""
    c = len(next(iter(candidates.values())))
    m = len(seasons)
    rule = _family(rule).build(facts, {k: np.repeat(np.asarray(v, float), m) for k, v in candidates.items()})
    episodes = run_episodes(rule, scenario, np.tile(seasons, c), seed=seed,
                            terms={k: np.tile(v, c) for k, v in terms.items()})
    return episodes.episode_return.reshape(c, m)


def _random_candidates(rng: np.random.Generator, n: int, names: tuple[str, ...], box: dict = SEARCH_BOX,
                       never: dict = NEVER) -> dict:
    out = {}
    for name in names:
        low, high = box[name]
        values = rng.uniform(low, high, n)
        if name in never:
            values = np.where(rng.random(n) < 0.35, never[name], values)
        out[name] = values
    return out


def _perturb(rng: np.random.Generator, best: list[dict], n: int, scale: float, box: dict = SEARCH_BOX,
             never: dict = NEVER) -> dict:
    out = {name: np.empty(n) for name in best[0]}
    for i in range(n):
        parent = best[i % len(best)]
        for name, value in parent.items():
            low, high = box[name]
            if not np.isfinite(value) or value == never.get(name):
                # a "never" value flips into the box now and then, else stays
                out[name][i] = rng.uniform(low, high) if rng.random() < 0.2 else value
            else:
                out[name][i] = np.clip(value + rng.normal(0.0, scale * (high - low)), low, high)
    return out


def tune_rule(scenario, seasons: np.ndarray, seed: int = 0, candidates: int = 192, rounds: int = 4,
              names: tuple[str, ...] | None = None, log=print, rule: str = "budget-rule", term_draws: int = 1,
              space: str = FULL) -> dict:
    """The best parameters of ``rule`` (a :data:`RULES` name) on ``seasons`` of ``scenario`` (see the module
    docstring), with its score. ``term_draws`` K > 1: every season is met K times, each with its own draw of
    the terms (quota, prices): the same seasons, K times the terms (less fitting to one quota per season).
    ``space``: the family's search space (:class:`SearchSpace`); its fixed parameters are never searched."""
    family = _family(rule)
    box, never, fixed = family.space(space)
    searched = tuple(name for name in family.names if name in box and name not in fixed)
    names = searched if names is None else tuple(name for name in names if name not in fixed)
    facts = family.facts_of(scenario)
    rng = np.random.default_rng(seed)
    unique_seasons, seasons = seasons, np.tile(seasons, term_draws)
    terms = draw_terms(scenario, seasons, seed)
    defaults = {k: np.array([getattr(family.defaults, k)]) for k in names}
    pool = _random_candidates(rng, candidates - 1, names, box, never)
    pool = {k: np.concatenate([defaults[k], pool[k]]) for k in names}
    history = []
    scale = 0.15
    everything = {k: np.empty(0) for k in names}
    scores_all = np.empty(0)
    for round_ in range(rounds + 1):
        held = {k: np.full(len(pool[names[0]]), v) for k, v in fixed.items()}
        scores = candidate_returns(scenario, facts, {**pool, **held}, seasons, seed, terms, rule).mean(axis=1)
        everything = {k: np.concatenate([everything[k], pool[k]]) for k in names}
        scores_all = np.concatenate([scores_all, scores])
        order = np.argsort(scores_all)[::-1]
        best = [{k: float(everything[k][i]) for k in names} for i in order[:8]]
        history.append(float(scores_all[order[0]]))
        log(f"round {round_}: best mean return {scores_all[order[0]]:.4f} of {len(scores_all)} candidates")
        if round_ < rounds:
            pool = _perturb(rng, best, candidates, scale, box, never)
            scale *= family.shrink
    return {**({} if rule == "budget-rule" else {"rule": rule}), **({} if space == FULL else {"search_space": space}),
            "parameters": {**{k: getattr(family.defaults, k) for k in family.names}, **best[0], **fixed},
            "mean_return": history[-1],
            "history": history, "seasons": [int(s) for s in unique_seasons], "seed": seed,
            **({"term_draws": term_draws} if term_draws > 1 else {}), "scenario": scenario.name,
            "facts": family.facts_record(facts)}


def tuned_rule(task: str, rule: str = "budget-rule"):
    """The ``rule`` (a :data:`RULES` name) tuned for ``task``; FileNotFoundError says how to tune it."""
    path = family_file(task, rule)
    if not path.exists():
        raise FileNotFoundError(f"{path} is missing: run `crop-sim tune-rule --task {task}"
                                + ("" if rule == "budget-rule" else f" --rule {rule}") + "`")
    if rule == "budget-rule":
        return rule_from_record(json.loads(path.read_text()))
    try:
        return paced_rule_from_record(json.loads(path.read_text()))
    except (ValueError, KeyError, TypeError) as error:  # json's errors are ValueErrors
        raise ValueError(f"{path}: not a tuned {rule} file ({str(error).splitlines()[0]})") from None


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


def paced_rule_from_record(record: dict) -> PacedRule:
    """The paced rule of a record with ``facts`` and ``parameters`` (family_<task>-paced.json); ValueError for a
    missing, unknown or non-numeric entry."""
    if not isinstance(record, dict) or not isinstance(record.get("parameters"), dict):
        raise ValueError("expected an object with 'facts' and 'parameters'")
    names = set(PacedParameters.names())
    parameters = record["parameters"]
    if not names - set(PacedParameters.later()) <= set(parameters) <= names:
        raise ValueError(f"parameters must be exactly {', '.join(PacedParameters.names())} (a file tuned before "
                         f"{', '.join(PacedParameters.later())} existed may leave them out)")
    for key, value in parameters.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise ValueError(f"parameter {key} must be a finite number, got {value!r}")
    return PacedRule(PacedFacts.from_record(record.get("facts")), parameters, name="paced-rule")


def paced_rule_record(rule: PacedRule) -> dict:
    """A paced rule with scalar parameters as :func:`paced_rule_from_record` reads it: ``facts`` and
    ``parameters``."""
    return {"facts": rule.facts.record(), "parameters": {k: float(v) for k, v in rule.parameters.items()}}


def write_tuned(task: str, result: dict, rule: str = "budget-rule") -> Path:
    """Write :func:`tune_rule`'s ``result`` to :func:`family_file` (an infinite parameter as null)."""
    from crop_sim_ros.output import write_json_atomic
    return write_json_atomic(family_file(task, rule), {**result, "parameters": _json_parameters(result["parameters"])})


def add_arguments(parser) -> None:
    parser.add_argument("--task", required=True, help="a family task (e.g. benton-quota)")
    parser.add_argument("--rule", default="budget-rule", help=f"the rule family to tune: {', '.join(RULES)}")
    parser.add_argument("--seasons", default="0..149",
                        help="training seasons FIRST..LAST of the task's pool (of each part of a mixture)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the search, the terms and the noise")
    parser.add_argument("--candidates", type=int, default=128, help="candidates per round (1..10000)")
    parser.add_argument("--rounds", type=int, default=4, help="local-search rounds after the random one (0..50)")
    parser.add_argument("--space", default=FULL,
                        help="the rule's search space (paced-rule: " + ", ".join(PACED_SPACES) + "; default full)")
    parser.add_argument("--term-draws", type=int, default=1,
                        help="draws of the terms (quota, prices) per training season (1..20): the same seasons, "
                             "each met with K quotas")


def run(args) -> int:
    from crop_sim_ros.task.scenario import get_scenario
    from crop_sim_ros.usage import UsageError, check_range, user_input
    with user_input("--task"):
        scenario = get_scenario(args.task)
    if not scenario.is_family_task or scenario.weather.kind not in ("generator", "mixture"):
        raise UsageError(f"--task {args.task}: the rule is tuned on a family task's generated training seasons")
    with user_input(None, (ValueError,)):  # the messages name --seasons
        seasons = of_each_part(scenario, season_range(str(args.seasons)))
    check_range("--seed", args.seed, 0, MAX_SEED)
    if not (1 <= args.candidates <= 10_000 and 0 <= args.rounds <= 50):
        raise UsageError("--candidates must be in 1..10000 and --rounds in 0..50")
    term_draws = getattr(args, "term_draws", 1)
    check_range("--term-draws", term_draws, 1, 20)
    rule = getattr(args, "rule", "budget-rule")
    if rule not in RULES:
        raise UsageError(f"--rule: unknown rule {rule!r}; known: {', '.join(RULES)}")
    space = getattr(args, "space", FULL)
    try:
        RULES[rule].space(space)  # the one check of a space's name
    except ValueError as error:
        raise UsageError(str(error)) from None
    result = tune_rule(scenario, seasons, args.seed, args.candidates, args.rounds, rule=rule, term_draws=term_draws,
                       space=space)
    print(f"tuned {args.task} {rule}: {result['parameters']} mean return {result['mean_return']:.2f}; "
          f"wrote {write_tuned(args.task, result, rule)}")
    return 0
