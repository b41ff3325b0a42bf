"""The monolithic reference: the boom's physics as one ODE, solved by scipy.

The same physics functions the FMUs step (``boomfmi.physics``) become one right-hand
side for the state ``(p_a, p_b, x, v)``, integrated with LSODA (or Radau) at tight
tolerance.  Discontinuities are handled as events, never smoothed:

* the command's steps are breakpoints (the integration restarts there);
* while the piston slides, its velocity reaching zero and the piston reaching a stop
  end the segment; the stick test of Eq. 9 then picks the next mode;
* while it sticks (or rests against a stop), the drive force reaching the static
  friction level ``F_s cos(phi)`` (away from a stop) ends the segment.

It is the yardstick for the co-simulation's error (``benchmarks/cosim_accuracy.py``).
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

    def check(self) -> None:
        ph.check_valve(self.valve)
        ph.check_gas(self.gas)
        ph.check_cylinder(self.cylinder)
        ph.check_load(self.load)
        ph.check_geometry(self.geometry, self.cylinder.L)


def _drive(model: Model, p_a, p_b, x, f_ext):
    return ph.drive_force(p_a, p_b, ph.phi_from_x(x, model.geometry), f_ext, model.cylinder,
                          model.load, model.P_atm)


def _pressure_rates(model: Model, u, p_a, p_b, x, v):
    mdot_a, mdot_b = ph.chamber_flows(u, p_a, p_b, model.valve, model.gas)
    return ph.pressure_rates(p_a, p_b, mdot_a, mdot_b, x, v, model.cylinder, model.gas)


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
    atol = np.array([1e-4, 1e-4, 1e-13, 1e-11])

    cuts = sorted({float(b) for b in breakpoints if 0.0 < b < stop_time} | {stop_time})
    y = np.array([model.p_a0, model.p_b0, model.x0, 0.0])
    t = 0.0
    mode = 0          # +1 / -1 sliding, 0 stuck (or resting against a stop)
    out = np.full((len(times), 4), np.nan)
    inputs = np.full((len(times), 2), np.nan)

    def forces(cmd, y):
        F = _drive(model, y[0], y[1], y[2], cmd.get("f_ext", 0.0))
        return F, model.load.F_s * math.cos(ph.phi_from_x(y[2], model.geometry))

    def next_mode(cmd, y):
        F, limit = forces(cmd, y)
        if abs(F) <= limit:
            return 0
        s = 1 if F > 0 else -1
        if (s > 0 and y[2] >= L) or (s < 0 and y[2] <= 0.0):
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
                dp_a, dp_b = _pressure_rates(model, u, y[0], y[1], y[2], y[3])
                if s == 0:
                    return [dp_a, dp_b, 0.0, 0.0]
                phi = ph.phi_from_x(y[2], model.geometry)
                F = ph.drive_force(y[0], y[1], phi, f_ext, model.cylinder, model.load, model.P_atm)
                return [dp_a, dp_b, y[3], ph.sliding_acceleration(y[3], F, phi, s, model.load)]

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
                out[sel] = sol.sol(times[sel]).T
                inputs[sel] = (u, f_ext)
            y = sol.y[:, -1].copy()
            if sol.status == 1:          # an event ended the segment
                if s != 0:
                    y[3] = 0.0
                    y[2] = min(max(y[2], 0.0), L)
                    mode = next_mode(cmd, y)
                else:
                    mode = next_mode(cmd, y)
                    if mode == 0:        # grazing: nudge past the event
                        mode = 1 if forces(cmd, y)[0] > 0 else -1
            if s == 0:
                out[sel, 3] = 0.0
            t = t_new
    df = pd.DataFrame({"time": times, "u": inputs[:, 0], "f_ext": inputs[:, 1],
                       "p_a": out[:, 0], "p_b": out[:, 1], "x": np.clip(out[:, 2], 0.0, L),
                       "v": out[:, 3]})
    df["alpha"] = ph.alpha_from_x(df["x"].to_numpy(), model.geometry)
    return df
