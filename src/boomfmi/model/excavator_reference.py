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

The machine starts at rest with every piston at mid-stroke and every valve closed
(5 V), each cylinder's chambers at pressures that hold its joint against gravity
(:func:`holding_pressures`), so the digging cycle starts from a still machine.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pandas as pd

from .. import physics as ph
from ..physics import reference_rig
from ..physics.excavator import JOINTS, Excavator, advance_linkage, excavator_parameters, joint_angles


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
    gas's (the reference rig's, each valve with its joint's A_max), and the start."""
    ex: Excavator = field(default_factory=excavator_parameters)
    gas: ph.Gas = field(default_factory=ph.Gas)
    P_s: float = reference_rig.P_s
    P_e: float = reference_rig.P_e
    payload: float = 0.0
    x0: tuple | None = None          #: start positions [m] (default: mid-stroke)
    p_a0: tuple | None = None        #: start pressures [Pa] (default: holding_pressures)
    p_b0: tuple | None = None

    @property
    def valves(self) -> tuple:
        return tuple(ph.Valve(A_max=a.A_max, P_s=self.P_s, P_e=self.P_e) for a in self.ex.actuators)

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


def simulate_excavator_reference(command: Callable[[float], dict], stop_time: float,
                                 machine: ExcavatorMachine | None = None, h: float = 5e-5,
                                 sample: float = 1e-3, f_tip: Callable[[float], tuple] | None = None) -> pd.DataFrame:
    """The machine from its start under ``command(t) -> {"u_<joint>": V}`` (held over
    each fine step ``h`` [s]) and the tip force ``f_tip(t)`` [N] (world frame; default
    none), sampled every ``sample`` [s] (a multiple of ``h``).

    Returns ``time``, then per joint ``u_<j>``, ``p_a_<j>``, ``p_b_<j>`` (absolute [Pa]),
    ``x_<j>``, ``v_<j>``, ``angle_<j>``.  Each sample holds the state at its time and the
    command applied from it."""
    machine = machine or ExcavatorMachine()
    ex, gas = machine.ex, machine.gas
    per = int(round(sample / h))
    if per < 1 or abs(per * h - sample) > 1e-12 * sample:
        raise ValueError(f"the sample interval {sample} s must be a multiple of the step h = {h} s")
    n_samples = int(round(stop_time / sample))
    valves, cyls = machine.valves, machine.cylinders
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
    closed = (0.0, 0.0)
    centre = valves[0].u_centre
    if any(float(ph.orifice_area(centre, va)) != 0.0 for va in valves):
        centre = None
    flows, slopes = ph.chamber_flows, ph.chamber_flow_slopes
    step_p = ph.chamber_pressure_step
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
            mf, sl = [], []
            for j in range(4):
                if u[j] == centre:              # a closed valve passes nothing (A(u) = 0)
                    mf.append(closed)
                    sl.append(closed)
                else:
                    mf.append(flows(u[j], p_a[j], p_b[j], valves[j], gas))
                    sl.append(slopes(u[j], p_a[j], p_b[j], valves[j], gas))
            x1, v1 = advance_linkage((x, v), p_a, p_b, tip, h, ex, payload=payload, max_substep=h)
            for j in range(4):
                c = cyls[j]
                V_a0, V_b0 = c.A_a * x[j] + c.V_a0, c.A_b * (c.L - x[j]) + c.V_b0
                x1j = float(x1[j])
                V_a1, V_b1 = c.A_a * x1j + c.V_a0, c.A_b * (c.L - x1j) + c.V_b0
                p_a[j] = step_p(p_a[j], V_a0, V_a1, float(mf[j][0]), h, gas, float(sl[j][0]))
                p_b[j] = step_p(p_b[j], V_b0, V_b1, float(mf[j][1]), h, gas, float(sl[j][1]))
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
    return df
