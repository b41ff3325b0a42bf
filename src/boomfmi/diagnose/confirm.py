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

The whole excavator's verdicts are confirmed the same way through ``excavator.ssp``
(:func:`confirm_machine`): each joint's effects on its own FMUs (``valve_<joint>``,
``cylinder_<joint>``, the linkage's options of that joint's cylinder), the per-joint
NRMSE before and after, and the shrink.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import physics as ph
from ..compare import initial_state, nrmse, shrink
from ..model import EFFECTS, fmu_variable, measure
from ..model.boom import measurement_lag
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
    tau, delay = measurement_lag(effects)
    return {c: measure(y, t, tau, delay) for c, y in sim.items()}


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


# ------------------------------------------------------------------ the whole excavator
def machine_parameters(values: dict, effects_by_joint: dict, rec) -> dict:
    """``excavator.ssp``'s parameters for the excavator holdout ``rec``: the identified
    friction and payload (``K_v_<joint>``, ``F_s_<joint>``, ``F_d_<joint>``, ``payload``
    as ``identify.joints`` names them; those not given keep the SSP's), the start
    where the recording starts (each piston from its first angles, each chamber's
    pressures absolute) and each joint's effects as its FMUs' options
    (``model.machine.joint_fmu_variable``: ``valve_arm.tau_spool``,
    ``cylinder_arm.C_leak``, ``linkage.v_s_arm``; sensor_lag is applied to the outputs)."""
    from ..identify.outputs import START_WINDOW, measured_pistons
    from ..identify.preprocess import machine_for
    from ..model.machine import check_joint_effects, excavator_machine, joint_fmu_variable
    from ..physics.linkage import JOINTS
    ex = machine_for(rec)
    ssp_name = excavator_machine(ex).ssp_name
    check_joint_effects(effects_by_joint, ex)
    params = {ssp_name(k): float(v) for k, v in values.items()
              if k == "payload" or any(k == f"{q}_{j}" for q in ("K_v", "F_s", "F_d") for j in JOINTS)}
    d = rec.data
    t = d["t"].to_numpy(float)
    n0 = max(1, int(START_WINDOW / float(np.median(np.diff(t)))))
    x0 = np.clip(measured_pistons(d.iloc[:n0], ex).mean(axis=0), 0.0, ex.strokes)
    P_atm = float(getattr(rec, "P_atm", ex.P_atm))
    for i, j in enumerate(JOINTS):
        params[f"linkage.x0_{j}"] = float(x0[i])
        params[f"cylinder_{j}.p_a0"] = float(d[f"p_a_{j}"].iloc[:n0].mean()) + P_atm
        params[f"cylinder_{j}.p_b0"] = float(d[f"p_b_{j}"].iloc[:n0].mean()) + P_atm
    for j, effects in effects_by_joint.items():
        for name, p in effects.items():
            for k, v in p.items():
                where = joint_fmu_variable(name, k, j)
                if where is not None:
                    params[where] = float(v)
    return params


def run_machine_fmus(ssp, values: dict, effects_by_joint: dict, rec) -> dict:
    """``excavator.ssp`` on the recording's commands (:func:`machine_parameters`): per
    joint ``x_<j>``, ``p_a_<j>``, ``p_b_<j>`` (gauge) on its samples, each joint with
    sensor_lag seen through it (its pressures and angle lagged, x from the lagged angle,
    as the excavator's bridge measures)."""
    from ..identify.preprocess import machine_for
    from ..physics.linkage import JOINTS, pistons_from_angles
    out = run_experiment(ssp, str(rec.path), parameters=[machine_parameters(values, effects_by_joint, rec)])
    t = rec.data["t"].to_numpy(float)
    ts = out["t"].to_numpy(float)
    sim = {f"{q}_{j}": np.interp(t, ts, out[f"{q}_{j}"].to_numpy(float))
           for j in JOINTS for q in ("x", "p_a", "p_b", "angle")}
    lagged = {j: measurement_lag(effects_by_joint.get(j, {})) for j in JOINTS}
    lagged = {j: q for j, q in lagged.items() if q[0] > 0.0 or q[1] > 0.0}
    if lagged:
        for j, (tau, delay) in lagged.items():
            for c in (f"p_a_{j}", f"p_b_{j}", f"angle_{j}"):
                sim[c] = measure(sim[c], t, tau, delay)
        pistons = pistons_from_angles(np.column_stack([sim[f"angle_{j}"] for j in JOINTS]), machine_for(rec))
        for i, j in enumerate(JOINTS):
            if j in lagged:
                sim[f"x_{j}"] = pistons[:, i]
    return sim


def confirm_machine(values: dict, effects_by_joint: dict, rec, ssp=None, effect_values: dict | None = None) -> dict:
    """The excavator holdout ``rec`` through ``excavator.ssp`` (default: the build
    folder's, ``paths.built``), co-simulated by our master on its recorded commands from
    its start state: once with the identified ``values`` alone and once with each joint's
    effects (``effects_by_joint``: ``{"arm": {"piston_leakage": {"C": 2e-11}}}``) set on
    its FMUs (``effect_values``: the friction and payload with the effects, where they
    were identified anew with them; default ``values``).  Returns per joint the NRMSE of
    x, p_a, p_b before and after (``identify.outputs.joint_nrmse``), each
    joint's ``shrink`` and the ``shrink`` over every channel of the joints with effects
    (:func:`compare.shrink`); ``skipped`` (why) where the SSP is not built.  A joint that
    is none, or an effect parameter that is not the catalogue's, raises
    :class:`physics.ParameterError` naming it (``effects.arm.piston_leakage.C``)."""
    from ..identify.outputs import joint_nrmse as excavator_nrmse
    from ..identify.preprocess import machine_for
    from ..model.machine import check_joint_effects
    ssp = Path(ssp) if ssp is not None else built("excavator.ssp")
    ex = machine_for(rec)
    check_joint_effects(effects_by_joint, ex)
    if not ssp.is_file():
        return {"ssp": str(ssp), "skipped": "the SSP is not built (python build_fmus.py)"}
    before = excavator_nrmse(run_machine_fmus(ssp, values, {}, rec), rec, ex)
    doc = {"ssp": str(ssp), "recording": str(rec.path),
           "nrmse_holdout_baseline": {j: {c: round(v, 6) for c, v in row.items()} for j, row in before.items()}}
    if effects_by_joint:
        after = excavator_nrmse(run_machine_fmus(ssp, effect_values or values, effects_by_joint, rec), rec, ex)
        joints = [j for j in before if j in effects_by_joint]
        doc.update({"effects": effects_by_joint,
                    "nrmse_holdout_after": {j: {c: round(v, 6) for c, v in row.items()} for j, row in after.items()},
                    "shrink_by_joint": {j: round(shrink(before[j], after[j]), 4) for j in before},
                    "shrink": round(shrink({f"{c}_{j}": before[j][c] for j in joints for c in before[j]},
                                           {f"{c}_{j}": after[j][c] for j in joints for c in after[j]}), 4)})
    return doc

__all__ = [
    "AGREEMENT", "default_ssp", "fmu_parameters", "run_fmus", "confirm", "agreement",
    "machine_parameters", "run_machine_fmus", "confirm_machine",
]
