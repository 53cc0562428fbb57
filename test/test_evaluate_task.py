"""The family tasks' evaluation protocol (crop_agent_ros.learning.evaluate_task): sets, paired runs, the
hierarchical bootstrap, the tables and plots. Tiny budgets: a PPO agent trained for 2,048 steps here, 2-season
generated sets, 2 noise seeds, 200 resamples."""

from __future__ import annotations

import argparse
import csv
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from crop_agent_ros.learning import evaluate_task as et
from crop_sim_ros.usage import UsageError
from policy_files import tiny_task_training

TASK = "benton-quota"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    et.add_arguments(parser)
    return parser.parse_args(argv)


@pytest.fixture(scope="module")
def rule_dir(tmp_path_factory):
    """The tuned-rule files live here (the package's family_<task>.json are never touched by the tests)."""
    from crop_agent_ros.policies import family_tuning
    directory = tmp_path_factory.mktemp("rules")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(family_tuning, "rule_file", lambda task: directory / f"family_{task}.json")
        yield directory


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory) -> Path:
    """One PPO run of the quota task, 2,048 steps, with its 1 % checkpoint and intermediate checkpoints."""
    out = tmp_path_factory.mktemp("runs") / f"{TASK}-ppo-s0"
    tiny_task_training(out, TASK, 0, timesteps=2048, net_arch=(16, 16), n_envs=8, batch_size=128, n_epochs=2,
                       eval_freq=1024, validation_seasons=4)
    return out


@pytest.fixture(scope="module")
def evaluation(rule_dir, trained_run, tmp_path_factory):
    """The protocol with the oracle on the held-out real seasons and a 2-season far generated set (a missing
    rule file: tuned now on 4 seasons)."""
    out = tmp_path_factory.mktemp("eval")
    args = parse(["--task", TASK, "--agents", f"ppo={trained_run.parent}/{TASK}-ppo-s*",
                  "--noise-seeds", "2", "--far-seasons", "2", "--sets", "heldout-real,far-benton",
                  "--bootstrap", "200", "--tune-seasons", "4", "--tune-candidates", "6", "--tune-rounds", "1",
                  "--out", str(out)])
    result = et.run_task(args)
    return out, result, trained_run


@pytest.fixture(scope="module")
def gap_evaluation(evaluation, trained_run, tmp_path_factory):
    """The 2-season far set without the oracle (after ``evaluation``, which tuned the rule)."""
    out = tmp_path_factory.mktemp("gap")
    args = parse(["--task", TASK, "--agents", f"ppo={trained_run}", "--no-oracle", "--no-curves",
                  "--noise-seeds", "2", "--far-seasons", "2", "--sets", "far-benton", "--bootstrap", "200",
                  "--out", str(out)])
    return out, et.run_task(args)


def rows_of(out: Path) -> list[dict]:
    with open(out / "table.csv", newline="") as f:
        return list(csv.DictReader(f))


# --- the end-to-end run ----------------------------------------------------------------------------------

def test_outputs_have_every_column_set_and_policy(evaluation):
    out, result, run = evaluation
    with open(out / "table.csv", newline="") as f:
        header = next(csv.reader(f))
    assert tuple(header) == et.CSV_COLUMNS
    rows = rows_of(out)
    assert [(r["set"], r["policy"], r["kind"]) for r in rows] == [
        (s, p, k) for s in ("heldout-real", "far-benton")
        for p, k in (("oracle", "oracle"), ("budget-rule", "rule"), ("ppo", "agent"),
                     ("ppo, 1 % checkpoint", "early"))]
    by_set = {s["name"]: s for s in result["sets"]}
    assert len(by_set["heldout-real"]["seasons"]) == 5 and len(by_set["far-benton"]["seasons"]) == 2
    for r in rows:
        assert r["noise_seeds"] == "2" and r["reference"] == "oracle"
        for column in ("return_usd_ha", "regret_usd_ha", "regret_pct_of_reference", "paired_wins"):
            assert np.isfinite(float(r[column])), (r["policy"], column)
        if r["kind"] in ("agent", "early"):
            assert np.isfinite(float(r["ratio_ci_low"])) and r["note"]
    md = (out / "table.md").read_text()
    assert md.count("| policy | return | regret [95 % CI] | regret % of oracle | ratio to rule [95 % CI] | "
                    "paired wins | note |") == 2
    assert "## heldout-real" in md and "## far-benton" in md and "gap" not in md
    for name in ("regret.png", "learning_curves.png"):
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
    saved = json.loads((out / "table.json").read_text())
    assert saved["seeds"] == {"far_weather_seed": 900_001, "terms_seed_base": et.TERMS_SEED, "noise_seeds": [0, 1],
                              "bootstrap_seed": 0, "bootstrap_resamples": 200, "oracle_noise_seed": 0}
    assert saved["versions"]["numpy"] == np.__version__ and saved["versions"]["stable-baselines3"]
    assert saved["agents"]["ppo"][0]["directory"] == str(run)
    assert saved["arguments"]["sets"] == "heldout-real,far-benton" and saved["command"].startswith("crop-sim")


