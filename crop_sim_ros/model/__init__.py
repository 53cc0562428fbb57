"""The pure SIMPLE crop model: parameters with units, state, the one-day step for N fields, ET0.

Imports neither rclpy, gymnasium nor torch.
"""

from .parameters import (Cultivar, CropLibrary, Management, Soil, Species, UnknownNameError, crop_library,
                         simple_r_library, zhao2019_library)
from .season import SeasonResult, simulate_season
from .simple import (CropState, DailyFluxes, DailyWeather, FieldParameters, check_irrigation, field_parameters,
                     harvestable_yield_kg_ha, initial_state, repeat_parameters, stack_parameters, step)

__all__ = ["Cultivar", "CropLibrary", "CropState", "DailyFluxes", "DailyWeather", "FieldParameters", "Management",
           "SeasonResult", "Soil", "Species", "UnknownNameError", "check_irrigation", "crop_library",
           "field_parameters", "harvestable_yield_kg_ha", "initial_state", "repeat_parameters",
           "simple_r_library", "simulate_season", "stack_parameters", "step", "zhao2019_library"]
