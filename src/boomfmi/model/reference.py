"""The monolithic reference: the assembled boom as one ODE, solved by scipy.

The boom's parts (:class:`.boom.Boom`) become one right-hand side (:func:`rhs`) for the
state ``(p_a, p_b, x, v)`` (plus the spool's position with valve_dynamics and the
chambers' air masses with heat_transfer), integrated with LSODA (or Radau) at tight
tolerance.  Discontinuities are handled as events, never smoothed, by the stick/slip/
stop state machine :class:`StickSlip`, which needs no ODE solve to be tested:

* the command's steps are breakpoints (the integration restarts there);
* while the piston slides, its velocity reaching zero and the piston reaching a stop
  end the segment; the stick test of Eq. 9 then picks the next mode;
* while it sticks (or rests against a stop), the drive force reaching the static
  friction level ``F_s cos(phi)`` (away from a stop) ends the segment.

Each segment is stepped by :func:`solve_segment` (``solve_ivp``'s LSODA with terminal
events and dense output, to the bit, without its generic loop's overhead per step).
:class:`Resampler` puts the segments' dense output on the requested times and applies
the measurement path.  This is the yardstick for the co-simulation's error
(``benchmarks/cosim_accuracy.py``) and, with effects switched on, the diagnosis's fast
model.

The whole excavator (:func:`simulate_linkage`): four valves, eight chambers and the
linkage as one system, integrated far finer than any co-simulation of it, with the
co-simulated components' own physics called directly: each valve's flows and their
slopes (Eq. 1), each chamber's pressure (Eq. 4 to 7, ``physics.chamber_pressure_step``
against the valve's linearisation, exact for a closed chamber) and the linkage
(``physics.advance_linkage``: M, C, G of the four joints, each cylinder through its
lever, Eq. 9 friction and the end stops per cylinder, the tip force through J^T).  Every
fine step (``h``, default 50 us, twenty times shorter than the co-simulation's 1 ms) the
valves see the chambers' newest pressures, the linkage moves under them, and the
chambers then integrate over exactly the linkage's motion; nothing is held over a
communication step.  The scheme is first order in ``h``, so its own error is gauged by
halving ``h`` (``benchmarks/excavator_cosim.py``).  The boom's event-driven solve is not
used there: with four cylinders each sticking and slipping it would restart at every
one of the sixteen combinations' transitions, and Eq. 9's stick test couples the joints
through M; the fine fixed step is the linkage FMU's stick/slip logic at a step where its
error is negligible.  Each joint's pneumatics step through a :class:`~.boom.Boom` of
its own (:meth:`.machine.Machine.booms`), so any effect of the catalogue acts on any
joint: its friction effects through ``advance_linkage``'s per-joint friction hooks
(:func:`.machine.friction_hook`), its sensor lag on the channels the excavator's bridge
measures (``p_a``, ``p_b``, ``angle``; ``x`` follows the lagged angle).

:func:`simulate` is the one entry: a :class:`~.machine.Machine` of one joint (the boom
rig, :func:`~.machine.boom_machine`) by the event-driven solve, of four by the linkage's.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
import pandas as pd
from scipy.integrate import LSODA, OdeSolution, solve_ivp
from scipy.optimize import brentq

from .. import physics as ph
from ..physics import reference_rig
from ..physics.linkage import JOINTS, advance_linkage, joint_angles, pistons_from_angles
from .boom import Boom, Model
from .machine import Machine


class Layout:
    """Where each state lives in the ODE's vector: ``p_a, p_b, x, v`` at 0 to 3, then
    the spool's position (``i_y``) and the chambers' air masses (``i_m``, ``i_m + 1``)
    where their effects are on (else None)."""

    def __init__(self, boom: Boom):
        self.i_y = 4 if boom.tau_spool > 0 else None
        self.i_m = (4 + (self.i_y is not None)) if boom.h_wall > 0 else None
        self.n = 4 + (self.i_y is not None) + 2 * (self.i_m is not None)
        self.atol = np.array([1e-4, 1e-4, 1e-13, 1e-11] + [1e-9] * (self.i_y is not None)
                             + [1e-15, 1e-15] * (self.i_m is not None))

    def initial(self, boom: Boom, model: Model, u0: float) -> np.ndarray:
        y = np.zeros(self.n)
        y[:4] = (model.p_a0, model.p_b0, model.x0, 0.0)
        if self.i_y is not None:
            y[self.i_y] = u0
        if self.i_m is not None:
            y[self.i_m], y[self.i_m + 1] = boom.air_masses(model.p_a0, model.p_b0, model.x0)
        return y


def rhs(boom: Boom, layout: Layout, u: float, f_ext: float, mode: int, y) -> list:
    """The state's derivatives in ``mode`` (+1 / -1 sliding, 0 stuck) under the command
    ``u`` [V] and external force ``f_ext`` [N]."""
    # the state as Python floats: the physics' scalar paths then run on floats, not NumPy
    # scalars (the same IEEE operations, to the bit; a fifth of a simulation's time)
    y = y.tolist()
    p_a, p_b, x, v = y[0], y[1], y[2], y[3]
    i_y, i_m = layout.i_y, layout.i_m
    cmd = y[i_y] if i_y is not None else u
    if boom.command_effects:            # (the stages without effects are skipped: the hot path)
        cmd = boom.opening(cmd)
    mdot_a, mdot_b = ph.chamber_flows(cmd, p_a, p_b, boom.valve, boom.gas)
    if boom.inflow_effects:
        mdot_a, mdot_b, _, _ = boom.inflows(mdot_a, mdot_b, None, None, p_a, p_b, x)
    if i_m is None and boom.V_port <= 0.0:
        dp_a, dp_b = ph.pressure_rates(p_a, p_b, mdot_a, mdot_b, x, v, boom.cylinder, boom.chamber_gas)
    else:
        dp_a, dp_b = boom.pressure_rates(p_a, p_b, mdot_a, mdot_b, x, v,
                                         (y[i_m], y[i_m + 1]) if i_m is not None else None)
    extra = []
    if i_y is not None:
        extra.append(boom.spool_rate(y[i_y], u))
    if i_m is not None:
        extra += list(boom.air_mass_rates(mdot_a, mdot_b, x, v, (y[i_m], y[i_m + 1])))
    if mode == 0:
        return [dp_a, dp_b, 0.0, 0.0, *extra]
    phi = ph.phi_from_x(x, boom.geometry)
    F = ph.drive_force(p_a, p_b, phi, f_ext, boom.cylinder, boom.load, boom.P_atm)
    load = boom.load_at(boom.load, v, p_a, p_b) if boom.friction_effects else boom.load
    return [dp_a, dp_b, v, ph.sliding_acceleration(v, F, phi, mode, load), *extra]


class StickSlip:
    """Eq. 9's modes of the piston, as ``physics.load.slide_or_stick`` applies them:
    +1 / -1 sliding, 0 stuck in mid-stroke or resting against a stop; the events that
    end a mode, and the mode after one."""

    def __init__(self, boom: Boom):
        self.boom = boom
        self.L = boom.cylinder.L

    def forces(self, y, f_ext: float):
        """(drive force [N], static friction level ``F_s cos(phi)`` [N]) in state ``y``."""
        b = self.boom
        return b.drive_force(y[0], y[1], y[2], f_ext), self._load(y).F_s * math.cos(ph.phi_from_x(y[2], b.geometry))

    def _load(self, y) -> ph.Load:
        """The load's levels at rest in state ``y`` (the friction effects at the
        chambers' pressures: pressure_friction raises them)."""
        b = self.boom
        return b.load_at(b.load, 0.0, y[0], y[1]) if b.friction_effects else b.load

    def next_mode(self, y, f_ext: float) -> int:
        """The mode from rest: the piston breaks away when the drive exceeds the static
        level, and only if the Coulomb friction then leaves a net force in that direction
        (F_s below F_d would otherwise stop it at once, forever), and not into a stop."""
        F, limit = self.forces(y, f_ext)
        if abs(F) <= limit:
            return 0
        s = 1 if F > 0 else -1
        if (s > 0 and y[2] >= self.L) or (s < 0 and y[2] <= 0.0):
            return 0
        c = math.cos(ph.phi_from_x(y[2], self.boom.geometry))
        if s * (F - s * self._load(y).F_d * c) <= 0.0:
            return 0
        return s

    def events(self, mode: int, y, f_ext: float) -> list:
        """The terminal events that end ``mode`` from state ``y``.  Each sits a hair past
        its threshold (1e-12 m/s, 1e-12 m, 1e-9 N), so a segment that starts on a
        threshold does not trigger it again at once."""
        L, s = self.L, mode
        if s != 0:
            stop_v = lambda _, y: y[3] + s * 1e-12
            stop_v.terminal, stop_v.direction = True, -s
            stop_x = (lambda _, y: y[2] - L - 1e-12) if s > 0 else (lambda _, y: y[2] + 1e-12)
            stop_x.terminal, stop_x.direction = True, s
            return [stop_v, stop_x]

        def away_up(_, y):
            F, limit = self.forces(y, f_ext)
            return F - limit - 1e-9

        def away_down(_, y):
            F, limit = self.forces(y, f_ext)
            return -F - limit - 1e-9
        away_up.terminal, away_up.direction = True, 1
        away_down.terminal, away_down.direction = True, 1
        events = []
        if y[2] < L:
            events.append(away_up)
        if y[2] > 0.0:
            events.append(away_down)
        return events

    def after_event(self, mode: int, y, f_ext: float) -> int:
        """The mode after an event ended ``mode`` at state ``y`` (modified in place: a
        sliding piston is stopped there, within the stroke)."""
        if mode != 0:
            y[3] = 0.0
            y[2] = min(max(y[2], 0.0), self.L)
            return self.next_mode(y, f_ext)
        new = self.next_mode(y, f_ext)
        F, limit = self.forces(y, f_ext)
        if new == 0 and abs(F) <= limit + 1e-6:
            new = 1 if F > 0 else -1           # grazing: nudge past the event
        return new