def test_missing_rule_file_is_tuned_on_training_seasons_and_written(evaluation, rule_dir):
    out, result, _ = evaluation
    path = rule_dir / f"family_{TASK}.json"
    assert result["rule"] == {**result["rule"], "file": str(path), "tuned_now": True, "tuned_on_seasons": [0, 1, 2, 3]}
    tuned = json.loads(path.read_text())
    assert tuned["scenario"] == TASK and tuned["seasons"] == [0, 1, 2, 3]
    assert {k: v for k, v in result["rule"].items() if k in tuned["parameters"]} == {
        k: (np.inf if v is None else v) for k, v in tuned["parameters"].items()}
    assert "(tuned by this run)" in (out / "table.md").read_text()


def test_every_policy_met_the_same_terms_and_noise_seeds(evaluation, rule_dir):
    """Rerun each policy on the saved terms with noise seeds 0 and 1: the saved returns, bit for bit."""
    from crop_agent_ros.policies.learned import LearnedPolicy
    from crop_agent_ros.policies.family_tuning import tuned_rule
    from crop_agent_ros.policies.rollout import run_episodes
    from crop_sim_ros.task.scenario import get_scenario, with_weather_of
    _, result, run = evaluation
    saved = {s["name"]: s for s in result["sets"]}["far-benton"]
    weather = get_scenario("benton-generated")
    far = with_weather_of(get_scenario(TASK), replace(weather, weather=replace(weather.weather, seed=900_001,
                                                                               n_seasons=2)))
    terms = {k: np.array(v) for k, v in saved["terms"].items()}
    assert len(set(terms["quota_mm"])) == 2 and all(150 <= q <= 450 for q in terms["quota_mm"])
    for name, policy in (("budget-rule", tuned_rule(TASK)), ("ppo", LearnedPolicy(run / "model.zip")),
                         ("ppo, 1 % checkpoint", LearnedPolicy(run / "early_model.zip"))):
        again = np.stack([run_episodes(policy, far, [0, 1], seed=seed, terms=terms).episode_return
                          for seed in (0, 1)], axis=1)
        np.testing.assert_array_equal(np.array(saved["returns_usd_ha"][name]), again[None], err_msg=name)


def test_regret_is_to_the_oracle_and_cis_contain_their_means(evaluation):
    _, result, _ = evaluation
    for s in result["sets"]:
        oracle = np.array(s["oracle_returns_usd_ha"])
        # the environment paid each plan what the oracle planned (its schedules are feasible as planned)
        planned = np.array([plan["planned_return_usd_ha"] for plan in s["oracle_plans"]])
        np.testing.assert_allclose(oracle, planned, rtol=1e-9)
        returns = {name: np.array(values) for name, values in s["returns_usd_ha"].items()}
        np.testing.assert_array_equal(returns["oracle"], np.broadcast_to(oracle[None, :, None], (1, len(oracle), 2)))
        for row in s["rows"]:
            regret = oracle[None, :, None] - returns[row["policy"]]
            assert row["regret_usd_ha"] == pytest.approx(regret.mean(), rel=1e-12, abs=1e-9)
            assert row["regret_pct_of_reference"] == pytest.approx(100 * regret.mean() / oracle.mean(), rel=1e-12,
                                                                   abs=1e-12)
            assert row["return_usd_ha"] == pytest.approx(returns[row["policy"]].mean(), rel=1e-12)
            for prefix, mean in (("return", row["return_usd_ha"]), ("regret", row["regret_usd_ha"]),
                                 ("regret_pct", row["regret_pct_of_reference"])):
                low, high = row[f"{prefix}_ci_low"], row[f"{prefix}_ci_high"]
                assert low - 1e-9 <= mean <= high + 1e-9, (row["policy"], prefix)
            if row["kind"] in ("agent", "early"):
                assert row["ratio_ci_low"] <= row["ratio_to_rule"] <= row["ratio_ci_high"]
            wins = np.mean(returns[row["policy"]] > returns["budget-rule"][None])
            assert row["paired_wins"] == pytest.approx(wins)
        rule = next(r for r in s["rows"] if r["kind"] == "rule")
        assert f"regret {rule['regret_pct_of_reference']:.1f} % of the oracle's return" in rule["note"]
        assert next(r for r in s["rows"] if r["kind"] == "oracle")["regret_usd_ha"] == 0.0


