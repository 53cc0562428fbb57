"""Every command's user errors end in one line ``crop-sim <command>: <what>`` and exit status 2, before any work
(issue 34, sections 1 and 5): sizes and ranges bounded before anything is allocated, training settings refused
when out of range, infinite or NaN, output folders that cannot be one, options the chosen protocol would ignore,
tasks a command cannot run. In-process through ``crop_agent_ros.cli.main``; none of these starts a node, a
training run or an evaluation."""

import os

import pytest

from crop_agent_ros.cli import main

QUOTA = ["--task", "benton-quota"]


def hyperparams(*pairs: str) -> list[str]:
    return ["train", *QUOTA, *[arg for pair in pairs for arg in ("--hyperparams", pair)], "--show"]


# (argv with {tmp} for the test's folder, a fragment of the one line)
CASES = [
    # train: the task, the seed, the output folder (before the training), the recipe's settings
    (["train", "--task", "atlantis"], "--task atlantis: unknown scenario 'atlantis'"),
    (["train", *QUOTA, "--seed", "-1"], "--seed: -1 is not in 0..2147483647"),
    (["train", "--task", "benton-generated", "--algorithm", "es"], "--algorithm es: for a family task only"),
    (["train", *QUOTA, "--out", "{tmp}/a_file"], "--out: {tmp}/a_file is a file, not a folder"),
    (["train", *QUOTA, "--out", "{tmp}/a_file/run"], "lies under {tmp}/a_file, which is a file"),
    (["train", *QUOTA, "--out", "/proc/crop-sim-run"], "--out: /proc/crop-sim-run is in a kernel file system"),
    (hyperparams("gae_lambda=-0.5"), "hyperparameter gae_lambda -0.5: Input should be greater than or equal to 0"),
    (hyperparams("clip_range=-1"), "hyperparameter clip_range -1: Input should be greater than 0"),
    (hyperparams("clip_range=1e308"), "hyperparameter clip_range 1e+308: Input should be less than or equal to 10"),
    (hyperparams("final_learning_rate=-1e-5"), "hyperparameter final_learning_rate -1e-05: Input should be greater"),
    (hyperparams("net_arch=0"), "hyperparameter net_arch 0: Input should be a valid tuple"),
    (hyperparams("net_arch=[0]"), "hyperparameter net_arch.0 0: Input should be greater than or equal to 1"),
    (hyperparams("net_arch=abc"), "hyperparameter net_arch 'abc': Input should be a valid tuple"),
    (hyperparams("net_arch=100000,100000"), "hyperparameter net_arch.0 100000: Input should be less than or equal "
                                            "to 4096; hyperparameter net_arch.1 100000"),
    (hyperparams("net_arch=[" + ",".join(["8"] * 40) + "]"), "hyperparameter net_arch (8, 8, 8, 8, 8, 8, ...): Tuple "
                                                             "should have at most 16 items after validation, not 40"),
    (hyperparams("n_epochs=0"), "hyperparameter n_epochs 0: Input should be greater than or equal to 1"),
    (hyperparams("batch_size=1"), "hyperparameter batch_size 1: Input should be greater than or equal to 2"),
    (hyperparams("gamma=5"), "hyperparameter gamma 5: Input should be less than or equal to 1"),
    (hyperparams("ent_coef=inf"), "hyperparameter ent_coef inf: Input should be a finite number"),
    (hyperparams("learning_rate=.nan"), "hyperparameter learning_rate nan: Input should be a finite number"),
    (hyperparams("log_std_init=-.inf"), "hyperparameter log_std_init -inf: Input should be a finite number"),
    (hyperparams("ent_coef=inf", "gamma=5"), "hyperparameter gamma 5: Input should be less than or equal to 1; "
                                             "hyperparameter ent_coef inf: Input should be a finite number"),
    (["train", "--task", "benton-generated", "--hyperparams", "margin_center_mm=.inf", "--show"],
     "hyperparameter margin_center_mm inf: Input should be a finite number"),
    # evaluate: the options of the other protocol are refused, not ignored
    (["evaluate", *QUOTA, "--seeds", "5..1"], "--seeds: not used with --task"),
    (["evaluate", *QUOTA, "--policies", "no-such-policy"], "--policies: not used with --task"),
    (["evaluate", *QUOTA, "--no-plots"], "--no-plots: not used with --task"),
    (["evaluate", "--noise-seeds", "3"], "--noise-seeds: an option of the family protocol (--task TASK)"),
    (["evaluate", "--no-oracle"], "--no-oracle: an option of the family protocol (--task TASK)"),
    (["evaluate", "--seeds", "0..10000000000"], "--seeds: 10000000001 seeds; at most 10000"),
    (["evaluate", "--task", "atlantis"], "--task: unknown scenario 'atlantis'"),
    (["evaluate", *QUOTA, "--out", "{tmp}/a_file/eval"], "lies under {tmp}/a_file, which is a file"),
    (["evaluate", *QUOTA, "--out", "/proc/crop-sim-eval"], "--out: /proc/crop-sim-eval is in a kernel file system"),
    # tune-rule: the season range is bounded before it is allocated (74.5 GiB), the seed non-negative
    (["tune-rule", *QUOTA, "--seasons", "0..10000000000"], "--seasons: '0..10000000000' goes past season 9999"),
    (["tune-rule", *QUOTA, "--seasons", "5..1"], "--seasons: '5..1' names no season"),
    (["tune-rule", *QUOTA, "--seasons", "0.." + "9" * 5000], "--seasons: expected 'A..B' or one index, got '0..999"),
    (["tune-rule", *QUOTA, "--seed", "-1"], "--seed: -1 is not in 0..4294967295"),
    (["tune-rule", "--task", "benton-generated"], "the rule is tuned on a family task's generated training seasons"),
    # farm: the domain id, refused before any node starts
    (["farm", "--domain-id", "500"], "--domain-id: 500 is not in 0..232"),
    (["farm", "--domain-id", "-1"], "--domain-id: -1 is not in 0..232"),
    # simulate: a task whose water is limited is not simulate's
    (["simulate", *QUOTA, "--out", "{tmp}/sim"], "--task benton-quota: its water is limited (a quota or a pivot's"),
    (["simulate", "--task", "benton-capacity", "--out", "{tmp}/sim"], "run it with `crop-sim evaluate --task "
                                                                      "benton-capacity` or `crop-sim farm"),
    # the benchmarks and the weather fit: every count bounded
    (["bench", "--fields", "100000000000"], "--fields: 100000000000 is not in 1..1000000"),
    (["bench", "--fields", "0"], "--fields: 0 is not in 1..1000000"),
    (["bench", "--repeats", "100000000000"], "--repeats: 100000000000 is not in 1..100"),
    (["ros-bench", "--seasons", "100000000000"], "--seasons: 100000000000 is not in 1..1000"),
    (["ros-bench", "--calls", "100000000000"], "--calls: 100000000000 is not in 1..100000"),
    (["fit-weather", "--check-seasons", "100000000000"], "--check-seasons: 100000000000 is not in 1..10000"),
    (["fit-weather", "--check-seasons", "0"], "--check-seasons: 0 is not in 1..10000"),
]


