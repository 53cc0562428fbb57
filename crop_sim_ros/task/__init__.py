"""The irrigation task: scenarios, the functional core (observation, reward), the Gymnasium environment and
its vectorised form, and their registration.

One name per task: every built-in scenario (``crop_sim_ros/task/scenarios/<name>.yaml``) is a task, and its name
is what the CLI (``--task``), the ROS parameter (``scenario:=``), the docs and the leaderboard use. Its Gymnasium
id is derived by one rule, :func:`gym_id`: ``crop-sim/<name>-v0`` (and back, :func:`task_name`). Every built-in
task is registered, with ``max_episode_steps`` its longest season in days (``max_season_days``):

.. code-block:: python

    gymnasium.make("crop-sim/benton-generated-v0")                 # an IrrigationEnv in a TimeLimit
    gymnasium.make_vec("crop-sim/benton-quota-v0", num_envs=1024)  # the batched IrrigationVectorEnv

========================================= ===================================================================
names                                     task
========================================= ===================================================================
``benton-generated``                      the paper's task on generated Benton County seasons (no data file)
``benton-2000``                           the paper's season, AgWeatherNet Benton E. 2000
``paterson-1992`` .. ``paterson-1995``    held-out real seasons (DSSAT WAPA9201..9501.WTH)
``heldout``                               the five real seasons together
``gainesville-*``, ``maricopa-*``,        other climates and sowing dates, generated (``-generated``) or
``benton-*-generated``                    real (``-real``)
``benton-money``                          family: net return USD/ha (29-value observation)
``benton-quota``                          family: + seasonal quota, pivot 8 mm/d
``benton-capacity``                       family: irrigation capacity 4.5 mm/d
``benton-sensing``, ``benton-blind``      family: quota + noisy PAW with dropouts / no PAW sensor
``climates*-quota``                       family: quota across climates (Benton, Gainesville; Maricopa held out)
``benton-early-*``, ``maricopa-*-quota``  family: quota at other sowing dates and climates
========================================= ===================================================================

The family tasks are documented in :mod:`crop_sim_ros.task.layout` (their 29-value observation) and
:mod:`crop_sim_ros.task.terms` (their terms and defaults); every scenario in :mod:`crop_sim_ros.task.scenario`.

Importing registers the ids from the scenario files alone (no weather is read or generated until an
environment is made). Imports neither rclpy nor torch (the Stable-Baselines3 adapter is
:mod:`crop_sim_ros.task.sb3_vec`).
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from .env import STATE_INFO_KEYS, STEP_INFO_KEYS, IrrigationEnv
from .scenario import ObservationNoise, Scenario, get_scenario, load_scenario, longest_season_days, scenario_names
from .vector_env import IrrigationVectorEnv

GYM_NAMESPACE = "crop-sim"
GYM_VERSION = 0
_GYM_PREFIX, _GYM_SUFFIX = f"{GYM_NAMESPACE}/", f"-v{GYM_VERSION}"


def _derived_id(name: str) -> str:
    """The rule: task name -> Gymnasium id (unchecked)."""
    return _GYM_PREFIX + name + _GYM_SUFFIX


def gym_id(name: str) -> str:
    """The Gymnasium id of the built-in task ``name``: ``crop-sim/<name>-v0``. ValueError naming ``name`` for a
    name that is not a built-in scenario."""
    if name not in scenario_names():
        raise ValueError(f"{name!r} is not a built-in task; known: {', '.join(scenario_names())}")
    return _derived_id(name)


def task_name(env_id: str) -> str:
    """The task of the Gymnasium id ``env_id`` (the inverse of :func:`gym_id`). ValueError naming ``env_id`` for
    an id the rule does not make from a built-in task."""
    if (not isinstance(env_id, str) or not (env_id.startswith(_GYM_PREFIX) and env_id.endswith(_GYM_SUFFIX))
            or env_id[len(_GYM_PREFIX):-len(_GYM_SUFFIX)] not in scenario_names()):
        raise ValueError(f"{env_id!r} is not the id of a built-in task ({_GYM_PREFIX}<task>{_GYM_SUFFIX}, a task of "
                         f"{', '.join(scenario_names())})")
    return env_id[len(_GYM_PREFIX):-len(_GYM_SUFFIX)]


for _name in scenario_names():
    if _derived_id(_name) not in registry:
        register(id=_derived_id(_name), entry_point="crop_sim_ros.task.env:IrrigationEnv",
                 vector_entry_point="crop_sim_ros.task.vector_env:IrrigationVectorEnv",
                 max_episode_steps=longest_season_days(_name), kwargs={"scenario": _name})

__all__ = ["GYM_NAMESPACE", "IrrigationEnv", "IrrigationVectorEnv", "ObservationNoise", "STATE_INFO_KEYS",
           "STEP_INFO_KEYS", "Scenario", "get_scenario", "gym_id", "load_scenario", "scenario_names", "task_name"]
