"""Simulated days per second through ROS, against bare rclpy baselines measured in alternating rounds.

    python -m crop_agent_ros.ros.bench [--rounds 5] [--seasons 1]

Three measurements, each between two processes on this machine (Fast DDS, localhost discovery, a
private ROS_DOMAIN_ID):

1. bare std_srvs/Trigger round trip: a client in this process (call_async + its own spin_once loop)
   against a trivial server in a child process;
2. bare topic ping-pong: the day's command message (crop_sim_interfaces/msg/IrrigationCommand) out, echoed
   back by the child;
3. whole seasons through the Gymnasium bridge (``RosIrrigationEnv``) against a ``sim_node`` child, both
   ways: ``via="topic"`` (the default: a stepping command on ``~/irrigation_step``, answered on
   ``~/step_result`` and ``~/observation``) and ``via="service"`` (the typed ``~/step`` service,
   crop_sim_interfaces/srv/Step: the command in the request, the StepResult and observation in the reply).

All peers start once. On a shared machine the load changes from second to second, and a ratio of two
figures measured at different moments mixes the load into it; so the measurements are interleaved: in each
of ``--rounds`` rounds the bridge runs ``--seasons`` seasons each way, and every ``BLOCK_DAYS`` (20)
simulated days alternate with 20 bare Trigger round trips and 20 ping-pongs. Each round gives its own
ratio (the median time of a day through ROS / the median Trigger round trip measured alongside it),
printed with the load
during the round; the figure to quote is the median of the rounds' ratios. The target: a day through ROS
costs at most 3x the bare round trip. The figures pooled over all rounds (median, mean, p99, days per
second) are printed too. ``--baselines-only`` measures ``--calls`` round trips of each kind per round.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

SERVE_FLAG = "--serve-baseline"
# Days through the bridge between blocks of as many bare round trips of each kind: short enough that both
# see the same load, long enough that the peers' work left over from one kind hardly touches the other.
BLOCK_DAYS = 20
BASE_NAME = "ros_bench_peer"


def serve_baseline() -> int:
    """Child: a Trigger server and a topic echo, until SIGINT."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from crop_sim_interfaces.msg import IrrigationCommand
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_srvs.srv import Trigger

    rclpy.init()
    node = rclpy.create_node(BASE_NAME)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    pong = node.create_publisher(IrrigationCommand, "bench_pong", qos)
    node.create_subscription(IrrigationCommand, "bench_ping", pong.publish, qos)

    def trigger(request, response):
        response.success = True
        response.message = "ok"
        return response

    node.create_service(Trigger, "bench_trigger", trigger)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _summary(times_s: list[float]) -> dict:
    ordered = sorted(times_s)
    return {"n": len(ordered), "median_ms": 1e3 * statistics.median(ordered),
            "mean_ms": 1e3 * statistics.fmean(ordered),
            "p99_ms": 1e3 * ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]}