def test_without_the_oracle_every_output_says_gap_not_regret(gap_evaluation):
    out, result = gap_evaluation
    assert result["regret"].startswith("NO ORACLE") and json.loads((out / "table.json").read_text())["sets"][0][
        "oracle_returns_usd_ha"] is None
    md = (out / "table.md").read_text()
    assert "not a regret" in md and "| gap to best [95 % CI] | gap to best % of best |" in md
    assert "regret [95 % CI]" not in md and not (out / "learning_curves.png").exists()
    returns = {name: np.array(v) for name, v in result["sets"][0]["returns_usd_ha"].items()}
    assert sorted(returns) == ["budget-rule", "ppo", "ppo, 1 % checkpoint"]
    best = np.max([r.max(axis=0) for r in returns.values()], axis=0)       # (seasons, noise seeds)
    for row in result["sets"][0]["rows"]:
        assert row["reference"] == "best evaluated policy (gap, not regret)"
        assert row["regret_usd_ha"] == pytest.approx((best[None] - returns[row["policy"]]).mean(), rel=1e-12, abs=1e-9)


def test_a_set_evaluated_alone_has_the_terms_and_returns_it_has_beside_others(evaluation, gap_evaluation):
    # far-benton is second in the protocol: alone (--sets far-benton) its terms keep that position's seed
    beside = next(s for s in evaluation[1]["sets"] if s["name"] == "far-benton")
    alone = gap_evaluation[1]["sets"][0]
    assert alone["name"] == "far-benton" and alone["terms_seed"] == beside["terms_seed"] == et.TERMS_SEED + 1
    assert alone["terms"] == beside["terms"]
    for policy in ("budget-rule", "ppo", "ppo, 1 % checkpoint"):
        assert alone["returns_usd_ha"][policy] == beside["returns_usd_ha"][policy], policy


def test_learning_curves_read_every_checkpoint_of_the_run(evaluation):
    out, result, run = evaluation
    saved = sorted({json.loads(p.read_text())["timesteps_at_save"] for p in run.glob("*.json")
                    if "timesteps_at_save" in json.loads(p.read_text())})
    with open(out / "learning_curves.csv", newline="") as f:
        curve = list(csv.DictReader(f))
    assert [int(c["timesteps"]) for c in curve] == saved
    assert len(saved) >= 3 and saved[-1] == 2048
    final = next(c for c in curve if c["checkpoint"] == "model.zip")
    heldout = next(r for r in rows_of(out) if r["set"] == "heldout-real" and r["policy"] == "ppo")
    assert float(final["regret_usd_ha"]) == pytest.approx(float(heldout["regret_usd_ha"]), rel=1e-12)


# --- statistics on arrays whose answers are known ---------------------------------------------------------

def _synthetic(agent_returns: np.ndarray, rule_returns: np.ndarray, reference: np.ndarray, early=None, seed=3,
               resamples=200):
    runs = agent_returns.shape[0]
    evaluated = [et.Evaluated("rule", "rule", rule_returns[None]),
                 et.Evaluated("agent", "agent", agent_returns, "agent", (100,) * runs, tuple(range(runs)),
                              partner=None if early is None else "agent-early")]
    if early is not None:
        evaluated.append(et.Evaluated("agent-early", "early", early, "agent", (1,) * runs, tuple(range(runs))))
    boot = et.Resamples.draw(seed, 0, reference.shape[0], reference.shape[1], {"agent": runs}, resamples)
    return et.compare(evaluated, reference, boot, with_oracle=True), boot


