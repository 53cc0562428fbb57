"""``crop-sim train --task T --algorithm A``: train an agent with the recipe of its algorithm and task.

The settings come from ``crop_agent_ros/learning/hyperparams/<algorithm>.yml`` (:mod:`.hyperparameters`: the
recipes that produced the published agents), each overridable with ``--hyperparams key=value``; ``--show``
prints the resolved settings and exits. The paper's task (``benton-generated``, 20 observed values) trains PPO
on fixed features (:mod:`.paper_ppo`); a family task (29 observed values, e.g. ``benton-quota``) trains PPO,
evolution strategies or group-relative PPO on the normalised raw observation (:mod:`.train_task`). Training
uses generated seasons only. Output in ``--out`` (default ``runs/<task>-<algorithm>-s<seed>``).
"""

from __future__ import annotations

import json
from pathlib import Path

from .hyperparameters import ALGORITHMS


def add_arguments(parser) -> None:
    parser.add_argument("--task", default="benton-generated",
                        help="the task to train on (default benton-generated, the paper's task; a family task, "
                             "e.g. benton-quota, trains a family agent)")
    parser.add_argument("--algorithm", default="ppo", choices=ALGORITHMS,
                        help="ppo (Stable-Baselines3), es (evolution strategies) or grpo (group-relative PPO); "
                             "es and grpo on family tasks only")
    parser.add_argument("--seed", type=int, default=0, help="training seed (weights, exploration, seasons drawn)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default runs/<task>-<algorithm>-s<seed>)")
    parser.add_argument("--hyperparams", action="append", default=[], metavar="KEY=VALUE",
                        help="override one setting of the recipe (repeatable; the value is read as YAML), e.g. "
                             "--hyperparams timesteps=200000 --hyperparams net_arch=[32,32]")
    parser.add_argument("--show", action="store_true", help="print the resolved settings (JSON) and exit")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def resolved_settings(task_name: str, algorithm: str, overrides: list[str]):
    """(the task's scenario, its validated settings); UsageError for an unknown task or a bad setting."""
    from crop_sim_ros.task.scenario import get_scenario
    from crop_sim_ros.usage import UsageError
    from .hyperparameters import parse_overrides, resolve
    try:
        scenario = get_scenario(task_name)
    except (KeyError, ValueError, FileNotFoundError) as error:
        raise UsageError(f"--task {task_name}: {error}") from None
    return scenario, resolve(scenario.name, algorithm, scenario.is_family_task, parse_overrides(overrides))


def run(args) -> int:
    from crop_sim_ros.usage import check_range
    check_range("--seed", args.seed, 0, 2**31 - 1)
    scenario, settings = resolved_settings(args.task, args.algorithm, args.hyperparams)
    if args.show:
        print(json.dumps({"task": scenario.name, "algorithm": args.algorithm, "seed": args.seed,
                          "hyperparams": settings.record()}, indent=1))
        return 0
    out = args.out if args.out is not None else Path("runs") / f"{scenario.name}-{args.algorithm}-s{args.seed}"
    from crop_sim_ros.output import check_output_directory
    check_output_directory(out)  # before the training: a file, under a file, /proc, read-only: one line
    progress = not args.no_progress
    if scenario.is_family_task:
        from .train_task import train_task
        train_task(scenario, args.algorithm, args.seed, out, settings, progress)
    else:
        from .paper_ppo import train
        train(scenario.name, args.seed, out, settings, progress)
    return 0
