"""The virtual rig: the boom as a machine (plant, effects, sensors) for the rig server.

``VirtualRig(load_config("examples/rig/none.json")).step(u)`` returns a
:class:`Sample` every millisecond; see :mod:`boomfmi.rig.plant` (the plant),
:mod:`boomfmi.rig.config` (its configuration) and :mod:`boomfmi.rig.truth` (the effects'
forms).

The whole excavator's rig is :class:`boomfmi.rig.excavator.ExcavatorRig`
(:func:`load_excavator_config`, ``examples/rig/excavator_*.json``); :func:`make_rig`
builds whichever a configuration describes.
"""
from .config import ExcavatorConfig, RigConfig, config_machine, load_config, load_excavator_config
from .plant import Sample, VirtualRig


def make_rig(config=None):
    """The rig a configuration describes (path, dict, config or None): an
    :class:`~boomfmi.rig.excavator.ExcavatorRig` for ``"machine": "excavator"``, else
    the boom's :class:`VirtualRig`."""
    if config_machine(config) == "excavator":
        from .excavator import ExcavatorRig
        return ExcavatorRig(load_excavator_config(config))
    return VirtualRig(load_config(config))


__all__ = ["VirtualRig", "RigConfig", "Sample", "load_config", "ExcavatorConfig", "load_excavator_config",
           "config_machine", "make_rig"]