def _by_hand_mean(values: np.ndarray, runs, seasons, noise) -> float:
    """The mean over the resampled grid, written as loops over the drawn index lists."""
    r_idx, m_idx, k_idx = (np.repeat(np.arange(len(c)), c) for c in (runs, seasons, noise))
    total = sum(values[r, m, k] for r in r_idx for m in m_idx for k in k_idx)
    return total / (len(r_idx) * len(m_idx) * len(k_idx))


def test_ratio_ci_comes_from_paired_hierarchical_resamples():
    rng = np.random.default_rng(11)
    reference = rng.uniform(9000, 11000, (4, 3))                         # seasons x noise seeds
    difficulty = rng.uniform(100, 2000, (4, 1))                          # hard seasons cost every policy
    rule = reference - difficulty * rng.uniform(0.9, 1.1, (4, 3))
    agent = reference[None] - 0.5 * difficulty * rng.uniform(0.8, 1.2, (3, 4, 3))   # 3 training seeds
    rows, boot = _synthetic(agent, rule, reference)
    assert boot.seasons.sum(axis=1).tolist() == [4] * 200 and boot.noise.sum(axis=1).tolist() == [3] * 200
    assert boot.runs["agent"].sum(axis=1).tolist() == [3] * 200
    # resamples differ (with replacement), and the same counts serve every policy of the set
    assert len({tuple(c) for c in boot.seasons}) > 20
    ratios = []
    for b in range(200):
        agent_mean = _by_hand_mean(reference[None] - agent, boot.runs["agent"][b], boot.seasons[b], boot.noise[b])
        rule_mean = _by_hand_mean((reference - rule)[None], [1], boot.seasons[b], boot.noise[b])
        ratios.append(agent_mean / rule_mean)
        if b == 0:
            assert boot.means(reference[None] - agent, "agent")[0] == pytest.approx(agent_mean, rel=1e-12)
    row = next(r for r in rows if r["policy"] == "agent")
    low, high = np.percentile(ratios, [2.5, 97.5])
    assert (row["ratio_ci_low"], row["ratio_ci_high"]) == pytest.approx((low, high), rel=1e-12)
    assert row["ratio_to_rule"] == pytest.approx((reference[None] - agent).mean() / (reference - rule).mean())
    # unpaired resamples (agent and rule each on their own seasons) would give a much wider interval
    other = et.Resamples.draw(4, 0, 4, 3, {"agent": 3}, 200)
    unpaired = boot.means(reference[None] - agent, "agent") / other.means((reference - rule)[None])
    assert np.percentile(unpaired, 97.5) - np.percentile(unpaired, 2.5) > 3 * (high - low)


def test_a_policy_against_itself_has_ratio_one_and_no_wins():
    rng = np.random.default_rng(5)
    reference = rng.uniform(9000, 11000, (5, 2))
    rule = reference - rng.uniform(100, 900, (5, 2))
    rows, _ = _synthetic(rule[None].copy(), rule, reference)
    row = next(r for r in rows if r["policy"] == "agent")
    assert (row["ratio_to_rule"], row["ratio_ci_low"], row["ratio_ci_high"]) == pytest.approx((1.0, 1.0, 1.0))
    assert row["paired_wins"] == 0.0 and row["paired_ties"] == 1.0
    assert row["beats_rule"] is False and "no better than the rule" in row["note"]


def test_note_says_beats_the_rule_only_when_the_ratio_ci_is_below_one():
    rng = np.random.default_rng(8)
    reference = rng.uniform(9000, 11000, (6, 2))
    rule = reference - rng.uniform(400, 600, (6, 2))
    better = reference[None] - rng.uniform(100, 200, (2, 6, 2))       # a third of the rule's regret
    worse = reference[None] - rng.uniform(500, 700, (2, 6, 2))
    good = next(r for r in _synthetic(better, rule, reference)[0] if r["policy"] == "agent")
    bad = next(r for r in _synthetic(worse, rule, reference)[0] if r["policy"] == "agent")
    assert good["ratio_ci_high"] < 1 and good["beats_rule"] is True and "beats the rule" in good["note"]
    assert good["paired_wins"] == 1.0
    assert bad["ratio_ci_low"] > 1 and bad["beats_rule"] is False and "no better than the rule" in bad["note"]


