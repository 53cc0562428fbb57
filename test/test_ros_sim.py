"""The simulator node over ROS 2: a season grown by the agent node in another process, topics, the season
log, bad inputs, resets, concurrent clients, a command racing a step, a crash and a restart, free running.

Every node runs as its own process (``python -m crop_sim_ros.sim_node``, exactly what ``ros2 run`` starts),
on this test process's private ROS_DOMAIN_ID and a namespace of its own (see ros_support).
"""

from __future__ import annotations

import json
import math
import os
import threading
import time
import uuid
from datetime import date

import numpy as np
import pytest


import ros_support  # noqa: E402  (sets ROS_DOMAIN_ID / discovery range before any context exists)
from rosgraph_msgs.msg import Clock  # noqa: E402
from crop_sim_interfaces.msg import (CropState, Forecast, IrrigationCommand, IrrigationStatus, StepResult,  # noqa: E402
                                     Weather)
from std_msgs.msg import Float32MultiArray, Header  # noqa: E402

from crop_agent_ros.ros.spin import PrivateRos, call  # noqa: E402
from crop_agent_ros.ros.process import (NodeProcess, StillRunning, _shm_files_of, clean_dead_ports,  # noqa: E402
                                        isolated_ros_env)
from crop_agent_ros.ros.sim_client import SimError  # noqa: E402
from crop_sim_ros import ros_interface as ri  # noqa: E402
from ros_support import connect, raw_step, ros, set_parameter, step_client, wait_for  # noqa: E402, F401 (ros: a fixture)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def shared_sim(tmp_path_factory):
    """One simulator for the tests that reset it first; started from the shipped parameter file."""
    tmp = tmp_path_factory.mktemp("shared_sim")
    process, name, log = ros_support.start_sim(tmp, params_file=ros_support.PARAMS_FILE)
    yield process, name, log
    assert process.stop() == 0, process.output()


# --- a season grown by two processes ------------------------------------------------------------------------