class Baselines:
    """The bare baselines' peer process and this process's client, connected once (a context manager)."""

    def __init__(self, warmup: int = 200):
        from crop_sim_interfaces.msg import IrrigationCommand
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from std_srvs.srv import Trigger

        from .spin import PrivateRos, wait_for_service, wait_for_subscribers
        from .process import NodeProcess

        self.peer = NodeProcess("crop_agent_ros.ros.bench", args=[SERVE_FLAG], name="baseline peer")
        self.ros = PrivateRos("ros_bench_client")
        try:
            self.client = self.ros.node.create_client(Trigger, "bench_trigger")
            wait_for_service(self.ros.executor, self.client, timeout=20)
            self.request = Trigger.Request()
            qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
            self.received = []
            self.ros.node.create_subscription(IrrigationCommand, "bench_pong", self.received.append, qos)
            self.ping = self.ros.node.create_publisher(IrrigationCommand, "bench_ping", qos)
            wait_for_subscribers(self.ros.executor, self.ping, timeout=20)
            self.ros.spin_until(lambda: self.ros.node.count_publishers("bench_pong") >= 1, 20, "the pong publisher")
            self.message = IrrigationCommand(irrigation_mm=5.0)  # its day: the ping's sequence number
            # discovery of the reverse direction: ping until the first pong comes back
            self.ros.spin_until(lambda: (self.ping.publish(self.message), bool(self.received))[1], 20,
                                "the first pong")
            self._sequence = 0
            self.trigger(warmup)
            self.ping_pong(warmup)
        except BaseException:
            self.close()
            raise

    def trigger(self, calls: int) -> list[float]:
        """Seconds of each of ``calls`` Trigger round trips."""
        times = []
        for _ in range(calls):
            t0 = time.perf_counter()
            self.ros.call(self.client, self.request)
            times.append(time.perf_counter() - t0)
        return times

    def ping_pong(self, calls: int) -> list[float]:
        """Seconds from each of ``calls`` pings to its pong."""
        times = []
        for _ in range(calls):
            self._sequence += 1
            sequence = self._sequence
            self.received.clear()
            self.message.day = sequence
            t0 = time.perf_counter()
            self.ping.publish(self.message)
            self.ros.spin_until(lambda: any(m.day == sequence for m in self.received), 10, "a pong")
            times.append(time.perf_counter() - t0)
        return times

    def close(self) -> None:
        try:
            self.ros.close()
        finally:
            self.peer.stop()

    def __enter__(self) -> "Baselines":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Bridge:
    """A ``sim_node`` child and a ``RosIrrigationEnv`` on it stepping ``via`` topic or service, connected
    once (a context manager)."""

    def __init__(self, via: str, tmp: Path, action_mm: float = 5.0):
        from .bridge import RosIrrigationEnv
        from .process import NodeProcess

        self.via, self.action_mm = via, action_mm
        namespace = f"/bench{os.getpid()}_{via}"
        self.sim = NodeProcess("crop_sim_ros.sim_node",
                               ros_args=["-r", f"__ns:={namespace}", "-p", f"log_path:={tmp / f'{via}.csv'}"],
                               name=f"sim_node ({via})", log_path=tmp / f"sim_node_{via}.out")
        self.env = None
        try:
            self.env = RosIrrigationEnv(sim_node=f"{namespace}/crop_sim", connect_timeout=30, via=via)
            self.env.reset(seed=0)  # warm-up season start
        except BaseException:
            self.close()
            raise

    def seasons(self, count: int, first_seed: int, before_each_day=None) -> tuple[list[float], float]:
        """Seconds of each simulated day of ``count`` whole seasons (``before_each_day()`` runs, untimed,
        before each), and the time spent in the days."""
        day_times = []
        for season in range(count):
            self.env.reset(seed=first_seed + season)
            done = False
            while not done:
                if before_each_day is not None:
                    before_each_day()
                t0 = time.perf_counter()
                _, _, terminated, truncated, _ = self.env.step(self.action_mm)
                day_times.append(time.perf_counter() - t0)
                done = terminated or truncated
        return day_times, sum(day_times)

    def close(self) -> None:
        try:
            if self.env is not None:
                self.env.close()
        finally:
            code = self.sim.stop()
            if code not in (0, None):
                print(f"sim_node ({self.via}) exited with {code}:\n{self.sim.output()[-2000:]}", file=sys.stderr)

    def __enter__(self) -> "Bridge":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def bench(rounds: int, seasons: int, vias: tuple[str, ...] = ("topic", "service")) -> dict:
    """The interleaved measurement (see the module docstring): per-round figures and the pooled ones."""
    from crop_sim_ros.throughput import MachineLoad, machine_summary

    figures = {"machine": machine_summary(), "rounds": []}
    pooled = {"trigger": [], "topic_ping_pong": [], **{f"bridge_{via}": [] for via in vias}}
    in_days = {via: 0.0 for via in vias}
    with tempfile.TemporaryDirectory(prefix="ros_bench_") as tmp, contextlib.ExitStack() as stack:
        baselines = stack.enter_context(Baselines())
        bridges = {via: stack.enter_context(Bridge(via, Path(tmp))) for via in vias}
        peers = (baselines.peer.pid, *(b.sim.pid for b in bridges.values()))
        for r in range(rounds):
            load = MachineLoad(own_pids=peers)
            times = {"trigger": [], "topic_ping_pong": []}
            days = [0]

            def baselines_every_block():
                if days[0] % BLOCK_DAYS == 0:
                    times["trigger"] += baselines.trigger(BLOCK_DAYS)
                    times["topic_ping_pong"] += baselines.ping_pong(BLOCK_DAYS)
                days[0] += 1

            for via, bridge in bridges.items():
                times[f"bridge_{via}"], spent = bridge.seasons(seasons, 1 + r * seasons, baselines_every_block)
                in_days[via] += spent
            row = {name: _summary(values) for name, values in times.items()}
            for via in vias:
                row[f"ratio_{via}"] = row[f"bridge_{via}"]["median_ms"] / row["trigger"]["median_ms"]
            row["load"] = load.figures()
            row["load_summary"] = load.summary()
            figures["rounds"].append(row)
            for name, values in times.items():
                pooled[name].extend(values)
    figures["pooled"] = {name: _summary(values) for name, values in pooled.items()}
    for via in vias:
        ratios = [row[f"ratio_{via}"] for row in figures["rounds"]]
        figures[f"ratio_{via}"] = {"per_round": ratios, "median_of_rounds": statistics.median(ratios)}
        figures["pooled"][f"bridge_{via}"]["days_per_second"] = len(pooled[f"bridge_{via}"]) / in_days[via]
    return figures


