"""The virtual rig: the boom as a machine (plant, effects, sensors) for the rig server.

``VirtualRig(load_config("examples/rig/none.json")).step(u)`` returns a
:class:`Sample` every millisecond; see :mod:`boomfmi.rig.plant` (the plant),
:mod:`boomfmi.rig.config` (its configuration) and :mod:`boomfmi.rig.truth` (the effects'
forms).

Both are one :class:`MachineRig` (its joints' :class:`~boomfmi.rig.plant.JointPlant`
and a mechanism): the boom's :class:`VirtualRig`, the whole excavator's
:class:`ExcavatorRig` (:func:`load_excavator_config`, ``examples/rig/excavator_*.json``,
recorded offline by :func:`run_excavator_offline`); :func:`make_rig` builds whichever a
configuration describes.
"""
from .config import ExcavatorConfig, RigConfig, config_machine, load_config, load_excavator_config
from .offline import run_excavator_offline, run_offline
from .plant import ExcavatorRig, ExcavatorSample, JointPlant, MachineRig, Sample, VirtualRig, vented_holding_pressures


def make_rig(config=None):
    """The rig a configuration describes (path, dict, config or None): an
    :class:`ExcavatorRig` for ``"machine": "excavator"``, else
    the boom's :class:`VirtualRig`."""
    if config_machine(config) == "excavator":
        return ExcavatorRig(load_excavator_config(config))
    return VirtualRig(load_config(config))


__all__ = ["VirtualRig", "RigConfig", "Sample", "load_config", "ExcavatorConfig", "load_excavator_config",
           "config_machine", "make_rig", "MachineRig", "JointPlant", "ExcavatorRig", "ExcavatorSample",
           "vented_holding_pressures", "run_offline", "run_excavator_offline"]