def test_final_over_early_ratio_and_the_learning_criterion():
    rng = np.random.default_rng(9)
    reference = rng.uniform(9000, 11000, (4, 2))
    rule = reference - 500.0
    early = reference[None] - rng.uniform(1500, 2500, (3, 4, 2))
    final = reference[None] - rng.uniform(300, 700, (3, 4, 2))
    rows, boot = _synthetic(final, rule, reference, early=early)
    row = next(r for r in rows if r["policy"] == "agent")
    expected = (reference[None] - final).mean() / (reference[None] - early).mean()
    assert row["final_over_early"] == pytest.approx(expected, rel=1e-12)
    assert row["final_over_early_ci_low"] <= expected <= row["final_over_early_ci_high"] < 0.5
    assert row["learning_is_real"] is True and "learning is real" in row["note"]
    # the same resampled training seeds for the final and early models: swap them and the ratio inverts
    swapped = next(r for r in _synthetic(early, rule, reference, early=final)[0] if r["policy"] == "agent")
    assert swapped["final_over_early"] == pytest.approx(1 / expected, rel=1e-12)
    assert swapped["learning_is_real"] is False and "NOT <= 0.5" in swapped["note"]


def test_headroom_note_of_the_rule():
    reference = np.full((3, 2), 10_000.0)
    rows, _ = _synthetic(reference[None] - 100.0, reference - 300.0, reference)
    assert "regret 3.0 % of the oracle's return (>= 2 %)" in rows[0]["note"]
    rows, _ = _synthetic(reference[None] - 100.0, reference - 150.0, reference)
    assert "regret 1.5 % of the oracle's return (NOT >= 2 %)" in rows[0]["note"]


# --- sets and input ---------------------------------------------------------------------------------------

def test_evaluation_sets_carry_the_task_terms_to_other_weather():
    from crop_sim_ros.task.scenario import get_scenario
    task = get_scenario(TASK)
    sets = et.evaluation_sets(task, far_seasons=3)
    late = ["maricopa-late-generated", "maricopa-late-real", "maricopa-march15-generated"]
    assert [s.name for s in sets] == ["heldout-real", "far-benton", "maricopa-generated", "maricopa-real"] + late
    for s in sets:
        assert s.scenario.economics == task.economics and s.scenario.limits == task.limits
        assert s.scenario.noise == task.noise and len(s.seasons) == s.scenario.n_seasons
    far, maricopa = sets[1].scenario.weather, sets[2].scenario.weather
    assert (far.generator, far.seed, far.n_seasons) == ("benton", 900_001, 3)
    assert (maricopa.generator, maricopa.seed) == ("maricopa", 900_001)
    assert [len(s.seasons) for s in sets] == [5, 3, 3, 3, 3, 3, 3]
    assert "transfer test: trained on benton weather only" in sets[2].role and "transfer" in sets[3].role
    # the held-out climate sown late: its own pool's seed + the far seed's offset, so no January draw repeats
    late_generated, late_real = sets[4].scenario, sets[5].scenario
    assert (late_generated.weather.generator, late_generated.weather.seed) == ("maricopa", 900_002)
    assert str(late_generated.sowing_date) == "2001-02-28" and "sown February 28" in sets[4].role
    assert [str(f.sowing_date) for f in late_real.weather.seasons] == ["2007-02-28", "2008-02-28", "2009-02-28"]
    assert late_real.economics == task.economics and "transfer" in sets[5].role
    # the blind check, sown later still: its own pool's seed + the far seed's offset
    blind = sets[6].scenario
    assert (blind.weather.generator, blind.weather.seed, str(blind.sowing_date)) == ("maricopa", 900_003, "2001-03-15")
    assert "sown March 15, a blind check" in sets[6].role and blind.economics == task.economics
    climates = et.evaluation_sets(get_scenario("climates-quota"), far_seasons=2)
    assert [s.name for s in climates] == ["heldout-real", "far-benton", "far-gainesville", "maricopa-generated",
                                          "maricopa-real"] + late
    assert climates[2].scenario.weather.generator == "gainesville" and "held-out climate" in climates[3].role
    assert climates[2].scenario.sowing_date == get_scenario("gainesville-generated").sowing_date
    assert "held-out climate, sown February 28" in climates[5].role
    # a third part on Benton's generator, sown March 1: its far set comes after the January held-out climate, so
    # those keep climates-quota's positions (hence their drawn terms) and their weather
    three = et.evaluation_sets(get_scenario("climates3-quota"), far_seasons=2)
    assert [s.name for s in three] == [s.name for s in climates[:5]] + ["far-benton-early"] + late
    for a, b in zip(climates[:5], three):
        assert (a.scenario.weather, a.scenario.sowing_date) == (b.scenario.weather, b.scenario.sowing_date)
    early = three[5]
    assert (early.scenario.weather.generator, early.scenario.weather.seed, str(early.scenario.sowing_date)) == \
        ("benton", 900_001, "2000-03-01")
    assert "sown March 1" in early.role and early.scenario.name == "climates3-quota@benton-early-generated-seed900001"
    # a far set's role names each delta-change of its part, the diurnal range and radiation factor too
    quota = get_scenario(TASK)
    desert_task = replace(quota, name="desert-quota", sowing_date=None, weather=replace(
        quota.weather, kind="mixture", mixture=("benton-generated", "benton-hot-arid-wide-sunny-generated")))
    desert = {s.name: s for s in et.evaluation_sets(desert_task, far_seasons=2)}["far-benton-hot-arid-wide-sunny"]
    assert ("sown April 1, +4 degC, diurnal range +4 degC, dew-point depression +8 degC, radiation x 1.25, "
            "rain x 0.3, seed 900001") in desert.role


