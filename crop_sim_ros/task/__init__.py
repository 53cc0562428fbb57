"""The irrigation task: scenarios, the functional core (observation, reward), the Gymnasium environment and
its vectorised form, and their registration.

Registered ids (``gymnasium.make(id)``; ``gymnasium.make_vec(id, num_envs=N)`` gives the batched
:class:`IrrigationVectorEnv`):

======================================= ===================== ===========================================
id                                      scenario              weather
======================================= ===================== ===========================================
SimpleIrrigation-Generated-v0           benton-generated      generated Benton County seasons (no file)
SimpleIrrigation-Benton2000-v0          benton-2000           AgWeatherNet Benton E., 2000 (the paper's)
SimpleIrrigation-Paterson1992-v0 .. 95  paterson-1992 .. 1995 DSSAT WAPA9201..9501.WTH (held out)
SimpleIrrigation-HeldOut-v0             heldout               the five real seasons
SimpleIrrigation-Money-v0               benton-money          family: net return USD/ha (29 values)
SimpleIrrigation-Quota-v0               benton-quota          family: + seasonal quota, pivot 8 mm/d
SimpleIrrigation-Capacity-v0            benton-capacity       family: irrigation capacity 4.5 mm/d
SimpleIrrigation-Sensing-v0             benton-sensing        family: quota + noisy PAW with dropouts
SimpleIrrigation-Blind-v0               benton-blind          family: quota + no PAW sensor
SimpleIrrigation-Climates-v0            climates-quota        family: quota, Benton + Gainesville weather
SimpleIrrigation-Climates3-v0           climates3-quota       family: climates-quota + Benton sown March 1
SimpleIrrigation-Climates4-v0           climates4-quota       family: climates3-quota + that Benton +4 degC
SimpleIrrigation-Climates6-v0           climates6-quota       family: + Benton April 1 and Gainesville +4 degC
SimpleIrrigation-Climates8-v0           climates8-quota       family: + Benton sown May 1, and +4 degC
SimpleIrrigation-Climates10-v0          climates10-quota      family: + Benton +6 degC in drier air
SimpleIrrigation-Climates12-v0          climates12-quota      family: + the same with 0.3 x the rain
SimpleIrrigation-ClimatesSpread-v0      climates-spread-quota family: + Benton, each season its own climate
======================================= ===================== ===========================================

The family tasks (money, quota, capacity, sensing, climates) are documented in :mod:`crop_sim_ros.task.layout`
(their 29-value observation) and :mod:`crop_sim_ros.task.terms` (their terms and defaults).

Imports neither rclpy nor torch (the Stable-Baselines3 adapter is :mod:`crop_sim_ros.task.sb3_vec`).
"""

from gymnasium.envs.registration import register, registry

from .env import STATE_INFO_KEYS, STEP_INFO_KEYS, IrrigationEnv
from .scenario import ObservationNoise, Scenario, get_scenario, load_scenario, scenario_names
from .vector_env import IrrigationVectorEnv

ENV_IDS = {
    "SimpleIrrigation-Generated-v0": "benton-generated",
    "SimpleIrrigation-Benton2000-v0": "benton-2000",
    "SimpleIrrigation-Paterson1992-v0": "paterson-1992",
    "SimpleIrrigation-Paterson1993-v0": "paterson-1993",
    "SimpleIrrigation-Paterson1994-v0": "paterson-1994",
    "SimpleIrrigation-Paterson1995-v0": "paterson-1995",
    "SimpleIrrigation-HeldOut-v0": "heldout",
    "SimpleIrrigation-Money-v0": "benton-money",
    "SimpleIrrigation-Quota-v0": "benton-quota",
    "SimpleIrrigation-Capacity-v0": "benton-capacity",
    "SimpleIrrigation-Sensing-v0": "benton-sensing",
    "SimpleIrrigation-Blind-v0": "benton-blind",
    "SimpleIrrigation-Climates-v0": "climates-quota",
    "SimpleIrrigation-Climates3-v0": "climates3-quota",
    "SimpleIrrigation-Climates4-v0": "climates4-quota",
    "SimpleIrrigation-Climates6-v0": "climates6-quota",
    "SimpleIrrigation-Climates8-v0": "climates8-quota",
    "SimpleIrrigation-Climates10-v0": "climates10-quota",
    "SimpleIrrigation-Climates12-v0": "climates12-quota",
    "SimpleIrrigation-ClimatesSpread-v0": "climates-spread-quota",
}

for _env_id, _scenario in ENV_IDS.items():
    if _env_id not in registry:
        register(id=_env_id, entry_point="crop_sim_ros.task.env:IrrigationEnv",
                 vector_entry_point="crop_sim_ros.task.vector_env:IrrigationVectorEnv",
                 kwargs={"scenario": _scenario})

__all__ = ["ENV_IDS", "IrrigationEnv", "IrrigationVectorEnv", "ObservationNoise", "STATE_INFO_KEYS",
           "STEP_INFO_KEYS", "Scenario", "get_scenario", "load_scenario", "scenario_names"]
