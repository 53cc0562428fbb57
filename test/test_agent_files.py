"""A family agent's ``model.json`` is validated before use (issue 34, section 5): a scaler of the wrong length
(silently broadcast), a std of 0, NaN or a string (crashed mid-run), ``"seed": "abc"`` (crashed the
evaluation) are refused at load in one line naming the file and the field; an agent of one task is refused on
another (it ran unchecked)."""

import json
import math
import shutil
from pathlib import Path

import pytest

from crop_agent_ros.cli import main
from crop_agent_ros.policies.learned import LearnedPolicy, read_agent_config
from crop_agent_ros.policies.registry import AGENTS_DIR

SHIPPED = AGENTS_DIR / "benton-quota" / "es"


@pytest.fixture
def agent(tmp_path) -> Path:
    """A copy of the shipped benton-quota ES agent (model.zip + model.json) in a run folder of its own."""
    run = tmp_path / "run-s0"
    run.mkdir()
    for name in ("model.zip", "model.json"):
        shutil.copyfile(SHIPPED / name, run / name)
    return run


def rewrite(run: Path, change) -> Path:
    config = json.loads((run / "model.json").read_text())
    change(config)
    (run / "model.json").write_text(json.dumps(config))
    return run / "model.zip"


def test_the_shipped_agents_files_are_valid():
    for path in sorted(AGENTS_DIR.glob("*/*/model.json")):
        config = read_agent_config(path)
        assert config.task == path.parent.parent.name and len(config.scaler.mean) == 29


@pytest.mark.parametrize("change, message", [
    (lambda c: c["scaler"].update(mean=c["scaler"]["mean"][:20]), r"scaler\.mean: List should have at least 29 items"),
    (lambda c: c["scaler"].update(std=c["scaler"]["std"] + [1.0]), r"scaler\.std: List should have at most 29 items"),
    (lambda c: c["scaler"]["std"].__setitem__(3, 0.0), r"scaler\.std\.3: Input should be greater than 0"),
    (lambda c: c["scaler"]["std"].__setitem__(3, -1.0), r"scaler\.std\.3: Input should be greater than 0"),
    (lambda c: c["scaler"]["std"].__setitem__(3, math.nan), r"scaler\.std\.3: Input should be a finite number"),
    (lambda c: c["scaler"]["mean"].__setitem__(0, math.inf), r"scaler\.mean\.0: Input should be a finite number"),
    (lambda c: c["scaler"]["std"].__setitem__(3, "1.0"), r"scaler\.std\.3: Input should be a valid number"),
    (lambda c: c.pop("scaler"), r"scaler: Field required"),
    (lambda c: c.update(seed="abc"), r"seed: Input should be a valid integer"),
    (lambda c: c.update(history=True), r"history: Input should be a valid integer"),
    (lambda c: c.update(history=0), r"history: Input should be greater than or equal to 1"),
    (lambda c: c.update(action_kind="margin"), r"action_kind: Input should be 'mm' or 'residual'"),
    (lambda c: c.update(action_kind="residual"), r"action_kind: 'residual' needs residual_rule \(the paced rule"),
    (lambda c: c.update(residual_rule={"facts": {}, "parameters": {}}),
     r"residual_rule: only for action_kind 'residual'"),
    # an earlier version's research variants: refused by name, never misread as the headline agent
    (lambda c: c.update(history=8), r"history: a frame history of more than one day is a research variant"),
    (lambda c: c.update(action_kind="residual", rule={"parameters": {}}),
     r"action_kind: the residual action on the budget rule is a research variant"),
    (lambda c: c.update(outlook={"features": ["water_vs_demand", "demand_trend"]}),
     r"outlook: the climate outlook is a research variant of an earlier version .*git history"),
    (lambda c: c.update(outlook=True), r"outlook: the climate outlook is a research variant"),
    (lambda c: c["scaler"].update(hidden=["days_since_sowing"]),
     r"scaler\.hidden: hiding observation columns is a research variant"),
    (lambda c: c.update(task=5), r"task: Input should be a valid string"),
    (lambda c: c.update(algorithm="dqn"), r"algorithm: Input should be 'ppo', "),
])
def test_a_bad_model_json_is_refused_at_load_naming_the_field(agent, change, message):
    zip_file = rewrite(agent, change)
    with pytest.raises(ValueError, match=message) as refused:
        LearnedPolicy(zip_file)
    assert str(refused.value).startswith(str(agent / "model.json")) and "\n" not in str(refused.value)


def test_duplicate_keys_and_non_objects_are_refused(agent):
    (agent / "model.json").write_text('{"task": "benton-quota", "task": "benton-capacity"}')
    with pytest.raises(ValueError, match=r"not valid JSON: the key 'task' appears twice"):
        read_agent_config(agent / "model.json")
    (agent / "model.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match=r"model\.json: not a JSON object$"):
        read_agent_config(agent / "model.json")


def _one_line(capsys, command: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"crop-sim {command}: ") and "Traceback" not in err[0], err
    return err[0]


def test_evaluate_refuses_a_string_seed_in_one_line(agent, tmp_path, capsys):
    rewrite(agent, lambda c: c.update(seed="abc"))
    assert main(["evaluate", "--task", "benton-quota", "--agents", f"es={agent}", "--no-oracle", "--no-curves",
                 "--out", str(tmp_path / "out")]) == 2
    assert "seed: Input should be a valid integer" in _one_line(capsys, "evaluate")


def test_an_agent_of_another_task_is_refused_by_evaluate_and_farm(agent, tmp_path, capsys):
    assert main(["evaluate", "--task", "benton-capacity", "--agents", f"es={agent}", "--no-oracle", "--no-curves",
                 "--out", str(tmp_path / "out")]) == 2
    assert "trained on 'benton-quota', not 'benton-capacity'" in _one_line(capsys, "evaluate")
    # the farm refuses before any node starts (in-process: no node could start here without ROS discovery)
    assert main(["farm", "--task", "benton-capacity", "--policy", "agent", "--policy-file",
                 str(agent / "model.zip")]) == 2
    assert "trained on 'benton-quota', not 'benton-capacity'" in _one_line(capsys, "farm")
    rewrite(agent, lambda c: c["scaler"]["std"].__setitem__(0, 0.0))
    assert main(["farm", "--task", "benton-quota", "--policy", "agent", "--policy-file",
                 str(agent / "model.zip")]) == 2
    assert "scaler.std.0: Input should be greater than 0" in _one_line(capsys, "farm")
