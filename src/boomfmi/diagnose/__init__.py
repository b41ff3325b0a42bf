"""Diagnosis of the sim-to-real gap (``shared/spec/diagnosis-report.md``).

``localise`` says where the model and a recording disagree: per channel, operating
regime and subsystem.  Attribution to the effects of ``effects.md`` and the
``boomfmi diagnose`` report build on it.
"""
from .localise import REGIMES, Localisation, localise, regimes

__all__ = ["REGIMES", "Localisation", "localise", "regimes"]