class SolverError(RuntimeError):
    """The reference solver could not integrate the model (a parameter set that makes
    it too stiff for its steps: a moving mass of micrograms, say)."""


class Resampler:
    """The segments' dense solutions put on the output ``times`` [s]."""

    def __init__(self, times: np.ndarray):
        self.times = times
        self.out = np.full((len(times), 4), np.nan)
        self.inputs = np.full((len(times), 2), np.nan)

    def segment(self, t0: float, t1: float, sol, u: float, f_ext: float, stuck: bool) -> None:
        """Record the segment from ``t0`` to ``t1`` [s]: states from its dense output,
        v exactly 0 where the piston was ``stuck``."""
        times = self.times
        sel = (times >= t0 - 1e-12) & (times <= t1 + 1e-12)
        if sel.any():
            self.out[sel] = sol(times[sel])[:4].T
            self.inputs[sel] = (u, f_ext)
        if stuck:
            self.out[sel, 3] = 0.0

    def frame(self, boom: Boom) -> pd.DataFrame:
        """``time, u, f_ext, p_a, p_b, x, v, alpha`` (absolute pressures), x within the
        stroke, and the measured channels through the measurement path."""
        times, out, inputs = self.times, self.out, self.inputs
        df = pd.DataFrame({"time": times, "u": inputs[:, 0], "f_ext": inputs[:, 1],
                           "p_a": out[:, 0], "p_b": out[:, 1], "x": np.clip(out[:, 2], 0.0, boom.cylinder.L),
                           "v": out[:, 3]})
        df["alpha"] = ph.alpha_from_x(df["x"].to_numpy(), boom.geometry)
        if boom.measures:
            for col in ("p_a", "p_b", "alpha", "x"):
                df[col] = boom.measured(df[col].to_numpy(), times)
        return df


