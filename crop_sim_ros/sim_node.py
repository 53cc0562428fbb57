"""The simulator node: one :class:`~crop_sim_ros.task.IrrigationEnv` served over ROS 2 (a thin adapter).

    ros2 run crop_sim_ros sim_node [--ros-args -p scenario:=benton-2000 -p seed:=3 ...]
    python -m crop_sim_ros.sim_node [--ros-args ...]        # the same without a ROS workspace
    sim_node --help                                         # the parameters; starts nothing

The node holds exactly the environment the offline users use and converts to and from messages (the typed ``crop_sim_interfaces`` and standard ones);
it computes nothing of its own beyond bookkeeping (the episode counter, the pending command, counters, the
log). Names, message layouts and QoS are in :mod:`crop_sim_ros.ros_interface`; the node itself is
:class:`crop_sim_ros.sim.SimNode`. This module is the executable: it imports only the standard library until
its signal handlers are installed, so that a signal at any moment after the start stops the node cleanly.

Day protocol (lockstep, the default)
------------------------------------
After a reset the field is on day 0 (the sowing day) and the node publishes day 0's state. A client calls
``~/step`` (``crop_sim_interfaces/srv/Step``) with today's ``irrigation_mm`` (and optionally the ``day`` and
``episode`` it is meant for): the node checks the command, applies it, advances exactly one day, answers with
the day's ``StepResult`` and observation, and publishes the new day. A client may instead publish a command
(``crop_sim_interfaces/msg/IrrigationCommand``: day, irrigation_mm, episode, -1 = any; stamped with the farm
time of the day, addressed to the field in ``header.frame_id``) on ``~/irrigation`` ahead of the day
(free-running mode's way); in lockstep a step's own command replaces it. Each command is applied at most once
and only to the day it names:

- a command for a past day, a future day, another episode, or after the season ended is rejected;
- so is one for another field (``header.frame_id`` neither '' nor the node's field) or stamped with another
  time than the farm time of its day (a stamp of 0 is not checked);
- NaN, infinite, negative or over-limit (> the scenario's ``max_irrigation_mm``) amounts are rejected;
- rejected commands are logged and reported on ``~/irrigation_status``
  (``crop_sim_interfaces/msg/IrrigationStatus``, fate REFUSED, with the reason); accepted ones are reported
  too (ACCEPTED); a refused ``~/step`` says why in its reply;
- a step with no accepted command for the day applies 0 mm (counted: ``days_without_command`` in the node's
  status on ``/diagnostics``; in free-running mode such a day is also a warning in the node's log).

The command subscriptions keep every message (reliable, keep-all): a burst of commands is queued, not
overwritten, however busy the node is. The node's status on ``/diagnostics`` counts the commands received,
accepted and rejected, so a client can compare with what it sent (what a publisher with a shallow queue of its
own drops never arrives).

A client that drives the season can do both in one message: a command on ``~/irrigation_step`` is validated
the same way and, if accepted, the day is stepped at once (one topic round trip per day; the outcome is on
``~/step_result`` and ``~/observation``; a repeated message cannot step twice, its day being past by then).

The ``~/step`` reply carries the day's ``StepResult`` (episode, day, irrigation_mm applied,
irrigation_requested_mm, reward, episode_return, reward_unit: ``t/ha`` for the paper's task, ``USD/ha`` for a
family task, terminated, truncated, yield_t_ha, command_sequence; stamped in farm time) and the float32
observation, exactly; its ``message`` names the season-log failure if the day's row could not be written.
``~/reset`` (``crop_sim_interfaces/srv/Reset``: an optional scenario, set as the parameter, and this season's
seed and weather_season, by default the parameters') answers with the season's ``FarmTerms`` (as on
``~/farm_terms``) and day 0's observation.

Family tasks
------------
A family scenario (``scenario:=benton-quota``, any built-in family task or a YAML file with ``economics`` or
``limits``) serves the family's task: the observation has 29 values (labels from its layout), rewards are net
return in USD/ha, and ``~/farm_terms`` carries the season's drawn price, water cost, quota and capacity at
each reset. The irrigation applied is min(command, capacity, quota left): a command the capacity or the
quota cut is accepted, and after its step ``~/irrigation_status`` says so (fate CUT, with the mm applied).
A scenario change between the paper's task and a family task takes effect at the next reset: every topic
then carries the new layout. A refusal is
``success: false`` with the reason in ``message``; the state is then unchanged.

Commands, steps, resets and the free-running timer all run on one single-threaded executor, and every
state change is also taken under one lock, so a command and a step never interleave. After a step, the
observation and ``~/step_result`` are published at once; the other topics (crop state, weather, /clock)
right after the callback has returned (so the caller waiting for the step waits less), always in day order.
``/clock`` uses the QoS of ROS time sources (best effort, volatile, depth 1): a node started with
``use_sim_time`` reads farm time from the first step after it started (0 until then). Farms side by side
(``-r __ns:=/field7``, ``/field8``) each publish their own clock with ``-p clock_topic:=clock``
(``/field7/clock``; a ``use_sim_time`` node of that farm remaps ``-r /clock:=/field7/clock``), and each writes
its own default season log, ``$ROS_HOME/field7/crop_sim/season_log.csv``.

The node's status (counters, the season log's health, level OK / WARN / ERROR) goes to ``/diagnostics`` as a
``diagnostic_msgs/DiagnosticArray`` (one status named ``<namespace>/crop_sim: farm``) every second and at once
on a change, where rqt_robot_monitor and the diagnostic aggregator read it.

Reference data (weather files of scenarios such as ``benton-2000``): the ``data_dir`` parameter; when it is
'', ``share/crop_sim_ros/data`` of a package installed in the ament index (if it has one), then
``$CROP_SIM_DATA_DIR``, then the checkout's ``shared/data`` (walking up from the current directory, then from
the package). If none has the file the node does not start, and its one line says where it looked and how to
set it.

Season log
----------
One CSV row per simulated day (:mod:`crop_sim_ros.season_log`: appended, written through at every row, never
torn): the observation the day started with (the family's 9 extra columns empty for a paper task), the
irrigation commanded and applied, the reward and its unit, the day's water fluxes, the true state at the end
of the day and the season's farm terms (``term_*``: nan where a paper task has none, inf = no quota). A restarted node first removes a torn last line (a row cut short by a
crash), then appends under a new ``run_id``. If a row cannot be written (a full disk), the day still counts:
the caller is told (``log_error``), the failure is logged and counted in the node's status on ``/diagnostics``
(level ERROR), and the file keeps its last whole row.

Stopping and exit status
------------------------
SIGINT and SIGTERM stop the node at any moment: the callback under way (a step, a reset) finishes, the
last day's topics go out, the season log is closed, and the process exits with status 0, without a
traceback; a second signal during that clean-up (Ctrl-C to a process group that a launcher also stops) is
ignored (within ``EXIT_WITHIN_S`` of the log's closing, even if rclpy's teardown hangs). A bad start
(unknown scenario or crop, a scenario file that is not a scenario, a value out of its range, a broken weather
file, an unusable log path, an unknown command-line argument) is one line on stderr and exit status 2 (within
``EXIT_WITHIN_S`` of that line). An
unknown ``-p name:=value`` is a warning naming it and the known parameters.

Parameters: see :data:`crop_sim_ros.sim_parameters.PARAMETERS` (``sim_node --help``, ``ros2 param describe /crop_sim <name>``). Changes
of ``scenario``, ``data_dir``, ``crop``, ``cultivar``, ``soil``, ``co2_ppm``, ``noise_scale``,
``irrigation_cost_per_mm``, ``seed``, ``weather_season`` and ``log_path`` take effect at the next reset;
``clock_topic`` is read at the start only (read-only);
``mode`` and ``days_per_second`` at once. Every change is checked when it is set (an unknown scenario or crop,
a weather season beyond the scenario's pool, an unusable log path are refused, not stored). Refusals name
the parameter, the file and what is wrong, never the contents of a file.
"""