def test_sim_and_agent_processes_grow_a_season(tmp_path, ros):
    sim, name, log = ros_support.start_sim(tmp_path, params={"seed": 3})
    agent = None
    try:
        got = {key: [] for key in ("obs", "crop", "today", "forecast", "result", "clock")}
        subs = [
            ros.node.create_subscription(Float32MultiArray, f"{name}/observation",
                                         lambda m: got["obs"].append(ri.observation_from_message(m)), ri.READER_QOS),
            ros.node.create_subscription(CropState, f"{name}/crop_state", got["crop"].append, ri.READER_QOS),
            ros.node.create_subscription(Weather, f"{name}/weather/today", got["today"].append, ri.READER_QOS),
            ros.node.create_subscription(Forecast, f"{name}/weather/forecast", got["forecast"].append, ri.READER_QOS),
            ros.node.create_subscription(StepResult, f"{name}/step_result", got["result"].append, ri.READER_QOS),
            ros.node.create_subscription(Clock, "/clock", lambda m: got["clock"].append(m.clock.sec), ri.CLOCK_QOS),
        ]
        ros.spin_until(lambda: all(s.get_publisher_count() >= 1 for s in subs), 30, "the simulator's topics")
        # Seeing a publisher is not being matched by it (a volatile message sent before the writer has matched
        # this reader is lost: a run here heard days only from 82 of 153). So step until every topic has been
        # heard, then forget that warm-up: the agent resets the simulator into a new episode.
        for _ in range(20):
            last = raw_step(ros, name)["day"]
            try:
                ros.spin_until(lambda: all(got.values()), 1.0, "every topic")
                break
            except TimeoutError:
                continue
        assert all(got.values()), {key: len(values) for key, values in got.items()}
        # the last warm-up day's messages (some published after the step's answer) have all arrived: forget them
        warm_clock = ri.sim_time(date(2000, 4, 1), last).sec
        ros.spin_until(lambda: got["clock"][-1] == warm_clock and got["result"][-1].day == last
                       and int(got["obs"][-1][ri.OBS_DAY]) == last and got["forecast"][-1].weather.day == last + 1
                       and all(got[k][-1].day == last for k in ("crop", "today")), 10, "the warm-up's last day")
        for values in got.values():
            values.clear()
        agent = NodeProcess("crop_agent_ros.ros.agent_node", env=isolated_ros_env(), name="agent_node",
                            ros_args=["-p", f"sim_node:={name}", "-p", "policy:=refill", "-p", "drive:=true"],
                            log_path=tmp_path / "agent.out")
        ros.spin_until(lambda: agent.poll() is not None, 60, "the agent to grow its season")
        output = agent.output()
        assert agent.poll() == 0, output
        summaries = [json.loads(line.split("season summary: ", 1)[1]) for line in output.splitlines()
                     if line.startswith("season summary: ")]
        assert len(summaries) == 1
        season = summaries[0]
        assert season["matured"] and season["yield_t_ha"] > 5 and season["irrigation_mm"] > 0
        episode = season["episode"]

        # the log: one row per day of the agent's episode, days 0..N-1, consistent with the summary
        rows = [r for r in ros_support.read_log(log) if int(r["episode"]) == episode]
        assert [int(r["day"]) for r in rows] == list(range(season["days"]))
        assert math.isclose(sum(float(r["irrigation_mm"]) for r in rows), season["irrigation_mm"], rel_tol=1e-12)
        assert float(rows[-1]["episode_return"]) == pytest.approx(season["return"], rel=1e-12)
        assert rows[-1]["terminated"] == "1" and float(rows[-1]["end_yield_t_ha"]) == season["yield_t_ha"]
        assert all(r["scenario"] == "benton-generated" and r["seed"] == "3" for r in rows)
        by_day = {int(r["day"]): r for r in rows}

        # topics: every message names its day and agrees exactly with the observation of that day
        ros.spin_until(lambda: got["result"] and got["result"][-1].day == season["days"], 10, "the last day")
        observations = {}
        for obs in got["obs"]:
            observations.setdefault(int(obs[ri.OBS_DAY]), []).append(obs)
        for day, row in by_day.items():  # the log's observation columns are the topic's float32 values
            if day in observations and day > 0:
                # the paper's 20 observation columns (a family task's 9 more are empty for it)
                logged = np.array([float(row[c]) for c in row if c.startswith("obs_") and row[c] != ""],
                                  dtype=np.float32)
                assert any(o.tobytes() == logged.tobytes() for o in observations[day])
        final = observations[season["days"]][-1]
        # the typed topics: named fields equal to the observation's values, stamped in farm time, frame the field
        crop, today, forecast = got["crop"][-1], got["today"][-1], got["forecast"][-1]
        assert (crop.episode, crop.day, crop.paw_observed, crop.mature) == (episode, season["days"], True, True)
        assert (crop.biomass_t_ha, crop.paw_mm, crop.thermal_time_degc_d) == (
            float(final[ri.OBS_BIOMASS]), float(final[ri.OBS_PAW]), float(final[ri.OBS_THERMAL_TIME]))
        assert 0.0 <= crop.canopy_fsolar <= 1.0
        assert today.day == season["days"] and ri.weather_of(today) == final[ri.OBS_TODAY].astype(float).tolist()
        assert forecast.weather.day == season["days"] + 1
        assert ri.weather_of(forecast.weather) == final[ri.OBS_FORECAST].astype(float).tolist()
        assert forecast.rain_sd_mm == 3.0 and forecast.tmax_sd_degc == 3.0  # the paper's noise (scenario.py)
        expected_stamp = ri.sim_time(date(2000, 4, 1), season["days"]).sec
        frame = name.rsplit("/", 2)[1]  # the namespace the simulator runs under
        for message in (crop, today, forecast, got["result"][-1]):
            assert (message.header.stamp.sec, message.header.frame_id) == (expected_stamp, frame)
        assert forecast.weather.header.stamp.sec == expected_stamp + 86400
        result = got["result"][-1]
        assert result.episode == episode and result.terminated and result.yield_t_ha == season["yield_t_ha"]
        assert result.episode_return == pytest.approx(season["return"], rel=1e-12)
        days_seen = [r.day for r in got["result"] if r.episode == episode]
        assert days_seen == sorted(days_seen) and len(days_seen) > season["days"] // 2

        # /clock in farm time, in day order; a late subscriber (transient local) gets the latest day at once
        expected = ri.sim_time(date(2000, 4, 1), season["days"]).sec
        ros.spin_until(lambda: got["clock"] and got["clock"][-1] == expected, 10, "farm time on /clock")
        assert got["clock"] == sorted(got["clock"])
        late = []
        ros.node.create_subscription(Float32MultiArray, f"{name}/observation",
                                     lambda m: late.append(ri.observation_from_message(m)), ri.LATCHED_READER_QOS)
        ros.spin_until(lambda: late, 10, "the latched observation")
        assert late[-1].tobytes() == final.tobytes()
    finally:
        if agent is not None:
            agent.stop()
        assert sim.stop() == 0, sim.output()