@pytest.mark.parametrize("argv, fragment", CASES, ids=[" ".join(argv)[:70] for argv, _ in CASES])
def test_a_user_error_is_one_line_and_status_2(tmp_path, capsys, argv, fragment):
    (tmp_path / "a_file").write_text("not a folder\n")
    argv = [arg.replace("{tmp}", str(tmp_path)) for arg in argv]
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    command = argv[0]
    assert len(lines) == 1 and lines[0].startswith(f"crop-sim {command}: "), captured.err[-2000:]
    assert fragment.replace("{tmp}", str(tmp_path)) in lines[0]
    assert "Traceback" not in captured.err and len(lines[0]) < 2000  # (an unknown task lists the 48 known)
    assert not (tmp_path / "sim").exists()


def test_simulate_still_grows_the_papers_task(tmp_path, capsys):
    assert main(["simulate", "--task", "benton-generated", "--irrigation-mm", "0,5", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "summary.json").is_file() or any(tmp_path.iterdir())


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes in a read-only folder")
@pytest.mark.parametrize("command", [["train", *QUOTA], ["evaluate", *QUOTA]])
def test_an_output_folder_in_a_read_only_folder_is_refused(tmp_path, capsys, command):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    try:
        assert main([*command, "--out", str(locked / "run")]) == 2
        line, = capsys.readouterr().err.strip().splitlines()
        assert line == f"crop-sim {command[0]}: --out: cannot write in {locked} (read-only or no permission)"
    finally:
        locked.chmod(0o755)
