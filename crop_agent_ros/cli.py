"""``crop-sim``: one command line for every job of the simulated farm.

Each sub-command lives in its own module, which
provides ``add_arguments(parser)`` and ``run(args) -> int``; modules load only when their command runs,
so ``crop-sim validate`` never pays for torch or rclpy.

A mistake in a command's input (:class:`crop_sim_ros.usage.UsageError`) is one line on stderr,
``crop-sim <command>: <what is wrong>``, and exit status 2; a traceback means a bug of ours.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from crop_sim_ros.usage import EXIT_USAGE, UsageError

# command -> (module, one-line help)
COMMANDS = {
    "farm": ("crop_agent_ros.ros.farm", "the main job: sim node + agent node grow a season over ROS 2"),
    "simulate": ("crop_sim_ros.simulate", "grow one season on a scenario and summarise it (with a plot)"),
    "validate": ("crop_sim_ros.validation.cli", "run the SIMPLE reference experiments and report RRMSE"),
    "fit-weather": ("crop_sim_ros.weather.fit", "fit the weather generator's parameters to observed files"),
    "bench": ("crop_sim_ros.bench", "benchmark the model and the environment (field-days per second)"),
    "train": ("crop_agent_ros.learning.train", "train an agent on a task: --task T --algorithm ppo|es|grpo (hyperparameters from YAML)"),
    "evaluate": ("crop_agent_ros.learning.evaluate", "evaluate policies on held-out seasons"),
    "tune-rule": ("crop_agent_ros.policies.family_tuning",
                  "tune a family task's water-budget rule on generated training seasons"),
    "sweep": ("crop_agent_ros.scale.sweep", "training and evaluation sweeps on Ray Tune (local or a cluster)"),
    "sweep-bench": ("crop_agent_ros.scale.bench", "benchmark sweep trials per hour with 1 and with 2 CPUs"),
    "es-bench": ("crop_agent_ros.learning.es_bench",
                 "benchmark one evolution strategies generation: the numpy learner beside the JAX learner"),
    "ros-bench": ("crop_agent_ros.ros.bench", "benchmark days per second through ROS 2 against bare rclpy"),
    "leaderboard": ("crop_agent_ros.leaderboard",
                    "write the results page and the README's excerpt from the committed evaluation summaries"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="crop-sim", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        sub = commands.add_parser(name, help=help_text, description=help_text)
        sub.set_defaults(_module=module)
        try:
            importlib.import_module(module).add_arguments(sub)
        except ModuleNotFoundError as error:
            if error.name != module:
                raise
            sub.set_defaults(_missing=f"command {name!r} is not available: module {module} is missing")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "_missing", None):
        print(args._missing, file=sys.stderr)
        return EXIT_USAGE
    try:
        return int(importlib.import_module(args._module).run(args) or 0)
    except UsageError as error:
        print(f"crop-sim {args.command}: {error}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
