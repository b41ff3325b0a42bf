"""A machine is a set of joints: each joint's valve, gas, cylinder, friction and effects
(a boom :class:`Model`), and the mechanism that carries them: the boom's load (Eq. 8 to
12, one joint: the boom rig) or the excavator's linkage (``physics/linkage.py``, four
joints).  :class:`Machine` is the one description the reference
(:func:`.reference.simulate`), the SSPs' names and the effects' checks read; the boom rig
is the one-joint machine (:func:`boom_machine`), the whole excavator the four-joint one
(:func:`excavator_machine`; ``ExcavatorMachine`` is this same class).

Names follow ``physics.params.channel``: one joint carries no suffix (``p_a``, ``alpha``,
``K_v``, ``boom_load.K_v``), more joints ``_<joint>`` (``p_a_arm``, ``angle_arm``,
``K_v_arm``, ``linkage.K_v_arm``).

The excavator starts at rest with every piston at mid-stroke and every valve closed
(5 V), each cylinder's chambers at pressures that hold its joint against gravity
(:func:`holding_pressures`).  Only relative imports, no scipy or pandas: the linkage FMU
bundles this module for :func:`friction_hook`.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .. import physics as ph
from ..physics import reference_rig
from ..physics.linkage import JOINTS, Excavator, excavator_parameters
from ..physics.params import channel
from .boom import Boom, Model, check_caps, check_effects
from .catalogue import EFFECTS, fmu_variable


def holding_pressures(ex: Excavator, x0, p_b0: float | None = None, payload: float = 0.0):
    """Absolute chamber pressures ``(p_a0, p_b0)`` [Pa] (4-vectors) that hold each joint
    still at piston positions ``x0`` [m]: ``p_b0`` (default: midway between the supply
    and the atmosphere) in every rod side, and the cap side's pressure whose cylinder
    force equals the gravity load reflected to the piston (``lam G``, the linkage's
    bias at rest)."""
    from ..physics.linkage import holding_forces
    if p_b0 is None:
        p_b0 = 0.5 * (reference_rig.P_s + ex.P_atm)
    forces = holding_forces(x0, payload, ex)
    p_a = []
    for j, a in enumerate(ex.actuators):
        force = forces[j]
        p_a.append((force + p_b0 * a.A_b + ex.P_atm * (a.A_a - a.A_b)) / a.A_a)
    return np.array(p_a), np.full(4, float(p_b0))


@dataclass(frozen=True)
class Joint:
    """One joint of a machine: its name and its valve, gas, cylinder, friction and
    effects as a boom :class:`Model`."""
    name: str
    model: Model


@dataclass(frozen=True)
class Machine:
    """A machine of joints.  The mechanism is the linkage ``ex`` (four joints; the
    valves and the gas the reference rig's, each valve with its joint's A_max) unless
    ``model`` is given: then the boom's load of that :class:`Model` (one joint,
    ``"boom"``).  ``effects`` maps each joint to its effects, as a boom :class:`Model`'s
    (checked by :meth:`check`: a joint that is none, or an effect or parameter that is
    not the catalogue's, is refused naming it)."""
    ex: Excavator | None = field(default_factory=excavator_parameters)
    gas: ph.Gas = field(default_factory=ph.Gas)
    P_s: float = reference_rig.P_s
    P_e: float = reference_rig.P_e
    payload: float = 0.0
    x0: tuple | None = None          #: start positions [m] (default: mid-stroke)
    p_a0: tuple | None = None        #: start pressures [Pa] (default: holding_pressures)
    p_b0: tuple | None = None
    #: joint -> its effects, as a boom :class:`Model`'s (``{"arm": {"piston_leakage": {"C": 2e-11}}}``)
    effects: dict = field(default_factory=dict)
    #: the one-joint machine's model (the boom rig: its load is the mechanism); None: the linkage
    model: Model | None = None

    @property
    def mechanism(self) -> str:
        """``"boom"`` (the boom's load, Eq. 8 to 12) or ``"linkage"`` (the excavator's)."""
        return "boom" if self.model is not None else "linkage"

    @property
    def names(self) -> tuple:
        return ("boom",) if self.model is not None else JOINTS

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def joints(self) -> tuple:
        return tuple(Joint(j, self.joint_model(j)) for j in self.names)

    @property
    def valves(self) -> tuple:
        if self.model is not None:
            return (self.model.valve,)
        return tuple(ph.Valve(A_max=a.A_max, P_s=self.P_s, P_e=self.P_e) for a in self.ex.actuators)

    @property
    def cylinders(self) -> tuple:
        if self.model is not None:
            return (self.model.cylinder,)
        return tuple(a.cylinder for a in self.ex.actuators)

    def check(self) -> None:
        """Raise :class:`physics.ParameterError` naming the first bad joint or effect
        parameter (``effects.arm.piston_leakage.C``)."""
        _check_effects(self.effects, dict(zip(self.names, self.cylinders)), self.mechanism)

    def joint_model(self, joint: str) -> Model:
        """Joint ``joint``'s valve, cylinder, friction and effects as a boom :class:`Model`
        (the linkage's joints carry the boom's geometry: only the boom's load uses it)."""
        if joint not in self.names:
            raise ph.ParameterError("joint", joint, f"not a joint of the machine ({', '.join(self.names)})")
        if self.model is not None:
            return replace(self.model, effects=dict(self.effects.get(joint, {})))
        j = JOINTS.index(joint)
        return Model(valve=self.valves[j], gas=self.gas, cylinder=self.cylinders[j], geometry=self.ex.geometry,
                     load=self.ex.load(joint), P_atm=self.ex.P_atm, effects=dict(self.effects.get(joint, {})))

    def booms(self) -> tuple:
        """One :class:`Boom` per joint (checked first: :meth:`check`)."""
        self.check()
        return tuple(Boom(self.joint_model(j), check=False) for j in self.names)

    def start(self):
        """``(x0, p_a0, p_b0)``, one entry per joint."""
        if self.model is not None:
            m = self.model
            return np.array([m.x0], dtype=float), np.array([m.p_a0], dtype=float), np.array([m.p_b0], dtype=float)
        x0 = np.array(self.x0 if self.x0 is not None else 0.5 * self.ex.strokes, dtype=float)
        p_a0, p_b0 = holding_pressures(self.ex, x0, payload=self.payload)
        if self.p_a0 is not None:
            p_a0 = np.array(self.p_a0, dtype=float)
        if self.p_b0 is not None:
            p_b0 = np.array(self.p_b0, dtype=float)
        return x0, p_a0, p_b0

    def channel(self, quantity: str, joint: str) -> str:
        """Joint ``joint``'s ``quantity`` in recordings (``physics.params.channel``)."""
        return channel(quantity, joint, self.n)

    def param_name(self, param: str, joint: str) -> str:
        """An identified parameter's name: ``K_v`` (one joint) or ``K_v_arm``."""
        return channel(param, joint, self.n)

    def ssp_name(self, param: str) -> str:
        """Where an identified parameter (:meth:`param_name`) lives in the machine's SSP:
        ``boom_load.K_v``, ``valve.A_max`` (one joint) or ``linkage.K_v_arm``,
        ``valve_arm.A_max``."""
        if param == "A_max" and self.n == 1:
            return "valve.A_max"
        if param.startswith("A_max_") and self.n > 1:
            return f"valve_{param[len('A_max_'):]}.A_max"
        return f"{'boom_load' if self.n == 1 else 'linkage'}.{param}"

    def fmu_variable(self, effect: str, parameter: str, joint: str) -> str | None:
        """The SSP's name of joint ``joint``'s effect parameter (:func:`fmu_variable`:
        ``valve.tau_spool`` for the boom, ``valve_arm.tau_spool``, ``linkage.v_s_arm``
        for the excavator); ``None`` for the sensors (the bridge's, on the measurement
        path)."""
        if joint not in self.names:
            raise ph.ParameterError("joint", joint, f"not a joint of the machine ({', '.join(self.names)})")
        if EFFECTS[effect].stage == "measurement":
            return None
        if self.n == 1:
            return fmu_variable(effect, parameter)
        return joint_fmu_variable(effect, parameter, joint)

    def friction_hooks(self, booms: tuple | None = None) -> list:
        """Each joint's :func:`friction_hook` (``None`` where it has no friction effect)."""
        booms = booms if booms is not None else self.booms()
        return [friction_hook(b, self.joint_model(j).load) for b, j in zip(booms, self.names)]


#: The whole excavator's construction: the same class (``ExcavatorMachine(effects=...)``).
ExcavatorMachine = Machine


def boom_machine(model: Model) -> Machine:
    """The boom rig as the one-joint machine: joint ``"boom"`` of ``model`` (its effects
    are the joint's), on the boom's load."""
    return Machine(ex=None, gas=model.gas, P_s=model.valve.P_s, P_e=model.valve.P_e,
                   effects={"boom": dict(model.effects)} if model.effects else {}, model=model)


def excavator_machine(ex: Excavator | None = None, effects: dict | None = None, payload: float = 0.0,
                      **start) -> Machine:
    """The whole excavator (``excavator.md``'s machine unless ``ex``) with ``effects``
    (joint -> effects), ``payload`` [kg] and any start (``x0``, ``p_a0``, ``p_b0``), the
    gas, ``P_s`` or ``P_e`` of :class:`Machine`."""
    return Machine(ex=ex if ex is not None else excavator_parameters(), effects=dict(effects or {}),
                   payload=payload, **start)


def _check_effects(effects, cylinders: dict, what: str) -> None:
    if not isinstance(effects, dict):
        raise ph.ParameterError("effects", effects, f"must map joints ({', '.join(cylinders)}) to their effects")
    for joint, eff in effects.items():
        if joint not in cylinders:
            raise ph.ParameterError("effects", joint, f"not a joint of the {'excavator' if what == 'linkage' else what}"
                                    f" ({', '.join(cylinders)})")
        if not isinstance(eff, dict):
            raise ph.ParameterError(f"effects.{joint}", eff, "must map effect names to their parameters")
        try:
            check_effects(eff)
            if cylinders[joint] is not None:
                check_caps(eff, cylinders[joint])
        except ph.ParameterError as e:
            reason = str(e).split(" is invalid: ", 1)[-1]
            raise ph.ParameterError(e.name.replace("effects", f"effects.{joint}", 1), e.value, reason) from None


def check_joint_effects(effects, ex: Excavator | None = None) -> None:
    """``effects`` maps joints of the excavator to a boom :class:`Model`'s effects
    (``model.check_effects``); raise :class:`physics.ParameterError` naming the joint
    that is none or the effect's parameter under its joint (``effects.arm.piston_leakage.C``).
    With ``ex``, an end cushion's port must fit the joint's dead volumes."""
    _check_effects(effects, {j: (getattr(ex, j).cylinder if ex is not None else None) for j in JOINTS}, "linkage")


def joint_fmu_variable(effect: str, parameter: str, joint: str) -> str | None:
    """The excavator SSP's name of joint ``joint``'s effect parameter: its valve's or
    cylinder's option (``valve_arm.tau_spool``, ``cylinder_arm.C_leak``), or the
    linkage's option for that joint's cylinder (``linkage.v_s_arm``: the boom_load FMU's
    friction options, suffixed); ``None`` for the sensors (the bridge's, on the
    measurement path: ``model.measure`` on the outputs)."""
    if joint not in JOINTS:
        raise ph.ParameterError("joint", joint, f"not a joint of the excavator ({', '.join(JOINTS)})")
    if EFFECTS[effect].stage == "measurement":
        return None
    fmu, option = fmu_variable(effect, parameter).split(".", 1)
    return f"linkage.{option}_{joint}" if fmu == "boom_load" else f"{fmu}_{joint}.{option}"


def friction_hook(boom: Boom, load: ph.Load):
    """The ``friction`` argument's entry of ``advance_linkage`` for one joint: its
    cylinder's ``load`` (K_v, F_s, F_d) through ``boom``'s friction effects
    (:meth:`Boom.load_at`) at the piston's speed and pressures; ``None`` where it has
    none (the linkage's constant levels)."""
    if not boom.friction_effects:
        return None

    def hook(v: float, p_a: float, p_b: float):
        ld = boom.load_at(load, v, p_a, p_b)
        return ld.K_v, ld.F_s, ld.F_d
    return hook

__all__ = [
    "holding_pressures", "Joint", "Machine", "ExcavatorMachine", "boom_machine", "excavator_machine",
    "check_joint_effects", "joint_fmu_variable", "friction_hook",
]
