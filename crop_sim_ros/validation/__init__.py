"""The SIMPLE reference input set (R distribution v1.1): reader, batched runner and RRMSE report.

Imports the model and weather layers only (neither rclpy, gymnasium nor torch).
"""

from .inputs import InputError, Observation, Treatment, read_irrigation, read_observations, read_treatments
from .report import PAPER_TABLE3_RRMSE_PERCENT, Comparison, compare, rrmse_percent
from .runner import TreatmentRun, run_treatments, select_treatments

__all__ = ["Comparison", "InputError", "Observation", "PAPER_TABLE3_RRMSE_PERCENT", "Treatment", "TreatmentRun",
           "compare", "read_irrigation", "read_observations", "read_treatments", "rrmse_percent",
           "run_treatments", "select_treatments"]
