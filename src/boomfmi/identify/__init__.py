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

from .._json import plain
from ..compare import nrmse, recorded, rig_model, simulate_recording
from ..recording import read_recording
from ..system.ssv import write_ssv
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
    rig = rig_model(recs[0])
    preps = [prepare(r, cutoff, geometry=rig.geometry, P_atm=rig.P_atm) for r in recs]
    if method == "fit":
        result = identify(preps, rig.cylinder, rig.geometry, P_atm=rig.P_atm, with_A_max=with_A_max,
                          valve=rig.valve, gas=rig.gas)
    elif method == "paper":
        result = identify_paper(preps, rig.cylinder, P_atm=rig.P_atm, eq13=eq13)
    else:
        raise ValueError(f"unknown method {method!r}: 'paper' or 'fit'")
    result.details["recordings"] = [str(p) for p in paths]
    result.details["cutoff_Hz"] = cutoff
    return result, recs, preps


def plot_fit(values: dict, rec, path) -> None:
    """Recorded and simulated x, p_a, p_b over the experiment (the paper's Fig. 6)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rig = rig_model(rec)
    sim = simulate_recording(values, rec, rig=rig)
    t = rec.data["t"].to_numpy()
    x_rec = recorded(rec, rig)["x"]
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


__all__ = ["identify_recordings", "write_outputs", "FitResult"]
