"""Throughput on a shared, noisy machine: the best of repeated runs by wall and by CPU time (:class:`Rate`), and
what else ran during a measurement (:class:`MachineLoad`: each CPU's busy share from ``/proc/stat`` and the CPUs
other processes used, i.e. all busy time minus this process's own CPU time). Every benchmark (``crop-sim bench``,
the environment's, the sweeps' and the ROS bridge's) prints its figures with these.
"""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo; the platform's processor string elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine_summary() -> str:
    """CPU model, CPU count (and those this process may use), load averages over 1, 5 and 15 minutes."""
    usable = sorted(os.sched_getaffinity(0))
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    return (f"{cpu_model()}, {os.cpu_count()} CPUs (this process may use {_cpu_list(usable)}); "
            f"load average {load} (1, 5, 15 min)")


def _cpu_list(cpus: list[int]) -> str:
    return f"{cpus[0]}-{cpus[-1]}" if len(cpus) > 1 and cpus == list(range(cpus[0], cpus[-1] + 1)) else \
        ",".join(map(str, cpus))


def _busy_s_per_cpu(proc_stat: str | None = None) -> tuple[list[float], float]:
    """Seconds each CPU spent running processes since boot (/proc/stat, or its text: user, nice, system,
    irq, softirq), and the seconds the hypervisor took from all CPUs (steal)."""
    ticks = os.sysconf("SC_CLK_TCK")
    busy, stolen = [], 0
    for line in (Path("/proc/stat").read_text() if proc_stat is None else proc_stat).splitlines():
        name, *values = line.split()
        if name.startswith("cpu") and name != "cpu":
            user, nice, system, idle, iowait, irq, softirq, steal = (int(v) for v in values[:8])
            busy.append((user + nice + system + irq + softirq) / ticks)
            stolen += steal
    return busy, stolen / ticks


def cpu_s_of(pid: int) -> float:
    """CPU seconds (user + system) a live process has used (/proc/PID/stat fields 14 and 15); 0 if gone."""
    try:
        after_name = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(after_name[11]) + int(after_name[12])) / os.sysconf("SC_CLK_TCK")


class MachineLoad:
    """What ran on the machine between construction and :meth:`figures`: each CPU's busy share and the
    CPUs used by other processes (every CPU's busy time minus the CPU time of this process, threads
    included, and of ``own_pids``, e.g. its ROS peers, per second of wall time)."""

    def __init__(self, own_pids: tuple[int, ...] = ()):
        self._own_pids = tuple(own_pids)
        self._start = self._sample()

    def _sample(self) -> tuple[float, tuple[list[float], float], float]:
        own = sum(os.times()[:2]) + sum(cpu_s_of(pid) for pid in self._own_pids)
        return time.perf_counter(), _busy_s_per_cpu(), own

    def figures(self) -> dict:
        """wall_s; cpu_busy: each CPU's busy share; this_process_cpus, other_cpus: CPUs used on average;
        stolen_cpus: CPU time the hypervisor took (a virtual machine's host was busy too)."""
        (wall0, (busy0, stolen0), own0), (wall1, (busy1, stolen1), own1) = self._start, self._sample()
        wall = max(wall1 - wall0, 1e-9)
        busy = [(b - a) / wall for a, b in zip(busy0, busy1)]
        own = (own1 - own0) / wall
        return {"wall_s": wall, "cpu_busy": [min(b, 1.0) for b in busy], "this_process_cpus": own,
                "other_cpus": max(sum(busy) - own, 0.0), "stolen_cpus": (stolen1 - stolen0) / wall}

    def summary(self) -> str:
        f = self.figures()
        if f["wall_s"] < 0.2:  # /proc/stat counts in 10 ms ticks
            return f"{f['wall_s'] * 1e3:.0f} ms: too short to measure the load"
        ours = "this one" if not self._own_pids else "this one and its peers"
        stolen = f"; hypervisor took {f['stolen_cpus']:.2f} CPUs" if f["stolen_cpus"] >= 0.01 else ""
        return (f"CPUs busy {', '.join(f'{b:.0%}' for b in f['cpu_busy'])}; other processes "
                f"{f['other_cpus']:.2f} CPUs, {ours} {f['this_process_cpus']:.2f}{stolen}")


class Rate(NamedTuple):
    """A throughput: per second of wall time, and per second of this process's CPU time (threads included;
    on a shared machine the second holds better: time slices given to other processes do not count)."""

    per_s: float
    per_cpu_s: float


def best_rate(run_once, work: float, repeats: int) -> Rate:
    """The best of ``repeats`` calls of ``run_once()`` (each doing ``work`` units), by wall and by CPU time."""
    return interleaved_best_rates({"run": (run_once, work)}, repeats)["run"]


def interleaved_best_rates(runs: dict, repeats: int) -> dict[str, Rate]:
    """``runs``: name -> (run_once, work). Calls each ``run_once()`` in turn, ``repeats`` rounds (so every
    figure sees the same moments' load), and returns each one's best by wall and by CPU time."""
    wall, cpu = dict.fromkeys(runs, np.inf), dict.fromkeys(runs, np.inf)
    for _ in range(repeats):
        for name, (run_once, _) in runs.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            run_once()
            wall[name] = min(wall[name], time.perf_counter() - start)
            cpu[name] = min(cpu[name], time.process_time() - start_cpu)
    return {name: Rate(work / wall[name], work / max(cpu[name], 1e-9)) for name, (_, work) in runs.items()}


def figure_line(label: str, rate: Rate, unit: str, load: MachineLoad) -> str:
    """One printed figure, per second and per CPU-second, with the load during its measurement."""
    return (f"  {label:<48} {rate.per_s:>11,.0f} {unit}/s, {rate.per_cpu_s:>11,.0f} per CPU-s   "
            f"({load.summary()})")


def measured(label: str, measure, unit: str = "field-days", echo=print) -> Rate:
    """Run ``measure()`` (a :class:`Rate`), print it with the load during the measurement; return it."""
    load = MachineLoad()
    rate = measure()
    echo(figure_line(label, rate, unit, load))
    return rate