# --- bad input ------------------------------------------------------------------------------------------------

def test_bad_commands_are_rejected_and_never_applied(shared_sim, ros):
    _, name, log = shared_sim
    client = connect(ros, name)
    client.reset(seed=11)
    episode = client.episode
    statuses: list[IrrigationStatus] = []
    status_sub = ros.node.create_subscription(IrrigationStatus, f"{name}/irrigation_status", statuses.append,
                                              ri.READER_QOS)
    publisher = ros.node.create_publisher(IrrigationCommand, f"{name}/irrigation", ri.COMMAND_QOS)
    ros.spin_until(lambda: publisher.get_subscription_count() >= 1 and status_sub.get_publisher_count() >= 1, 20,
                   "the simulator's command topics")
    client.step(5.0)  # day 0 -> 1, with an accepted command
    day_1 = Header(stamp=ri.sim_time(client.sowing, 1), frame_id=client.field)
    other_day, other_field = ri.sim_time(client.sowing, 2), "field3"

    def command(day, mm, header=day_1, command_episode=episode):
        return IrrigationCommand(header=header, day=day, irrigation_mm=mm, episode=command_episode)

    bad = [  # (what the refusal says, the command)
        ("not a finite", command(1, math.nan)), ("not a finite", command(1, math.inf)),
        ("negative", command(1, -1.0)), ("exceeds", command(1, 100.5)), ("past", command(0, 5.0)),
        ("future", command(2, 5.0)), ("episode", command(1, 5.0, command_episode=episode - 1)),
        (f"frame_id '{other_field}' is not", command(1, 5.0, Header(stamp=day_1.stamp, frame_id=other_field))),
        ("header.stamp", command(1, 5.0, Header(stamp=other_day, frame_id=client.field)))]
    for _, sent in bad:
        publisher.publish(sent)
    rejected = lambda: [s for s in statuses if s.fate == IrrigationStatus.REFUSED]  # noqa: E731
    ros.spin_until(lambda: len(rejected()) >= len(bad), 10, "the status of every bad command")
    assert len(rejected()) == len(bad)
    assert [s.command.irrigation_mm for s in statuses if s.fate == IrrigationStatus.ACCEPTED] in ([], [5.0])
    for (word, sent), refusal in zip(bad, rejected()):  # one refusal each, in order, with the command as sent
        assert word in refusal.message and refusal.message.startswith("rejected: "), (word, refusal.message)
        assert (refusal.current_day, refusal.episode, refusal.header) == (1, episode, day_1)
        assert refusal.command.header == sent.header and refusal.command.day == sent.day
        assert math.isnan(refusal.applied_mm) and refusal.sequence > 0
    summary = raw_step(ros, name)  # nothing bad was applied on day 1: no command, 0 mm
    assert summary["success"] and summary["day"] == 2
    assert summary["irrigation_mm"] == 0.0 and summary["command_sequence"] == -1
    client.day = 2
    _, _, _, _, summary = client.step(100.0)  # the limit itself is fine
    assert summary["irrigation_mm"] == 100.0
    rows = [r for r in ros_support.read_log(log) if int(r["episode"]) == episode]
    assert [float(r["irrigation_mm"]) for r in rows] == [5.0, 0.0, 100.0]

    # run to the end: a step after the season ended fails cleanly, commands are refused, reset works
    done = False
    while not done:
        _, _, terminated, truncated, _ = client.step(3.0)
        done = terminated or truncated
    summary = raw_step(ros, name)
    assert not summary["success"] and "ended" in summary["error"] and summary["day"] == client.day
    client.ended = False
    with pytest.raises(SimError, match="ended"):
        client.command(1.0)
    client.reset(seed=11)
    assert client.day == 0