#: the event roots' tolerance, as ``solve_ivp``'s (``brentq``'s xtol and rtol)
_ROOT_TOL = 4 * np.finfo(float).eps


def _crossed(g_old: float, g_new: float, direction: float) -> bool:
    """Whether an event function went from ``g_old`` to ``g_new`` through zero in its
    ``direction`` (> 0 rising, < 0 falling, 0 either): ``solve_ivp``'s test, on floats."""
    up = g_old <= 0 and g_new >= 0
    down = g_old >= 0 and g_new <= 0
    return (up and direction > 0) or (down and direction < 0) or ((up or down) and direction == 0)


def solve_segment(fun, t0: float, t1: float, y0, rtol: float, atol, events: list, max_step: float):
    """One segment of the boom's solve: LSODA from ``t0`` to ``t1`` [s] until the first
    of the terminal ``events`` (each ``event(t, y)`` with ``terminal`` and ``direction``)
    crosses zero.  Returns ``(t_end, y_end, status, message, dense)``: status 0 at
    ``t1``, 1 at an event, -1 where the solver failed; ``dense`` the segment's solution,
    callable on times.

    It is ``solve_ivp(..., method="LSODA", events=events, dense_output=True)`` without
    the generic loop's overhead per step (its events tested as arrays, its results
    gathered): the same steps, the same roots (``brentq`` on the step's dense output,
    tolerance ``_ROOT_TOL``) and the same solution to the bit, in two thirds of the
    time (the loop cost more than the right-hand side)."""
    if not all(getattr(e, "terminal", False) for e in events):
        raise ValueError("solve_segment ends at the first event: every event must be terminal")
    solver = LSODA(fun, t0, y0, t1, rtol=rtol, atol=atol, max_step=max_step)
    ts, interpolants, y_end = [t0], [], solver.y
    g = [event(t0, solver.y) for event in events]
    directions = [getattr(e, "direction", 0) for e in events]
    status, message = None, None
    while status is None:
        message = solver.step()
        if solver.status == "finished":
            status = 0
        elif solver.status == "failed":
            return float(ts[-1]), y_end, -1, message, None
        t_old, t, y = solver.t_old, solver.t, solver.y
        sol = solver.dense_output()
        interpolants.append(sol)
        if events:
            g_new = [event(t, y) for event in events]
            roots = [brentq(lambda tau, event=event: event(tau, sol(tau)), t_old, t, xtol=_ROOT_TOL, rtol=_ROOT_TOL)
                     for event, a, b, d in zip(events, g, g_new, directions) if _crossed(a, b, d)]
            if roots:
                status = 1
                t = np.asarray(roots)[int(np.argmin(roots))]
                y = sol(t)
            g = g_new
        if len(ts) > 1 and ts[-1] == t:      # a step of no length: its solution is not kept
            interpolants.pop()
        else:
            ts.append(t)
            y_end = y
    return float(ts[-1]), y_end, status, message, OdeSolution(ts, interpolants, alt_segment=True)


