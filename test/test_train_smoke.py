"""A few hundred steps of ``crop-sim train`` into a temporary directory write every promised file."""

import json
import tempfile

import pytest

from crop_agent_ros.cli import main


def test_train_smoke(tmp_path, monkeypatch):
    out = tmp_path / "run"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))  # where SB3's default logger makes its folder
    code = main(["train", "--timesteps", "256", "--n-envs", "2", "--n-steps", "64", "--batch-size", "64",
                 "--n-epochs", "1", "--eval-freq", "128", "--eval-seeds", "1", "--validation-seasons", "2",
                 "--eval-scenario", "benton-2000", "--seed", "3", "--net-arch", "16", "--out", str(out),
                 "--no-progress"])
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


def test_train_refuses_held_out_seasons(tmp_path):
    with pytest.raises(SystemExit, match="refusing"):
        main(["train", "--scenario", "paterson-1992", "--timesteps", "64", "--out", str(tmp_path), "--no-progress"])