def test_bad_parameters_are_refused(shared_sim, ros):
    _, name, _ = shared_sim
    cases = {"scenario": "no-such-scenario", "crop": "banana", "soil": "moon dust", "mode": "fast"}
    for key, value in cases.items():
        (result,) = set_parameter(ros, name, **{key: value})
        assert not result.successful and result.reason, key
    (result,) = set_parameter(ros, name, seed=-5)  # outside the declared range
    assert not result.successful
    (result,) = set_parameter(ros, name, co2_ppm=-0.5)
    assert not result.successful and "co2_ppm" in result.reason
    client = connect(ros, name)
    _, info = client.reset(seed=2)  # the node still works with its old values
    assert info["scenario"] == "benton-generated"


def test_startup_errors_exit_non_zero_with_a_clear_message(tmp_path):
    broken = tmp_path / "broken.csv"
    broken.write_text("this is not,an AgWeatherNet file\n1,2\n")
    scenario = tmp_path / "broken.yaml"
    scenario.write_text(f"name: broken\nsowing_date: 2000-04-01\nweather:\n  kind: file\n  path: {broken}\n"
                        "  format: agweathernet\n")
    absurd = tmp_path / "absurd.yaml"  # a season of 20,000 days (the scenario's bound refuses it)
    absurd.write_text("base: benton-generated\nname: absurd\nmax_season_days: 20000\n")
    text = tmp_path / "notes.txt"  # any readable file given as the scenario: refused without being quoted
    text.write_text("confidential line one of the notes\nconfidential: line two\n")
    cases = {"unknown scenario": {"scenario": "no-such-scenario"}, "unknown crop": {"crop": "banana"},
             "broken weather file": {"scenario": str(scenario)}, "absurd season length": {"scenario": str(absurd)},
             "not a scenario": {"scenario": str(text)}, "weather season beyond the pool": {"weather_season": 1000}}
    processes = {what: ros_support.start_sim(tmp_path, params=params, log_name=f"{i}.csv")[0]
                 for i, (what, params) in enumerate(cases.items())}
    try:
        said = {}
        for what, process in processes.items():
            assert process.wait(60) == 2, (what, process.output())
            output = process.output()
            lines = [line for line in output.splitlines() if "cannot start" in line]
            assert len(lines) == 1 and "Traceback" not in output, (what, output)  # one line, no traceback
            said[what] = lines[0]
        assert "no-such-scenario" in said["unknown scenario"]
        assert "banana" in said["unknown crop"]
        assert "broken.csv" in said["broken weather file"]
        assert "max_season_days" in said["absurd season length"] and str(absurd) in said["absurd season length"]
        assert str(text) in said["not a scenario"] and "confidential" not in processes["not a scenario"].output()
        assert "weather_season" in said["weather season beyond the pool"]
    finally:
        for process in processes.values():
            process.stop()


# --- resets, concurrency, races ------------------------------------------------------------------------------

def test_reset_mid_season(shared_sim, ros):
    _, name, log = shared_sim
    client = connect(ros, name)
    client.reset(seed=4)
    first = client.episode
    for _ in range(5):
        client.step(2.0)
    client.command(7.0)  # accepted for day 5 of the old episode ...
    obs, info = client.reset(seed=4)  # ... and dropped by the reset
    assert info["episode"] == first + 1 and info["day"] == 0 and obs[ri.OBS_DAY] == 0
    result = raw_step(ros, name)
    assert result["day"] == 1 and result["irrigation_mm"] == 0.0 and result["command_sequence"] == -1
    client.day = 1
    with pytest.raises(SimError, match="episode"):  # a command of the old episode is refused
        client.episode = first
        client.command(1.0)
    rows = ros_support.read_log(log)
    old = [r for r in rows if int(r["episode"]) == first]
    new = [r for r in rows if int(r["episode"]) == first + 1]
    assert [int(r["day"]) for r in old] == [0, 1, 2, 3, 4]
    assert [(int(r["day"]), float(r["irrigation_mm"])) for r in new] == [(0, 0.0)]


