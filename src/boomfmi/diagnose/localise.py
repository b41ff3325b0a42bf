"""Where the model and a recording disagree: channel, operating regime, subsystem.

**Regimes.**  Every sample of a recording belongs to one operating regime, decided
from the recorded command and motion:

* ``valve_step``: the first 60 ms after the command changes;
* ``breakaway``: from 50 ms before to 30 ms after a start of motion from rest;
* ``stroke_end``: the piston within 3 mm of a stop while moving, or against a stop
  with the valve pushing it there;
* ``steady_motion``: moving (|v| > 10 mm/s) otherwise;
* ``hold``: the rest (at rest in mid-stroke, or the valve centred).

**Subsystems**, by co-simulating parts of the model with measured signals in place of
model signals (the SSP's structure makes the cut natural):

* the boom alone, driven by the recorded pressures: a position gap that remains is
  mechanical (``boom_load``);
* the pneumatics alone, valve and cylinder driven by the recorded command and motion:
  a pressure gap that remains is pneumatic; it is put on the ``valve`` where it
  follows a command change and on the ``cylinder`` otherwise;
* the time shift of the whole model that removes most of its residual is reported
  (``lag``): a lag in the measurement path shows as one, but so does a slow valve
  (the pressures answer a command late, and the motion with them), so the shift is a
  hint for attribution, not a verdict of its own.

**Shares**: each (channel, regime, subsystem) cell holds its part of the total
squared normalised residual of the whole model (residual over the channel's range in
the recording), with the time windows where that cell's residual is largest.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..compare import CHANNELS, PRESSURES, as_sensed
from ..identify.fit import breakaways, simulate_load
from ..identify.preprocess import Prepared
from ..model import Boom, Model

REGIMES = ("hold", "breakaway", "valve_step", "steady_motion", "stroke_end")


def regimes(p: Prepared, L: float) -> np.ndarray:
    """The operating regime of every sample (strings from :data:`REGIMES`)."""
    n = len(p.t)
    out = np.full(n, "hold", dtype=object)
    moving = np.abs(p.v) > 0.01
    out[moving] = "steady_motion"
    near_end = (p.x_raw < 0.003) | (p.x_raw > L - 0.003)
    pushing = ((p.x_raw < 0.003) & (p.u > 5.0)) | ((p.x_raw > L - 0.003) & (p.u < 5.0))
    out[(near_end & moving) | pushing] = "stroke_end"
    for i in breakaways(p, L):
        out[max(0, i - int(0.05 * p.fs)):min(n, i + int(0.03 * p.fs))] = "breakaway"
    for i in np.flatnonzero(np.diff(p.u) != 0) + 1:
        out[i:min(n, i + int(0.06 * p.fs))] = "valve_step"
    return out


def simulate_pneumatics(p: Prepared, boom: Boom):
    """Valve and cylinder alone, driven by the recorded command and motion (measured
    signals in place of the boom's): the chamber pressures [Pa, absolute].  With
    valve_dynamics on, the spool (starting at the first command) lags the command
    (``Boom.spool_step`` before ``Boom.opening``, as the FMUs and the reference do),
    the orifices seeing its position at each step's middle."""
    n = len(p.t)
    pa, pb = np.empty(n), np.empty(n)
    p_a, p_b = float(p.p_a_raw[0]), float(p.p_b_raw[0])
    pa[0], pb[0] = p_a, p_b
    # the loop on Python floats (a NumPy scalar's arithmetic costs several times a float's)
    x = np.clip(p.x, 0.0, boom.cylinder.L).tolist()
    t, u = np.asarray(p.t, float).tolist(), np.asarray(p.u, float).tolist()
    masses = list(boom.air_masses(p_a, p_b, x[0]))
    spool = boom.tau_spool > 0.0
    y = u[0]
    for k in range(n - 1):
        x0, dt = x[k], t[k + 1] - t[k]
        if spool:
            y1 = boom.spool_step(y, u[k], dt)
            cmd, y = 0.5 * (y + y1), y1
        else:
            cmd = u[k]
        m_a, m_b, s_a, s_b = boom.chamber_inflows(boom.opening(cmd), p_a, p_b, x0)
        p_a, p_b = boom.step_chambers(p_a, p_b, x0, x[k + 1], m_a, m_b, s_a, s_b, dt, masses)
        pa[k + 1], pb[k + 1] = p_a, p_b
    return pa, pb


@dataclass
class Localisation:
    """The breakdown of one recording's residual (see the module's docstring)."""
    nrmse: dict                   #: whole model, per channel
    where: list = field(default_factory=list)   #: dicts: channel, regime, subsystem, share, windows
    regime_share: dict = field(default_factory=dict)
    subsystem_share: dict = field(default_factory=dict)
    lag: float = 0.0              #: the model's time shift [s] that removes most residual
    lag_gain: float = 0.0         #: the share of the residual that shift removes


def _windows(t, r2, mask, width=0.05, most=3):
    """The ``most`` time windows of ``width`` [s] where ``r2`` (masked) sums largest."""
    if not mask.any():
        return []
    fs = 1.0 / float(np.median(np.diff(t)))
    n = max(1, int(width * fs))
    score = np.convolve(np.where(mask, r2, 0.0), np.ones(n), mode="same")
    out = []
    for _ in range(most):
        i = int(np.argmax(score))
        if score[i] <= 0:
            break
        lo, hi = max(0, i - n // 2), min(len(t) - 1, i + n // 2)
        out.append([round(float(t[lo]), 4), round(float(t[hi]), 4)])
        score[max(0, i - n):i + n] = 0.0
    return out


def localise(p: Prepared, model_sim, model: Model, lag_max: float = 0.02) -> Localisation:
    """Break the whole model's residual on one recording down by channel, regime and
    subsystem.  ``model_sim`` is the whole ``model`` (at the recording's rig, with the
    identified load; ``compare.model_for``) driven by the recording's command (columns
    x, p_a, p_b absolute), on the recording's samples."""
    L = model.cylinder.L
    measured = {"x": p.x_raw, "p_a": p.p_a_raw, "p_b": p.p_b_raw}
    span = {c: max(float(np.ptp(measured[c])), 1e-9) for c in CHANNELS}
    # the pressures as their sensors would read them (compare.as_sensed: a rail is no gap)
    model_sim = {c: as_sensed(measured[c], model_sim[c]) if c in PRESSURES else np.asarray(model_sim[c], float)
                 for c in CHANNELS}
    whole = {c: (model_sim[c] - measured[c]) / span[c] for c in CHANNELS}
    nrmse = {c: float(np.sqrt(np.mean(whole[c] ** 2))) for c in CHANNELS}

    # parts of the model with measured signals in place of model signals
    x_mech = simulate_load(p, model.load, model.cylinder, model.geometry, model.P_atm, 0, len(p.t),
                           float(np.clip(p.x_raw[0], 0, L)))
    pa_pn, pb_pn = simulate_pneumatics(p, Boom(model))
    part = {"x": (x_mech - measured["x"]) / span["x"],
            "p_a": (as_sensed(measured["p_a"], pa_pn) - measured["p_a"]) / span["p_a"],
            "p_b": (as_sensed(measured["p_b"], pb_pn) - measured["p_b"]) / span["p_b"]}
    # a lag of the model that removes most of its residual points at the sensors
    n_lag = int(lag_max * p.fs)
    best_gain, lag = 0.0, 0
    total0 = sum(float(np.sum(whole[c] ** 2)) for c in CHANNELS)
    for s in range(1, n_lag + 1):
        tot = sum(float(np.sum(((np.asarray(model_sim[c], float)[:-s] - measured[c][s:]) / span[c]) ** 2))
                  for c in CHANNELS)
        gain = 1.0 - tot / max(total0, 1e-30)
        if gain > best_gain:
            best_gain, lag = gain, s

    reg = regimes(p, L)
    total = max(total0, 1e-30)
    cells = {}
    for c in CHANNELS:
        r2_whole = whole[c] ** 2
        r2_part = np.minimum(part[c] ** 2, r2_whole)     # what the part alone also shows
        if c == "x":
            sub = np.where(r2_part >= 0.5 * r2_whole, "boom_load", "cylinder")
        else:
            pneumatic = r2_part >= 0.5 * r2_whole
            sub = np.where(pneumatic, np.where(reg == "valve_step", "valve", "cylinder"), "boom_load")
        for r in REGIMES:
            for s in ("valve", "cylinder", "boom_load"):
                mask = (reg == r) & (sub == s)
                share = float(np.sum(r2_whole[mask])) / total
                if share > 0:
                    cells[(c, r, s)] = (share, mask, r2_whole)
    where = []
    for (c, r, s), (share, mask, r2) in sorted(cells.items(), key=lambda kv: -kv[1][0]):
        if share < 0.02:
            continue
        where.append({"channel": c, "regime": r, "subsystem": s, "share": round(share, 4),
                      "windows": _windows(p.t, r2, mask)})
    regime_share = {r: round(sum(v[0] for k, v in cells.items() if k[1] == r), 4) for r in REGIMES}
    subsystem_share = {s: round(sum(v[0] for k, v in cells.items() if k[2] == s), 4)
                       for s in ("valve", "cylinder", "boom_load")}
    return Localisation(nrmse, where, regime_share, subsystem_share, lag / p.fs, best_gain)


__all__ = ["REGIMES", "regimes", "simulate_pneumatics", "Localisation", "localise"]
