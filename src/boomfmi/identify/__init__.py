"""Identification of the model's parameters from recordings.

``fit`` is the sound method (all samples, least squares, intervals); ``paper`` the
paper's method as written.  :func:`identify_recordings` reads, prepares and fits;
:func:`write_outputs` writes ``params.json``, the SSP parameter set ``params.ssv`` that
``boomfmi simulate --params`` takes, and a plot like the paper's Fig. 6.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .. import physics as ph
from .._json import plain
from ..recording import read_recording
from .fit import FitResult, identify
from .paper import identify_paper
from .preprocess import CUTOFF, prepare

#: Where each identified parameter lives in the SSP system.
SSP_NAMES = {"K_v": "boom_load.K_v", "F_s": "boom_load.F_s", "F_d": "boom_load.F_d",
             "F_L": "boom_load.F_L", "M": "boom_load.M", "A_max": "valve.A_max"}


def identify_recordings(paths, method: str = "fit", with_A_max: bool = False,
                        cutoff: float = CUTOFF, eq13: str = "printed"):
    """Read, validate and prepare the recordings, then identify; returns
    ``(FitResult, recordings, prepared)``."""
    recs = [read_recording(p) for p in paths]
    rigs = {json.dumps(r.rig, sort_keys=True) for r in recs}
    if len(rigs) > 1:
        raise ValueError("the recordings come from different rigs (their sidecars' 'rig' values differ): "
                         + ", ".join(str(r.path) for r in recs))
    P_atm = recs[0].P_atm
    geom, cyl, valve, gas = (recs[0].rig_tuple(cls) for cls in (ph.Geometry, ph.Cylinder, ph.Valve, ph.Gas))
    preps = [prepare(r, cutoff, geometry=geom, P_atm=P_atm) for r in recs]
    if method == "fit":
        result = identify(preps, cyl, geom, P_atm=P_atm, with_A_max=with_A_max, valve=valve, gas=gas)
    elif method == "paper":
        result = identify_paper(preps, cyl, P_atm=P_atm, eq13=eq13)
    else:
        raise ValueError(f"unknown method {method!r}: 'paper' or 'fit'")
    result.details["recordings"] = [str(p) for p in paths]
    result.details["cutoff_Hz"] = cutoff
    return result, recs, preps


def initial_state(rec) -> tuple[float, float, float]:
    """Where a recording starts: the piston position x0 [m] (Eq. 12 from the first
    angle, within the stroke, at the recording's rig) and the absolute chamber pressures
    p_a0, p_b0 [Pa]."""
    alpha0 = float(rec.data["alpha"].iloc[0])
    x0 = float(np.clip(ph.x_from_alpha(alpha0, rec.rig_tuple(ph.Geometry)), 0.0, rec.rig_tuple(ph.Cylinder).L))
    return (x0, float(rec.data["p_a"].iloc[0]) + rec.P_atm, float(rec.data["p_b"].iloc[0]) + rec.P_atm)


def model_for(values: dict, effects: dict | None = None, rec=None):
    """A ``reference.Model`` at the reference rig, or at the rig of the recording ``rec``
    (its sidecar's values over the reference rig's, as identification used them), with
    the identified ``values`` in place of its load (and ``A_max``) and the candidate
    ``effects`` switched on."""
    from ..reference import Model
    rig_of = rec.rig_tuple if rec is not None else (lambda cls: cls())
    load = rig_of(ph.Load)._replace(**{k: values[k] for k in ph.Load._fields
                                      if k in values and math.isfinite(values[k])})
    valve = rig_of(ph.Valve)
    if "A_max" in values:
        valve = valve._replace(A_max=values["A_max"])
    return Model(valve=valve, gas=rig_of(ph.Gas), cylinder=rig_of(ph.Cylinder), geometry=rig_of(ph.Geometry),
                 load=load, P_atm=rec.P_atm if rec is not None else Model.P_atm, effects=dict(effects or {}))


def simulate_recording(values: dict, rec, effects: dict | None = None, rtol: float = 1e-9):
    """The model with ``values`` driven by a recording's command (its u held between
    samples), on the recording's times; pressures gauge like the recording."""
    from ..reference import simulate_reference
    t = rec.data["t"].to_numpy(dtype=float)
    u = rec.data["u"].to_numpy(dtype=float)
    changes = t[1:][np.diff(u) != 0]

    def command(s):
        i = max(0, int(np.searchsorted(t, s + 1e-9, side="right")) - 1)
        return {"u": float(u[i])}
    model = model_for(values, effects, rec)
    model.x0, model.p_a0, model.p_b0 = initial_state(rec)
    sim = simulate_reference(model, command, float(t[-1]), times=t - t[0], breakpoints=changes - t[0],
                             rtol=rtol)
    sim["p_a"] -= rec.P_atm
    sim["p_b"] -= rec.P_atm
    return sim


