"""``crop-sim train``'s recipes (crop_agent_ros/learning/hyperparams/*.yml): every entry validates, the defaults
are the settings that trained the published agents, a bad override is one line and exit 2, and the command's
help stays short."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from crop_agent_ros.learning import hyperparameters as hp
from crop_sim_ros.task.scenario import get_scenario
from crop_sim_ros.usage import UsageError

ROOT = Path(__file__).resolve().parents[1]
CROP_SIM = str(Path(sys.executable).parent / "crop-sim")
RECORDED = json.loads((ROOT / "test/fixtures/family_agent_settings.json").read_text())["runs"]


def _family(task: str) -> bool:
    return get_scenario(task).is_family_task


@pytest.mark.parametrize("algorithm", hp.ALGORITHMS)
def test_every_entry_of_every_file_loads_and_validates(algorithm):
    entries = hp.recipes(algorithm)
    assert hp.DEFAULT_ENTRY in entries
    for task in entries:
        family = task == hp.DEFAULT_ENTRY or _family(task)
        settings = hp.resolve(task, algorithm, family)
        assert isinstance(settings, hp.recipe_model(algorithm, family))
        assert settings.final_learning_rate <= settings.learning_rate


def test_the_paper_recipe_is_the_shipped_agents_recorded_training():
    """ppo x benton-generated: the arguments the shipped policies/ppo_benton.zip was trained with."""
    shipped = json.loads((ROOT / "crop_agent_ros/policies/ppo_benton.json").read_text())
    arguments = shipped["training"]["arguments"]
    recorded = {**{k: arguments[k] for k in ("timesteps", "eval_freq", "validation_seasons", "eval_seeds",
                                             "learning_rate", "final_learning_rate", "n_envs", "n_steps", "batch_size",
                                             "n_epochs", "gamma", "gae_lambda", "clip_range", "ent_coef",
                                             "log_std_init", "action_mode", "feature_set", "demand_span",
                                             "reward_shaping")},
                "net_arch": [int(x) for x in arguments["net_arch"].split(",")],
                "margin_center_mm": arguments["margin_center"], "margin_span_mm": arguments["margin_span"]}
    assert shipped["training"]["scenario"] == "benton-generated" and shipped["seed"] == 0
    assert hp.resolve("benton-generated", "ppo", False).record() == recorded


def _recorded_settings(run: dict) -> dict:
    """A published agent's recorded settings under the recipe's names (ES's and GRPO's were prefixed)."""
    hyper = {re.sub(r"^(es|grpo)_", "", k): v for k, v in run["hyper_parameters"].items() if k != "exploration"}
    return {**hyper, "timesteps": run["timesteps"], "net_arch": run["net_arch"],
            "paw_filter": run["paw_filter"] is not None}


def _command_option(command: str, flag: str):
    match = re.search(rf"{flag} (\S+)", command)
    return None if match is None else float(match.group(1))


@pytest.mark.parametrize("run", sorted(RECORDED))
def test_the_family_recipes_are_the_published_agents_recorded_settings(run):
    recorded = RECORDED[run]
    settings = hp.resolve(recorded["task"], recorded["algorithm"], True)
    mine = settings.record()
    assert {k: mine[k] for k in _recorded_settings(recorded)} == _recorded_settings(recorded)
    # what the summaries do not hold: the checkpoints' spacing (the first past each multiple of eval_freq, ES and
    # GRPO ending a generation or an iteration there) and the validation seasons the command gave
    regular = [steps for steps in recorded["checkpoint_timesteps"][2:] if steps < settings.timesteps]
    for k, steps in enumerate(regular, start=1):
        assert k * settings.eval_freq <= steps < (k + 0.5) * settings.eval_freq, (k, steps)
    for flag, value in (("--validation-seasons", settings.validation_seasons), ("--eval-freq", settings.eval_freq)):
        given = _command_option(recorded["command"], flag)
        assert given is None or given == value


def test_the_shipped_es_agents_were_trained_with_the_es_recipe():
    shipped = sorted((ROOT / "crop_agent_ros/agents").glob("*/es/model.json"))
    if not shipped:
        pytest.skip("no shipped ES agent in crop_agent_ros/agents")
    for path in shipped:
        recorded = json.loads(path.read_text())
        settings = hp.resolve(recorded["task"], "es", True).record()
        for key, value in _recorded_settings({**recorded, "paw_filter": recorded.get("paw_filter")}).items():
            assert settings[key] == value, (path, key)


def test_overrides_are_read_as_yaml_and_validated():
    settings = hp.resolve("benton-quota", "es", True, hp.parse_overrides(
        ["timesteps=2000", "net_arch=[8, 8]", "noise_std=3e-1", "paw_filter=true"]))
    assert (settings.timesteps, settings.net_arch, settings.noise_std, settings.paw_filter) == (2000, (8, 8), 0.3, True)
    # a family task without an entry of its own: the algorithm's default recipe
    assert hp.resolve("benton-capacity", "es", True) == hp.resolve("benton-quota", "es", True)
    for overrides, message in ((["timesteps=many"], "hyperparameter timesteps 'many': Input should be a valid integer"),
                               (["timestep=5"], "hyperparameter timestep 5: Extra inputs are not permitted (known: "),
                               (["timesteps=0"], "timesteps 0: Input should be greater than or equal to 1"),
                               (["paw_filter=maybe"], "paw_filter 'maybe': Input should be a valid boolean"),
                               (["timesteps"], "--hyperparams 'timesteps': give KEY=VALUE")):
        with pytest.raises(UsageError, match=re.escape(message)):
            hp.resolve("benton-quota", "es", True, hp.parse_overrides(overrides))
    with pytest.raises(UsageError, match="no ppo hyperparameters for task 'maricopa-generated'"):
        hp.resolve("maricopa-generated", "ppo", False)


def test_train_help_lists_at_most_twelve_options_and_a_bad_setting_is_one_line_and_exit_2(tmp_path):
    shown = subprocess.run([CROP_SIM, "train", "--help"], capture_output=True, text=True, timeout=120)
    options = [line for line in shown.stdout.splitlines() if re.match(r"^  -", line)]
    assert shown.returncode == 0 and 1 <= len(options) <= 12, shown.stdout
    for argv, message in ((["--task", "benton-quota", "--hyperparams", "learning_rate=fast"],
                           "hyperparameter learning_rate 'fast': Input should be a valid number"),
                          (["--task", "benton-quota", "--algorithm", "es", "--hyperparams", "n_steps=64"],
                           "hyperparameter n_steps 64: Extra inputs are not permitted")):
        result = subprocess.run([CROP_SIM, "train", *argv, "--out", str(tmp_path / "x")], capture_output=True,
                                text=True, timeout=120)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("crop-sim train: "), result.stderr
        assert message in lines[0]
    assert not (tmp_path / "x").exists()
    shown = subprocess.run([CROP_SIM, "train", "--task", "benton-sensing", "--algorithm", "grpo", "--show",
                            "--hyperparams", "timesteps=5000"], capture_output=True, text=True, timeout=120)
    settings = json.loads(shown.stdout)
    assert settings["hyperparams"]["timesteps"] == 5000 and settings["hyperparams"]["paw_filter"] is True
