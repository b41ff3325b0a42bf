"""The monolithic reference of the whole excavator: four valves, eight chambers and the
linkage as one system, integrated far finer than any co-simulation of it.

The physics is the co-simulated components' own, called directly: each valve's flows
and their slopes (Eq. 1, ``physics.chamber_flows`` and ``chamber_flow_slopes``), each
chamber's pressure (Eq. 4 to 7, ``physics.chamber_pressure_step`` against the valve's
linearisation, exact for a closed chamber) and the linkage (``physics.advance_linkage``:
M, C, G of the four joints, each cylinder through its lever, Eq. 9 friction and the end
stops per cylinder, the tip force through J^T).  What differs from the co-simulation is
the coupling: every fine step (``h``, default 50 us, twenty times shorter than the
co-simulation's 1 ms) the valves see the chambers' newest pressures, the linkage moves
under them, and the chambers then integrate over exactly the linkage's motion; nothing
is held over a communication step.  The scheme is first order in ``h``, so the
reference's own error is gauged by halving ``h`` (``benchmarks/excavator_cosim.py``
prints that difference beside the co-simulation's error).

A scipy solve with stick/slip events (as the boom's :mod:`.reference`) is not used: with
four cylinders each sticking and slipping, an event-driven solve restarts at every one
of the sixteen combinations' transitions, and Eq. 9's stick test couples the joints
through M; the fine fixed step is the same stick/slip logic as the linkage FMU's, at a
step where its error is negligible.

Effects of the catalogue (``model/catalogue.py``) act on any joint
(:attr:`ExcavatorMachine.effects`: joint -> effects, as a boom :class:`Model`'s): each
joint's pneumatics step through a :class:`~.boom.Boom` of that joint's valve and cylinder
(its spool, opening, valve flows, inflows and chambers: the one pneumatic implementation
the boom's FMUs and reference share), its friction effects act in ``advance_linkage``
through a per-joint friction hook (:func:`friction_hook`: the catalogue's ``friction``
stage on that cylinder's K_v, F_s, F_d) and its sensor lag on the sampled channels the
excavator's bridge measures (``p_a``, ``p_b``, ``angle``; ``x`` follows the lagged angle).

The machine starts at rest with every piston at mid-stroke and every valve closed
(5 V), each cylinder's chambers at pressures that hold its joint against gravity
(:func:`holding_pressures`), so the digging cycle starts from a still machine.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .. import physics as ph
from ..physics import effects as fx
from ..physics import reference_rig
from ..physics.excavator import (JOINTS, Excavator, advance_linkage, excavator_parameters, joint_angles,
                                 pistons_from_angles)
from .boom import Boom, Model, check_effects
from .catalogue import EFFECTS, fmu_variable


def holding_pressures(ex: Excavator, x0, p_b0: float | None = None, payload: float = 0.0):
    """Absolute chamber pressures ``(p_a0, p_b0)`` [Pa] (4-vectors) that hold each joint
    still at piston positions ``x0`` [m]: ``p_b0`` (default: midway between the supply
    and the atmosphere) in every rod side, and the cap side's pressure whose cylinder
    force equals the gravity load reflected to the piston (``lam G``, the linkage's
    bias at rest)."""
    from ..physics.excavator import _fast_posture, _prepared, _rigid_terms
    if p_b0 is None:
        p_b0 = 0.5 * (reference_rig.P_s + ex.P_atm)
    P = _prepared(ex, float(payload))
    q, lam, _, _ = _fast_posture([float(t) for t in x0], P)
    _, _, G = _rigid_terms(q, [0.0] * 4, P)
    p_a = []
    for j, a in enumerate(ex.actuators):
        force = lam[j] * G[j]
        p_a.append((force + p_b0 * a.A_b + ex.P_atm * (a.A_a - a.A_b)) / a.A_a)
    return np.array(p_a), np.full(4, float(p_b0))


@dataclass(frozen=True)
class ExcavatorMachine:
    """The whole machine for the reference: the linkage's constants, the valves' and the
    gas's (the reference rig's, each valve with its joint's A_max), the start, and each
    joint's effects (checked by :meth:`check`: a joint that is none, or an effect or
    parameter that is not the catalogue's, is refused naming it)."""
    ex: Excavator = field(default_factory=excavator_parameters)
    gas: ph.Gas = field(default_factory=ph.Gas)
    P_s: float = reference_rig.P_s
    P_e: float = reference_rig.P_e
    payload: float = 0.0
    x0: tuple | None = None          #: start positions [m] (default: mid-stroke)
    p_a0: tuple | None = None        #: start pressures [Pa] (default: holding_pressures)
    p_b0: tuple | None = None
    #: joint -> its effects, as a boom :class:`Model`'s (``{"arm": {"piston_leakage": {"C": 2e-11}}}``)
    effects: dict = field(default_factory=dict)

    @property
    def valves(self) -> tuple:
        return tuple(ph.Valve(A_max=a.A_max, P_s=self.P_s, P_e=self.P_e) for a in self.ex.actuators)

    def check(self) -> None:
        """Raise :class:`physics.ParameterError` naming the first bad joint or effect
        parameter (``effects.arm.piston_leakage.C``)."""
        check_joint_effects(self.effects, self.ex)

    def joint_model(self, joint: str) -> Model:
        """Joint ``joint``'s valve, cylinder, friction and effects as a boom :class:`Model`
        (the geometry is the boom's: only the boom's load uses it)."""
        j = JOINTS.index(joint)
        return Model(valve=self.valves[j], gas=self.gas, cylinder=self.cylinders[j], geometry=self.ex.geometry,
                     load=self.ex.load(joint), P_atm=self.ex.P_atm, effects=dict(self.effects.get(joint, {})))

    def booms(self) -> tuple:
        """One :class:`Boom` per joint (checked first: :meth:`check`)."""
        self.check()
        return tuple(Boom(self.joint_model(j), check=False) for j in JOINTS)

    @property
    def cylinders(self) -> tuple:
        return tuple(a.cylinder for a in self.ex.actuators)

    def start(self):
        """``(x0, p_a0, p_b0)`` as 4-vectors."""
        x0 = np.array(self.x0 if self.x0 is not None else 0.5 * self.ex.strokes, dtype=float)
        p_a0, p_b0 = holding_pressures(self.ex, x0, payload=self.payload)
        if self.p_a0 is not None:
            p_a0 = np.array(self.p_a0, dtype=float)
        if self.p_b0 is not None:
            p_b0 = np.array(self.p_b0, dtype=float)
        return x0, p_a0, p_b0


