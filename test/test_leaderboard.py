"""The generated leaderboard: evaluation summaries (crop_agent_ros.learning.summary) and ``crop-sim leaderboard``
(crop_agent_ros.leaderboard). The committed page must be what the command writes from the committed summaries;
every check on a changed tree runs on a copy under tmp_path."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml

from crop_agent_ros import leaderboard as lb
from crop_agent_ros.cli import main
from crop_agent_ros.learning.summary import PLANNER_KIND, dumps, seed_command, summary, write_summary

ROOT = Path(__file__).resolve().parents[1]


# --- a small synthetic evaluation ------------------------------------------------------------------------

def _row(policy, kind, group="", seeds="", timesteps="", ret=0.0, regret=0.0, ci=(0.0, 0.0), pct=0.0,
         ratio=0.0, ratio_ci=(0.0, 0.0), wins=0.0, final=None, final_ci=(None, None)):
    return {"set": "heldout-real", "role": "held-out real seasons", "policy": policy, "kind": kind, "group": group,
            "runs": 2 if group else 1, "training_seeds": seeds, "seasons": 2, "noise_seeds": 3,
            "timesteps": timesteps, "reference": "oracle", "return_usd_ha": ret, "return_ci_low": ret - 900,
            "return_ci_high": ret + 900, "regret_usd_ha": regret, "regret_ci_low": ci[0], "regret_ci_high": ci[1],
            "regret_pct_of_reference": pct, "regret_pct_ci_low": 0.0, "regret_pct_ci_high": 0.0,
            "ratio_to_rule": ratio, "ratio_ci_low": ratio_ci[0], "ratio_ci_high": ratio_ci[1], "paired_wins": wins,
            "paired_ties": 0.0, "above_reference": 0.0, "final_over_early": final,
            "final_over_early_ci_low": final_ci[0], "final_over_early_ci_high": final_ci[1], "beats_rule": "",
            "learning_is_real": "", "note": "a note the summary drops"}


def synthetic_table(task: str = "benton-quota") -> dict:
    """A table.json of one set (2 seasons x 3 noise seeds), the oracle, the rule and one ES group of two runs
    with its 1 % checkpoint, in the layout crop-sim evaluate --task writes."""
    rows = [
        _row("oracle", "oracle", ret=16160.307639552719, ratio=0.0, wins=1.0),
        _row("budget-rule", "rule", ret=15736.77, regret=423.5358066957, ci=(342.94, 518.249), pct=2.62083999,
             ratio=1.0, ratio_ci=(1.0, 1.0)),
        _row("es", "agent", "es", "0 1", "140229541 110202700", ret=15973.869, regret=186.43861635252043,
             ci=(103.1499, 274.2501), pct=1.1536823463447423, ratio=0.4401956420332717,
             ratio_ci=(0.23493836481273928, 0.6716), wins=0.984, final=0.42036929164769304,
             final_ci=(0.1982578505729955, 0.78512)),
        _row("es, 1 % checkpoint", "early", "es", "0 1", "1863654 1871497", ret=15717.0, regret=443.5, ci=(297, 591),
             pct=2.74, ratio=1.047, ratio_ci=(0.72, 1.44), wins=0.344),
    ]
    return {
        "task": task,
        "command": f"crop-sim evaluate --task {task} --agents es=runs/{task}-es-s*",
        "arguments": {"noise_seeds": 3},
        "regret": "oracle return - policy return, USD/ha",
        "seeds": {"far_weather_seed": 900001, "terms_seed_base": 4049, "noise_seeds": [0, 1, 2], "bootstrap_seed": 0,
                  "bootstrap_resamples": 2000, "oracle_noise_seed": 0},
        "rule": {"file": f"/somewhere/family_{task}.json", "tuned_now": False, "name": "budget-rule",
                 "level_factor": 0.8699662333760666, "pace": None},
        "agents": {"es": [{"directory": f"runs/{task}-es-s{seed}", "training_seed": seed,
                           "checkpoints": [[0, f"runs/{task}-es-s{seed}/checkpoint_000000000.zip"]]} for seed in (0, 1)]},
        "sets": [{"name": "heldout-real", "role": "held-out real seasons", "scenario": f"{task}@heldout",
                  "seasons": [0, 1], "season_sources": ["a.csv", "b.csv"], "terms_seed": 4049,
                  "terms": {"quota_mm": [260.5, 414.8]}, "oracle_returns_usd_ha": [18792.0, 13528.6],
                  "oracle_plans": [{}, {}], "reference": "oracle", "returns_usd_ha": {"oracle": [[[1.0]]]},
                  "returns_shape": "training runs x seasons x noise seeds", "rows": rows, "units_s": 8.0}],
        "learning_curves": [{"group": "es", "timesteps": 0, "regret_usd_ha": 4803.2}],
        "versions": {"python": "3.11.7", "numpy": "2.4.6"},
        "wall_s": {"setup_s": 8.06, "units_s": 225.6, "total_s": 233.94},
        "execution": {"units": 657, "unit_log": [{"seconds": 5.94}]},
    }


def run_records(task: str = "benton-quota") -> dict[str, dict]:
    """The summary.json of each synthetic run, by directory (as crop-sim train --task writes them)."""
    return {f"runs/{task}-es-s{seed}": {
        "algorithm": "es", "seed": seed, "steps_run": 170_000_000 + seed, "training_wall_s": 500.0 + seed,
        "total_wall_s": 510.04 + seed,
        "command": f"crop-sim train --task {task} --algorithm es --seed {seed} --out runs/{task}-es-s{seed} "
                   "--no-progress --timesteps 170000000"} for seed in (0, 1)}


def test_summary_keeps_the_leaderboard_numbers_rounded_and_drops_the_rest():
    result = summary(synthetic_table(), run_records())
    assert result["task"] == "benton-quota" and result["format"] == 1
    assert result["command"] == "crop-sim evaluate --task benton-quota --agents es=runs/benton-quota-es-s*"
    assert result["rule"] == {"name": "budget-rule", "file": "family_benton-quota.json", "tuned_now": False,
                              "parameters": {"level_factor": 0.869966, "pace": None}}
    (evaluation_set,) = result["sets"]
    assert {key: evaluation_set[key] for key in ("name", "seasons", "noise_seeds", "terms_seed",
                                                 "oracle_return_usd_ha")} == {
        "name": "heldout-real", "seasons": 2, "noise_seeds": 3, "terms_seed": 4049, "oracle_return_usd_ha": 16160.3}
    rule, agent = evaluation_set["rows"]  # the oracle is the set's return; the 1 % checkpoint row is dropped
    assert rule == {"policy": "budget-rule", "kind": "rule", "return_usd_ha": 15736.8, "regret_usd_ha": 423.5,
                    "regret_ci_usd_ha": [342.9, 518.2], "regret_pct_of_reference": 2.621}
    assert agent == {"policy": "es", "kind": "agent", "return_usd_ha": 15973.9, "regret_usd_ha": 186.4,
                     "regret_ci_usd_ha": [103.1, 274.3], "regret_pct_of_reference": 1.154, "group": "es",
                     "training_seeds": [0, 1], "ratio_to_rule": 0.44, "ratio_to_rule_ci": [0.235, 0.672],
                     "paired_wins": 0.984, "final_over_1pct": 0.42, "final_over_1pct_ci": [0.198, 0.785]}
    assert result["training"] == {"es": {
        "algorithm": "es", "seeds": [0, 1], "timesteps_selected": [140229541, 110202700],
        "steps_run": [170000000, 170000001], "wall_s": [510.0, 511.0],
        "commands": ["crop-sim train --task benton-quota --algorithm es --seed {seed} --timesteps 170000000"]}}
    assert result["evaluation_wall_s"] == 233.9
    text = dumps(result)
    assert json.loads(text) == result
    for dropped in ("learning_curves", "execution", "unit_log", "oracle_plans", "season_sources", "note"):
        assert dropped not in text


def test_summary_without_run_records_has_no_training_cost():
    training = summary(synthetic_table())["training"]["es"]
    assert training["steps_run"] is None and training["wall_s"] is None and training["commands"] == []
    assert training["timesteps_selected"] == [140229541, 110202700]


def test_seed_command_puts_the_seed_placeholder_and_drops_run_only_flags():
    assert (seed_command("crop-sim train --task t --seed 3 --out 'runs/a b-s3' --no-progress --imitate 'd/*.npz'", 3)
            == "crop-sim train --task t --seed {seed} --imitate 'd/*.npz'")


def test_write_summary_is_one_line_per_row_and_stable(tmp_path):
    write_summary(tmp_path / "a.json", synthetic_table(), run_records())
    write_summary(tmp_path / "b.json", synthetic_table(), run_records())
    text = (tmp_path / "a.json").read_text()
    assert text == (tmp_path / "b.json").read_text()
    assert sum('"kind": "agent"' in line for line in text.splitlines()) == 1
    assert len(text) < 5_000


# --- a small leaderboard tree ----------------------------------------------------------------------------

def small_config(task: str = "benton-quota") -> dict:
    return {"stronger_rule": "A stronger rule exists (issue 33).", "tasks": [{
        "task": task, "readme_sets": ["heldout-real"],
        "headline": {"summary": f"{task}-es", "evaluate": f"crop-sim evaluate --task {task} --agents es=runs/x-s*",
                     "train": {"es": {"command": f"crop-sim train --task {task} --algorithm es --seed {{seed}}",
                                      "seeds": [0, 1]}}},
        "variants": []}]}


def small_tree(root: Path, config: dict | None = None, readme: str | None = "# Farm\n\n"
               f"{lb.START}\nold rows\n{lb.END}\n\nmore text\n", table: dict | None = None) -> Path:
    (root / "results" / "summaries").mkdir(parents=True)
    write_summary(root / "results" / "summaries" / "benton-quota-es.json", table or synthetic_table(), run_records())
    (root / "results" / "leaderboard.yaml").write_text(yaml.safe_dump(config or small_config(), sort_keys=False))
    if readme is not None:
        (root / "README.md").write_text(readme)
    return root


def leaderboard(root: Path, *flags: str) -> int:
    return main(["leaderboard", "--root", str(root), *flags])


def test_the_command_writes_the_page_and_the_readme_block_and_then_checks_clean(tmp_path, capsys):
    root = small_tree(tmp_path)
    assert leaderboard(root, "--check") == 1  # nothing written yet
    assert leaderboard(root) == 0
    assert leaderboard(root, "--check") == 0
    page = (root / "docs" / "leaderboard.md").read_text()
    assert page.startswith("# Leaderboard\n\n> **Which rule the ratios are against.**")
    assert "`budget-rule`" in page and "A stronger rule exists (issue 33)." in page
    assert ("| **benton-quota-es** | es | 16,160 | budget-rule | 424 [343, 518] | 186 [103, 274] | 1.15 % | 0.44 [0.23, 0.67] "
            "| 98 % | 0.42 [0.20, 0.79] | 170 M steps, 9 min |") in page
    assert "`crop-sim train --task benton-quota --algorithm es --seed S`, S = 0, 1" in page
    readme = (root / "README.md").read_text()
    assert readme.startswith(f"# Farm\n\n{lb.START}\n") and readme.endswith(f"{lb.END}\n\nmore text\n")
    assert "old rows" not in readme
    assert "| benton-quota | heldout-real | budget-rule | 424 | - | - | es | 186 [103, 274] | 0.44 [0.23, 0.67] |" in readme


@pytest.mark.parametrize("tamper, named", [
    (lambda root: (root / "docs" / "leaderboard.md").write_text(
        (root / "docs" / "leaderboard.md").read_text().replace("186 [103, 274]", "150 [103, 274]")),
     "docs/leaderboard.md"),
    (lambda root: (root / "README.md").write_text((root / "README.md").read_text().replace("| 424 |", "| 420 |")),
     "README.md"),
    (lambda root: (root / "results" / "summaries" / "benton-quota-es.json").write_text(
        (root / "results" / "summaries" / "benton-quota-es.json").read_text().replace("186.4", "186.9")),
     "docs/leaderboard.md and README.md"),
])
def test_check_fails_on_a_tampered_copy_naming_the_file(tmp_path, capsys, tamper, named):
    root = small_tree(tmp_path)
    assert leaderboard(root) == 0
    before = {path: path.read_text() for path in (root / "docs" / "leaderboard.md", root / "README.md")}
    tamper(root)
    tampered = {path: path.read_text() for path in before}
    capsys.readouterr()
    assert leaderboard(root, "--check") == 1
    error = capsys.readouterr().err
    assert error == f"crop-sim leaderboard: {named} out of date; run crop-sim leaderboard\n"
    assert {path: path.read_text() for path in before} == tampered  # --check writes nothing


def test_a_readme_without_markers_is_left_alone(tmp_path, capsys):
    root = small_tree(tmp_path, readme="# Farm\n\nno block here\n")
    assert leaderboard(root) == 0
    assert (root / "README.md").read_text() == "# Farm\n\nno block here\n"
    assert "no <!-- leaderboard:start --> marker, left alone" in capsys.readouterr().out
    assert leaderboard(root, "--check") == 0


def _without(config: dict, *path) -> dict:
    node = config
    for key in path[:-1]:
        node = node[key]
    del node[path[-1]]
    return config


def _with(config: dict, value, *path) -> dict:
    node = config
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return config


@pytest.mark.parametrize("config, message", [
    (_with(small_config(), 3, "extra"), "results/leaderboard.yaml: extra: Extra inputs are not permitted"),
    (_without(small_config(), "tasks", 0, "headline", "train"), "results/leaderboard.yaml: tasks.0.headline.train: "
                                                                  "Field required"),
    (_with(small_config(), "crop-sim train --task benton-quota --seed 0", "tasks", 0, "headline", "train", "es",
           "command"), "tasks.0.headline.train.es.command: Value error, must be a `crop-sim train ...` command"),
    (_with(small_config(), "../../etc/passwd", "tasks", 0, "headline", "summary"), "tasks.0.headline.summary: "),
    (_with(small_config(), [0, 1, 2], "tasks", 0, "headline", "train", "es", "seeds"),
     "benton-quota-es: train es: seeds [0, 1, 2]; the evaluated runs have [0, 1]"),
    (_with(small_config(), {"es": {"command": "crop-sim train --seed {seed}", "seeds": [0, 1]},
                            "ppo": {"command": "crop-sim train --seed {seed}", "seeds": [0, 1]}},
           "tasks", 0, "headline", "train"), "train names groups ['es', 'ppo']; the summary has ['es']"),
    (_with(small_config(), "climates-quota", "tasks", 0, "task"),
     "results/summaries/benton-quota-es.json: an evaluation of 'benton-quota', listed under task 'climates-quota'"),
    (_with(small_config(), ["far-benton"], "tasks", 0, "readme_sets"),
     "benton-quota: readme_sets: 'far-benton' is not a set of benton-quota-es (heldout-real)"),
    (_with(small_config(), [small_config()["tasks"][0]["headline"]], "tasks", 0, "variants"),
     "summary 'benton-quota-es' is named more than once"),
])
def test_a_malformed_configuration_is_refused_with_one_line(tmp_path, capsys, config, message):
    root = small_tree(tmp_path, config)
    assert leaderboard(root) == 2
    error = capsys.readouterr().err
    assert error.startswith("crop-sim leaderboard: ") and error.count("\n") == 1 and message in error
    assert not (root / "docs").exists()


def test_bad_yaml_and_unlisted_missing_or_oracle_less_summaries_are_refused_with_one_line(tmp_path, capsys):
    root = small_tree(tmp_path / "syntax")
    (root / "results" / "leaderboard.yaml").write_text("tasks: [unclosed\n")
    assert leaderboard(root) == 2
    assert capsys.readouterr().err.startswith("crop-sim leaderboard: results/leaderboard.yaml: ")

    root = small_tree(tmp_path / "unlisted")
    shutil.copy(root / "results" / "summaries" / "benton-quota-es.json", root / "results" / "summaries" / "extra.json")
    assert leaderboard(root) == 2
    assert "results/summaries/extra.json is in no task's headline, variants or planner" in capsys.readouterr().err

    root = small_tree(tmp_path / "missing")
    (root / "results" / "summaries" / "benton-quota-es.json").unlink()
    assert leaderboard(root) == 2
    error = capsys.readouterr().err
    assert error.startswith("crop-sim leaderboard: results/summaries/benton-quota-es.json: ") and error.count("\n") == 1

    root = small_tree(tmp_path / "no-oracle")
    path = root / "results" / "summaries" / "benton-quota-es.json"
    gaps = json.loads(path.read_text())
    gaps["sets"][0].update(reference="best evaluated policy per (season, noise seed)", oracle_return_usd_ha=None)
    path.write_text(dumps(gaps))
    assert leaderboard(root) == 2
    assert "set heldout-real was scored without the oracle (--no-oracle)" in capsys.readouterr().err

    assert leaderboard(tmp_path / "nowhere") == 2
    assert "results/leaderboard.yaml not found" in capsys.readouterr().err


def test_a_readme_with_one_marker_is_refused(tmp_path, capsys):
    root = small_tree(tmp_path, readme=f"# Farm\n{lb.START}\nno end\n")
    assert leaderboard(root) == 2
    assert "README.md: expected one" in capsys.readouterr().err


# --- the committed leaderboard ---------------------------------------------------------------------------

def test_the_committed_page_and_readme_block_are_what_the_command_writes():
    written = lb.outputs(ROOT)
    assert written[lb.PAGE] == (ROOT / lb.PAGE).read_text(encoding="utf-8"), \
        "docs/leaderboard.md is out of date: run crop-sim leaderboard"
    if lb.README in written:
        assert written[lb.README] == (ROOT / lb.README).read_text(encoding="utf-8"), \
            "README.md's leaderboard block is out of date: run crop-sim leaderboard"


SUMMARY_MAX_BYTES = 40_000
PLANNER_BYTES_PER_SEASON = 40  # a planner summary keeps each season's oracle return and regret, unrounded, to re-pair


def test_every_committed_summary_is_small_and_has_a_row(tmp_path):
    summaries = sorted((ROOT / lb.SUMMARIES).glob("*.json"))
    assert summaries
    page = (ROOT / lb.PAGE).read_text(encoding="utf-8")
    for path in summaries:
        content = json.loads(path.read_text(encoding="utf-8"))
        limit = SUMMARY_MAX_BYTES
        if content.get("kind") == PLANNER_KIND:
            limit += PLANNER_BYTES_PER_SEASON * sum(s["seasons"] for s in content["sets"])
        assert path.stat().st_size < limit, (path.name, limit)
        assert f"| {path.stem} |" in page or f"| **{path.stem}** |" in page, path.name


def test_check_passes_on_a_copy_of_the_tree_and_fails_once_a_summary_changes(tmp_path, capsys):
    for part in (lb.CONFIG, lb.PAGE):
        (tmp_path / part).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / part, tmp_path / part)
    shutil.copytree(ROOT / lb.SUMMARIES, tmp_path / lb.SUMMARIES)
    assert leaderboard(tmp_path, "--check") == 0
    first = sorted((tmp_path / lb.SUMMARIES).glob("*.json"))[0]
    data = json.loads(first.read_text())
    data["sets"][0]["rows"][0]["regret_usd_ha"] += 50.0
    first.write_text(dumps(data) + "\n")
    capsys.readouterr()
    assert leaderboard(tmp_path, "--check") == 1
    assert capsys.readouterr().err == "crop-sim leaderboard: docs/leaderboard.md out of date; run crop-sim leaderboard\n"


def test_ratios_are_against_the_strongest_rule_the_summary_names():
    """A summary that scored two rules names the set's strongest one: the page and the README show that rule's
    regret (and name it), not the first rule row; a summary without the name shows its only rule."""
    evaluation_set = {"rows": [
        {"policy": "budget-rule", "kind": "rule", "regret_usd_ha": 424.0, "regret_ci_usd_ha": [343.0, 518.0]},
        {"policy": "paced-rule", "kind": "rule", "regret_usd_ha": 135.0, "regret_ci_usd_ha": [82.0, 198.0]}],
        "strongest_rule": "paced-rule"}
    assert lb.reference_rule(evaluation_set)["policy"] == "paced-rule"
    assert lb.reference_rule({"rows": evaluation_set["rows"][:1]})["policy"] == "budget-rule"


def test_the_summary_records_the_strongest_rule():
    from crop_agent_ros.learning.summary import _set_summary
    rows = [{"policy": name, "kind": "rule", "reference_rule": "paced-rule", "noise_seeds": 5, "return_usd_ha": 1.0,
             "regret_usd_ha": 1.0, "regret_ci_low": 0.0, "regret_ci_high": 2.0, "regret_pct_of_reference": 0.1}
            for name in ("budget-rule", "paced-rule")]
    summarised = _set_summary({"name": "far-benton", "role": "far", "scenario": "benton-quota", "seasons": [0],
                               "terms_seed": 1, "reference": "oracle", "rows": rows})
    assert summarised["strongest_rule"] == "paced-rule"
    for row in rows:
        row.pop("reference_rule")
    assert "strongest_rule" not in _set_summary({"name": "far-benton", "role": "far", "scenario": "benton-quota",
                                                 "seasons": [0], "terms_seed": 1, "reference": "oracle", "rows": rows})


# --- the causal limit: a planner summary beside the headline -------------------------------------------------

def planned_table(rule_regrets=(400.0, 447.0716133914)) -> dict:
    """The synthetic table with the budget rule's returns per season and noise seed (regrets ``rule_regrets``
    per season: by default the mean the table's rule row has, 423.54 USD/ha)."""
    table = synthetic_table()
    oracle = table["sets"][0]["oracle_returns_usd_ha"]
    table["sets"][0]["returns_usd_ha"]["budget-rule"] = [[[o - r] * 3 for o, r in zip(oracle, rule_regrets)]]
    return table