def test_resample_counts_draw_with_replacement():
    counts = et.resample_counts(np.random.default_rng(0), 7, 1000)
    assert counts.shape == (1000, 7) and (counts.sum(axis=1) == 7).all()
    # each unit is drawn 1 time per resample on average, and some resamples leave units out
    assert counts.mean() == pytest.approx(1.0, abs=0.05) and (counts == 0).any(axis=1).mean() > 0.9


@pytest.mark.parametrize("argv, message", [
    (["--task", "nowhere"], "--task: unknown scenario 'nowhere'"),
    (["--task", "benton-generated"], "not a family task"),
    (["--task", TASK, "--agents", "ppo"], "is not NAME=GLOB"),
    (["--task", TASK, "--agents", "ppo=/nonexistent/run-*"], "no run directory matches"),
    (["--task", TASK, "--noise-seeds", "0"], "--noise-seeds: 0 is not in"),
    (["--task", TASK, "--sets", "heldout-real,moon"], "--sets: moon unknown"),
])
def test_bad_input_is_one_clear_usage_error(argv, message, tmp_path):
    with pytest.raises(UsageError, match=message.replace("(", r"\(")):
        et.run_task(parse(argv + ["--no-oracle", "--out", str(tmp_path / "out")]))
    assert not (tmp_path / "out").exists()


def test_runs_of_another_task_or_repeated_seeds_are_refused(trained_run, tmp_path):
    other = tmp_path / "other-s0"
    shutil.copytree(trained_run, other)
    config = json.loads((other / "model.json").read_text())
    (other / "model.json").write_text(json.dumps({**config, "task": "benton-money"}))
    with pytest.raises(UsageError, match="trained on 'benton-money', not 'benton-quota'"):
        et.agent_runs([f"ppo={other}"], TASK)
    for name in ("a-s0", "b-s0"):
        shutil.copytree(trained_run, tmp_path / name)
    with pytest.raises(UsageError, match=r"training seeds \[0, 0\] repeat"):
        et.agent_runs([f"ppo={tmp_path}/[ab]-s0"], TASK)


def test_crop_sim_evaluate_task_runs_from_the_command_line(evaluation, trained_run, tmp_path):
    """``crop-sim evaluate --task`` reaches the protocol and exits 0 (after ``evaluation`` tuned the rule)."""
    from crop_agent_ros.cli import main
    out = tmp_path / "cli"
    status = main(["evaluate", "--task", TASK, "--agents", f"ppo={trained_run}", "--no-oracle", "--no-curves",
                   "--noise-seeds", "1", "--far-seasons", "2", "--sets", "far-benton", "--bootstrap", "100",
                   "--out", str(out)])
    assert status == 0
    assert {r["policy"] for r in rows_of(out)} >= {"budget-rule", "ppo"}


