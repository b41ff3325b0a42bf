"""The virtual rig: the boom as a machine (plant, effects, sensors) for the rig server.

``VirtualRig(load_config("examples/rig/none.json")).step(u)`` returns a
:class:`Sample` every millisecond; see :mod:`boomfmi.rig.plant`.
"""
from .plant import RigConfig, Sample, VirtualRig, load_config

__all__ = ["VirtualRig", "RigConfig", "Sample", "load_config"]
