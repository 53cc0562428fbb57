"""The agent node: an irrigation policy over ROS 2 (a thin adapter over :mod:`crop_agent_ros.policies`).

    ros2 run crop_sim_ros agent_node --ros-args -p policy:=refill              # reacts to the simulator
    ros2 run crop_sim_ros agent_node --ros-args -p policy:=ppo -p drive:=true   # grows a season itself
    ros2 run crop_sim_ros agent_node --ros-args -p policy:=es -p drive:=true    # the shipped agent of the task
    python -m crop_agent_ros.ros.agent_node --ros-args ...                     # the same without a workspace

Two ways of working:

- reactive (``drive: false``, the default): for every observation the simulator publishes
  (``<sim_node>/observation``; transient-local, so a late start still sees the current day), the node
  publishes the policy's irrigation for that day on ``<sim_node>/irrigation`` (an IrrigationCommand stamped
  with the day's farm time, addressed to the field and valid in the current episode, all three taken from
  the day's ``<sim_node>/step_result``), repeating it every 0.2 s until ``<sim_node>/irrigation_status``
  reports it accepted (or rejected). Whoever steps the
  simulator (a user with ``ros2 service call``, or the simulator itself with ``mode:=free_running``)
  decides when days pass. The reactive node also serves the action ``~/run_season``
  (``crop_sim_interfaces/action/RunSeason``): a goal (scenario, seed, policy; '' = the simulator's scenario,
  the node's policy) grows one season through the simulator's typed services, with each day's StepResult as
  feedback and the yield, water and return as result (``ros2 action send_goal --feedback
  /crop_agent/run_season crop_sim_interfaces/action/RunSeason "{seed: 3}"``). While a goal runs, the node
  does nothing else (no cancel).
- drive (``drive: true``): the node runs ``seasons`` seasons itself: ``<sim_node>/reset``, then every day
  ``<sim_node>/step`` with the policy's irrigation (the stepping command on ``<sim_node>/irrigation_step``,
  answered on ``<sim_node>/step_result``), until the season ends; it prints a summary of each season (yield
  t/ha, irrigation mm, return) as a line ``season summary: {json}`` and exits (status 0; 1 if the simulator
  failed or did not answer within ``timeout`` seconds, the start included). Each season's seed travels in the
  Reset request: the simulator's parameters stay as they are (:class:`~crop_agent_ros.ros.sim_client.SimClient`).

Policies (parameter ``policy``, built by :func:`crop_agent_ros.ros.agent.make_agent_policy`): ``zero``;
``constant`` (``constant_mm`` mm/day); ``best-constant`` and ``refill`` (the rules tuned on generated seasons);
``ppo`` (a Stable-Baselines3 PPO policy file, ``policy_file``, by default the shipped
``crop_agent_ros/policies/ppo_benton.zip``, checked against the task's spaces when it loads). For the task
family (a simulator with a family scenario, 29-value observations): ``budget-rule`` (the water-budget rule
tuned for the family task named by ``task``; by default the simulator's ``scenario``, read at start), ``es``
(the shipped evolution-strategies agent of that task, package data under ``crop_agent_ros/agents/``; a task
without one is refused at start, naming the tasks that have one) and
``agent`` (a family agent trained with ``crop-sim train --task``: ``policy_file:=.../model.zip``, its
``model.json`` beside it). The paper's policies read either observation; the family's read only 29 values:
one that cannot read the simulator's observation is refused at start (drive mode, or a policy that reads the
simulator's scenario), else at the first observation, with one line and exit status 2.

Exit status: 0 when done, and on SIGINT or SIGTERM whenever it lands (the node stops at its next wait, a
fraction of a second, or after loading its policy; without a traceback; within 10 s in any case; a second
signal during the shutdown is ignored); 2 when it cannot start (bad parameters, an
unknown policy, a policy file that is missing or not for this task, a policy that cannot read the simulator's
observation: one line); 1 when the simulator failed or did not answer within ``timeout``. Whatever the status,
the process is gone within 10 s of its last line, even if rclpy's teardown hangs.
``agent_node --help`` prints the parameters and exits.
"""

from __future__ import annotations

import signal
import sys

from crop_sim_ros.usage import exit_within, node_arguments

class StopSignal(BaseException):
    """SIGINT or SIGTERM arrived: stop where we are and exit 0. A BaseException, so that no ``except
    Exception`` on the way (ours or a library's) takes it for an error."""


_stopped_by: str | None = None  # the signal that stopped the node, once one has
EXIT_WITHIN_S = 10.0  # after a signal the process is gone within this, whatever the clean-up is waiting on