def check_joint_effects(effects, ex: Excavator | None = None) -> None:
    """``effects`` maps joints of the excavator to a boom :class:`Model`'s effects
    (``model.check_effects``); raise :class:`physics.ParameterError` naming the joint
    that is none or the effect's parameter under its joint (``effects.arm.piston_leakage.C``).
    With ``ex``, an end cushion's port must fit the joint's dead volumes."""
    if not isinstance(effects, dict):
        raise ph.ParameterError("effects", effects, f"must map joints ({', '.join(JOINTS)}) to their effects")
    for joint, eff in effects.items():
        if joint not in JOINTS:
            raise ph.ParameterError("effects", joint, f"not a joint of the excavator ({', '.join(JOINTS)})")
        if not isinstance(eff, dict):
            raise ph.ParameterError(f"effects.{joint}", eff, "must map effect names to their parameters")
        try:
            check_effects(eff)
            if ex is not None:
                V_p = float(eff.get("end_cushioning", {}).get("V_p", 0.0))
                fx.check_cushion_port(V_p, getattr(ex, joint).cylinder, "effects.end_cushioning.V_p")
        except ph.ParameterError as e:
            reason = str(e).split(" is invalid: ", 1)[-1]
            raise ph.ParameterError(e.name.replace("effects", f"effects.{joint}", 1), e.value, reason) from None


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