def test_two_clients_stepping_concurrently_are_serialised(shared_sim):
    _, name, log = shared_sim
    with PrivateRos(f"setup_{uuid.uuid4().hex[:6]}") as setup:
        client = connect(setup, name)
        client.reset(seed=5)
        episode = client.episode
    n = 40
    days: dict[int, list[int]] = {0: [], 1: []}
    errors = []

    def stepper(k):
        try:
            with PrivateRos(f"stepper{k}_{uuid.uuid4().hex[:6]}") as ros:
                # one step each, one after the other, so that each client's first request (which DDS may lose
                # right after discovery) is handled safely; then both step at the same time
                if k == 1:
                    warmed.wait(60)
                raw_step(ros, name)
                step = ros.__dict__["_raw_step"][name][0]
                if k == 0:
                    warmed.set()
                ready.wait(60)
                for _ in range(n):
                    response = call(ros.executor, step, ros_support.pending_step())
                    assert response.success, response.message
                    days[k].append(response.result.day)
        except BaseException as error:  # noqa: BLE001
            errors.append(error)

    warmed = threading.Event()
    ready = threading.Barrier(2)  # both clients connected: then they step at the same time
    threads = [threading.Thread(target=stepper, args=(k,)) for k in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors, errors
    assert sorted(days[0] + days[1]) == list(range(3, 2 * n + 3)), "every day exactly once"
    assert days[0] == sorted(days[0]) and days[1] == sorted(days[1])
    rows = [r for r in ros_support.read_log(log) if int(r["episode"]) == episode]
    assert [int(r["day"]) for r in rows] == list(range(2 * n + 2))


def test_command_racing_step_is_applied_exactly_once_to_its_day(shared_sim):
    """One client floods commands (for the day it believes current, and the next) while another steps:
    every day gets the latest command accepted for it (by sequence number), or 0 mm, never another day's."""
    _, name, log = shared_sim
    with PrivateRos(f"setup_{uuid.uuid4().hex[:6]}") as setup:
        client = connect(setup, name)
        client.reset(seed=6)
        episode = client.episode
    n_steps = 60
    acks: list[IrrigationStatus] = []
    stop = threading.Event()
    errors = []
    current = {"day": 0}

    def commander():
        try:
            with PrivateRos(f"commander_{uuid.uuid4().hex[:6]}") as ros:
                ros.node.create_subscription(IrrigationStatus, f"{name}/irrigation_status", acks.append,
                                             ri.READER_QOS)
                ros.node.create_subscription(StepResult, f"{name}/step_result",
                                             lambda m: current.__setitem__("day", m.day), ri.READER_QOS)
                publisher = ros.node.create_publisher(IrrigationCommand, f"{name}/irrigation", ri.COMMAND_QOS)
                ros.spin_until(lambda: publisher.get_subscription_count() >= 1, 20, "the command subscriber")
                rng = np.random.default_rng(0)
                sent = 0
                while not stop.is_set():
                    if not flowing.is_set() and any(a.fate == IrrigationStatus.ACCEPTED for a in acks):
                        flowing.set()  # commands are accepted and acknowledged: the stepper may start
                    day = current["day"] + int(rng.integers(0, 2))
                    publisher.publish(IrrigationCommand(day=day, irrigation_mm=float(rng.integers(1, 100))))
                    sent += 1
                    # the next command once this one is answered: one in flight, racing the steps. (The simulator
                    # keeps every command: sent faster than it takes them, they would queue and all come late.)
                    answered = time.monotonic() + 0.05
                    while len(acks) < sent and time.monotonic() < answered:
                        ros.executor.spin_once(timeout_sec=0.005)
                end = time.monotonic() + 0.3  # collect the last acknowledgements
                while time.monotonic() < end:
                    ros.executor.spin_once(timeout_sec=0.05)
        except BaseException as error:  # noqa: BLE001
            errors.append(error)

    flowing = threading.Event()
    thread = threading.Thread(target=commander)
    thread.start()
    try:
        with PrivateRos(f"stepper_{uuid.uuid4().hex[:6]}") as ros:
            assert flowing.wait(30), "the commander's commands were never accepted"
            for _ in range(n_steps):
                response = raw_step(ros, name)
                assert response["success"], response
                time.sleep(0.003)  # give the commander (same process, GIL) time to learn the new day
    finally:
        stop.set()
        thread.join(30)
    assert not errors, errors
    rows = [r for r in ros_support.read_log(log) if int(r["episode"]) == episode]
    assert [int(r["day"]) for r in rows] == list(range(n_steps))
    accepted = [a for a in acks if a.fate == IrrigationStatus.ACCEPTED]
    assert accepted, "some commands were accepted"
    assert any(a.fate == IrrigationStatus.REFUSED and ("past" in a.message or "future" in a.message) for a in acks)
    by_sequence = {a.sequence: a for a in acks}
    applied_sequences = [int(r["command_sequence"]) for r in rows if int(r["command_sequence"]) >= 0]
    assert len(applied_sequences) == len(set(applied_sequences)), "no command applied twice"
    applied_days = 0
    for row in rows:
        day, sequence, mm = int(row["day"]), int(row["command_sequence"]), float(row["irrigation_mm"])
        for_day = [a for a in accepted if a.command.day == day and a.sequence > 0]
        if sequence < 0:
            assert mm == 0.0 and not for_day, row
            continue
        applied_days += 1
        ack = by_sequence.get(sequence)
        if ack is not None:  # the ack of the applied command: accepted, for this very day, same amount
            assert ack.fate == IrrigationStatus.ACCEPTED and ack.command.day == day and ack.command.irrigation_mm == mm
        assert all(a.sequence <= sequence for a in for_day), "the latest accepted command of the day"
    assert applied_days >= 5, "the race was exercised"


# --- crash and restart, free running ---------------------------------------------------------------------------

def test_sim_killed_and_restarted_keeps_its_log(tmp_path, ros):
    namespace = ros_support.unique_namespace("crash")
    sim, name, log = ros_support.start_sim(tmp_path, namespace=namespace)
    try:
        client = connect(ros, name)
        client.reset(seed=8)
        episode = client.episode
        for day in range(20):
            client.step(float(day))
        shm = _shm_files_of(sim.pid)
        sim.kill()  # SIGKILL mid-season
        assert sim.poll() == -9
        assert shm and not any(os.path.exists(p) for p in shm if "_port" not in p), "its /dev/shm files removed"
        client.close()
    finally:
        sim.stop()
    rows = ros_support.read_log(log)
    first = [r for r in rows if int(r["episode"]) == episode]
    assert [(int(r["day"]), float(r["irrigation_mm"])) for r in first] == [(d, float(d)) for d in range(20)]
    text = log.read_text()
    assert text.endswith("\n") and text.count("wall_time_utc") == 1

    sim2, name2, _ = ros_support.start_sim(tmp_path, namespace=namespace)
    try:
        assert name2 == name
        with PrivateRos(f"after_crash_{uuid.uuid4().hex[:6]}") as fresh:  # no memory of the dead process
            client = connect(fresh, name)
            client.reset(seed=8)
            for _ in range(5):
                client.step(1.0)
            client.close()
    finally:
        assert sim2.stop() == 0, sim2.output()
    ros.close()  # the last participant of this test that knew the killed process
    clean_dead_ports()
    # its own segments are gone; a port segment that a live peer (another node of this run) still maps goes at
    # the latest when this process exits (clean_dead_ports runs at exit)
    assert all("fastrtps_port" in p for p in shm if os.path.exists(p)), "the killed process's segments removed"
    rows = ros_support.read_log(log)
    assert len(rows) == len(first) + 5 and rows[:len(first)] == first
    runs = {r["run_id"] for r in rows}
    assert len(runs) == 2 and log.read_text().count("wall_time_utc") == 1


def test_a_process_that_outlives_its_wait_says_where_it_hangs(tmp_path):
    """A child still running when a test's wait expires prints its stacks and is gone: a rare hang (a sim node
    given a bad scenario that had not exited after 60 s, once in CI) names its frame in the failure instead of
    only the timeout."""
    (tmp_path / "hangs_here.py").write_text("import time\n\ndef wait_forever():\n    time.sleep(600)\n\n"
                                            "print('started', flush=True)\nwait_forever()\n")
    env = isolated_ros_env()
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), env["PYTHONPATH"]])
    process = NodeProcess("hangs_here", env=env, log_path=tmp_path / "hangs_here.out")
    try:
        wait_for(lambda: "started" in process.output(), 60, "the child to start")
        with pytest.raises(StillRunning) as raised:
            process.wait(0.5)
        assert process.poll() is not None, "the hung process is gone"
        assert "wait_forever" in raised.value.output and "hangs_here.py" in raised.value.output
        assert "wait_forever" in str(raised.value)
    finally:
        process.stop()


