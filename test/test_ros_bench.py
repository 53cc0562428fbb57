"""``crop-sim ros-bench``: the bridge and the bare baselines measured interleaved, a ratio per round."""

from __future__ import annotations

import json
import math
import statistics

import ros_support  # noqa: F401, E402  (private ROS_DOMAIN_ID before any context exists)

from crop_agent_ros.cli import main  # noqa: E402
from crop_agent_ros.ros.bench import BLOCK_DAYS  # noqa: E402


def test_ros_bench_interleaves_baselines_with_the_bridge_days(capsys):
    assert main(["ros-bench", "--rounds", "2", "--seasons", "1", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert len(figures["rounds"]) == 2
    for row in figures["rounds"]:
        days = {via: row[f"bridge_{via}"]["n"] for via in ("topic", "service")}
        # a block of bare round trips of each kind before every BLOCK_DAYS days of each bridge
        blocks = sum(math.ceil(n / BLOCK_DAYS) for n in days.values())
        assert row["trigger"]["n"] == row["topic_ping_pong"]["n"] == blocks * BLOCK_DAYS
        for via in days:
            assert days[via] > 30  # a whole season
            assert row[f"ratio_{via}"] == row[f"bridge_{via}"]["median_ms"] / row["trigger"]["median_ms"]
        assert len(row["load"]["cpu_busy"]) >= 1 and row["load"]["other_cpus"] >= 0.0
    for via in ("topic", "service"):
        per_round = [row[f"ratio_{via}"] for row in figures["rounds"]]
        assert figures[f"ratio_{via}"] == {"per_round": per_round, "median_of_rounds": statistics.median(per_round)}
        assert figures["pooled"][f"bridge_{via}"]["n"] == sum(r[f"bridge_{via}"]["n"] for r in figures["rounds"])
    assert figures["machine"].split(",")[0] in open("/proc/cpuinfo").read()


def test_ros_bench_refuses_a_round_count_below_one(capsys):
    assert main(["ros-bench", "--rounds", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["crop-sim ros-bench: --rounds: 0 is not in 1..100"]
