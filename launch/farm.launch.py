"""The simulated farm: the simulator node and an agent node that drives the season(s), then both stop.

    ros2 launch crop_sim_ros farm.launch.py [scenario:=benton-2000] [policy:=ppo|refill|...|budget-rule|agent]
                                            [seasons:=1] [namespace:=/field7] [log_path:=season.csv]
                                            [clock_topic:=/clock] [params_file:=...]

Parameters come from share/crop_sim_ros/config/farm_params.yaml (or params_file); the launch arguments
override it. ``scenario`` is the simulator's (a built-in name or a scenario YAML path, family tasks included);
``namespace`` puts both nodes under it (the agent finds the simulator there); ``log_path`` is the simulator's
season log ('' = its default per node: $ROS_HOME/crop_sim/season_log.csv, $ROS_HOME/field7/crop_sim/... under
namespace:=/field7); ``clock_topic`` is where farm time goes ('/clock'; ``clock`` = the namespace's own, for
farms side by side; '' = none).

When the agent has grown its season(s) it exits, and the launch shuts down the simulator with it. When the
agent fails (a nonzero exit status: 2 for bad input such as an unknown policy, 1 when the simulator failed),
the launch fails too: the exit handler raises, launch logs "Caught exception in launch", shuts everything
down and ``ros2 launch`` returns 1 (LaunchService.run's return code when an event handler raised).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

from crop_agent_ros.policies.registry import NODE_POLICIES


class AgentFailed(RuntimeError):
    """The agent node exited with a nonzero status: the farm did not grow its seasons."""


def on_agent_exit(event, context):
    """Shut the launch down when the agent is done; raise (the launch then returns 1) when it failed."""
    if event.returncode != 0:
        raise AgentFailed(f"agent_node exited with status {event.returncode}: the farm failed (see its output above)")
    return [EmitEvent(event=Shutdown(reason="the season is grown"))]


def generate_launch_description():
    params_file = LaunchConfiguration("params_file")
    namespace = LaunchConfiguration("namespace")
    # typed values: an empty or numeric-looking string stays a string (launch would read it as YAML)
    sim = Node(package="crop_sim_ros", executable="sim_node", name="crop_sim", namespace=namespace,
               output="screen",
               parameters=[params_file, {
                   "scenario": ParameterValue(LaunchConfiguration("scenario"), value_type=str),
                   "log_path": ParameterValue(LaunchConfiguration("log_path"), value_type=str),
                   "clock_topic": ParameterValue(LaunchConfiguration("clock_topic"), value_type=str)}])
    agent = Node(package="crop_sim_ros", executable="agent_node", name="crop_agent", namespace=namespace,
                 output="screen",
                 parameters=[params_file, {
                     "policy": ParameterValue(LaunchConfiguration("policy"), value_type=str),
                     "drive": True,
                     "seasons": ParameterValue(LaunchConfiguration("seasons"), value_type=int),
                     # the simulator in the same namespace ("" -> /crop_sim; the agent adds a missing leading /)
                     "sim_node": ParameterValue([namespace, "/crop_sim"], value_type=str)}])
    return LaunchDescription([
        DeclareLaunchArgument(
            "params_file",
            default_value=PathJoinSubstitution([FindPackageShare("crop_sim_ros"), "config", "farm_params.yaml"]),
            description="parameter file of both nodes"),
        DeclareLaunchArgument("scenario", default_value="benton-generated",
                              description="the simulator's scenario: a built-in name (benton-2000, benton-quota, "
                                          "...) or a scenario YAML path"),
        DeclareLaunchArgument("policy", default_value="ppo", description=" | ".join(NODE_POLICIES)),
        DeclareLaunchArgument("seasons", default_value="1", description="seasons the agent grows (1..100000)"),
        DeclareLaunchArgument("namespace", default_value="", description="namespace of both nodes ('' = none)"),
        DeclareLaunchArgument("log_path", default_value="",
                              description="the simulator's season log CSV ('' = $ROS_HOME/<namespace>/crop_sim/"
                                          "season_log.csv)"),
        DeclareLaunchArgument("clock_topic", default_value="/clock",
                              description="where the simulator publishes farm time: /clock, clock (the "
                                          "namespace's own: farms side by side) or '' (none)"),
        sim,
        agent,
        RegisterEventHandler(OnProcessExit(target_action=agent, on_exit=on_agent_exit)),
    ])
