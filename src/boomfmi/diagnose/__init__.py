"""Diagnosis of the sim-to-real gap (``shared/spec/diagnosis-report.md``).

``localise`` says where the model and a recording disagree: per channel, operating
regime and subsystem; ``attribute`` which effect of ``effects.md`` explains it and by
how much; ``diagnose`` runs both and writes the report.
"""
from .attribute import CANDIDATES, attribute
from .localise import REGIMES, Localisation, localise, regimes
from .report import diagnose

__all__ = ["CANDIDATES", "REGIMES", "Localisation", "attribute", "diagnose", "localise", "regimes"]