def simulate_excavator_reference(command: Callable[[float], dict], stop_time: float,
                                 machine: ExcavatorMachine | None = None, h: float = 5e-5,
                                 sample: float = 1e-3, f_tip: Callable[[float], tuple] | None = None) -> pd.DataFrame:
    """The machine from its start under ``command(t) -> {"u_<joint>": V}`` (held over
    each fine step ``h`` [s]) and the tip force ``f_tip(t)`` [N] (world frame; default
    none), sampled every ``sample`` [s] (a multiple of ``h``).

    Returns ``time``, then per joint ``u_<j>``, ``p_a_<j>``, ``p_b_<j>`` (absolute [Pa]),
    ``x_<j>``, ``v_<j>``, ``angle_<j>``.  Each sample holds the state at its time and the
    command applied from it; a joint with sensor_lag, its ``p_a``, ``p_b`` and ``angle``
    as its sensors report them (``x`` from that angle).  ``machine.effects`` is checked
    before any step (:class:`physics.ParameterError` naming the joint or parameter)."""
    import pandas as pd        # (here: the linkage FMU bundles this module for friction_hook, without pandas)
    machine = machine or ExcavatorMachine()
    ex = machine.ex
    booms = machine.booms()
    per = int(round(sample / h))
    if per < 1 or abs(per * h - sample) > 1e-12 * sample:
        raise ValueError(f"the sample interval {sample} s must be a multiple of the step h = {h} s")
    n_samples = int(round(stop_time / sample))
    valves = machine.valves
    x, p_a, p_b = machine.start()
    x = [float(t) for t in x]
    v = [0.0] * 4
    p_a = [float(t) for t in p_a]
    p_b = [float(t) for t in p_b]
    payload = machine.payload
    out = np.empty((n_samples + 1, 1 + 6 * 4))
    keys = [f"u_{j}" for j in JOINTS]

    def record(i, t, u):
        out[i, 0] = t
        out[i, 1:5] = u
        out[i, 5:9] = p_a
        out[i, 9:13] = p_b
        out[i, 13:17] = x
        out[i, 17:21] = v

    no_tip = (0.0, 0.0, 0.0)
    closed = (0.0, 0.0, 0.0, 0.0)
    centre = valves[0].u_centre
    if any(float(ph.orifice_area(centre, va)) != 0.0 for va in valves):
        centre = None
    hooks = [friction_hook(b, ex.load(j)) for b, j in zip(booms, JOINTS)]
    friction = hooks if any(hooks) else None
    spools = [b.tau_spool > 0.0 for b in booms]
    cmd0 = command(0.0)
    y = [float(cmd0[k]) for k in keys]                     # the spools' positions (valve_dynamics)
    masses = [list(b.air_masses(p_a[j], p_b[j], x[j])) if b.h_wall > 0.0 else None
              for j, b in enumerate(booms)]
    for i in range(n_samples):
        t0 = i * sample
        cmd = command(t0)
        record(i, t0, [cmd[k] for k in keys])
        for s in range(per):
            t = t0 + s * h
            if s:
                cmd = command(t)
            u = [float(cmd[k]) for k in keys]
            tip = no_tip if f_tip is None else f_tip(t)
            mf = []
            for j in range(4):
                b = booms[j]
                c = y[j] if spools[j] else u[j]
                if b.command_effects:
                    c = b.opening(c)
                if c == centre:                 # a closed valve passes nothing (A(u) = 0)
                    m = closed
                else:
                    m = b.valve_flows(c, p_a[j], p_b[j])
                if b.inflow_effects:
                    m = b.inflows(*m, p_a[j], p_b[j], x[j])
                mf.append(m)
            x1, v1 = advance_linkage((x, v), p_a, p_b, tip, h, ex, payload=payload, max_substep=h,
                                     friction=friction)
            for j in range(4):
                m_a, m_b, s_a, s_b = mf[j]
                p_a[j], p_b[j] = booms[j].step_chambers(p_a[j], p_b[j], x[j], float(x1[j]), float(m_a), float(m_b),
                                                        float(s_a), float(s_b), h, masses[j])
                if spools[j]:
                    y[j] = booms[j].spool_step(y[j], u[j], h)
            x = [float(t) for t in x1]
            v = [float(t) for t in v1]
    t_end = n_samples * sample
    cmd = command(t_end) if t_end < getattr(command, "duration", np.inf) else command(t_end - 0.5 * h)
    record(n_samples, t_end, [cmd[k] for k in keys])
    cols = (["time"] + keys + [f"p_a_{j}" for j in JOINTS] + [f"p_b_{j}" for j in JOINTS]
            + [f"x_{j}" for j in JOINTS] + [f"v_{j}" for j in JOINTS])
    df = pd.DataFrame(out[:, :21], columns=cols)
    angles = joint_angles(df[[f"x_{j}" for j in JOINTS]].to_numpy(), ex)
    for k, j in enumerate(JOINTS):
        df[f"angle_{j}"] = angles[:, k]
    lagged = [k for k, b in enumerate(booms) if b.measures]
    if lagged:                         # the sensors of the joints with sensor_lag (the bridge's channels)
        time = df["time"].to_numpy()
        for k in lagged:
            for c in (f"p_a_{JOINTS[k]}", f"p_b_{JOINTS[k]}", f"angle_{JOINTS[k]}"):
                df[c] = booms[k].measured(df[c].to_numpy(), time)
        pistons = pistons_from_angles(df[[f"angle_{j}" for j in JOINTS]].to_numpy(), ex)
        for k in lagged:
            df[f"x_{JOINTS[k]}"] = pistons[:, k]
    return df
