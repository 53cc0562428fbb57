"""What ``crop-sim train`` reports about its own run: the steps that really ran, training and evaluation
time apart, when training started after launch, and regrets filled in after training."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from crop_agent_ros.cli import main
from test_train_smoke import TINY


def test_train_reports_steps_run_times_and_regrets(tmp_path, capsys):
    out = tmp_path / "run"
    # 100 steps asked; PPO collects whole rollouts of 64 steps x 2 fields = 128 steps
    code = main(["train", "--task", "benton-generated", "--seed", "3", "--out", str(out), *TINY,
                 "--hyperparams", "timesteps=100", "--hyperparams", "eval_freq=1000", "--hyperparams", "net_arch=[8]"])
    assert code == 0
    err = capsys.readouterr().err
    started = re.search(r"training started ([\d.]+) s after launch, after ([\d.]+) s of CPU: imports", err)
    assert started, err
    assert re.search(r"trained 128 steps \(100 asked; PPO runs whole rollouts of 64 x 2 steps\) in [\d.]+ s of "
                     r"training, plus [\d.]+ s in 2 evaluations and [\d.]+ s planning the held-out oracle", err), err
    config = json.loads((out / "config.json").read_text())
    assert config["timesteps_run"] == 128 and config["evaluations"] == 2
    assert config["training_time_s"] + config["evaluation_time_s"] == pytest.approx(config["wall_time_s"], abs=0.15)
    assert config["startup_wall_cpu_s"]["training started"][0] == pytest.approx(float(started.group(1)), abs=0.051)
    # the regrets, filled in once the oracle is planned after training: oracle return - policy return
    from crop_agent_ros.policies.oracle import OraclePolicy
    from crop_agent_ros.policies.rollout import season_contexts
    oracle = OraclePolicy()
    oracle.begin_season(season_contexts("heldout"))
    best = float(np.mean([result.return_value for result in oracle.results]))  # the mean over the seasons
    lines = (out / "learning_curve.csv").read_text().strip().splitlines()
    header = lines[0].split(",")
    for line in lines[1:]:
        row = dict(zip(header, line.split(",")))
        assert float(row["heldout_regret"]) == pytest.approx(best - float(row["heldout_return"]), abs=1e-9)
        assert float(row["heldout_refill_regret"]) == pytest.approx(best - float(row["heldout_refill_return"]),
                                                                    abs=1e-9)
    assert np.isfinite(config["final"]["heldout_regret"])


def test_seconds_since_launch_counts_the_interpreter_start():
    code = ("import time; time.sleep(0.6); from crop_agent_ros.learning.training_support import seconds_since_launch; "
            "print(seconds_since_launch())")
    since = float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
    assert 0.6 <= since < 60.0
