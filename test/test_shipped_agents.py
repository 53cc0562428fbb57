"""The shipped agents (package data under crop_agent_ros/agents/<task>/<policy>/): loaded by the policy name
(``es``, ``es-residual``) for the current task, acting on that task's observation; a task without one refused in
one line; the policies package runs them without importing training."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from crop_agent_ros.policies import PolicyArguments, build_policy
from crop_agent_ros.policies.learned import ACTION_SCALE_MM, LearnedPolicy
from crop_agent_ros.policies.registry import AGENTS_DIR, SHIPPED_POLICIES, shipped_agent_file, shipped_agent_tasks
from crop_sim_ros.task import IrrigationEnv, get_scenario, scenario_names
from crop_sim_ros.task.layout import EXTENDED
from crop_sim_ros.task.scenario import with_weather_of

REPO = Path(__file__).resolve().parents[1]
ES_TASKS = shipped_agent_tasks("es")
# the family tasks published with evolution strategies; the other family tasks have no shipped agent
EXPECTED_ES_TASKS = ["benton-quota", "benton-sensing", "climates-hot-quota", "climates-quota",
                     "climates-spread-quota", "climates10-quota", "climates12-quota", "climates3-quota",
                     "climates4-quota", "climates6-quota", "climates8-quota", "maricopa-late-quota",
                     "maricopa-sown-spread-quota"]
# the tasks with a tuned paced rule, whose residual agent (ES correcting that rule) is shipped
EXPECTED_RESIDUAL_TASKS = ["benton-quota", "benton-sensing", "climates-quota", "climates12-quota"]
SHIPPED = [("es", task) for task in EXPECTED_ES_TASKS] + [("es-residual", task) for task in EXPECTED_RESIDUAL_TASKS]


def test_the_shipped_agents_are_one_small_final_policy_per_task():
    assert SHIPPED_POLICIES == ("es", "es-residual") and ES_TASKS == EXPECTED_ES_TASKS
    assert shipped_agent_tasks("es-residual") == EXPECTED_RESIDUAL_TASKS
    for policy, task in SHIPPED:
        folder = AGENTS_DIR / task / policy
        assert sorted(p.name for p in folder.iterdir()) == ["model.json", "model.zip"], task  # no early model, curve
        config = json.loads((folder / "model.json").read_text())
        assert (config["task"], config["algorithm"], config["seed"]) == (task, "es", 0)
        assert get_scenario(task).is_family_task
        assert sum(p.stat().st_size for p in folder.iterdir()) < 200_000
        if policy == "es-residual":  # it corrects the paced rule shipped for its task, exactly
            from crop_agent_ros.policies.family_tuning import paced_rule_record, tuned_rule
            assert config["action_kind"] == "residual"
            assert config["residual_rule"] == json.loads(json.dumps(paced_rule_record(tuned_rule(task, "paced-rule"))))


@pytest.mark.usefixtures("shared_data")
@pytest.mark.parametrize("policy, task", SHIPPED)
def test_a_shipped_policy_loads_the_agent_of_the_task_and_grows_its_season(policy, task):
    """The agent of ``task`` on the task's observation (its terms, quota and noise; the weather of the real
    Benton 2000 season, so that no pool of generated seasons is built): it irrigates within its action's range
    and the quota, and the crop matures."""
    name = policy
    policy = build_policy(name, PolicyArguments(task=task), node=True)
    assert isinstance(policy, LearnedPolicy) and policy.name == name
    assert policy.describe()["trained_on"] == task and policy.path == shipped_agent_file(name, task)
    env = IrrigationEnv(with_weather_of(get_scenario(task), get_scenario("benton-2000")))
    obs, info = env.reset(seed=0)
    assert obs.shape == (EXTENDED.size,)
    policy.reset(0)
    asked, applied, done = [], 0.0, False
    while not done:
        mm = float(policy.act(obs))
        asked.append(mm)
        obs, _, terminated, truncated, info = env.step(mm)
        applied += info["irrigation_applied_mm"]
        done = terminated or truncated
    assert all(0.0 <= mm <= ACTION_SCALE_MM for mm in asked) and max(asked) > 1.0
    assert terminated and info["mature"] and 0.0 < applied <= info["quota_mm"] + 1e-9


def test_policy_es_refuses_a_task_without_a_shipped_agent_naming_those_with_one():
    family_without = [name for name in scenario_names()
                      if get_scenario(name).is_family_task and name not in ES_TASKS]
    assert {"benton-money", "benton-capacity", "benton-blind"} <= set(family_without)
    for task in family_without + ["benton-generated", "../agents/benton-quota"]:
        with pytest.raises(ValueError) as refused:
            build_policy("es", PolicyArguments(task=task))
        assert str(refused.value) == (f"policy es: no shipped agent for task {task!r}; tasks with one: "
                                      f"{', '.join(EXPECTED_ES_TASKS)}")
    with pytest.raises(ValueError, match=r"^policy es needs a family task \(task:=, --task\)$"):
        build_policy("es", PolicyArguments())
    with pytest.raises(ValueError) as refused:
        build_policy("es-residual", PolicyArguments(task="climates10-quota"))
    assert str(refused.value) == ("policy es-residual: no shipped agent for task 'climates10-quota'; tasks with one: "
                                  f"{', '.join(EXPECTED_RESIDUAL_TASKS)}")


def test_farm_refuses_a_task_without_a_shipped_agent_in_one_line(tmp_path):
    done = subprocess.run([sys.executable, "-m", "crop_agent_ros.cli", "farm", "--task", "benton-money", "--policy",
                           "es", "--log", str(tmp_path / "season.csv")], capture_output=True, text=True,
                          timeout=120, cwd=REPO)
    assert (done.returncode, done.stdout) == (2, ""), (done.returncode, done.stdout, done.stderr)
    assert done.stderr.splitlines() == [f"crop-sim farm: policy es: no shipped agent for task 'benton-money'; tasks "
                                        f"with one: {', '.join(EXPECTED_ES_TASKS)}"]
    assert not (tmp_path / "season.csv").exists()  # refused before any node started


def test_the_policies_package_runs_a_shipped_agent_without_importing_training():
    code = ("import sys; from crop_agent_ros.policies import PolicyArguments, build_policy; "
            "import numpy as np; policy = build_policy('es', PolicyArguments(task='benton-quota'), node=True); "
            "policy.reset(0); policy.act(np.zeros(29, np.float32)); "
            "print(sorted(m for m in sys.modules if m.startswith('crop_agent_ros.learning')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_the_shipped_files_are_package_data():
    """setup.py's package_data patterns match every shipped file (a wheel then carries the agents)."""
    from fnmatch import fnmatch
    setup = (REPO / "setup.py").read_text()
    patterns = [p for p in ("agents/*/*/model.zip", "agents/*/*/model.json") if f'"{p}"' in setup]
    files = [p.relative_to(REPO / "crop_agent_ros").as_posix() for p in AGENTS_DIR.rglob("*") if p.is_file()]
    assert len(files) == 2 * len(SHIPPED)
    assert all(any(fnmatch(f, pattern) for pattern in patterns) for f in files), (patterns, files)
