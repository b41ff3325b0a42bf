"""Running FMUs: one instance by variable name (``instance``); the SSP system and the
co-simulation master join here."""
from .instance import FmuError, FmuInstance

__all__ = ["FmuError", "FmuInstance"]
