"""The agent node's class and parameters (run it with ``agent_node``: :mod:`crop_agent_ros.ros.agent_node`,
whose docstring describes what it does)."""


from __future__ import annotations

import json
import math

from crop_sim_interfaces.action import RunSeason
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.action import ActionServer
from rclpy.node import Node
from crop_sim_interfaces.msg import IrrigationCommand, IrrigationStatus, StepResult
from std_msgs.msg import Float32MultiArray

from crop_sim_ros import ros_interface as ri
from crop_sim_ros.simulate import is_scenario_path

from ..policies import NODE_POLICIES, POLICY_KINDS, PolicyArguments, build_policy
from .sim_client import UNCHANGED, SimClient, SimError, scenario_layout
from .spin import PrivateRos, ServiceTimeout

NODE_NAME = "crop_agent"
RUN_SEASON_ACTION = "run_season"  # ~/run_season: the RunSeason action the reactive node serves


class PolicyMismatch(ValueError):
    """The policy cannot read the simulator's observation (20 values vs 29): the agent exits with status 2."""


def _descriptor(kind, description, low=None, high=None, constraints=""):
    d = ParameterDescriptor(type=kind, description=description, additional_constraints=constraints)
    if kind == ParameterType.PARAMETER_DOUBLE and low is not None:
        d.floating_point_range = [FloatingPointRange(from_value=low, to_value=high, step=0.0)]
    if kind == ParameterType.PARAMETER_INTEGER and low is not None:
        d.integer_range = [IntegerRange(from_value=low, to_value=high, step=1)]
    return d


S, D, I, B = (ParameterType.PARAMETER_STRING, ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_INTEGER,
              ParameterType.PARAMETER_BOOL)
PARAMETERS = {
    "sim_node": ("/" + ri.NODE_NAME, _descriptor(S, "fully qualified name of the simulator node")),
    "policy": ("refill", _descriptor(S, "irrigation policy", constraints=" | ".join(NODE_POLICIES))),
    "policy_file": ("", _descriptor(S, "policy ppo: Stable-Baselines3 PPO .zip ('' = the shipped ppo_benton.zip); "
                                       "policy agent: a family agent's model.zip (model.json beside it), required")),
    "task": ("", _descriptor(S, "policies budget-rule and es: the family task whose tuned rule or shipped agent to "
                                "use, e.g. benton-quota ('' = the simulator's scenario parameter, read at start)")),
    "constant_mm": (10.0, _descriptor(D, "policy constant: irrigation per day, mm", 0.0, 100.0)),
    "drive": (False, _descriptor(B, "run the seasons itself (reset, command, step ...) and exit")),
    "seasons": (1, _descriptor(I, "drive: number of seasons", 1, 100000)),
    "seed": (-2, _descriptor(I, "drive: seed of the first season (later seasons continue the stream); -2 = the "
                                "simulator's own seed parameter, -1 = unseeded", -2, 2**31 - 1)),
    "timeout": (10.0, _descriptor(D, "drive: seconds to wait for any one answer of the simulator", 0.1, 3600.0)),
}


def make_agent_policy(kind: str, policy_file: str = "", constant_mm: float = 10.0, task: str = ""):
    """The node policy ``kind`` (:data:`~crop_agent_ros.policies.NODE_POLICIES`, see
    :mod:`crop_agent_ros.policies.registry`) with the node's parameters. ValueError for an unknown kind or a
    missing parameter, FileNotFoundError for a missing policy or rule file."""
    return build_policy(kind, PolicyArguments(policy_file=policy_file, constant_mm=constant_mm, task=task), node=True)


def check_observation_size(policy, size: int, where: str) -> None:
    """PolicyMismatch unless ``policy`` reads observations of ``size`` values."""
    if size not in policy.observation_sizes:
        sizes = " or ".join(map(str, policy.observation_sizes))
        raise PolicyMismatch(f"policy {policy.name!r} reads observations of {sizes} values, but {where} has {size} "
                             "(the paper's task: 20; a family task: 29)")


def grow_season(client: SimClient, policy, obs, info: dict, on_day=None) -> dict:
    """One season through ``client`` (just reset: ``obs``, ``info``) with ``policy``; ``on_day(water_mm)`` after
    each day (the client's ``last_result`` is that day's StepResult). Returns the season's summary."""
    water = total = 0.0
    days = 0
    done = False
    summary = info
    while not done:
        mm = float(policy.act(obs))
        obs, reward, terminated, truncated, summary = client.step(mm)
        water += summary["irrigation_mm"]
        total += reward
        days += 1
        done = terminated or truncated
        if on_day is not None:
            on_day(water)
    # the return over the potential yield's value (as offline: info["normalized_return"])
    potential = (info.get("potential_yield_t_ha") or math.nan) * info.get("yield_value_per_t", 1.0)
    return {"episode": summary["episode"], "scenario": info.get("scenario"), "seed": info.get("seed"),
            "weather": info.get("weather_source"), "policy": policy.name, "days": days,
            "matured": bool(summary["terminated"]), "yield_t_ha": summary["yield_t_ha"],
            "irrigation_mm": water, "return": total, "reward_unit": info.get("reward_unit", "t/ha"),
            "normalized_return": total / potential if potential else None}


