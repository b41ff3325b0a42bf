"""The monolithic reference: the boom's physics as one ODE, solved by scipy.

The same physics functions the FMUs step (``boomfmi.physics``) become one right-hand
side for the state ``(p_a, p_b, x, v)``, integrated with LSODA (or Radau) at tight
tolerance.  Discontinuities are handled as events, never smoothed:

* the command's steps are breakpoints (the integration restarts there);
* while the piston slides, its velocity reaching zero and the piston reaching a stop
  end the segment; the stick test of Eq. 9 then picks the next mode;
* while it sticks (or rests against a stop), the drive force reaching the static
  friction level ``F_s cos(phi)`` (away from a stop) ends the segment.

It is the yardstick for the co-simulation's error (``benchmarks/cosim_accuracy.py``),
and, with the candidate forms of the unmodelled effects (``Model.effects``, forms in
``physics/effects.py``, the same the FMUs' options use), the diagnosis's fast model.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

from . import physics as ph
from .physics import reference_rig as rig
from .physics.effects import cushion_outflow as fx_cushion
from .physics.effects import deadband_command as fx_deadband
from .physics.effects import leakage_orifice_flow as fx_leak
from .physics.effects import sensor_lag_step as fx_sensor
from .physics.effects import chamber_wall_area as fx_wall
from .physics.effects import stribeck_load as fx_stribeck
from .physics.effects import thermal_time_constant as fx_tau


@dataclass
class Model:
    """All parameters of the boom model (defaults: the reference rig)."""
    valve: ph.Valve = field(default_factory=ph.Valve)
    gas: ph.Gas = field(default_factory=ph.Gas)
    cylinder: ph.Cylinder = field(default_factory=ph.Cylinder)
    geometry: ph.Geometry = field(default_factory=ph.Geometry)
    load: ph.Load = field(default_factory=ph.Load)
    P_atm: float = rig.P_atm
    p_a0: float = rig.P_atm
    p_b0: float = rig.P_atm
    x0: float = 0.0
    #: candidate effects switched on: name (effects.md) -> parameters, e.g.
    #: ``{"valve_dynamics": {"tau": 0.004}, "piston_leakage": {"C": 2e-11}}``
    effects: dict = field(default_factory=dict)

    def check(self) -> None:
        for name, params in self.effects.items():
            if name not in EFFECT_PARAMETERS:
                raise ph.ParameterError("effects", name, f"not an effect of effects.md ({', '.join(EFFECT_PARAMETERS)})")
            unknown = set(params) - set(EFFECT_PARAMETERS[name])
            if unknown:
                raise ph.ParameterError(f"effects.{name}", sorted(unknown), f"takes {EFFECT_PARAMETERS[name]}")
            for k, v in params.items():
                if not (v >= 0.0 and math.isfinite(v)):
                    raise ph.ParameterError(f"effects.{name}.{k}", v, "must be a finite number >= 0")
        ph.check_valve(self.valve)
        ph.check_gas(self.gas)
        ph.check_cylinder(self.cylinder)
        ph.check_load(self.load)
        ph.check_geometry(self.geometry, self.cylinder.L)


#: Each effect's parameters in ``Model.effects`` (the FMU options' names in brackets):
#: valve_dynamics tau [s] (valve.tau_spool), valve_deadband width [V] (valve.deadband),
#: heat_transfer h [W/(m^2 K)] (cylinder.h_wall), piston_leakage C [kg/(s Pa)] or A
#: [m^2] (cylinder.C_leak, A_leak), stribeck_friction v_s [m/s] (boom_load.v_s), end_cushioning
#: length [m], A_n [m^2] (cylinder.l_cushion, A_cushion), sensor_lag tau [s]
#: (hardware_bridge.tau_sensor).
EFFECT_PARAMETERS = {"valve_dynamics": ("tau",), "valve_deadband": ("width",),
                     "heat_transfer": ("h",), "piston_leakage": ("C", "A"),
                     "stribeck_friction": ("v_s",), "end_cushioning": ("length", "A_n"),
                     "sensor_lag": ("tau",)}


def _drive(model: Model, p_a, p_b, x, f_ext):
    return ph.drive_force(p_a, p_b, ph.phi_from_x(x, model.geometry), f_ext, model.cylinder,
                          model.load, model.P_atm)


def simulate_reference(model: Model, command: Callable[[float], dict], stop_time: float,
                       times: np.ndarray | None = None, breakpoints=(), rtol: float = 1e-9,
                       method: str = "LSODA") -> pd.DataFrame:
    """Solve the boom from rest at ``p_a0, p_b0, x0`` under ``command(t) -> {"u", "f_ext"}``.

    ``command`` must be piecewise constant between ``breakpoints`` [s] (the integrator
    restarts at each).  Returns a DataFrame on ``times`` (default: every ms) with
    columns ``time, u, f_ext, p_a, p_b, x, v, alpha`` (absolute pressures).
    """
    model.check()
    if times is None:
        times = np.round(np.arange(0.0, stop_time + 1e-12, 1e-3), 12)
    times = np.asarray(times, dtype=float)
    L = model.cylinder.L
    fx = model.effects
    tau_v = fx.get("valve_dynamics", {}).get("tau", 0.0)
    width = fx.get("valve_deadband", {}).get("width", 0.0)
    h_wall = fx.get("heat_transfer", {}).get("h", 0.0)
    bore = math.sqrt(4.0 * model.cylinder.A_a / math.pi)
    C_leak = fx.get("piston_leakage", {}).get("C", 0.0)
    A_leak = fx.get("piston_leakage", {}).get("A", 0.0)
    v_s = fx.get("stribeck_friction", {}).get("v_s", 0.0)
    l_c = fx.get("end_cushioning", {}).get("length", 0.0)
    A_n = fx.get("end_cushioning", {}).get("A_n", 0.0)
    tau_s = fx.get("sensor_lag", {}).get("tau", 0.0)
    k_, R_, T_ = model.gas
    i_y = 4 if tau_v > 0 else None                      # the spool's position [V]
    i_m = (4 + (i_y is not None)) if h_wall > 0 else None   # the chambers' air masses [kg]
    n_state = 4 + (i_y is not None) + 2 * (i_m is not None)
    atol = np.array([1e-4, 1e-4, 1e-13, 1e-11] + [1e-9] * (i_y is not None) + [1e-15, 1e-15] * (i_m is not None))

    def pneumatics(u, y):
        """The state's derivatives but x and v: dp_a, dp_b, then spool and masses."""
        p_a, p_b, x, v = y[0], y[1], y[2], y[3]
        cmd = y[i_y] if i_y is not None else u
        if width > 0:
            cmd = fx_deadband(cmd, width)
        mdot_a, mdot_b = ph.chamber_flows(cmd, p_a, p_b, model.valve, model.gas)
        if l_c > 0:
            mdot_a = fx_cushion(mdot_a, p_a, x, l_c, A_n, model.valve.P_e, model.gas)
            mdot_b = fx_cushion(mdot_b, p_b, L - x, l_c, A_n, model.valve.P_e, model.gas)
        if C_leak > 0 or A_leak > 0:
            q = C_leak * (p_a - p_b) + fx_leak(p_a, p_b, A_leak, model.gas)
            mdot_a, mdot_b = mdot_a - q, mdot_b + q
        dp_a, dp_b = ph.pressure_rates(p_a, p_b, mdot_a, mdot_b, x, v, model.cylinder, model.gas)
        extra = []
        if i_y is not None:
            extra.append((u - y[i_y]) / tau_v)
        if i_m is not None:
            V_a, V_b = ph.chamber_volumes(x, model.cylinder)
            for i, (V, A, m) in enumerate(((V_a, model.cylinder.A_a, y[i_m]), (V_b, model.cylinder.A_b, y[i_m + 1]))):
                tau = fx_tau(max(m, 1e-12), fx_wall(V, A, bore), h_wall, k_, R_)
                rate = (m * R_ * T_ / V - (p_a, p_b)[i]) / tau
                if i == 0:
                    dp_a += rate
                else:
                    dp_b += rate
            extra += [mdot_a, mdot_b]
        return dp_a, dp_b, extra

    def slide_accel(y, F, phi, s):
        load = model.load if v_s <= 0 else fx_stribeck(model.load, y[3], v_s)
        return ph.sliding_acceleration(y[3], F, phi, s, load)

    cuts = sorted({float(b) for b in breakpoints if 0.0 < b < stop_time} | {stop_time})
    y = np.zeros(n_state)
    y[:4] = (model.p_a0, model.p_b0, model.x0, 0.0)
    if i_y is not None:
        y[i_y] = command(0.0).get("u", rig.u_centre)
    if i_m is not None:
        V_a, V_b = ph.chamber_volumes(model.x0, model.cylinder)
        y[i_m], y[i_m + 1] = model.p_a0 * V_a / (R_ * T_), model.p_b0 * V_b / (R_ * T_)
    t = 0.0
    mode = 0          # +1 / -1 sliding, 0 stuck (or resting against a stop)
    out = np.full((len(times), 4), np.nan)
    inputs = np.full((len(times), 2), np.nan)

    def forces(cmd, y):
        F = _drive(model, y[0], y[1], y[2], cmd.get("f_ext", 0.0))
        return F, model.load.F_s * math.cos(ph.phi_from_x(y[2], model.geometry))

    def next_mode(cmd, y):
        """Eq. 9's test at rest, as ``physics.load.slide_or_stick`` applies it: the piston
        breaks away when the drive exceeds the static level, and only if the Coulomb
        friction then leaves a net force in that direction (F_s below F_d would
        otherwise stop it at once, forever)."""
        F, limit = forces(cmd, y)
        if abs(F) <= limit:
            return 0
        s = 1 if F > 0 else -1
        if (s > 0 and y[2] >= L) or (s < 0 and y[2] <= 0.0):
            return 0
        c = math.cos(ph.phi_from_x(y[2], model.geometry))
        if s * (F - s * model.load.F_d * c) <= 0.0:
            return 0
        return s

    for cut in cuts:
        cmd = dict(command(t))
        u, f_ext = cmd.get("u", rig.u_centre), cmd.get("f_ext", 0.0)
        if mode == 0:
            mode = next_mode(cmd, y)
        while t < cut - 1e-15:
            s = mode

            def rhs(_, y, s=s):
                dp_a, dp_b, extra = pneumatics(u, y)
                if s == 0:
                    return [dp_a, dp_b, 0.0, 0.0, *extra]
                phi = ph.phi_from_x(y[2], model.geometry)
                F = ph.drive_force(y[0], y[1], phi, f_ext, model.cylinder, model.load, model.P_atm)
                return [dp_a, dp_b, y[3], slide_accel(y, F, phi, s), *extra]

            # each event sits a hair past its threshold (1e-12 m/s, 1e-12 m, 1e-9 N), so a
            # segment that starts on a threshold does not trigger it again at once
            events = []
            if s != 0:
                stop_v = lambda _, y, s=s: y[3] + s * 1e-12
                stop_v.terminal, stop_v.direction = True, -s
                stop_x = (lambda _, y: y[2] - L - 1e-12) if s > 0 else (lambda _, y: y[2] + 1e-12)
                stop_x.terminal, stop_x.direction = True, s
                events = [stop_v, stop_x]
            else:
                def away_up(_, y):
                    F, limit = forces(cmd, y)
                    return F - limit - 1e-9
                def away_down(_, y):
                    F, limit = forces(cmd, y)
                    return -F - limit - 1e-9
                for ev in (away_up, away_down):
                    ev.terminal, ev.direction = True, 1
                if y[2] < L:
                    events.append(away_up)
                if y[2] > 0.0:
                    events.append(away_down)
            sol = solve_ivp(rhs, (t, cut), y, method=method, rtol=rtol, atol=atol,
                            events=events or None, dense_output=True)
            if sol.status < 0:
                raise RuntimeError(f"reference solver failed at t = {t:g} s: {sol.message}")
            t_new = float(sol.t[-1])
            sel = (times >= t - 1e-12) & (times <= t_new + 1e-12)
            if sel.any():
                out[sel] = sol.sol(times[sel])[:4].T
                inputs[sel] = (u, f_ext)
            y = sol.y[:, -1].copy()
            if sol.status == 1:          # an event ended the segment
                if s != 0:
                    y[3] = 0.0
                    y[2] = min(max(y[2], 0.0), L)
                    mode = next_mode(cmd, y)
                else:
                    mode = next_mode(cmd, y)
                    if mode == 0 and abs(forces(cmd, y)[0]) <= forces(cmd, y)[1] + 1e-6:
                        mode = 1 if forces(cmd, y)[0] > 0 else -1     # grazing: nudge past the event
            if s == 0:
                out[sel, 3] = 0.0
            t = t_new
    df = pd.DataFrame({"time": times, "u": inputs[:, 0], "f_ext": inputs[:, 1],
                       "p_a": out[:, 0], "p_b": out[:, 1], "x": np.clip(out[:, 2], 0.0, L),
                       "v": out[:, 3]})
    df["alpha"] = ph.alpha_from_x(df["x"].to_numpy(), model.geometry)
    if tau_s > 0:                        # the measurement path: what the sensors report
        for col in ("p_a", "p_b", "alpha", "x"):
            df[col] = first_order_lag(df[col].to_numpy(), times, tau_s)
    return df


def first_order_lag(y: np.ndarray, t: np.ndarray, tau: float) -> np.ndarray:
    """A first-order lag (``physics.effects.sensor_lag_step``) run along a signal."""
    out = np.empty_like(y)
    out[0] = y[0]
    for k in range(1, len(y)):
        out[k] = fx_sensor(out[k - 1], y[k], t[k] - t[k - 1], tau)
    return out
