"""Daily weather: the series type, file readers, the seeded generator and the noisy forecast.

Imports neither rclpy, gymnasium nor torch.
"""

from .readers import BENTON_E_SITE, read_agweathernet_csv, read_dssat_wth
from .series import Site, WeatherError, WeatherSeries, make_series

__all__ = ["BENTON_E_SITE", "Site", "WeatherError", "WeatherSeries", "make_series", "read_agweathernet_csv",
           "read_dssat_wth"]