class AgentNode(Node):
    """What it does: see :mod:`crop_agent_ros.ros.agent_node`."""

    def __init__(self, node_name: str = NODE_NAME, **kwargs):
        super().__init__(node_name, **kwargs)
        ri.set_up_or_destroy(self, self._setup)

    def _setup(self) -> None:
        for name, (default, descriptor) in PARAMETERS.items():
            self.declare_parameter(name, default, descriptor)
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self.sim = "/" + p["sim_node"].strip("/")  # fully qualified: the launch file may give "ns/crop_sim"
        self.drive_mode = bool(p["drive"])
        self._client: SimClient | None = None
        # a policy of a task (budget-rule, es) without one: the simulator's scenario names it (built in start(),
        # once it is read); an unknown kind is refused here, by make_agent_policy
        kind = POLICY_KINDS.get(p["policy"])
        self._policy_kind = p["policy"]
        self.policy = (None if kind is not None and kind.node and kind.reads_task and not p["task"].strip()
                       else make_agent_policy(p["policy"], p["policy_file"], p["constant_mm"], p["task"].strip()))
        self.commands_sent = 0
        policy = repr(self.policy) if self.policy is not None else f"{p['policy']} (of the simulator's scenario)"
        self.get_logger().info(f"policy {policy}, simulator {self.sim}, "
                               f"{'driving' if self.drive_mode else 'reacting to observations'}")

    def start(self, executor) -> None:
        """Before the first day: in drive mode, or when the policy waits for the simulator's scenario, connect to
        the simulator (ServiceTimeout after ``timeout`` s), build the policy and check that it reads the
        scenario's observation (PolicyMismatch). A reacting agent checks every observation's size."""
        if self.drive_mode or self.policy is None:
            self._client = SimClient(self, executor, self.sim, timeout=self.get_parameter("timeout").value)
            scenario = self._client.connect()["scenario"]
            if self.policy is None:
                if is_scenario_path(scenario):
                    raise ValueError(f"policy {self._policy_kind}: the simulator's scenario is the file {scenario}: "
                                     "name the task with task:=")
                self.policy = make_agent_policy(self._policy_kind, task=scenario)
                self.get_logger().info(f"policy {self.policy!r} of the simulator's scenario {scenario!r}")
            check_observation_size(self.policy, scenario_layout(scenario).size,
                                   f"the simulator's scenario {scenario!r}")
            agent = getattr(self.policy, "agent_config", None)  # a family agent: of this task only
            if agent is not None and not is_scenario_path(scenario):
                from ..policies.learned import check_agent_task
                check_agent_task(agent, scenario, "policy_file")
            if not self.drive_mode:
                self._client.close()
                self._client = None
        if not self.drive_mode:  # react from now on (the policy is built)
            self.policy.reset(None)
            self._pending: tuple[int, float] | None = None  # today's command until the simulator accepts it
            self._today: StepResult | None = None  # the simulator's latest day: its farm time, field and episode
            self._command = self.create_publisher(IrrigationCommand, f"{self.sim}/{ri.IRRIGATION_TOPIC}",
                                                  ri.COMMAND_QOS)
            # created before the observation's: the executor takes ready subscriptions in creation order, so a
            # day's StepResult (published with its observation) is usually there when the observation arrives
            self.create_subscription(StepResult, f"{self.sim}/{ri.STEP_RESULT_TOPIC}", self._on_step_result,
                                     ri.LATCHED_READER_QOS)
            self.create_subscription(Float32MultiArray, f"{self.sim}/{ri.OBSERVATION_TOPIC}", self._on_observation,
                                     ri.LATCHED_READER_QOS)
            self.create_subscription(IrrigationStatus, f"{self.sim}/{ri.IRRIGATION_STATUS_TOPIC}", self._on_status,
                                     ri.COMMAND_QOS)
            # a command published before the simulator's subscription matched is lost: repeat it until accepted
            self.create_timer(0.2, self._repeat_pending)
            # feedback: one message a day in a burst; a deep queue keeps them for a reader that lags
            self._season_server = ActionServer(self, RunSeason, "~/" + RUN_SEASON_ACTION, self._run_season,
                                               feedback_pub_qos_profile=ri.COMMAND_STATUS_QOS)

    def _on_observation(self, message: Float32MultiArray) -> None:
        obs = ri.observation_from_message(message)
        check_observation_size(self.policy, obs.size, f"the observation of {self.sim}")
        day = int(obs[ri.OBS_DAY])
        if day == 0:
            self.policy.reset(None)
        mm = float(self.policy.act(obs))
        self._pending = (day, mm)
        self._publish_pending()
        self.get_logger().debug(f"day {day}: {mm:.2f} mm")

    def _on_step_result(self, message: StepResult) -> None:
        self._today = message
        self._publish_pending()

    def _publish_pending(self) -> None:
        """Today's command, stamped with the day's farm time, addressed to the field and valid in this episode
        only, as the simulator's StepResult of that day says; until it arrives, the command waits."""
        today = self._today
        if self._pending is None or today is None or today.day != self._pending[0]:
            return
        day, mm = self._pending
        self._command.publish(IrrigationCommand(header=today.header, day=day, irrigation_mm=mm,
                                                episode=today.episode))
        self.commands_sent += 1

    def _on_status(self, status: IrrigationStatus) -> None:
        command = status.command
        if self._pending != (command.day, command.irrigation_mm):
            return
        if status.fate == IrrigationStatus.REFUSED and command.episode != status.episode:
            # sent with the last season's StepResult (the new one not yet read, as after two resets): it goes
            # again, in the new episode, when that StepResult arrives
            return
        if status.fate == IrrigationStatus.REFUSED:
            self.get_logger().warning(f"command for day {command.day} rejected: {status.message}")
        self._pending = None

    def _repeat_pending(self) -> None:
        if self._pending is not None and self._command.get_subscription_count() > 0:
            self._publish_pending()

    def _run_season(self, goal_handle) -> RunSeason.Result:
        """~/run_season: grow one season with the goal's policy (or the node's), a StepResult per day as
        feedback. The season runs on a private ROS context of its own, so that this node's executor (blocked
        meanwhile: no cancel, no reactive commands) is not spun from inside its own callback."""
        goal = goal_handle.request
        result = RunSeason.Result()
        try:
            with PrivateRos(f"{self.get_name()}_season") as ros:
                client = SimClient(ros.node, ros.executor, self.sim, timeout=self.get_parameter("timeout").value)
                simulator_scenario = client.connect()["scenario"]
                scenario = goal.scenario.strip() or simulator_scenario
                policy = self._goal_policy(goal.policy.strip(), scenario)
                parameters = {"scenario": scenario} if goal.scenario.strip() else {}
                obs, info = client.reset(seed=None if goal.seed < 0 else goal.seed, weather_season=UNCHANGED,
                                         **parameters)
                check_observation_size(policy, obs.size, f"the observation of {self.sim}")
                policy.reset(None if goal.seed < 0 else goal.seed)

                def feedback(water_mm: float) -> None:
                    goal_handle.publish_feedback(RunSeason.Feedback(step=client.last_result, water_mm=water_mm))

                season = grow_season(client, policy, obs, info, feedback)
                client.close()
        except (SimError, ServiceTimeout, TimeoutError, PolicyMismatch, ValueError, FileNotFoundError) as error:
            self.get_logger().error(f"run_season aborted: {type(error).__name__}: {error}")
            goal_handle.abort()
            result.success, result.message = False, f"{type(error).__name__}: {error}"
            return result
        goal_handle.succeed()
        result.success, result.episode, result.days = True, season["episode"], season["days"]
        result.yield_t_ha, result.water_mm = season["yield_t_ha"], season["irrigation_mm"]
        result.episode_return, result.reward_unit = season["return"], season["reward_unit"]
        self.get_logger().info(f"run_season: {json.dumps(season)}")
        return result

    def _goal_policy(self, kind: str, scenario: str):
        """The goal's policy (''  = this node's), built for the simulator's ``scenario`` when it reads a task."""
        if not kind:
            return self.policy
        parameter = {name: self.get_parameter(name).value for name in ("policy_file", "constant_mm", "task")}
        task = parameter["task"].strip() or ("" if is_scenario_path(scenario) else scenario)
        return make_agent_policy(kind, parameter["policy_file"], parameter["constant_mm"], task)

    def drive(self, executor) -> list[dict]:
        """Grow ``seasons`` seasons through the simulator; returns one summary per season."""
        seasons = self.get_parameter("seasons").value
        seed = self.get_parameter("seed").value
        client = self._client  # connected by start()
        summaries = []
        for k in range(seasons):
            if k == 0:
                # -2: the simulator's own seed parameter, untouched
                obs, info = client.reset(seed=UNCHANGED if seed == -2 else (None if seed == -1 else seed),
                                         weather_season=UNCHANGED)
            else:
                obs, info = client.reset(seed=None, weather_season=UNCHANGED)  # continue the stream
            check_observation_size(self.policy, obs.size, f"the observation of {self.sim}")  # a scenario change
            self.policy.reset(None if seed < 0 else seed + k)
            result = grow_season(client, self.policy, obs, info)
            water, total, days = result["irrigation_mm"], result["return"], result["days"]
            summaries.append(result)
            print("season summary: " + json.dumps(result), flush=True)
            self.get_logger().info(
                f"season {k + 1}/{seasons} ({info.get('weather_source')}): yield {result['yield_t_ha']:.2f} t/ha, "
                f"irrigation {water:.0f} mm, return {total:.3f} {result['reward_unit']} over {days} days "
                f"({'matured' if result['matured'] else 'weather ran out'})")
        client.close()
        return summaries
