"""The simulator node's name, modes and parameters (:data:`PARAMETERS`: default, description, range, constraints).

Standard library only: the executable (:mod:`crop_sim_ros.sim_node`) prints them for ``--help`` before rclpy
loads, and the node (:class:`crop_sim_ros.sim.SimNode`) declares them to ROS 2.
"""

from __future__ import annotations

from typing import NamedTuple

NODE_NAME = "crop_sim"
MODES = ("lockstep", "free_running")
INT32_MAX = 2**31 - 1
CLOCK_TOPIC_DEFAULT = "/clock"


class ParameterSpec(NamedTuple):
    """A parameter of the node: its default (whose Python type is the ROS type), description, inclusive range
    (numbers) and constraints text."""
    default: object
    description: str
    low: float | None = None
    high: float | None = None
    constraints: str = ""


PARAMETERS = {
    "scenario": ParameterSpec(
        "benton-generated", "built-in scenario name (e.g. benton-generated, benton-2000, paterson-1992..1995, "
        "heldout) or the path of a scenario YAML file; applied at the next reset",
        constraints="must load: unknown names and files that are not scenarios are refused"),
    "data_dir": ParameterSpec(
        "", "directory of the scenario weather files ('' = share/crop_sim_ros/data of an installed package if it "
        "has one, else $CROP_SIM_DATA_DIR, else the shared/data found walking up from the current directory, then "
        "from the package); applied at the next reset"),
    "seed": ParameterSpec(0, "seed of every reset (weather draw and all noise); -1 = do not reseed: continue the "
                             "random stream like Gymnasium's reset(seed=None)", -1, INT32_MAX),
    "weather_season": ParameterSpec(-1, "index of the scenario's season to grow at the next resets; -1 = drawn "
                                        "with the seed", -1, INT32_MAX,
                                    "below the scenario's number of seasons"),
    "crop": ParameterSpec("", "crop override ('' = the scenario's), e.g. potato",
                          constraints="a crop of the parameter library"),
    "cultivar": ParameterSpec("", "cultivar override ('' = the scenario's), e.g. Russet Burbank"),
    "soil": ParameterSpec("", "soil override ('' = the scenario's), e.g. Benton USA potato"),
    "co2_ppm": ParameterSpec(-1.0, "atmospheric CO2 override, ppm (-1 = the scenario's)", -1.0, 5000.0,
                             "-1 or 0..5000"),
    "noise_scale": ParameterSpec(1.0, "factor on every observation noise standard deviation of the scenario "
                                      "(0 = exact observations)", 0.0, 100.0),
    "irrigation_cost_per_mm": ParameterSpec(-1.25e-4, "reward per mm irrigated (C_I; <= 0); the paper's task "
                                                      "only: a family task's water cost is its scenario's",
                                            -1.0, 0.0),
    "mode": ParameterSpec("lockstep", "lockstep: one day per ~/step call; free_running: the node steps by "
                                      "itself, days_per_second days per second of wall time (~/step is then "
                                      "refused)", constraints=" | ".join(MODES)),
    "days_per_second": ParameterSpec(5.0, "free_running: simulated days per second of wall time", 0.01, 1000.0),
    "log_path": ParameterSpec("", "season log CSV, one row per day, appended ('' = $ROS_HOME/<namespace>/<node "
                                  "name>/season_log.csv: $ROS_HOME/crop_sim/season_log.csv for /crop_sim, "
                                  "$ROS_HOME/field7/crop_sim/season_log.csv under -r __ns:=/field7; ROS_HOME "
                                  "defaulting to ~/.ros); applied at the next reset",
                              constraints="a writable file with this log's columns, or a new file in a writable "
                                          "directory"),
    "clock_topic": ParameterSpec(CLOCK_TOPIC_DEFAULT, "where farm time is published (rosgraph_msgs/Clock): '/clock' "
                                                      "(the ROS time source of use_sim_time nodes), a relative name "
                                                      "such as 'clock' for the node's namespace (two farms side by "
                                                      "side: /field7/clock, /field8/clock), or '' for none; read at "
                                                      "the start only",
                                 constraints="read-only: set it with -p or a parameter file"),
}
# Parameters read once at the start (declared read-only: ros2 param set refuses them).
READ_ONLY_PARAMETERS = ("clock_topic",)
