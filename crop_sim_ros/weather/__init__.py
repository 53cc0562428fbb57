"""Daily weather: the series type, file readers, the seeded generator.

Imports neither rclpy, gymnasium nor torch.
"""

from .csv_readers import read_nasa_power_csv, read_plain_csv, write_plain_csv
from .generator import (GENERATOR_NAMES, GeneratorParameters, benton_parameters, generate_season, generate_seasons,
                        generator_parameters)
from .readers import BENTON_E_SITE, read_agweathernet_csv, read_dssat_wth
from .series import Site, WeatherError, WeatherSeries, make_series

__all__ = ["BENTON_E_SITE", "GENERATOR_NAMES", "GeneratorParameters", "Site", "WeatherError", "WeatherSeries",
           "benton_parameters", "generate_season", "generate_seasons", "generator_parameters", "make_series",
           "read_agweathernet_csv", "read_dssat_wth", "read_nasa_power_csv", "read_plain_csv", "write_plain_csv"]