def simulate_reference(model: Model, command: Callable[[float], dict], stop_time: float,
                       times: np.ndarray | None = None, breakpoints=(), rtol: float = 1e-9,
                       method: str = "LSODA", u_between=None, max_step: float = np.inf) -> pd.DataFrame:
    """Solve the boom from rest at ``p_a0, p_b0, x0`` under ``command(t) -> {"u", "f_ext"}``.

    ``command`` must be piecewise constant between ``breakpoints`` [s] (the integrator
    restarts at each), unless ``u_between(t)`` is given: then the command is that
    continuous function of time between breakpoints (a sampled command that moves a
    little each sample, as a sine sweep does, without a restart per sample); then give
    ``max_step`` [s] too, or the solver may stride over the command's moves while the
    state rests.  Returns a DataFrame on ``times`` (default: every ms) with
    columns ``time, u, f_ext, p_a, p_b, x, v, alpha`` (absolute pressures).
    """
    boom = Boom(model)
    if times is None:
        times = np.round(np.arange(0.0, stop_time + 1e-12, 1e-3), 12)
    times = np.asarray(times, dtype=float)
    layout = Layout(boom)
    machine = StickSlip(boom)
    result = Resampler(times)
    cuts = sorted({float(b) for b in breakpoints if 0.0 < b < stop_time} | {stop_time})
    y = layout.initial(boom, model, command(0.0).get("u", reference_rig.u_centre))
    t = 0.0
    mode = 0
    for cut in cuts:
        cmd = command(t)
        u, f_ext = cmd.get("u", reference_rig.u_centre), cmd.get("f_ext", 0.0)
        if mode == 0:
            mode = machine.next_mode(y, f_ext)
        while t < cut - 1e-15:
            s = mode
            events = machine.events(s, y, f_ext)
            if u_between is None:
                fun = lambda _, y, s=s: rhs(boom, layout, u, f_ext, s, y)
            else:
                fun = lambda tau, y, s=s: rhs(boom, layout, u_between(tau), f_ext, s, y)
            try:
                if method == "LSODA":
                    t_new, y_end, status, message, dense = solve_segment(fun, t, cut, y, rtol, layout.atol, events,
                                                                         max_step)
                else:
                    sol = solve_ivp(fun, (t, cut), y, method=method, rtol=rtol, atol=layout.atol,
                                    events=events or None, max_step=max_step, dense_output=True)
                    t_new, y_end, status, message, dense = float(sol.t[-1]), sol.y[:, -1], sol.status, sol.message, sol.sol
            except ValueError as err:       # steps of zero length (scipy's dense output refuses them)
                raise SolverError(f"reference solver failed at t = {t:g} s: its steps collapsed ({err}); "
                                  f"the load's mechanical time constant M/K_v is "
                                  f"{model.load.M / model.load.K_v:.3g} s") from err
            except ArithmeticError as err:   # a state where the model divides by zero or overflows (floats
                raise SolverError(f"reference solver failed at t = {t:g} s: the model's arithmetic failed "
                                  f"({type(err).__name__}: {err}) in a state its solver tried") from err
            if status < 0:
                raise SolverError(f"reference solver failed at t = {t:g} s: {message}")
            y = np.array(y_end, dtype=float)
            if status == 1:          # an event ended the segment
                mode = machine.after_event(s, y, f_ext)
            result.segment(t, t_new, dense, u, f_ext, s == 0)
            t = t_new
    return result.frame(boom)


