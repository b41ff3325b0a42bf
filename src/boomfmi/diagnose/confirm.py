"""The verdict confirmed through the FMUs.

The fits and scores run on the monolithic reference (``reference.py``), which is fast;
what a user takes away is the FMUs with the verdict's options switched on.  So the
holdout recording is run once more through the boom's SSP (``build/excavator_boom.ssp``:
valve, cylinder and boom load, co-simulated at 1 ms by boomfmi's master over fmpy),
with the re-identified baseline and then with the verdict's effects as FMU parameters,
and its NRMSE and shrink are compared with the reference's.

Each effect's FMU option comes from the catalogue (``model/catalogue.py``).  Sensor lag
is the hardware bridge's option, on the measurement path: on the model's side it is the
same dead time and first-order lag (``model.measure``) applied to the co-simulation's
outputs.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import physics as ph
from ..compare import initial_state, nrmse, shrink
from ..model import EFFECTS, fmu_variable, measure
from ..paths import built
from ..simulate import run_experiment

#: the FMUs and the reference agree when their shrinks differ by less than this
AGREEMENT = 0.1


def default_ssp() -> Path:
    """The boom's SSP in the build folder (``paths.built``), whatever the working directory."""
    return built("excavator_boom.ssp")


def fmu_parameters(values: dict, effects: dict, rec) -> dict:
    """SSP parameters for the holdout ``rec``: the baseline load, the start where the
    recording starts, and the effects' FMU options."""
    params = {f"boom_load.{k}": float(values[k]) for k in ph.Load._fields if k in values}
    x0, p_a0, p_b0 = initial_state(rec)
    params.update({"boom_load.x0": x0, "cylinder.p_a0": p_a0, "cylinder.p_b0": p_b0})
    if "A_max" in values:
        params["valve.A_max"] = float(values["A_max"])
    for name, p in effects.items():
        if EFFECTS[name].stage == "measurement":     # the bridge's: applied to the outputs
            continue
        for k, v in p.items():
            params[fmu_variable(name, k)] = float(v)
    return params


def run_fmus(ssp, values: dict, effects: dict, rec) -> dict:
    """The SSP on the recording's command: x, p_a, p_b (gauge) on its samples."""
    out = run_experiment(ssp, str(rec.path), parameters=[fmu_parameters(values, effects, rec)])
    t = rec.data["t"].to_numpy(float)
    sim = {c: np.interp(t, out["t"].to_numpy(), out[c].to_numpy()) for c in ("x", "p_a", "p_b")}
    lag = effects.get("sensor_lag", {})
    return {c: measure(y, t, lag.get("tau", 0.0), lag.get("delay", 0.0)) for c, y in sim.items()}


def confirm(values: dict, effects: dict, rec, ssp=None, effect_values: dict | None = None) -> dict:
    """The holdout ``rec`` through the FMUs, baseline and (where ``effects``) with the
    verdict's options: NRMSE per channel and shrink (set beside the reference's by
    :func:`agreement`).  ``effect_values``: the load with the verdict's effects, where
    it was identified anew with them (a friction effect); default ``values``."""
    ssp = Path(ssp) if ssp is not None else default_ssp()
    if not ssp.is_file():
        return {"ssp": str(ssp), "skipped": "the SSP is not built (python build_fmus.py)"}
    before = nrmse(run_fmus(ssp, values, {}, rec), rec)
    doc = {"ssp": str(ssp), "recording": str(rec.path),
           "nrmse_holdout_baseline": {k: round(v, 6) for k, v in before.items()}}
    if effects:
        after = nrmse(run_fmus(ssp, effect_values or values, effects, rec), rec)
        doc.update({"effects": effects, "nrmse_holdout_after": {k: round(v, 6) for k, v in after.items()},
                    "shrink": round(shrink(before, after), 4)})
    return doc


def agreement(doc: dict, reference_shrink: float) -> dict:
    """``doc`` (from :func:`confirm`) with the reference's shrink and whether the two
    agree within :data:`AGREEMENT`."""
    return dict(doc, reference_shrink=round(reference_shrink, 4),
                agrees=bool(abs(doc["shrink"] - reference_shrink) < AGREEMENT))
