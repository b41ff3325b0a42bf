"""The virtual rig: the boom as a machine (plant, effects, sensors) for the rig server.

``VirtualRig(load_config("examples/rig/none.json")).step(u)`` returns a
:class:`Sample` every millisecond; see :mod:`boomfmi.rig.plant` (the plant),
:mod:`boomfmi.rig.config` (its configuration) and :mod:`boomfmi.rig.truth` (the effects'
forms).
"""
from .config import RigConfig, load_config
from .plant import Sample, VirtualRig

__all__ = ["VirtualRig", "RigConfig", "Sample", "load_config"]
