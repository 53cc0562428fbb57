"""The benchmarks' machine report (CPU model, load average, load during each figure) and the vector
environment's single-core option. Speed targets are checked by the benchmark commands, not here."""

import os
from pathlib import Path

import numpy as np
import pytest

from crop_sim_ros import bench
from crop_agent_ros.cli import main


def test_busy_seconds_per_cpu_from_proc_stat_text():
    ticks = os.sysconf("SC_CLK_TCK")
    text = ("cpu  300 10 100 5000 40 6 4 9 0 0\n"
            "cpu0 200 10 60 2000 30 5 3 2 0 0\n"  # busy: user nice system irq softirq, not idle, iowait, steal
            "cpu1 100 0 40 3000 10 1 1 7 0 0\n"
            "intr 12345 0 0\nctxt 999\n")
    busy, stolen = bench._busy_s_per_cpu(text)
    assert busy == pytest.approx([278 / ticks, 142 / ticks]) and stolen == pytest.approx(9 / ticks)


def test_machine_load_subtracts_this_process_and_its_peers(monkeypatch):
    samples = iter([(10.0, ([100.0, 50.0], 3.0), 7.0),  # wall s, (busy s per CPU, stolen s), ours
                    (12.0, ([101.8, 51.0], 3.1), 8.2)])
    monkeypatch.setattr(bench.MachineLoad, "_sample", lambda self: next(samples))
    figures = bench.MachineLoad().figures()
    # over 2 s: CPU 0 busy 1.8 s, CPU 1 1.0 s; this process (and peers) 1.2 CPU s -> others 1.6 CPU s
    assert figures["wall_s"] == pytest.approx(2.0)
    assert figures["cpu_busy"] == pytest.approx([0.9, 0.5])
    assert figures["this_process_cpus"] == pytest.approx(0.6)
    assert figures["other_cpus"] == pytest.approx(0.8)
    assert figures["stolen_cpus"] == pytest.approx(0.05)


def test_cpu_seconds_of_a_peer_process_count_as_ours():
    import subprocess
    import sys
    import time
    busy = subprocess.Popen([sys.executable, "-c", "import time\nt = time.process_time()\n"
                             "while time.process_time() - t < 0.5: pass\nimport sys; sys.stdout.write('done')\n"
                             "sys.stdout.flush(); time.sleep(30)"], stdout=subprocess.PIPE)
    try:
        assert busy.stdout.read(4) == b"done"
        assert bench._cpu_s_of(busy.pid) >= 0.5
    finally:
        busy.kill()
        busy.wait()
    time.sleep(0.05)
    assert bench._cpu_s_of(busy.pid) == 0.0  # gone


def test_bench_prints_the_cpu_model_and_the_load(capsys):
    model = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                 if line.startswith("model name"))
    assert main(["bench", "--model-only", "--fields", "2000", "--repeats", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"machine: {model}, {os.cpu_count()} CPUs") and "load average" in lines[0]
    figures = [line for line in lines if "field-days/s" in line and "per CPU-s" in line]
    assert len(figures) == 3
    for line in figures:
        assert "other processes" in line or "too short to measure the load" in line, line
    assert lines[-1].startswith("machine after the run: load average")


def test_on_one_cpu_pins_this_thread_and_restores_it():
    from crop_sim_ros.task.bench import on_one_cpu
    before = os.sched_getaffinity(0)
    cpu, inside = on_one_cpu(lambda: os.sched_getaffinity(0))
    assert inside == {min(before)} and cpu == min(before)
    assert os.sched_getaffinity(0) == before


def test_vector_env_noise_on_the_main_thread_gives_the_same_values():
    from crop_sim_ros.task.bench import on_one_cpu
    from crop_sim_ros.task.vector_env import IrrigationVectorEnv, PrefetchedNormal
    n = PrefetchedNormal.MIN_ROWS_TO_PREFETCH  # enough fields for the worker thread to be used
    threaded = IrrigationVectorEnv(n, noise_thread=True)
    inline = IrrigationVectorEnv(n, noise_thread=False)
    assert threaded.noise_thread and not inline.noise_thread
    actions = np.full((n, 1), 4.0, dtype=np.float32)
    obs_a, _ = threaded.reset(seed=5)
    obs_b, _ = inline.reset(seed=5)
    np.testing.assert_array_equal(obs_a, obs_b)
    assert threaded._noise_rng._next is not None and inline._noise_rng._next is None
    for _ in range(3):
        np.testing.assert_array_equal(threaded.step(actions)[0], inline.step(actions)[0])
    # by default: the thread only when this process may use a second CPU
    assert on_one_cpu(lambda: IrrigationVectorEnv(4).noise_thread)[1] is False
    assert IrrigationVectorEnv(4).noise_thread == (len(os.sched_getaffinity(0)) > 1)