def test_free_running_mode_steps_by_itself_and_counts_days_without_a_command(shared_sim, ros):
    process, name, _ = shared_sim
    client = connect(ros, name)
    client.reset(seed=9)
    statuses = ros_support.status_reader(ros, name)
    client.step(2.0)  # lockstep: day 0 with a command, day 1 without (the caller's choice: counted, no warning)
    assert raw_step(ros, name)["irrigation_mm"] == 0.0
    ros.spin_until(lambda: statuses[-1]["day"] == 2, 10, "the status of day 2")
    assert statuses[-1]["days_without_command"] == 1 and statuses[-1]["level"] == 0, statuses[-1]
    days = []
    ros.node.create_subscription(StepResult, f"{name}/step_result", lambda m: days.append(m.day), ri.READER_QOS)
    try:
        (result,) = set_parameter(ros, name, days_per_second=200.0)
        assert result.successful
        (result,) = set_parameter(ros, name, mode="free_running")
        assert result.successful
        ros.spin_until(lambda: days and days[-1] >= 20, 20, "20 free-running days")
        # nobody commands: every day since day 1 passed without a command; a warning, on /diagnostics and in the log
        ros.spin_until(lambda: statuses[-1]["mode"] == "free_running" and statuses[-1]["day"] >= 20, 10,
                       "the free-running status")
        status = statuses[-1]
        assert status["days_without_command"] == status["day"] - 1 and status["level"] == 1, status
        assert "without a command" in status["message"]
        assert "passed without a command" in process.output()
        step = step_client(ros, name)
        for _ in range(3):  # refused without a change of state: safe to repeat if DDS lost the first request
            try:
                response = call(ros.executor, step, ros_support.pending_step(), timeout=5)
                break
            except TimeoutError:
                continue
        assert not response.success and "free_running" in response.message
    finally:
        (result,) = set_parameter(ros, name, mode="lockstep")
        assert result.successful
    seen = [d for d in days if d > 0]
    assert seen == sorted(seen)


