"""``crop-sim sweep-bench``: trials per hour of ``crop-sim sweep`` with 1 and with 2 CPUs, in one run.

Each round runs the same small sweep (``--trials`` trials of ``benton-quota``, ``--timesteps`` steps each, a
tiny evaluation without the oracle) once on a local Ray instance with 1 CPU and once with 2, alternating
which goes first, so both sides of the ratio see the same moments of a shared machine. Every sweep runs in
its own loopback-only network namespace (``unshare -n``; Ray would otherwise bind the outside interface).
An untimed one-trial sweep warms the disk cache first. Printed: the CPU model and load, each sweep's wall time,
trials per hour and the load during it (CPUs the sweep's own processes used, found by their namespace, and
CPUs used by other processes), each round's ratio (2 CPUs / 1 CPU) and their median. A sweep's wall time
includes starting its Ray instance (a few seconds), as a user's would.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import yaml

from crop_sim_ros.usage import UsageError

LOOPBACK = "ip link set lo up && exec \"$@\""


def add_arguments(parser) -> None:
    parser.add_argument("--trials", type=int, default=4, help="trials per sweep (training seeds 0..N-1)")
    parser.add_argument("--timesteps", type=int, default=20000, help="training steps per trial")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of (1 CPU, 2 CPUs), order alternating")
    parser.add_argument("--out", type=Path, default=Path("runs") / "sweep-bench", help="scratch folder (replaced)")


def loopback_prefix() -> list[str]:
    """The command prefix that runs a command in a new network namespace with only loopback up (root:
    ``unshare -n``; otherwise a user namespace, ``unshare -rn``); UsageError if neither works here."""
    for unshare in (["unshare", "-n"], ["unshare", "-rn"]):
        probe = subprocess.run([*unshare, "sh", "-c", LOOPBACK, "sh", "true"], capture_output=True)
        if probe.returncode == 0:
            return [*unshare, "sh", "-c", LOOPBACK, "sh"]
    raise UsageError("cannot make a loopback-only network namespace (`unshare -n` / `unshare -rn`); the benchmark "
                     "runs Ray only inside one")


class NamespaceCpu:
    """CPU seconds used by every process in the network namespace of ``pid`` (the sweep, its Ray instance and
    workers, however they are parented): /proc is polled every ``interval_s`` and each process's last seen
    user + system time is kept, so a process that lived less than one interval is missed. Reaped-children
    counters (what ``os.times`` sees) miss Ray's workers, which their raylet, not the sweep, reaps."""

    def __init__(self, pid: int, interval_s: float = 0.5):
        self._namespace = self._new_namespace_of(pid)
        self._interval_s = interval_s
        self._cpu_s: dict[int, float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()

    @staticmethod
    def _new_namespace_of(pid: int, timeout_s: float = 10.0) -> str:
        """The network namespace of ``pid`` once it has left ours (``unshare`` does so just after it starts)."""
        ours = os.readlink("/proc/self/ns/net")
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                namespace = os.readlink(f"/proc/{pid}/ns/net")
            except OSError as error:
                raise RuntimeError(f"the sweep (pid {pid}) ended before it entered its namespace") from error
            if namespace != ours:
                return namespace
            time.sleep(0.005)
        raise RuntimeError(f"the sweep (pid {pid}) did not leave this network namespace in {timeout_s:.0f} s")

    def _poll(self) -> None:
        from crop_sim_ros.throughput import cpu_s_of
        while True:
            for entry in Path("/proc").iterdir():
                if not entry.name.isdigit():
                    continue
                try:
                    if os.readlink(entry / "ns" / "net") != self._namespace:
                        continue
                except OSError:
                    continue
                cpu_s = cpu_s_of(int(entry.name))
                if cpu_s > 0.0:
                    self._cpu_s[int(entry.name)] = cpu_s
            if self._stop.wait(self._interval_s):
                return

    def stop(self) -> float:
        """Stop polling; the CPU seconds seen."""
        self._stop.set()
        self._thread.join()
        return sum(self._cpu_s.values())


def sweep_config(trials: int, timesteps: int) -> dict:
    return {"name": "bench", "tasks": ["benton-quota"], "seeds": list(range(trials)),
            "train": {"timesteps": timesteps, "n-envs": 16, "n-steps": 128, "batch-size": 512,
                      "eval-freq": max(timesteps // 2, 1), "validation-seasons": 4, "no-progress": True},
            "evaluate": {"sets": "heldout-real", "noise-seeds": 1, "bootstrap": 100, "oracle": False,
                         "curves": False},
            "retries": 0}


def run_sweep(prefix: list[str], crop_sim: str, config: Path, cpus: int, out: Path) -> tuple[float, float]:
    """Run ``crop-sim sweep CONFIG --cpus CPUS --out OUT`` in its own loopback-only namespace; (wall time s,
    CPUs the sweep's processes used on average). Exits with the sweep's error if it fails."""
    started = time.perf_counter()
    sweep = subprocess.Popen([*prefix, crop_sim, "sweep", str(config), "--cpus", str(cpus), "--out", str(out)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    namespace_cpu = NamespaceCpu(sweep.pid)
    _, stderr = sweep.communicate()
    wall = time.perf_counter() - started
    sweep_cpus = namespace_cpu.stop() / wall
    if sweep.returncode != 0:
        print(stderr[-3000:], file=sys.stderr)
        raise SystemExit(f"crop-sim sweep-bench: the sweep with {cpus} CPU(s) exited {sweep.returncode}")
    return wall, sweep_cpus


def run(args) -> int:
    from crop_sim_ros.throughput import MachineLoad, machine_summary
    for name, value, high in (("--trials", args.trials, 64), ("--timesteps", args.timesteps, 10_000_000),
                              ("--rounds", args.rounds, 20)):
        if not 1 <= value <= high:
            raise UsageError(f"{name} {value}: must be in 1..{high:,}")
    prefix = loopback_prefix()
    shutil.rmtree(args.out, ignore_errors=True)
    args.out.mkdir(parents=True)
    config = args.out / "bench.yaml"
    config.write_text(yaml.safe_dump(sweep_config(args.trials, args.timesteps)))
    crop_sim = str(Path(sys.executable).parent / "crop-sim")
    print(f"machine: {machine_summary()}")
    print(f"sweep: {args.trials} trials of benton-quota, {args.timesteps:,} training steps each, tiny evaluation; "
          f"{args.rounds} round(s) of 1 and 2 CPUs")
    # Untimed: the first sweep after a while reads torch, Ray and the task data from disk (a cold round 0 took
    # 88 s against 55 s for the same 1-CPU sweep later in the run).
    warm_up = args.out / "warm-up.yaml"
    warm_up.write_text(yaml.safe_dump(sweep_config(1, min(args.timesteps, 2048))))
    run_sweep(prefix, crop_sim, warm_up, 1, args.out / "warm-up")
    ratios, figures = [], []
    for round_index in range(args.rounds):
        per_cpus = {}
        for cpus in ((1, 2) if round_index % 2 == 0 else (2, 1)):
            out = args.out / f"round{round_index}-cpus{cpus}"
            load = MachineLoad()
            wall, sweep_cpus = run_sweep(prefix, crop_sim, config, cpus, out)
            machine = load.figures()
            others = max(sum(machine["cpu_busy"]) - sweep_cpus, 0.0)
            rows = json.loads((out / "table.json").read_text())["rows"]
            finished = sum(1 for r in rows if r["status"] == "finished")
            per_hour = finished / wall * 3600.0
            per_cpus[cpus] = per_hour
            figures.append({"round": round_index, "cpus": cpus, "wall_s": round(wall, 1), "finished": finished,
                            "trials_per_hour": round(per_hour, 1), "sweep_cpus": round(sweep_cpus, 2),
                            "other_cpus": round(others, 2), "load": machine})
            print(f"round {round_index}, {cpus} CPU(s): {finished}/{len(rows)} trials in {wall:.1f} s = "
                  f"{per_hour:.0f} trials/hour; the sweep used {sweep_cpus:.2f} CPUs, other processes "
                  f"{others:.2f}, the hypervisor {machine['stolen_cpus']:.2f} (CPUs busy "
                  f"{', '.join(f'{b:.0%}' for b in machine['cpu_busy'])})", flush=True)
        ratios.append(per_cpus[2] / per_cpus[1])
        print(f"round {round_index}: 2 CPUs / 1 CPU = {ratios[-1]:.2f}x", flush=True)
    print(f"median ratio over {len(ratios)} round(s): {statistics.median(ratios):.2f}x "
          f"(rounds: {', '.join(f'{r:.2f}x' for r in ratios)}); machine after: {machine_summary()}")
    (args.out / "bench.json").write_text(json.dumps({"machine": machine_summary(), "runs": figures,
                                                     "ratios": ratios}, indent=1) + "\n")
    return 0