def bench_baselines_only(rounds: int, calls: int) -> dict:
    """The bare baselines alone, in ``rounds`` rounds."""
    from crop_sim_ros.throughput import MachineLoad, machine_summary

    figures = {"machine": machine_summary(), "rounds": []}
    pooled = {"trigger": [], "topic_ping_pong": []}
    with Baselines() as baselines:
        for _ in range(rounds):
            load = MachineLoad(own_pids=(baselines.peer.pid,))
            times = {"trigger": baselines.trigger(calls), "topic_ping_pong": baselines.ping_pong(calls)}
            figures["rounds"].append({**{k: _summary(v) for k, v in times.items()}, "load": load.figures(),
                                      "load_summary": load.summary()})
            for name, values in times.items():
                pooled[name].extend(values)
    figures["pooled"] = {name: _summary(values) for name, values in pooled.items()}
    return figures


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rounds", type=int, default=5, help="alternating measurement rounds (default 5, at most 100)")
    parser.add_argument("--calls", type=int, default=400,
                        help="with --baselines-only: round trips of each kind per round (default 400, at most 100000)")
    parser.add_argument("--seasons", type=int, default=1, help="seasons through the bridge per round, each way "
                                                                 "(default 1, at most 1000)")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument("--baselines-only", action="store_true", help="skip the bridge")


def run(args) -> int:
    from .process import isolated_ros_env, pick_domain_id

    from crop_sim_ros.usage import check_range
    for name, most in (("rounds", 100), ("calls", 100_000), ("seasons", 1_000)):
        check_range(f"--{name}", getattr(args, name), 1, most)
    # one private domain for this run and its children
    os.environ.update(isolated_ros_env(int(os.environ.get("ROS_DOMAIN_ID") or pick_domain_id(salt=37))))
    vias = () if args.baselines_only else ("topic", "service")
    figures = (bench_baselines_only(args.rounds, args.calls) if args.baselines_only
               else bench(args.rounds, args.seasons, vias))
    if args.json:
        print(json.dumps(figures, indent=1))
        return 0
    print(f"machine: {figures['machine']}")
    for i, row in enumerate(figures["rounds"], 1):
        parts = [f"Trigger {row['trigger']['median_ms']:.3f} ms", f"ping-pong {row['topic_ping_pong']['median_ms']:.3f} ms"]
        parts += [f"bridge {via} {row[f'bridge_{via}']['median_ms']:.3f} ms ({row[f'ratio_{via}']:.2f}x)" for via in vias]
        print(f"round {i}, medians: {', '.join(parts)}; {row['load_summary']}")
    for name, row in figures["pooled"].items():
        if not name.startswith("bridge_"):
            print(f"bare {name:16s} (all rounds) median {row['median_ms']:.3f} ms  mean {row['mean_ms']:.3f} ms  "
                  f"p99 {row['p99_ms']:.3f} ms  ({row['n']} calls)")
    for via, what in (("topic", "command on ~/irrigation_step -> step_result + observation"),
                      ("service", "typed ~/step service: command in, StepResult + observation out")):
        if via not in vias:
            continue
        b = figures["pooled"][f"bridge_{via}"]
        ratio = figures[f"ratio_{via}"]
        print(f"bridge via {via} ({what}), all rounds: median {b['median_ms']:.3f} ms  mean {b['mean_ms']:.3f} ms  "
              f"p99 {b['p99_ms']:.3f} ms per day; {b['days_per_second']:.0f} simulated days per second of "
              f"stepping ({b['n']} days)")
        print(f"  ratio to the bare Trigger round trip, per round: "
              f"{' '.join(f'{x:.2f}x' for x in ratio['per_round'])}; median of rounds {ratio['median_of_rounds']:.2f}x "
              f"(target <= 3x)")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if SERVE_FLAG in argv:
        return serve_baseline()
    parser = argparse.ArgumentParser(prog="python -m crop_agent_ros.ros.bench", description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