from __future__ import annotations

import signal
import sys

from crop_sim_ros.sim_parameters import NODE_NAME, PARAMETERS
from crop_sim_ros.usage import exit_within, node_arguments

EXIT_WITHIN_S = 10.0  # after a signal once the season log is closed, or after a bad start: gone within this


def usage() -> str:
    """``sim_node --help``: how to run it and every parameter with its default."""
    lines = [__doc__.split("\n\n")[0], "",
             "usage: sim_node [--help] [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] [-r __ns:=/NS]]", "",
             "parameters:"]
    for name, spec in PARAMETERS.items():
        bounds = f", {spec.low}..{spec.high}" if spec.low is not None else ""
        lines.append(f"  {name} ({type(spec.default).__name__}, default {spec.default!r}{bounds}): {spec.description}"
                     + (f" [{spec.constraints}]" if spec.constraints else ""))
    lines += ["", "topics, services and the day protocol: python -m pydoc crop_sim_ros.sim_node"]
    return "\n".join(lines)


class _StopRequest:
    """SIGINT / SIGTERM handler: notes the signal and returns. The node checks it between two callbacks, so a
    signal never interrupts a step half-way (rclpy's own handlers shut the context down from another thread,
    and whatever the node was publishing then failed with a traceback)."""

    def __init__(self):
        self.signal_name: str | None = None
        for kind in (signal.SIGINT, signal.SIGTERM):
            signal.signal(kind, self._note)

    def _note(self, signum, frame) -> None:
        if self.signal_name is None:
            self.signal_name = signal.Signals(signum).name
        # The first signal stops the node; a later one (Ctrl-C to a process group after a launcher's own SIGINT, a
        # second SIGTERM) must not cut the clean-up short: ignored from now on, as by the agent node. (Keeping this
        # handler would not do: Python puts SIGINT back to its default while the interpreter finalises, and a
        # second SIGINT then killed the process, exit -2.)
        for kind in (signal.SIGINT, signal.SIGTERM):
            signal.signal(kind, signal.SIG_IGN)

    @property
    def requested(self) -> bool:
        return self.signal_name is not None


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    status = node_arguments("sim_node", argv, usage)
    if status is not None:
        return status
    stop = _StopRequest()  # before rclpy, numpy and the task load (about a second)
    return _run(argv, stop)


def _run(argv: list[str], stop: _StopRequest) -> int:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from .sim import SimNode, one_line

    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as error:  # noqa: BLE001 - malformed --ros-args: one line, exit 2
        print(f"sim_node: cannot start: {one_line(error)}", file=sys.stderr)
        return 2
    node = None
    try:
        try:
            node = SimNode()
        except Exception as error:  # noqa: BLE001 - bad parameters, scenario, weather or log path: one line, exit 2
            rclpy.logging.get_logger(NODE_NAME).fatal(f"cannot start: {one_line(error)}")
            exit_within(EXIT_WITHIN_S, status=2)  # said all it had to: gone in bounded time, whatever the teardown
            return 2
        executor = SingleThreadedExecutor()  # one thread: callbacks run one at a time
        executor.add_node(node)
        while not stop.requested:  # bounded waits: the signal is seen within 0.1 s
            executor.spin_once(timeout_sec=0.1)
        node.get_logger().info(f"stopped by {stop.signal_name}")
        return 0
    finally:
        if node is not None:
            node.finish()  # publishes what is deferred, closes the season log
        if stop.requested:  # nothing left that must finish: the process is gone within EXIT_WITHIN_S from here
            exit_within(EXIT_WITHIN_S)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