def planner_run(regrets=(100.0, 160.0), task: str = "benton-quota") -> dict:
    """A ``python -m experiments.planners --out`` file of the synthetic set: the planner's regret per season."""
    oracle = synthetic_table()["sets"][0]["oracle_returns_usd_ha"]
    return {"command": ["experiments/planners.py", "--table", "t.json", "--set", "heldout-real"], "task": task,
            "set": "heldout-real", "settings": {"name": "family-expected", "scenarios": 4, "pool_generator": "benton"},
            "decisions": 330, "planning_cpu_s": 61.0, "wall_s": 64.0,
            "rows": [{"season": season, "oracle_usd_ha": o, "mpc_regret_usd_ha": r}
                     for season, (o, r) in enumerate(zip(oracle, regrets))]}


def planned_tree(root: Path, regrets=(100.0, 160.0), table: dict | None = None, headline: dict | None = None) -> Path:
    from experiments.planners_summary import planner_summary
    config = small_config()
    config["tasks"][0]["planner"] = "benton-quota-planner"
    root = small_tree(root, config, table=headline)
    summary = planner_summary(table or planned_table(), [planner_run(regrets)])
    (root / "results" / "summaries" / "benton-quota-planner.json").write_text(dumps(summary) + "\n")
    return root


def test_the_planner_summary_pairs_the_planner_with_the_rules_of_the_evaluation():
    from experiments.planners_summary import planner_summary
    summary = planner_summary(planned_table(), [planner_run()])
    assert summary["kind"] == "causal-planner" and summary["task"] == "benton-quota"
    assert summary["planner"] == {"name": "family-expected", "scenarios": 4}
    (planned,) = summary["sets"]
    (rule,) = planned["rules"]
    # the rule regret is the evaluation summary's (the same returns and the protocol's resamples)
    assert rule["regret_usd_ha"] == summary_rule(synthetic_table())["regret_usd_ha"] == 423.5
    assert rule["ratio_to_strongest_rule"] == 1.0 and planned["strongest_rule"] == "budget-rule"
    assert planned["planner"]["regret_usd_ha"] == 130.0 and planned["planner"]["return_usd_ha"] == 16030.3
    assert planned["planner"]["ratio_to_strongest_rule"] == round(130 / 423.5358066957, 3)
    assert planned["headroom_usd_ha"] == 293.5
    assert planned["headroom_pct_of_oracle"] == round(100 * 293.5358066957 / 16160.3, 3)
    low, high = planned["headroom_ci_usd_ha"]
    assert low <= 293.5 <= high and low > 0  # every season: the planner below the rule
    assert planned["planner"]["paired_wins"] == 1.0
    assert planned["per_season_usd_ha"] == [[0, 18792.0, 100.0], [1, 13528.6, 160.0]]
    assert planned["planning_cpu_s"] == 61.0