def test_the_oracle_cache_gives_the_same_tables_and_misses_on_other_terms(evaluation, trained_run, tmp_path):
    first_out, _, _ = evaluation
    cache = tmp_path / "cache"
    common = ["--task", TASK, "--agents", f"ppo={trained_run}", "--noise-seeds", "2", "--far-seasons", "2",
              "--sets", "heldout-real,far-benton", "--bootstrap", "200", "--oracle-cache", str(cache)]
    filled = et.run_task(parse([*common, "--out", str(tmp_path / "a")]))
    assert len(list(cache.glob("*.json"))) == 2      # heldout-real (5 seasons) and far-benton (2): one chunk each
    reused = et.run_task(parse([*common, "--out", str(tmp_path / "b")]))
    oracle_units = [u for u in reused["execution"]["unit_log"] if u["policy"] == "oracle"]
    assert [u["node"] for u in oracle_units] == ["oracle cache"] * 2
    assert [u["node"] for u in filled["execution"]["unit_log"] if u["policy"] == "oracle"] == ["this process"] * 2
    # the same tables as each other and as the fixture's run without a cache
    assert (tmp_path / "a" / "table.csv").read_bytes() == (tmp_path / "b" / "table.csv").read_bytes()
    assert [s["oracle_returns_usd_ha"] for s in reused["sets"]] == [s["oracle_returns_usd_ha"] for s in filled["sets"]]
    assert [s["oracle_plans"] for s in reused["sets"]] == [s["oracle_plans"] for s in filled["sets"]]
    assert [r for r in rows_of(tmp_path / "b") if r["kind"] == "oracle"] == [
        r for r in rows_of(first_out) if r["kind"] == "oracle"]
    # other terms are other plans: nothing found
    other = et.run_task(parse([*common, "--terms-seed", "7", "--no-curves", "--out", str(tmp_path / "c")]))
    assert [u["node"] for u in other["execution"]["unit_log"] if u["policy"] == "oracle"] == ["this process"] * 2
    assert len(list(cache.glob("*.json"))) == 4


@pytest.mark.parametrize("arguments, message", [
    (["--seasons", "5..1"], "crop-sim tune-rule: --seasons: '5..1' names no season"),
    (["--seasons", "0..1000"], "crop-sim tune-rule: --seasons: must lie within 0..999 (of each part of a mixture)"),
    (["--seasons", "0..2", "--candidates", "0"], "crop-sim tune-rule: --candidates must be in 1..10000"),
])
def test_tune_rule_refuses_bad_seasons_with_one_line(arguments, message, capsys):
    from crop_agent_ros.cli import main
    assert main(["tune-rule", "--task", "climates-quota", *arguments]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(message), err


def test_ratios_are_against_the_strongest_rule_of_the_set():
    """Two rule rows: the agent's ratio and paired wins are against the one with the lower regret on the set,
    every row names it, and the other rule's note calls it a weaker baseline."""
    rng = np.random.default_rng(9)
    reference = rng.uniform(9000, 11000, (6, 2))
    weak = reference - rng.uniform(400, 600, (6, 2))
    strong = reference - rng.uniform(100, 200, (6, 2))
    agent = reference[None] - rng.uniform(150, 250, (2, 6, 2))
    for rules in ((weak, strong), (strong, weak)):   # the order of the rows does not matter
        evaluated = [et.Evaluated(name, "rule", returns[None]) for name, returns in zip(("first", "second"), rules)]
        evaluated.append(et.Evaluated("agent", "agent", agent, "agent", (100, 100), (0, 1)))
        boot = et.Resamples.draw(3, 0, 6, 2, {"agent": 2}, 200)
        rows = {r["policy"]: r for r in et.compare(evaluated, reference, boot, with_oracle=True)}
        strongest = "second" if rules[1] is strong else "first"
        weaker = "first" if strongest == "second" else "second"
        assert {r["reference_rule"] for r in rows.values()} == {strongest}
        assert rows["agent"]["ratio_to_rule"] == pytest.approx((reference[None] - agent).mean()
                                                               / (reference - strong).mean())
        assert rows["agent"]["paired_wins"] == pytest.approx(np.mean(agent > strong[None]))
        assert "the strongest rule of this set" in rows[strongest]["note"]
        assert "a weaker baseline" in rows[weaker]["note"]