def recorded(rec) -> dict:
    """A recording's x (Eq. 12 from its alpha, at its rig's geometry), p_a and p_b
    (gauge) as arrays."""
    return {"x": ph.x_from_alpha(rec.data["alpha"].to_numpy(dtype=float), rec.rig_tuple(ph.Geometry)),
            "p_a": rec.data["p_a"].to_numpy(float), "p_b": rec.data["p_b"].to_numpy(float)}


def nrmse(sim, rec) -> dict:
    """NRMSE of x, p_a, p_b: RMS error over the recording's range.  ``sim`` maps each
    channel to values on the recording's samples (gauge pressures)."""
    out = {}
    for name, measured in recorded(rec).items():
        span = float(np.ptp(measured)) or 1.0
        out[name] = float(np.sqrt(np.mean((np.asarray(sim[name], float) - measured) ** 2)) / span)
    return out


def plot_fit(values: dict, rec, path) -> None:
    """Recorded and simulated x, p_a, p_b over the experiment (the paper's Fig. 6)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sim = simulate_recording(values, rec)
    t = rec.data["t"].to_numpy()
    x_rec = ph.x_from_alpha(rec.data["alpha"].to_numpy(dtype=float))
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
    axes[0].plot(t, 1e3 * x_rec, lw=0.8, label="recorded")
    axes[0].plot(t, 1e3 * sim["x"], lw=1.0, label="model, identified parameters")
    axes[0].set_ylabel("x [mm]")
    for ax, ch in ((axes[1], "p_a"), (axes[2], "p_b")):
        ax.plot(t, rec.data[ch] / 1e5, lw=0.8)
        ax.plot(t, sim[ch] / 1e5, lw=1.0)
        ax.set_ylabel(f"{ch} [bar gauge]")
    axes[2].set_xlabel("t [s]")
    axes[0].legend(loc="upper left")
    axes[0].set_title(f"{Path(rec.path).name}: recorded and simulated response")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_outputs(result: FitResult, recs, out, holdout=()) -> dict:
    """Write ``out`` (params.json), ``params.ssv`` and ``params.png`` beside it."""
    from ..system.ssv import write_ssv
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    values = result.values()
    doc = {"method": result.method,
           "params": {k: {"value": e.value, "ci95": list(e.ci95), "unit": e.unit}
                      for k, e in result.params.items()},
           "warnings": result.warnings,
           "details": plain(result.details)}
    finite = {k: v for k, v in values.items() if math.isfinite(v)}
    doc["nrmse_fit"] = {str(r.path): nrmse(simulate_recording(finite, r), r) for r in recs} if _usable(finite) else {}
    for h in holdout:
        hr = read_recording(h)
        doc.setdefault("nrmse_holdout", {})[str(hr.path)] = nrmse(simulate_recording(finite, hr), hr)
    out.write_text(json.dumps(doc, indent=2))
    ssv = out.with_suffix(".ssv")
    write_ssv(ssv, "identified", {SSP_NAMES[k]: (v, result.params[k].unit) for k, v in finite.items()},
              f"identified by boomfmi ({result.method}) from " + ", ".join(str(r.path) for r in recs))
    if _usable(finite):
        plot_fit(finite, recs[0], out.with_suffix(".png"))
    return doc


def _usable(values: dict) -> bool:
    return all(k in values and values[k] > 0 for k in ("K_v", "F_d", "M")) and "F_L" in values


__all__ = ["identify_recordings", "write_outputs", "simulate_recording", "nrmse", "recorded", "FitResult"]
