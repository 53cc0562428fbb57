"""Simulated days per second through ROS, against bare rclpy baselines measured in the same run.

    python -m crop_agent_ros.ros_bench [--calls 2000] [--seasons 5]

Three measurements, each between two processes on this machine (Fast DDS, localhost discovery, a
private ROS_DOMAIN_ID):

1. bare std_srvs/Trigger round trip: a client in this process (call_async + its own spin_once loop)
   against a trivial server in a child process;
2. bare topic ping-pong: std_msgs/Float64MultiArray out, echoed back by the child;
3. whole seasons through the Gymnasium bridge (``RosIrrigationEnv``) against a ``sim_node`` child, both
   ways: ``via="topic"`` (the default: a stepping command on ``~/irrigation_step``, answered on
   ``~/step_result`` and ``~/observation``) and ``via="service"`` (a command on ``~/irrigation``, its
   acknowledgement, then the ``~/step`` service).

It prints per-call times (median, mean, p99), simulated days per second, and the ratio
(time of one simulated day through ROS) / (bare Trigger round trip), of the means and of the medians.
The target: a day through ROS costs at most 3x the bare round trip.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

SERVE_FLAG = "--serve-baseline"
BASE_NAME = "ros_bench_peer"


def serve_baseline() -> int:
    """Child: a Trigger server and a topic echo, until SIGINT."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import Trigger

    rclpy.init()
    node = rclpy.create_node(BASE_NAME)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    pong = node.create_publisher(Float64MultiArray, "bench_pong", qos)
    node.create_subscription(Float64MultiArray, "bench_ping", pong.publish, qos)

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


def bench_baselines(calls: int, warmup: int = 200) -> dict:
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import Trigger

    from .ros_client import PrivateRos, wait_for_service, wait_for_subscribers
    from .ros_process import NodeProcess

    peer = NodeProcess("crop_agent_ros.ros_bench", args=[SERVE_FLAG], name="baseline peer")
    ros = PrivateRos("ros_bench_client")
    try:
        client = ros.node.create_client(Trigger, "bench_trigger")
        wait_for_service(ros.executor, client, timeout=20)
        request = Trigger.Request()
        trigger_times = []
        for i in range(warmup + calls):
            t0 = time.perf_counter()
            ros.call(client, request)
            if i >= warmup:
                trigger_times.append(time.perf_counter() - t0)

        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        received = []
        ros.node.create_subscription(Float64MultiArray, "bench_pong", received.append, qos)
        ping = ros.node.create_publisher(Float64MultiArray, "bench_ping", qos)
        wait_for_subscribers(ros.executor, ping, timeout=20)
        ros.spin_until(lambda: ros.node.count_publishers("bench_pong") >= 1, 20, "the pong publisher")
        message = Float64MultiArray()
        # discovery of the reverse direction: ping until the first pong comes back
        ros.spin_until(lambda: (ping.publish(message), bool(received))[1], 20, "the first pong")
        topic_times = []
        for i in range(warmup + calls):
            received.clear()
            message.data = [float(i)]
            t0 = time.perf_counter()
            ping.publish(message)
            ros.spin_until(lambda: any(len(m.data) and m.data[0] == float(i) for m in received), 10, "a pong")
            if i >= warmup:
                topic_times.append(time.perf_counter() - t0)
        return {"trigger": _summary(trigger_times), "topic_ping_pong": _summary(topic_times)}
    finally:
        ros.close()
        peer.stop()


def bench_bridge(seasons: int, action_mm: float = 5.0, via: str = "topic") -> dict:
    from .bridge import RosIrrigationEnv
    from .ros_process import NodeProcess

    namespace = f"/bench{os.getpid()}"
    with tempfile.TemporaryDirectory(prefix="ros_bench_") as tmp:
        log = Path(tmp) / "season.csv"
        sim = NodeProcess("crop_sim_ros.sim_node", ros_args=["-r", f"__ns:={namespace}", "-p", f"log_path:={log}"],
                          name="sim_node", log_path=Path(tmp) / "sim_node.out")
        env = None
        try:
            env = RosIrrigationEnv(sim_node=f"{namespace}/crop_sim", connect_timeout=30, via=via)
            env.reset(seed=0)  # warm-up season start
            day_times = []
            days = 0
            t_all = time.perf_counter()
            for season in range(seasons):
                env.reset(seed=season)
                done = False
                while not done:
                    t0 = time.perf_counter()
                    _, _, terminated, truncated, _ = env.step(action_mm)
                    day_times.append(time.perf_counter() - t0)
                    days += 1
                    done = terminated or truncated
            elapsed = time.perf_counter() - t_all
            return {"via": via, "seasons": seasons, "days": days, "days_per_second": days / elapsed,
                    "step": _summary(day_times)}
        finally:
            if env is not None:
                env.close()
            code = sim.stop()
            if code not in (0, None):
                print(f"sim_node exited with {code}:\n{sim.output()[-2000:]}", file=sys.stderr)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--calls", type=int, default=2000, help="bare round trips per baseline (default 2000)")
    parser.add_argument("--seasons", type=int, default=5, help="seasons through the bridge (default 5)")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument("--baselines-only", action="store_true", help="skip the bridge")


def run(args) -> int:
    from .ros_process import isolated_ros_env, pick_domain_id

    # one private domain for this run and its children
    os.environ.update(isolated_ros_env(int(os.environ.get("ROS_DOMAIN_ID") or pick_domain_id(salt=37))))
    figures = {"baselines": bench_baselines(args.calls)}
    if not args.baselines_only:
        trigger = figures["baselines"]["trigger"]
        for via in ("topic", "service"):
            bridge = figures[f"bridge_{via}"] = bench_bridge(args.seasons, via=via)
            bridge["ratio_mean"] = bridge["step"]["mean_ms"] / trigger["mean_ms"]
            bridge["ratio_median"] = bridge["step"]["median_ms"] / trigger["median_ms"]
    if args.json:
        print(json.dumps(figures, indent=1))
        return 0
    for name, row in figures["baselines"].items():
        print(f"bare {name:16s} median {row['median_ms']:.3f} ms  mean {row['mean_ms']:.3f} ms  "
              f"p99 {row['p99_ms']:.3f} ms  ({row['n']} calls)")
    for via, what in (("topic", "command on ~/irrigation_step -> step_result + observation"),
                      ("service", "command on ~/irrigation + acknowledgement, ~/step service")):
        b = figures.get(f"bridge_{via}")
        if b is None:
            continue
        print(f"bridge via {via} ({what}): median {b['step']['median_ms']:.3f} ms  mean {b['step']['mean_ms']:.3f} ms  "
              f"p99 {b['step']['p99_ms']:.3f} ms per day; {b['days_per_second']:.0f} simulated days/s "
              f"({b['days']} days, {b['seasons']} seasons); ratio to the bare Trigger round trip: "
              f"mean {b['ratio_mean']:.2f}x, median {b['ratio_median']:.2f}x")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if SERVE_FLAG in argv:
        return serve_baseline()
    parser = argparse.ArgumentParser(prog="python -m crop_agent_ros.ros_bench", description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
