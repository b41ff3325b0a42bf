"""Running FMUs: one instance by variable name (``instance``); the SSP system and the
co-simulation master join here."""
from .instance import FmuError, FmuInstance
from .master import CoSimulation, fmpy_input, simulate_ssp
from .ssv import SspError

__all__ = ["CoSimulation", "FmuError", "FmuInstance", "SspError", "fmpy_input", "simulate_ssp"]
