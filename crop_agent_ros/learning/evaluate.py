"""``crop-sim evaluate``: run policies on held-out seasons with several observation-noise seeds.

For each policy, season and noise seed: return, normalized return (return / the season's potential yield:
no water stress, no water cost), yield t/ha, irrigation mm, water productivity (yield kg/ha per m3/ha of
irrigation + rain received from sowing to harvest; 1 mm = 10 m3/ha) and regret (the hindsight oracle's
return on the season minus the policy's). Prints a table, writes ``evaluation.csv`` (one row per run),
``evaluation.json`` (summary, paired comparisons, the oracle's search certificate) and one PNG per policy
of the first season with the first seed (biomass, PAW, rain and irrigation by day).

    crop-sim evaluate --policies zero,constant10,best-constant,refill,ppo,oracle --seasons heldout --seeds 0..9

Input is checked before any season runs: an unknown policy or scenario, a policy file that is missing,
corrupt or made for other spaces, bad seeds (at most MAX_SEEDS) or an output path that is a file are one
line on stderr and exit status 2.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from crop_sim_ros.output import output_directory, save_figure_atomic, write_csv_atomic, write_json_atomic
from crop_sim_ros.usage import UsageError, shown, user_input

DEFAULT_POLICIES = "zero,constant10,best-constant,refill,ppo,oracle"
# the hand-made baselines PPO must beat (margin<mm>, the PPO policy's own starting point, is reported apart)
RULES = ("zero", "constant10", "best-constant", "refill")
MAX_SEEDS = 10_000  # noise seeds of one evaluation (each runs every policy on every season)


def add_arguments(parser) -> None:
    parser.add_argument("--policies", default=DEFAULT_POLICIES,
                        help=f"comma-separated policy names (default {DEFAULT_POLICIES}); also constant<mm>, "
                             "ppo:<path.zip>")
    parser.add_argument("--seasons", default="heldout",
                        help="scenario whose seasons to run: a name or a YAML path (default heldout)")
    parser.add_argument("--seeds", default="0..9", help="observation-noise seeds: 'A..B' (inclusive) or 'a,b,c'")
    parser.add_argument("--ppo-path", default=None, help="policy file for 'ppo' (default: the shipped one)")
    parser.add_argument("--out", type=Path, default=None,
                        help="output directory (default runs/evaluate, or runs/eval-<task> with --task)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    from .evaluate_task import add_task_arguments
    add_task_arguments(parser)


def parse_seeds(text: str) -> list[int]:
    """'A..B' (inclusive, A <= B) or 'a,b,c': non-negative seeds, at most MAX_SEEDS; UsageError otherwise."""
    text = text.strip()
    try:
        if ".." in text:
            low, high = (int(part) for part in text.split("..", 1))
            if low > high:
                raise UsageError(f"--seeds: {shown(text)} runs backwards; write {high}..{low}")
            count = high - low + 1
            seeds = range(low, high + 1)
        else:
            seeds = [int(s) for s in text.split(",") if s.strip()]
            count = len(seeds)
    except ValueError as error:
        if isinstance(error, UsageError):
            raise
        raise UsageError(f"--seeds: {shown(text)} is neither 'A..B' nor a comma-separated list of whole "
                         "numbers") from None
    if count == 0:
        raise UsageError(f"--seeds: no seeds in {shown(text)}")
    if count > MAX_SEEDS:
        raise UsageError(f"--seeds: {count} seeds; at most {MAX_SEEDS}")
    if min(seeds) < 0:
        raise UsageError(f"--seeds: seeds are non-negative, got {min(seeds)}")
    return list(seeds)


def make_policies(names: list[str], ppo_path=None) -> dict:
    """The policies of ``names`` (make_policy's short names), built before any season runs; UsageError names a
    policy that is unknown, or whose file is missing or not a policy for this task."""
    from ..policies import make_policy
    if not names:
        raise UsageError("--policies: no policy named")
    policies = {}
    for name in names:
        with user_input(f"--policies {name}"):
            policies[name] = make_policy(name, ppo_path=ppo_path)
    return policies


def evaluate(policy_names: list[str], scenario_name: str, seeds: list[int], ppo_path=None, record: bool = True):
    """Run every policy; returns (rows, episodes by policy, oracle results, contexts)."""
    from ..policies.oracle import OraclePolicy
    from ..policies.rollout import run_episodes, scenario_of, season_contexts
    policies = make_policies(policy_names, ppo_path)
    scenario = scenario_of(scenario_name)
    print(f"evaluating {', '.join(policy_names)} on '{scenario.name}' with noise seeds {seeds[0]}..{seeds[-1]} "
          f"({len(seeds)} seeds)", file=sys.stderr)
    contexts = season_contexts(scenario)
    m = len(contexts)
    seasons = np.arange(m)
    oracle = policies.get("oracle") or OraclePolicy()
    oracle.begin_season(contexts)
    oracle_return = np.array([r.return_value for r in oracle.results])
    rows, episodes = [], {}
    for name in policy_names:
        policy = policies[name]
        started = time.perf_counter()
        runs = []
        for seed in seeds:
            ep = run_episodes(policy, scenario, seasons, seed=seed, record=record and seed == seeds[0],
                              contexts=contexts)
            runs.append(ep)
            for k in range(m):
                rows.append({
                    "policy": name, "season": contexts[k].name, "source": contexts[k].extra["source"],
                    "seed": seed, "return": ep.episode_return[k], "normalized_return": ep.normalized_return[k],
                    "yield_t_ha": ep.yield_t_ha[k], "irrigation_mm": ep.water_mm[k], "rain_mm": ep.rain_mm[k],
                    "water_productivity_kg_m3": ep.water_productivity_kg_m3[k],
                    "regret": oracle_return[k] - ep.episode_return[k],
                    "potential_yield_t_ha": ep.potential_yield_t_ha[k], "days": int(ep.days[k]),
                    "matured": bool(ep.matured[k])})
        episodes[name] = runs
        print(f"  {name}: {len(seeds)} seeds x {m} seasons in {time.perf_counter() - started:.1f} s",
              file=sys.stderr)
    return rows, episodes, oracle.results, contexts


METRICS = ("return", "normalized_return", "yield_t_ha", "irrigation_mm", "water_productivity_kg_m3", "regret")


def summarize(rows: list[dict]) -> dict:
    """Per policy: mean and std (over seasons x seeds) of each metric, and per-season mean return."""
    summary = {}
    for name in dict.fromkeys(r["policy"] for r in rows):
        mine = [r for r in rows if r["policy"] == name]
        entry = {"runs": len(mine)}
        for metric in METRICS:
            values = np.array([r[metric] for r in mine], dtype=float)
            entry[metric] = {"mean": float(values.mean()), "std": float(values.std())}
        entry["per_season_return"] = {s: float(np.mean([r["return"] for r in mine if r["season"] == s]))
                                      for s in dict.fromkeys(r["season"] for r in mine)}
        summary[name] = entry
    return summary


def paired_difference(rows: list[dict], a: str, b: str) -> dict | None:
    """Return of ``a`` minus ``b`` on the same season and seed: mean, standard error, wins."""
    key = {(r["season"], r["seed"]): r["return"] for r in rows if r["policy"] == b}
    diffs = np.array([r["return"] - key[(r["season"], r["seed"])] for r in rows
                      if r["policy"] == a and (r["season"], r["seed"]) in key])
    if diffs.size == 0:
        return None
    return {"mean": float(diffs.mean()), "stderr": float(diffs.std(ddof=1) / np.sqrt(diffs.size)) if diffs.size > 1
            else float("nan"), "n": int(diffs.size), "wins": int((diffs > 0).sum()), "ties": int((diffs == 0).sum())}


def format_table(summary: dict) -> str:
    header = (f"{'policy':<15}{'return':>17}{'normalized':>12}{'yield t/ha':>12}{'water mm':>10}"
              f"{'WP kg/m3':>10}{'regret':>17}")
    lines = [header, "-" * len(header)]
    for name, e in summary.items():
        lines.append(f"{name:<15}{e['return']['mean']:>9.4f} ±{e['return']['std']:<6.3f}"
                     f"{e['normalized_return']['mean']:>12.4f}{e['yield_t_ha']['mean']:>12.3f}"
                     f"{e['irrigation_mm']['mean']:>10.0f}{e['water_productivity_kg_m3']['mean']:>10.3f}"
                     f"{e['regret']['mean']:>9.4f} ±{e['regret']['std']:<6.4f}")
    lines.append("(mean ± std over seasons x noise seeds; the std is mostly the seasons' spread: see the paired "
                 "differences for rankings)")
    return "\n".join(lines)


def plot_policy(name: str, episodes, context, path: Path) -> None:
    """Biomass, PAW, rain and irrigation by day of the first field of ``episodes`` (a recorded run)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from crop_sim_ros.model.simple import WATER_UPTAKE_COEFFICIENT
    daily = episodes.daily
    days = int(episodes.days[0])
    t = np.arange(days)
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    axes[0].plot(t, daily["biomass_t_ha"][:days, 0], color="tab:green")
    axes[0].set_ylabel("biomass, t/ha")
    axes[0].set_title(f"{name} on {context.name} ({context.extra['source'].split('/')[-1]}): return "
                      f"{episodes.episode_return[0]:.3f}, yield {episodes.yield_t_ha[0]:.2f} t/ha, "
                      f"irrigation {episodes.water_mm[0]:.0f} mm", fontsize=9)
    axes[1].plot(t, daily["paw_mm"][:days, 0], color="tab:blue", label="PAW (true, start of day)")
    axes[1].plot(t, np.asarray(context.et0_mm[:days]) / WATER_UPTAKE_COEFFICIENT, color="tab:gray", lw=0.8,
                 label="ET0 / 0.096 (no-stress level)")
    axes[1].set_ylabel("mm")
    axes[1].legend(fontsize=8)
    axes[2].bar(t, daily["rain_mm"][:days, 0], color="tab:cyan", label="rain")
    axes[2].bar(t, daily["irrigation_mm"][:days, 0], bottom=daily["rain_mm"][:days, 0], color="tab:orange",
                label="irrigation")
    axes[2].set_ylabel("mm/day")
    axes[2].set_xlabel("days since sowing")
    axes[2].legend(fontsize=8)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


# the options of this evaluation (--policies ...); the others (but --out) are the family protocol's (--task)
POLICY_OPTIONS = ("policies", "seasons", "seeds", "ppo_path", "no_plots")


def _refuse_options_of_the_other_protocol(args) -> None:
    """UsageError naming an option given (not at its default) that the chosen evaluation would ignore: --seeds,
    --policies, ... with --task; --agents, --noise-seeds, ... without it."""
    import argparse
    parser = argparse.ArgumentParser(add_help=False)
    add_arguments(parser)
    defaults = vars(parser.parse_args([]))
    with_task = args.task is not None
    for dest, default in defaults.items():
        if dest in ("task", "out") or (dest in POLICY_OPTIONS) != with_task or getattr(args, dest) == default:
            continue
        flag = "--" + ("no-" if default is True else "") + dest.replace("_", "-")
        if with_task:
            raise UsageError(f"{flag}: not used with --task (the family protocol evaluates --agents with "
                             "--noise-seeds K on its own sets)")
        if dest in ("address", "cpus"):
            raise UsageError(f"{flag}: Ray runs the family protocol (--task TASK); this evaluation (--policies) runs "
                             "in this process")
        raise UsageError(f"{flag}: an option of the family protocol (--task TASK), not of this evaluation "
                         "(--policies)")


def run(args) -> int:
    _refuse_options_of_the_other_protocol(args)
    if args.task is not None:
        from .evaluate_task import run_task
        run_task(args)
        return 0
    if args.out is None:
        args.out = Path("runs/evaluate")
    from crop_sim_ros.simulate import find_scenario
    from crop_sim_ros.task.core import scenario_table
    names = [n.strip() for n in args.policies.split(",") if n.strip()]
    seeds = parse_seeds(args.seeds)
    with user_input("--seasons"):
        scenario = find_scenario(args.seasons)
        scenario_table(scenario)  # reads the weather now (a broken file is the user's); cached for the run
    out = output_directory(args.out)
    rows, episodes, oracle_results, contexts = evaluate(names, scenario, seeds, args.ppo_path,
                                                        record=not args.no_plots)
    summary = summarize(rows)
    comparisons = {}
    if "ppo" in summary:
        for other in [n for n in names if n not in ("ppo", "oracle")]:
            comparisons[f"ppo - {other}"] = paired_difference(rows, "ppo", other)
    rules_present = [n for n in names if n in RULES and n in summary]
    best_rule = max(rules_present, key=lambda n: summary[n]["return"]["mean"]) if rules_present else None
    print(format_table(summary))
    if best_rule:
        print(f"best rule of {', '.join(rules_present)}: {best_rule} "
              f"(regret {summary[best_rule]['regret']['mean']:.4f})")
        if "ppo" in summary:
            ratio = summary["ppo"]["regret"]["mean"] / max(summary[best_rule]["regret"]["mean"], 1e-12)
            print(f"ppo regret / best rule regret = {ratio:.2f}")
    for label, diff in comparisons.items():
        if diff:
            print(f"{label}: {diff['mean']:+.4f} ± {diff['stderr']:.4f} (s.e.) t/ha, wins {diff['wins']}/{diff['n']}")
    oracle_info = [{"season": c.name, "return": r.return_value, "potential_yield_t_ha": r.potential_yield_t_ha,
                    "bound_gap": r.bound_gap, "stress_free_gap": r.stress_free_gap,
                    "stress_free_water_floor_mm": r.stress_free_water_floor_mm, "last_refinement_gain": r.last_gain,
                    "refinement_gain_over_family": r.refinement_gain, "family": r.family_parameters,
                    "yield_t_ha": r.yield_t_ha, "irrigation_mm": r.water_mm, "evaluations": r.evaluations}
                   for c, r in zip(contexts, oracle_results)]
    write_csv_atomic(out / "evaluation.csv", list(rows[0]), rows)
    write_json_atomic(out / "evaluation.json", {
        "command": "crop-sim " + " ".join(sys.argv[1:]) if sys.argv and "crop" in sys.argv[0] else None,
        "policies": names, "scenario": args.seasons, "seeds": seeds, "ppo_path": args.ppo_path,
        "water_productivity": "yield kg/ha per m3/ha of irrigation + rain from sowing to harvest",
        "summary": summary, "best_rule": best_rule, "paired_differences": comparisons, "oracle": oracle_info},
        indent=2)
    if not args.no_plots:
        for name, runs in episodes.items():
            plot_policy(name, runs[0], contexts[0], out / f"{name.replace(':', '_').replace('/', '_')}.png")
    print(f"wrote {out}/evaluation.csv, evaluation.json" + ("" if args.no_plots else " and one PNG per policy"),
          file=sys.stderr)
    return 0
