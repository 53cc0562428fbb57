"""A few hundred steps of ``crop-sim train`` into a temporary directory write every promised file."""

import json
import tempfile

import pytest

from crop_agent_ros.cli import main

TINY = ["--hyperparams", "n_envs=2", "--hyperparams", "n_steps=64", "--hyperparams", "batch_size=64",
        "--hyperparams", "n_epochs=1", "--hyperparams", "eval_seeds=1", "--hyperparams", "validation_seasons=2",
        "--no-progress"]  # the paper recipe at a budget of seconds


def test_train_smoke(tmp_path, monkeypatch):
    out = tmp_path / "run"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))  # where SB3's default logger makes its folder
    code = main(["train", "--task", "benton-generated", "--algorithm", "ppo", "--seed", "3", "--out", str(out),
                 *TINY, "--hyperparams", "timesteps=256", "--hyperparams", "eval_freq=128",
                 "--hyperparams", "net_arch=[16]"])
    assert code == 0
    assert not list(scratch.glob("SB3-*")), "training left an SB3 log folder in the temporary directory"
    for name in ("model.zip", "model.json", "learning_curve.csv", "learning_curve.png", "config.json"):
        assert (out / name).stat().st_size > 0, name
    config = json.loads((out / "config.json").read_text())
    assert config["seed"] == 3 and config["scenario"] == "benton-generated"
    assert config["hyper_parameters"]["n_envs"] == 2 and config["hyper_parameters"]["net_arch"] == [16]
    assert config["wall_time_s"] > 0 and "stable_baselines3" in config["versions"]
    rows = (out / "learning_curve.csv").read_text().strip().splitlines()
    assert rows[0].startswith("timesteps,") and len(rows) >= 3
    # the written policy file loads and acts
    from crop_agent_ros.policies import make_policy
    import numpy as np
    policy = make_policy(f"ppo:{out / 'model.zip'}")
    assert policy.action_mode == json.loads((out / "model.json").read_text())["action_mode"]
    assert 0.0 <= policy.act(np.full(20, 10.0, dtype=np.float32)) <= 100.0


def test_train_refuses_held_out_seasons(tmp_path, capsys):
    # (a held-out scenario has no recipe of its own: the refusal names the real reason, its weather)
    from crop_agent_ros.learning.paper_ppo import check_training_scenario
    from crop_sim_ros.task.scenario import get_scenario
    from crop_sim_ros.usage import UsageError
    with pytest.raises(UsageError, match="refusing to train on 'paterson-1992'"):
        check_training_scenario(get_scenario("paterson-1992"))
    assert main(["train", "--task", "paterson-1992", "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    assert capsys.readouterr().err.startswith("crop-sim train: ")
    assert not (tmp_path / "x").exists()