def simulate_linkage(command: Callable[[float], dict], stop_time: float,
                     machine: Machine | None = None, h: float = 5e-5,
                     sample: float = 1e-3, f_tip: Callable[[float], tuple] | None = None) -> pd.DataFrame:
    """The machine from its start under ``command(t) -> {"u_<joint>": V}`` (held over
    each fine step ``h`` [s]) and the tip force ``f_tip(t)`` [N] (world frame; default
    none), sampled every ``sample`` [s] (a multiple of ``h``).

    Returns ``time``, then per joint ``u_<j>``, ``p_a_<j>``, ``p_b_<j>`` (absolute [Pa]),
    ``x_<j>``, ``v_<j>``, ``angle_<j>``.  Each sample holds the state at its time and the
    command applied from it; a joint with sensor_lag, its ``p_a``, ``p_b`` and ``angle``
    as its sensors report them (``x`` from that angle).  ``machine.effects`` is checked
    before any step (:class:`physics.ParameterError` naming the joint or parameter)."""
    machine = machine or Machine()
    if machine.mechanism != "linkage":
        raise ValueError(f"simulate_linkage steps the excavator's linkage, not the {machine.mechanism}'s load: "
                         "use simulate(machine, ...)")
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
    hooks = machine.friction_hooks(booms)
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


#: The excavator's reference by its former name (``simulate_linkage``).
simulate_excavator_reference = simulate_linkage


def simulate(machine: Machine, command: Callable[[float], dict], stop_time: float, **options) -> pd.DataFrame:
    """The machine's monolithic reference under ``command``, by its mechanism: one joint
    (:func:`~.machine.boom_machine`) by the boom's event-driven solve
    (:func:`simulate_reference`: ``{"u", "f_ext"}`` commands, columns ``u, p_a, ..., alpha``),
    the linkage by its fine fixed step (:func:`simulate_linkage`: ``{"u_<joint>"}``,
    columns ``u_<joint>, ..., angle_<joint>``); ``options`` are that solver's."""
    if machine.mechanism == "boom":
        machine.check()
        return simulate_reference(machine.joint_model("boom"), command, stop_time, **options)
    return simulate_linkage(command, stop_time, machine, **options)


__all__ = ["Layout", "rhs", "StickSlip", "Resampler", "SolverError", "simulate_reference", "simulate_linkage",
           "simulate_excavator_reference", "simulate"]
