"""Diagnosis of the sim-to-real gap (``shared/spec/diagnosis-report.md``).

``localise`` says where the model and a recording disagree: per channel, operating
regime and subsystem; ``attribute`` which effect of ``effects.md`` explains it and by
how much; ``diagnose`` runs both and writes the report (``report``: one entry for one
joint or four; the whole excavator's recordings are judged joint by joint, ``joints``).

One meaning per name: ``boomfmi.diagnose.attribute`` and ``boomfmi.diagnose.localise``
are the modules (their functions are ``attribute.attribute`` and ``localise.localise``);
the package re-exports no function under a module's name.
"""
from . import attribute, localise
from .attribute import CANDIDATES
from .localise import REGIMES, Localisation, regimes
from .report import diagnose

__all__ = ["CANDIDATES", "REGIMES", "Localisation", "attribute", "diagnose", "localise", "regimes"]
