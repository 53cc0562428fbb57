"""``crop-sim bench``: throughput of the crop model (and of the irrigation environments, when present).

Prints field-days per second for one field (array path and scalar path) and for a batch of fields over a
full season. Machines here are shared and noisy: every run first prints the CPU model and the load average,
and every figure is followed by what else ran during its measurement (:class:`MachineLoad`: each CPU's
busy share from ``/proc/stat`` and the CPUs other processes used, i.e. all busy time minus this
process's own CPU time). Compare figures from one run, or from runs with the same load.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .model import DailyWeather, Management, field_parameters, initial_state, repeat_parameters, step
from .model import zhao2019_library
from .model.simple import SCALAR_MATH, scalar_parameters, scalar_state

SEASON_DAYS = 183


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


def _season_weather(days: int, n_fields: int, seed: int) -> list[np.ndarray]:
    """Synthetic but realistic Benton-summer weather, (days, n_fields): TMAX, TMIN degC, SRAD MJ m-2,
    rain mm, ET0 mm (the model's cost does not depend on the values)."""
    rng = np.random.default_rng(seed)
    tmax = rng.uniform(15, 35, (days, n_fields))
    return [tmax, tmax - rng.uniform(8, 16, (days, n_fields)), rng.uniform(8, 30, (days, n_fields)),
            rng.exponential(4, (days, n_fields)) * (rng.random((days, n_fields)) < 0.1),
            rng.uniform(2, 9, (days, n_fields))]


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


def bench_model(n_fields: int, repeats: int = 3, seed: int = 0, seasons: int = 1) -> Rate:
    """Best-of-``repeats`` field-days per second of the array path for ``n_fields`` over ``seasons``
    seasons (several for a small batch: long enough for the load figures)."""
    library = zhao2019_library()
    params = repeat_parameters(field_parameters(library.species("potato"),
                                                library.cultivar("potato", "Russet Burbank"),
                                                library.soil("Benton USA potato"), Management(co2_ppm=369.0)),
                               n_fields)
    weather = _season_weather(SEASON_DAYS, n_fields, seed)
    days = [DailyWeather(*(w[d] for w in weather)) for d in range(SEASON_DAYS)]
    irrigation = np.full(n_fields, 5.0)

    def run_once():
        for _ in range(seasons):
            state = initial_state(params)
            for day in days:
                state, _ = step(params, state, day, irrigation)

    return best_rate(run_once, seasons * n_fields * SEASON_DAYS, repeats)


def bench_scalar(repeats: int = 3, seed: int = 0, seasons: int = 1) -> Rate:
    """Best-of-``repeats`` field-days per second of the one-field scalar path over ``seasons`` seasons."""
    library = zhao2019_library()
    params = field_parameters(library.species("potato"), library.cultivar("potato", "Russet Burbank"),
                              library.soil("Benton USA potato"), Management(co2_ppm=369.0))
    weather = _season_weather(SEASON_DAYS, 1, seed)
    days = [DailyWeather(*(float(w[d, 0]) for w in weather)) for d in range(SEASON_DAYS)]
    one_field = scalar_parameters(params)

    def run_once():
        for _ in range(seasons):
            state = scalar_state(initial_state(params))
            for day in days:
                state, _ = step(one_field, state, day, 5.0, xp=SCALAR_MATH)

    return best_rate(run_once, seasons * SEASON_DAYS, repeats)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fields", type=int, default=10_000,
                        help="fields in the batched model and vector environment runs (default 10000)")
    parser.add_argument("--repeats", type=int, default=3, help="best of this many seasons (default 3)")
    parser.add_argument("--model-only", action="store_true", help="skip the environment benchmarks")


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


def run(args: argparse.Namespace) -> int:
    print(f"machine: {machine_summary()}")
    print(f"SIMPLE model, {SEASON_DAYS}-day season, one thread, best of {args.repeats}:")
    measured("N = 1 (array path, 20 seasons a run)", lambda: bench_model(1, args.repeats, seasons=20))
    measured("N = 1 (scalar path, 200 seasons a run)", lambda: bench_scalar(args.repeats, seasons=200))
    measured(f"N = {args.fields} (batched)", lambda: bench_model(args.fields, args.repeats))
    if not args.model_only:
        from .task.bench import bench_env  # the environment layer; imported only when asked for
        bench_env(num_fields=args.fields, repeats=args.repeats)
    print(f"machine after the run: load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0
