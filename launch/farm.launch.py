"""The simulated farm: the simulator node and an agent node that drives one season, then both stop.

    ros2 launch crop_sim_ros farm.launch.py [policy:=ppo|refill|best-constant|constant|zero] [params_file:=...]

Parameters come from share/crop_sim_ros/config/farm_params.yaml (or params_file). When the agent has
grown its season(s) it exits, and the launch shuts down the simulator with it.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    params_file = LaunchConfiguration("params_file")
    sim = Node(package="crop_sim_ros", executable="sim_node", name="crop_sim", output="screen",
               parameters=[params_file])
    agent = Node(package="crop_sim_ros", executable="agent_node", name="crop_agent", output="screen",
                 parameters=[params_file, {"policy": LaunchConfiguration("policy"),
                                           "drive": True}])
    return LaunchDescription([
        DeclareLaunchArgument(
            "params_file",
            default_value=PathJoinSubstitution([FindPackageShare("crop_sim_ros"), "config", "farm_params.yaml"]),
            description="parameter file of both nodes"),
        DeclareLaunchArgument("policy", default_value="ppo", description="zero | constant | best-constant | refill | ppo"),
        sim,
        agent,
        RegisterEventHandler(OnProcessExit(target_action=agent,
                                           on_exit=[EmitEvent(event=Shutdown(reason="the season is grown"))])),
    ])