def test_ros2_run_wrapper_starts_the_node_from_its_prefix(tmp_path):
    """scripts/sim_node as installed in <prefix>/lib/crop_sim_ros/ (where `ros2 run` looks) runs
    <prefix>/bin/python -m crop_sim_ros.sim_node with the arguments it was given."""
    import shutil
    import subprocess
    import sys

    prefix = tmp_path / "prefix"
    (prefix / "bin").mkdir(parents=True)
    (prefix / "lib" / "crop_sim_ros").mkdir(parents=True)
    python = prefix / "bin" / "python"  # stands for the environment's python
    python.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    python.chmod(0o755)
    for exe in ("sim_node", "agent_node"):
        shutil.copy2(ros_support.REPO / "scripts" / exe, prefix / "lib" / "crop_sim_ros" / exe)
        assert os.access(prefix / "lib" / "crop_sim_ros" / exe, os.X_OK)
    done = subprocess.run([str(prefix / "lib" / "crop_sim_ros" / "sim_node"), "--ros-args", "-p",
                           "scenario:=no-such-scenario", "-p", f"log_path:={tmp_path / 'log.csv'}"],
                          env=isolated_ros_env(), cwd=ros_support.REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "no-such-scenario" in done.stderr + done.stdout


def test_stepping_commands_step_once_and_only_their_day(shared_sim, ros):
    """~/irrigation_step: a command that also steps. Repeating it cannot step twice (its day is then past);
    a bad one steps nothing."""
    _, name, log = shared_sim
    client = connect(ros, name)
    client.reset(seed=13)
    episode = client.episode
    statuses, results = [], []
    status_sub = ros.node.create_subscription(IrrigationStatus, f"{name}/irrigation_status", statuses.append,
                                              ri.READER_QOS)
    result_sub = ros.node.create_subscription(StepResult, f"{name}/step_result", results.append, ri.READER_QOS)
    publisher = ros.node.create_publisher(IrrigationCommand, f"{name}/irrigation_step", ri.COMMAND_QOS)
    ros.spin_until(lambda: publisher.get_subscription_count() >= 1 and status_sub.get_publisher_count() >= 1
                   and result_sub.get_publisher_count() >= 1, 20, "the simulator's topics")
    for _ in range(5):  # the same stepping command five times
        publisher.publish(IrrigationCommand(day=0, irrigation_mm=4.0, episode=episode))
    refused = lambda: [s for s in statuses if s.fate == IrrigationStatus.REFUSED]  # noqa: E731
    ros.spin_until(lambda: len(refused()) >= 4 and results, 10, "the outcome")
    assert [r.day for r in results] == [1] and results[0].irrigation_mm == 4.0 and results[0].command_sequence > 0
    assert all("past" in s.message for s in refused()) and len(statuses) == 4, "no ACCEPTED for a stepping command"
    for day, mm in ((1, math.nan), (1, 150.0), (3, 1.0)):
        publisher.publish(IrrigationCommand(day=day, irrigation_mm=mm, episode=episode))
    ros.spin_until(lambda: len(refused()) >= 7, 10, "three more refusals")
    assert [r.day for r in results] == [1], "no step for a bad command"
    rows = [r for r in ros_support.read_log(log) if int(r["episode"]) == episode]
    assert [(int(r["day"]), float(r["irrigation_mm"])) for r in rows] == [(0, 4.0)]
    client.day = 1
    obs, reward, terminated, truncated, summary = client.step(2.0)  # the client's own topic path
    assert summary["day"] == 2 and summary["irrigation_mm"] == 2.0 and obs[ri.OBS_DAY] == 2


def test_typed_step_and_reset_requests(shared_sim, ros):
    """~/step: the request's day and episode are checked like a command's (a wrong one is refused, nothing
    changes); ~/reset: the request's seed is this season's only (the parameter stays), its scenario is set as
    the parameter, a seed below FROM_PARAMETER is refused."""
    from crop_sim_interfaces.srv import Reset, Step

    _, name, _ = shared_sim
    reset = ros.node.create_client(Reset, f"{name}/reset", qos_profile=ri.SERVICE_CLIENT_QOS)
    step = step_client(ros, name)
    seed_before = ros_support.connect(ros, name).get_parameters(["seed"])["seed"]
    answer = call(ros.executor, reset, Reset.Request(seed=21))
    assert answer.success and answer.terms.seed == 21 and answer.terms.scenario == "benton-generated"
    episode = answer.terms.episode
    assert np.asarray(answer.observation, np.float32)[ri.OBS_DAY] == 0.0
    for request, why in ((Step.Request(irrigation_mm=1.0, day=1), "day 1 is in the future"),
                         (Step.Request(irrigation_mm=1.0, episode=episode + 1), f"episode {episode + 1} is not"),
                         (Step.Request(irrigation_mm=-1.0), "negative")):
        refused = call(ros.executor, step, request)
        assert not refused.success and why in refused.message, refused.message
        assert (refused.result.episode, refused.result.day) == (episode, 0)
    stepped = call(ros.executor, step, Step.Request(irrigation_mm=3.5, day=0, episode=episode))
    assert stepped.success and (stepped.result.day, stepped.result.irrigation_mm) == (1, 3.5)
    assert stepped.result.header.stamp.sec == ri.sim_time(date.fromisoformat(answer.terms.sowing_date), 1).sec
    bad = call(ros.executor, reset, Reset.Request(seed=-3))
    assert not bad.success and "seed: -3" in bad.message
    other = call(ros.executor, reset, Reset.Request(scenario="benton-quota", seed=2))
    assert other.success and other.terms.scenario == "benton-quota" and len(other.observation) == 29
    assert other.terms.reward_unit == "USD/ha" and other.terms.quota_mm < math.inf
    client = ros_support.connect(ros, name)
    assert client.get_parameters(["seed", "scenario"]) == {"seed": seed_before, "scenario": "benton-quota"}
    assert call(ros.executor, reset, Reset.Request(scenario="benton-generated")).success  # as the fixture had it