def _stop_on_signal(signum, frame) -> None:
    global _stopped_by
    # The first signal stops the node; a later one (Ctrl-C to a process group after a launcher's own SIGINT, a
    # second SIGTERM) would otherwise interrupt the clean-up itself: ignore them from now on.
    for kind in (signal.SIGINT, signal.SIGTERM):
        signal.signal(kind, signal.SIG_IGN)
    _stopped_by = signal.Signals(signum).name
    # Only a flag: an exception raised where the signal lands can be swallowed there (inside rclpy's wait
    # machinery: the node then drove on, 1 of 40 trials) or, inside Python called from C++, abort the process
    # (pybind11 error_already_set -> std::terminate, 1 of 20). The executor raises StopSignal at its next spin
    # (every wait is a bounded spin_once, :func:`_stoppable_executor`); the start-up checks between its steps;
    # and this timer ends the process with status 0 if it is somehow still there.
    exit_within(EXIT_WITHIN_S)


def _stop_if_signalled() -> None:
    if _stopped_by is not None:
        raise StopSignal(_stopped_by)


def _stoppable_executor():
    """A single-threaded executor whose ``spin_once`` raises :class:`StopSignal` once a signal has arrived
    (every wait of the node goes through ``spin_once``)."""
    from rclpy.executors import SingleThreadedExecutor

    class StoppableExecutor(SingleThreadedExecutor):
        def spin_once(self, timeout_sec=None):
            _stop_if_signalled()
            super().spin_once(timeout_sec=timeout_sec)
            _stop_if_signalled()

    return StoppableExecutor()


def usage() -> str:
    """``agent_node --help``: how to run it and every parameter with its default."""
    from .agent import PARAMETERS

    lines = [__doc__.split("\n\n")[0], "", "usage: agent_node [--help] [--ros-args -p NAME:=VALUE ...]", "",
             "parameters:"]
    for name, (default, descriptor) in PARAMETERS.items():
        lines.append(f"  {name} (default {default!r}): {descriptor.description}"
                     + (f" [{descriptor.additional_constraints}]" if descriptor.additional_constraints else ""))
    return "\n".join(lines)


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    status = node_arguments("agent_node", argv, usage)
    if status is not None:
        return status
    # Our own handlers, not rclpy's: rclpy's shut the context down from another thread, and whichever rclpy call
    # the main thread was in then failed with one of several errors (a traceback, status 1). They are installed
    # before rclpy, the task and the policy load (seconds), so a signal during the loading stops cleanly too.
    signal.signal(signal.SIGINT, _stop_on_signal)
    signal.signal(signal.SIGTERM, _stop_on_signal)
    try:
        return _run(argv)
    except StopSignal:
        return 0
    except Exception:
        if _stopped_by is not None:
            return 0  # stopping anyway: an error on the way out is not the node's failure
        raise
    finally:
        for kind in (signal.SIGINT, signal.SIGTERM):  # from here on the process only exits
            signal.signal(kind, signal.SIG_IGN)


def _unless_stopped(status: int) -> int:
    """``status``, or 0 when a signal has arrived (the node was stopping anyway). The node has said why it
    ends: the process is gone within ``EXIT_WITHIN_S``, whatever the clean-up waits on."""
    status = 0 if _stopped_by is not None else status
    exit_within(EXIT_WITHIN_S, status=status)
    return status


def _run(argv: list[str]) -> int:
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from .agent import NODE_NAME, AgentNode, PolicyMismatch
    from .spin import ServiceTimeout
    from .sim_client import SimError

    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        try:
            node = AgentNode()
        except Exception as error:  # noqa: BLE001 - bad parameters or a policy file: one line, exit 2
            rclpy.logging.get_logger(NODE_NAME).fatal(f"cannot start: {type(error).__name__}: {error}")
            return _unless_stopped(2)
        _stop_if_signalled()  # a signal during the start-up (loading the policy takes seconds)
        executor = _stoppable_executor()
        executor.add_node(node)
        try:
            node.start(executor)
            if not node.drive_mode:
                while True:  # bounded waits: the signal handler runs between two of them
                    executor.spin_once(timeout_sec=0.1)
            node.drive(executor)
        except (PolicyMismatch, ValueError, FileNotFoundError) as error:  # the policy for another task: one line
            node.get_logger().fatal(f"cannot run: {type(error).__name__}: {error}")
            return _unless_stopped(2)
        except (SimError, TimeoutError, ServiceTimeout) as error:
            node.get_logger().error(f"season aborted: {error}")
            return _unless_stopped(1)
        return 0
    finally:
        try:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        except Exception:  # noqa: BLE001
            if _stopped_by is None:
                raise
            # stopping anyway: what is left of the node goes with the process
        if _stopped_by is not None:
            rclpy.logging.get_logger(NODE_NAME).info(f"stopped by {_stopped_by}")


if __name__ == "__main__":
    sys.exit(main())
