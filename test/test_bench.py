"""The benchmarks' machine report (CPU model, load average, load during each figure: crop_sim_ros.throughput)
and the vector environment's single-core option. Speed targets are checked by the benchmark commands, not here."""

import os
from pathlib import Path

import numpy as np
import pytest

from crop_sim_ros import throughput
from crop_agent_ros.cli import main


def test_busy_seconds_per_cpu_from_proc_stat_text():
    ticks = os.sysconf("SC_CLK_TCK")
    text = ("cpu  300 10 100 5000 40 6 4 9 0 0\n"
            "cpu0 200 10 60 2000 30 5 3 2 0 0\n"  # busy: user nice system irq softirq, not idle, iowait, steal
            "cpu1 100 0 40 3000 10 1 1 7 0 0\n"
            "intr 12345 0 0\nctxt 999\n")
    busy, stolen = throughput._busy_s_per_cpu(text)
    assert busy == pytest.approx([278 / ticks, 142 / ticks]) and stolen == pytest.approx(9 / ticks)


def test_machine_load_subtracts_this_process_and_its_peers(monkeypatch):
    samples = iter([(10.0, ([100.0, 50.0], 3.0), 7.0),  # wall s, (busy s per CPU, stolen s), ours
                    (12.0, ([101.8, 51.0], 3.1), 8.2)])
    monkeypatch.setattr(throughput.MachineLoad, "_sample", lambda self: next(samples))
    figures = throughput.MachineLoad().figures()
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
        assert throughput.cpu_s_of(busy.pid) >= 0.5
    finally:
        busy.kill()
        busy.wait()
    time.sleep(0.05)
    assert throughput.cpu_s_of(busy.pid) == 0.0  # gone


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


# Sums over 300 fields x 200 days (every field matures once and autoresets), computed with the vector
# environment as it was before its speed work (commit 1eff249): per observation column, then rewards,
# terminations, truncations and rain_mm infos. Speed work must leave every number the environment produces
# unchanged; any change of the noise stream, the observation values or the rewards moves these sums by far
# more than the tolerance (which only allows for another machine's floating point).
_VECTOR_ENV_SUMS = {
    "benton-generated": (
        [359452.4362136978, 45827327.70283266, 3770862.0, 1548338.1556196213, 560033.0182009998, 1054185.586911559,
         36590.838615596294, 1289260.675264351, 22250700.0, 556080.7363862991, 110761.76035810262,
         1553390.9048080444, 565198.4322493179, 1059670.8134230375, 100170.00538547424, 1293474.8662901223,
         22250416.918945312, 558108.4078919888, 207229.08940532804, 6719804.535186768],
        [5132.051223911765, 300.0, 0.0, 36352.91593882425]),
    "benton-quota": (
        [211114.68895155418, 37101275.975444384, 3259430.0, 1521246.0764939785, 548601.0138944995,
         1034923.5451208949, 39949.769457638264, 1300050.794522196, 22250700.0, 547759.096241951, 114064.99728421122,
         1527552.1345607042, 554854.1697051665, 1041331.3007422686, 102918.31685580165, 1305514.9266686775,
         22250285.268798828, 550078.5571670532, 209955.52995111048, 4689633.560750917, 13544700.369262695,
         102924.62451195717, 0.0, 5606628.2816395555, 5785570.0, 482400.0, 60300.0, 176972.38869673616,
         286167.66602867673],
        [3570708.0596256116, 300.0, 0.0, 39743.58956119615]),
}


@pytest.mark.parametrize("scenario, mode", [("benton-generated", "NEXT_STEP"), ("benton-quota", "SAME_STEP")])
def test_vector_env_numbers_are_those_from_before_its_speed_work(scenario, mode):
    from gymnasium.vector import AutoresetMode
    from crop_sim_ros.task.vector_env import IrrigationVectorEnv
    fields = 300
    env = IrrigationVectorEnv(fields, scenario, autoreset_mode=AutoresetMode[mode], noise_thread=False)
    obs, _ = env.reset(seed=11)
    actions = np.random.default_rng(3)
    obs_sums = obs.astype(np.float64).sum(axis=0)
    totals = np.zeros(4)
    for _ in range(200):
        obs, rewards, terminated, truncated, infos = env.step(actions.uniform(0, 12, (fields, 1)).astype(np.float32))
        obs_sums += obs.astype(np.float64).sum(axis=0)
        totals += [rewards.sum(), terminated.sum(), truncated.sum(), infos["rain_mm"].sum()]
    expected_obs, expected_totals = _VECTOR_ENV_SUMS[scenario]
    np.testing.assert_allclose(obs_sums, expected_obs, rtol=1e-9)
    np.testing.assert_allclose(totals, expected_totals, rtol=1e-9)


def test_interleaved_rates_take_turns_and_keep_each_best(monkeypatch):
    calls = []
    clock = iter(np.arange(0.0, 100.0, 1.0))  # every clock reading 1 s after the one before
    monkeypatch.setattr(throughput.time, "perf_counter", lambda: next(clock))
    monkeypatch.setattr(throughput.time, "process_time", lambda: 0.5 * len(calls))  # 0.5 CPU s per call
    rates = throughput.interleaved_best_rates({"a": (lambda: calls.append("a"), 10.0),
                                          "b": (lambda: calls.append("b"), 30.0)}, repeats=3)
    assert calls == ["a", "b"] * 3
    # each run: wall readings one apart -> 1 s; CPU 0.5 s
    assert rates["a"] == pytest.approx(throughput.Rate(10.0, 20.0)) and rates["b"] == pytest.approx(throughput.Rate(30.0, 60.0))


def test_bench_env_prints_the_one_cpu_floors_and_their_bound():
    from crop_sim_ros.task.bench import bench_env
    lines = []
    results = bench_env(steps=20, num_fields=256, vector_steps=3, repeats=1, echo=lines.append)
    model, noise = results["model_floor_field_days"], results["noise_floor_field_days"]
    bound = results["one_cpu_bound_field_days"]
    assert bound.per_cpu_s == pytest.approx(model.per_cpu_s * noise.per_cpu_s / (model.per_cpu_s + noise.per_cpu_s))
    assert bound.per_s == pytest.approx(model.per_s * noise.per_s / (model.per_s + noise.per_s))
    printed = "\n".join(lines)
    for label in ("CPU", "floor: model step alone", "floor: noise alone (10 normals/field-day)",
                  "bound 1/(1/model + 1/noise)"):
        assert label in printed, label
    assert sum("field-days/s" in line and "per CPU-s" in line for line in lines) == 5  # + the threaded figure
