"""Grow a season over ROS 2 with one command: start the simulator node and an agent node as two processes,
let the agent drive the season(s), print the summary, stop both.

    python -m crop_agent_ros.ros.farm [--policy ppo|refill|best-constant|constant|zero|budget-rule|es|agent]
                                      [--policy-file F] [--seasons 1] [--task NAME] [--seed 0] [--log season.csv]

Defaults: the shipped PPO policy (``crop_agent_ros/policies/ppo_benton.zip``) on the embedded default
task ``benton-generated`` (no data file needed), seed 0. On a family task (``--task benton-quota``, ...)
``--policy budget-rule`` is that task's tuned rule, ``--policy es`` its shipped evolution-strategies agent
(``crop-sim farm --task benton-quota --policy es``; a task without one is refused in one line naming the tasks
that have one) and ``--policy agent --policy-file .../model.zip`` a family agent (``crop-sim train --task``). Both nodes run on a private ROS_DOMAIN_ID
with discovery kept on this machine, so nothing else on the network sees them (``--domain-id`` to choose, 0..232).
The nodes die with the farm, even when it is killed by SIGKILL (a parent-death signal: :mod:`.process`).
On a ROS 2 machine the same job is ``ros2 launch crop_sim_ros farm.launch.py``.

Exit status: 0 when every season was grown; 2 for a mistake in the input (a bad argument, an unknown
scenario or policy, a policy file that is missing or not for this task, a family agent of another task: a node
that cannot start says why in one line); 1 when a node failed later (its output is printed); 128 + the signal's
number when stopped by SIGINT or SIGTERM (both nodes are stopped first, without a traceback).
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import sys
import tempfile
import time
from pathlib import Path

from crop_sim_ros.usage import EXIT_USAGE, UsageError, check_range, user_input

from ..policies import NODE_POLICIES
from ..policies.registry import SHIPPED_POLICIES, shipped_agent_file
from .process import NodeProcess, isolated_ros_env, pick_domain_id

SUMMARY_PREFIX = "season summary: "
MAX_SEASONS = 100_000  # the agent node's own bound of its ``seasons`` parameter
MAX_DOMAIN_ID = 232  # DDS's bound of ROS_DOMAIN_ID (ports grow with it; Linux keeps 0..101 clear of ephemeral ports)
# seconds the agent waits for any answer of the simulator, its start-up included (both nodes load for seconds)
AGENT_TIMEOUT_S = 30.0
# a log line of rclpy: "[FATAL] [1700000000.123] [crop_agent]: message"
_LOG_LINE = re.compile(r"^\[(?P<level>[A-Z]+)\] \[[0-9.]+\] \[[^]]*\]: (?P<message>.*)$")


class Interrupted(BaseException):
    """SIGINT or SIGTERM while the farm runs (the number is the signal's)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policy", default="ppo", choices=NODE_POLICIES,
                        help="the agent's policy (default: the shipped PPO policy; budget-rule: the family task's "
                             "tuned rule; es: the family task's shipped agent; agent: a family agent, --policy-file)")
    parser.add_argument("--policy-file", default="", help="policy ppo: a Stable-Baselines3 PPO .zip "
                        "(default: the shipped crop_agent_ros/policies/ppo_benton.zip); policy agent: a family "
                        "agent's model.zip (required)")
    parser.add_argument("--constant-mm", type=float, default=10.0, help="policy constant: mm per day (default 10)")
    parser.add_argument("--seasons", type=int, default=1, help=f"seasons to grow (default 1, at most {MAX_SEASONS})")
    parser.add_argument("--task", default="benton-generated", help="task: a built-in scenario's name or a "
                        "scenario YAML path (default benton-generated, the embedded default)")
    parser.add_argument("--data-dir", default="", help="directory of the scenario's weather files")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first season (default 0)")
    parser.add_argument("--log", default="", help="season log CSV (default: a file in a temporary directory, "
                        "printed at the end)")
    parser.add_argument("--domain-id", type=int, default=None, help=f"ROS_DOMAIN_ID, 0..{MAX_DOMAIN_ID} (default: "
                        "derived from the pid)")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds before giving up (default 600)")
    parser.add_argument("--json", action="store_true", help="print the summaries as JSON lines only")
    parser.add_argument("--no-plot", action="store_true", help="do not draw the last season (PNG beside the log)")