def summary_rule(table: dict) -> dict:
    return next(row for row in summary(table)["sets"][0]["rows"] if row["kind"] == "rule")


def test_the_planner_summary_refuses_a_partial_or_foreign_run():
    from experiments.planners_summary import planner_summary
    partial = planner_run()
    partial["rows"] = partial["rows"][:1]
    with pytest.raises(ValueError, match="the run planned 1 of the set's 2 seasons"):
        planner_summary(planned_table(), [partial])
    other = planner_run()
    other["rows"][0]["oracle_usd_ha"] += 1.0
    with pytest.raises(ValueError, match="the run's oracle returns are not the table's"):
        planner_summary(planned_table(), [other])
    with pytest.raises(ValueError, match="two runs of set heldout-real"):
        planner_summary(planned_table(), [planner_run(), planner_run()])


def test_the_page_shows_the_causal_limit_of_each_planned_set(tmp_path, capsys):
    root = planned_tree(tmp_path)
    assert leaderboard(root) == 0 and leaderboard(root, "--check") == 0
    page = (root / "docs" / "leaderboard.md").read_text()
    limit = page[page.index("| policy | summary |"):page.index("| evaluation | agent |")]
    lines = [line for line in limit.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert [line.split(" | ")[0] for line in lines] == [
        "| oracle (knows the season's weather)", "| causal planner (knows the weather so far and its climate)",
        "| budget-rule (strongest rule)", "| es (agent)"]
    assert lines[1].startswith("| causal planner (knows the weather so far and its climate) | benton-quota-planner "
                               "| 16,030 | 130 [")
    assert "| 0.80 % | 0.31 [" in lines[1] and lines[1].endswith("| 61 s CPU (30 s CPU a season) |")
    assert lines[3].startswith("| es (agent) | benton-quota-es | 15,974 | 186 [103, 274] | 1.15 % | 0.44 [0.23, 0.67] |")
    assert "Headroom (budget-rule's regret - the causal planner's): 294 [" in limit
    assert "USD/ha, 1.82 % [" in limit and "of the oracle's return: under 2 %" in limit
    readme = (root / "README.md").read_text()
    assert "| benton-quota | heldout-real | budget-rule | 424 | 130 | 1.82 % | es | 186 [103, 274] |" in readme


def test_a_headroom_of_two_percent_or_more_is_marked_as_worth_learning(tmp_path):
    root = planned_tree(tmp_path, regrets=(10.0, 30.0))
    assert leaderboard(root) == 0
    assert "USD/ha, 2.50 % [" in (root / "docs" / "leaderboard.md").read_text()
    assert "of the oracle's return: reaches 2 %" in (root / "docs" / "leaderboard.md").read_text()


def test_a_planner_summary_against_other_rule_regrets_is_refused_as_stale(tmp_path, capsys):
    root = planned_tree(tmp_path, table=planned_table(rule_regrets=(300.0, 347.0)))  # a rule re-tuned since
    assert leaderboard(root) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith(
        "crop-sim leaderboard: results/summaries/benton-quota-planner.json: set heldout-real: its rule regrets "
        "(budget-rule 323.5) are not benton-quota-es's (budget-rule 423.5): a rule changed since; re-run")
    assert "--runs results/summaries/benton-quota-planner.json --out results/summaries/benton-quota-planner.json` " \
           "(no re-planning)" in error
    assert not (root / "docs").exists()


@pytest.mark.parametrize("change, message", [
    (lambda s: s.update(kind="evaluation"), "not a planner summary (kind: String should match pattern"),
    (lambda s: s["sets"][0].pop("headroom_usd_ha"), "not a planner summary (sets.0.headroom_usd_ha: Field required)"),
    (lambda s: s["sets"][0].update(per_season_usd_ha=[[0, 1.0, 1.0]]), "set heldout-real: 2 seasons, 1 rows per season"),
    (lambda s: s.update(task="climates-quota"), "the planner of 'climates-quota', listed under task 'benton-quota'"),
    (lambda s: s["sets"][0].update(name="far-benton"), "set far-benton is not a set of benton-quota-es"),
])
def test_a_malformed_planner_summary_is_refused_with_one_line(tmp_path, capsys, change, message):
    root = planned_tree(tmp_path)
    path = root / "results" / "summaries" / "benton-quota-planner.json"
    summary = json.loads(path.read_text())
    change(summary)
    path.write_text(dumps(summary))
    assert leaderboard(root) == 2
    error = capsys.readouterr().err
    assert error.startswith("crop-sim leaderboard: results/summaries/benton-quota-planner.json: ")
    assert error.count("\n") == 1 and message in error


def test_the_strongest_rule_comes_first_and_the_budget_rule_is_labelled_the_old_rule(tmp_path):
    table = planned_table()
    evaluated = table["sets"][0]
    evaluated["returns_usd_ha"]["paced-rule"] = [[[o - r] * 3 for o, r in zip(evaluated["oracle_returns_usd_ha"],
                                                                              (150.0, 170.0))]]
    evaluated["rows"].insert(2, _row("paced-rule", "rule", ret=16000.3, regret=160.0, ci=(150.0, 170.0), pct=0.99))
    for row in evaluated["rows"]:
        row["reference_rule"] = "paced-rule"
    root = planned_tree(tmp_path, table=table, headline=table)
    assert leaderboard(root) == 0
    page = (root / "docs" / "leaderboard.md").read_text()
    rules = [line for line in page.splitlines() if line.startswith(("| paced-rule (", "| budget-rule ("))]
    assert rules[0].startswith("| paced-rule (strongest rule) | benton-quota-es | 16,000 | 160 [150, 170] | 0.99 % "
                               "| 1.00 [1.00, 1.00] |")
    assert rules[1].startswith("| budget-rule (old rule) | benton-quota-es | 15,737 | 424 [400, 447] | 2.62 % | 2.65 [")
    assert "Headroom (paced-rule's regret - the causal planner's): 30 [" in page


def test_a_stale_planner_summary_is_paired_again_with_the_new_rule_without_re_planning(tmp_path, capsys):
    from experiments import planners_summary
    root = planned_tree(tmp_path, table=planned_table(rule_regrets=(300.0, 347.0)))
    assert leaderboard(root) == 2  # stale: the rule changed since
    path = root / "results" / "summaries" / "benton-quota-planner.json"
    stale = json.loads(path.read_text())
    (tmp_path / "table.json").write_text(json.dumps(planned_table()))  # the evaluation with today's rule
    assert planners_summary.main(["--table", str(tmp_path / "table.json"), "--runs", str(path), "--out", str(path)]) == 0
    fresh = json.loads(path.read_text())
    assert fresh["sets"][0]["planner"]["regret_usd_ha"] == stale["sets"][0]["planner"]["regret_usd_ha"] == 130.0
    assert fresh["sets"][0]["per_season_usd_ha"] == stale["sets"][0]["per_season_usd_ha"]
    assert fresh["sets"][0]["command"] == stale["sets"][0]["command"]
    assert fresh["sets"][0]["headroom_usd_ha"] == 293.5 != stale["sets"][0]["headroom_usd_ha"]
    assert leaderboard(root) == 0