def _interrupt(signum, frame) -> None:
    _set_signal_handlers(signal.SIG_IGN)  # one is enough: the nodes' shutdown must not be interrupted
    raise Interrupted(signum)


def _set_signal_handlers(handler) -> None:
    for kind in (signal.SIGINT, signal.SIGTERM):
        signal.signal(kind, handler)


def startup_failure(node: NodeProcess) -> str:
    """Why a node that exited with status 2 could not start: its last FATAL or ERROR log line (else its last
    line), without rclpy's prefix."""
    lines = [line.strip() for line in node.output().splitlines() if line.strip()]
    for line in reversed(lines):
        match = _LOG_LINE.match(line)
        if match and match["level"] in ("FATAL", "ERROR"):
            return f"{node.name}: {match['message']}"
    return f"{node.name}: {lines[-1] if lines else f'exited with status {node.poll()}'}"


def run(args) -> int:
    if not 1 <= args.seasons <= MAX_SEASONS:
        raise UsageError(f"--seasons: {args.seasons} is not in 1..{MAX_SEASONS}")
    if args.domain_id is not None:
        check_range("--domain-id", args.domain_id, 0, MAX_DOMAIN_ID)
    if not args.timeout > 0:
        raise UsageError(f"--timeout: {args.timeout} s is not positive")
    if args.policy_file and not Path(args.policy_file).expanduser().is_file():
        raise UsageError(f"--policy-file: {args.policy_file} is not a file")
    if args.policy == "agent" and not args.policy_file:
        raise UsageError("--policy agent needs --policy-file (a family agent's model.zip)")
    if args.policy == "agent":
        # model.json beside the agent: valid, and of this task (a scenario file is a task of its own: not checked)
        from crop_sim_ros.simulate import is_scenario_path

        from ..policies.learned import check_agent_task, read_agent_config
        with user_input("--policy-file"):
            agent = read_agent_config(Path(args.policy_file).expanduser().with_suffix(".json"))
            if not is_scenario_path(args.task):
                check_agent_task(agent, args.task, args.policy_file)
    if args.policy in SHIPPED_POLICIES:  # refused here, before any node starts
        try:
            shipped_agent_file(args.policy, args.task)
        except ValueError as error:
            raise UsageError(str(error)) from None
    _set_signal_handlers(_interrupt)
    try:
        return _grow(args)
    except Interrupted as stop:
        return 128 + stop.args[0]
    finally:
        _set_signal_handlers(signal.SIG_DFL)


def _grow(args) -> int:
    env = isolated_ros_env(args.domain_id if args.domain_id is not None else pick_domain_id(salt=53))
    workdir = Path(tempfile.mkdtemp(prefix="crop_farm_"))
    log = Path(args.log).expanduser().resolve() if args.log else workdir / "season_log.csv"
    sim_args = ["-p", f"scenario:={args.task}", "-p", f"seed:={args.seed}", "-p", f"log_path:={log}"]
    if args.data_dir:
        sim_args += ["-p", f"data_dir:={args.data_dir}"]
    agent_args = ["-p", f"policy:={args.policy}", "-p", "drive:=true", "-p", f"seasons:={args.seasons}",
                  "-p", f"constant_mm:={args.constant_mm}", "-p", "seed:=-2", "-p", f"timeout:={AGENT_TIMEOUT_S}"]
    if args.policy_file:
        agent_args += ["-p", f"policy_file:={Path(args.policy_file).expanduser().resolve()}"]
    started = time.monotonic()
    sim = agent = None
    code = 0
    try:
        sim = NodeProcess("crop_sim_ros.sim_node", ros_args=sim_args, env=env, name="sim_node",
                          log_path=workdir / "sim_node.out")
        agent = NodeProcess("crop_agent_ros.ros.agent_node", ros_args=agent_args, env=env, name="agent_node",
                            log_path=workdir / "agent_node.out")
        while agent.poll() is None:
            if sim.poll() is not None:
                break
            if time.monotonic() - started > args.timeout:
                print(f"timed out after {args.timeout:.0f} s", file=sys.stderr)
                code = 1
                break
            time.sleep(0.05)
        failed = next((node for node in (sim, agent) if node.poll() not in (None, 0)), None)
        if code == 0 and failed is not None:
            if failed.poll() == EXIT_USAGE:  # could not start: bad input, said in one line
                raise UsageError(startup_failure(failed))
            print(f"{failed.name} exited with status {failed.poll()}:\n{failed.output()}", file=sys.stderr)
            code = 1
    finally:
        # a signal must not leave a node running (each has its own session; SIGKILL: NodeProcess's parent-death
        # signal stops them)
        _set_signal_handlers(signal.SIG_IGN)
        for node in (agent, sim):
            if node is not None:
                node.stop()
        _set_signal_handlers(_interrupt)
    sim_status = sim.poll()
    summaries = [json.loads(line[len(SUMMARY_PREFIX):]) for line in agent.output().splitlines()
                 if line.startswith(SUMMARY_PREFIX)]
    if summaries and not args.no_plot:
        plot_season_log(log, log.with_suffix(".png"))
    if args.json:
        for summary in summaries:
            print(json.dumps(summary))
    else:
        for s in summaries:
            print(f"season {s['episode'] - 1}: {s['weather']}, policy {s['policy']}: yield {s['yield_t_ha']:.2f} t/ha, "
                  f"irrigation {s['irrigation_mm']:.0f} mm, return {s['return']:.3f} "
                  f"(normalized {s['normalized_return']:.3f}), {s['days']} days"
                  f"{'' if s['matured'] else ' (weather ran out before maturity)'}")
        if summaries:
            print(f"grown over ROS 2 (sim_node + agent_node, ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}) in "
                  f"{time.monotonic() - started:.1f} s; season log {log}; node output in {workdir}")
            if not args.no_plot:
                print(f"plot of the last season: {log.with_suffix('.png')}")
        else:
            print(f"no season grown; node output in {workdir}", file=sys.stderr)
    if code == 0 and len(summaries) != args.seasons:
        print(f"expected {args.seasons} season summaries, got {len(summaries)}", file=sys.stderr)
        code = 1
    if code == 0 and sim_status not in (0, None):
        print(f"sim_node stopped with status {sim_status}", file=sys.stderr)
    return code


def plot_season_log(log: Path, png: Path) -> Path:
    """Draw the last season of a simulator season log: true and observed biomass, true and observed PAW,
    rain and irrigation by day. Returns ``png``."""
    import csv

    import matplotlib  # only for the picture

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with log.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    last = [r for r in rows if (r["run_id"], r["episode"]) == (rows[-1]["run_id"], rows[-1]["episode"])]

    def column(name: str) -> list[float]:
        return [float(r[name]) for r in last]

    day = column("day")  # observations are of the start of a day, true values of its end (day + 1)
    end_of_day = [d + 1 for d in day]
    figure, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    axes[0].plot(end_of_day, column("end_true_biomass_t_ha"), label="true")
    axes[0].plot(day, column("obs_biomass_t_ha"), ".", markersize=2, label="observed (noisy)")
    axes[0].set_ylabel("biomass, t/ha")
    axes[1].plot(end_of_day, column("end_true_paw_mm"), label="true")
    paw = column("obs_paw_mm")
    if last[0].get("obs_paw_observed"):  # a family task logs a missing reading as 0 mm with its flag at 0
        paw = [value if seen > 0.5 else float("nan") for value, seen in zip(paw, column("obs_paw_observed"))]
    axes[1].plot(day, paw, ".", markersize=2, label="observed (noisy; none where the reading is missing)")
    axes[1].set_ylabel("PAW, mm")
    axes[2].bar(day, column("rain_mm"), color="tab:blue", label="rain")
    axes[2].bar(day, column("irrigation_mm"), bottom=column("rain_mm"), color="tab:green", label="irrigation")
    axes[2].set_ylabel("water, mm/day")
    axes[2].set_xlabel(f"days after sowing ({last[0]['date']})")
    for ax in axes:
        ax.legend(loc="upper left")
    axes[0].set_title(f"{last[0]['scenario']}, season {last[0]['weather_season']}: grown over ROS 2")
    figure.tight_layout()
    figure.savefig(png, dpi=90)
    plt.close(figure)
    return png


def main(argv: list[str] | None = None) -> int:
    """``python -m crop_agent_ros.ros.farm ...`` is ``crop-sim farm ...``."""
    from ..cli import main as crop_sim

    return crop_sim(["farm", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
