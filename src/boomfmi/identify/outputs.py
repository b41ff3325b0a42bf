"""``identify``'s outputs for a machine of one joint or four: ``params.json``, the SSP
parameter set ``params.ssv`` and the plot ``params.png``, written as one set
(``outputs.OutputSet``) by :func:`write_outputs`; the human summary
(:func:`summary_lines`); the identified machine simulated on a recording and its error
per joint (:func:`simulate_machine`, :func:`joint_nrmse`); the run file of ``view
--model`` (:func:`write_run`).

The boom rig (one joint) binds its values to ``excavator_boom.ssp``'s ``boom_load`` (and
``valve``); its params.json holds each parameter's value, 95 % interval and unit, the
NRMSE on every fit and ``--holdout`` recording and whether a holdout's error is a gap
beyond its noise (``preprocess.beyond_noise``).

The whole excavator (four joints) writes, as one set:

- ``params.json``: ``"kind": "excavator"``, every parameter (``K_v_<joint>``,
  ``F_s_<joint>``, ``F_d_<joint>``, ``payload``, the linkage FMU's own names) with its
  value, 95 % interval (``null`` where there is none), unit, joint, whether the data
  identify it (``identified``; else ``cannot_tell`` says why), the name it has in
  ``build/excavator.ssp`` and the value ``params.ssv`` binds; the warnings, the
  recordings, and each joint's NRMSE of x, p_a and p_b on every fit and ``--holdout``
  recording (:func:`joint_nrmse`);
- ``params.ssv``: the values bound to the excavator SSP's ``linkage`` component
  (``linkage.K_v_arm``, ``linkage.payload``...), for ``boomfmi simulate
  build/excavator.ssp --params params.ssv``;
- ``params.png``: recorded and simulated x, p_a, p_b of every joint on the first
  recording.

What its ``params.ssv`` binds is what a machine can have (the linkage FMU rejects the
rest): a negative friction value is left out (the SSP's own value stays; a warning says
so), F_s is raised to F_d where it is below it (Eq. 9) and a negative payload is bound
as 0 (:func:`ssv_values`, :func:`bound_machine`).  The NRMSE are those of that same
machine.

**The identified machine on an excavator recording** (:func:`simulate_machine`): the
monolithic reference (``model.reference.simulate_linkage``) with the identified values,
driven by the recording's four commands (and its tip force where it has one), from the
recording's first state (the pistons from the mean of the first 20 ms of angles, the
chambers at their mean pressures then), at rest.  Its step ``H`` = 0.5 ms: on the
virtual rig's digging cycle (5 s, with a payload) within 0.03 % NRMSE of the reference's
own 50 us on every joint's x and pressures, at a tenth of its cost (about 0.2 s per
second recorded).

Only the sidecar's ``P_atm`` applies to an excavator recording: its other rig values
are the boom's (reference-rig names) and are reported as not applied.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from .._json import dumps, plain
from ..compare import as_sensed, nrmse, recorded, rig_model, simulate_recording
from ..model.machine import excavator_machine
from ..outputs import OutputSet
from ..physics import linkage as exc
from ..recording import EXCAVATOR_RIG_KEYS, check_distinct, check_same_rig, read_checked, recording_inputs
from ..system.ssv import write_ssv
from .fit import FitResult
from .joints import JOINT_PARAMS, JOINTS, PARAMETER_UNITS, PROMISE
from .preprocess import ABS_FLOOR, NOISE_FACTOR, beyond_noise, machine_for, machine_of

#: The excavator SSP's component that holds the identified parameters (its linkage FMU
#: declares ``K_v_<joint>``, ``F_s_<joint>``, ``F_d_<joint>`` and ``payload``).
SSP_COMPONENT = "linkage"
#: Step of the identified machine's simulation [s] (see the module's docstring).
H = 5e-4
#: The least span a channel's error is measured over: a piston that barely moves is
#: judged against 1 mm, a chamber against half a bar (``diagnose.joints.P_SPAN_MIN``).
X_SPAN_MIN = 1e-3
P_SPAN_MIN = 5e4
#: The start state is the mean over this first stretch of the recording [s].
START_WINDOW = 0.02


def param_joint(param: str) -> str | None:
    """The joint a parameter belongs to by its name (``physics.params.channel``:
    ``K_v_arm`` -> ``"arm"``); ``None`` for a name without a joint (the one-joint
    machine's ``K_v``, the payload)."""
    head, _, tail = param.rpartition("_")
    return tail if head and tail in JOINTS else None


def cannot_tell(result: FitResult) -> dict[str, str | None]:
    """Per parameter of either machine, why the data cannot tell its value (``None``
    where they can): no interval; F_s where its starts do not place it
    (``fit.static_friction``'s ``identified``, per joint on the linkage:
    ``identify.joints``' stage 2); any other (not the payload) where the interval is
    wider than half the value (the identification's warning's rule)."""
    out = {}
    statics = result.details.get("static_friction", {})
    for name, e in result.params.items():
        lo, hi = e.ci95
        joint = param_joint(name)
        static = statics.get(joint, {}) if joint is not None else statics
        is_F_s = name == "F_s" or name.startswith("F_s_")
        if not (math.isfinite(lo) and math.isfinite(hi) and math.isfinite(e.value)):
            reason = "no interval"
            if is_F_s and not static.get("starts", 1):
                reason = f"no start of motion from rest ({name.replace('F_s', 'F_d', 1)} is used)"
        elif is_F_s and not static.get("identified", True):
            reason = "the starts put it anywhere in its interval" + (
                f", wider than {100 * PROMISE:.0f} % of it on a side" if joint is not None else "")
        elif name != "payload" and not is_F_s and not e.tells:
            reason = "its interval is wider than half its value"
        else:
            reason = None
        out[name] = reason
    return out


def sidecar_warnings(recs) -> list[str]:
    """A warning per recording whose sidecar sets rig values the excavator does not apply."""
    out = []
    for r in recs:
        ignored = sorted(k for k in r.rig if k not in EXCAVATOR_RIG_KEYS)
        if ignored:
            out.append(f"{r.path}: the sidecar's rig values {', '.join(ignored)} are the boom's; the excavator's "
                       f"identification and diagnosis use excavator.md's machine (only P_atm applies)")
    return out


def ssv_values(result: FitResult, ex: exc.Excavator) -> tuple[dict[str, float], list[str]]:
    """What ``params.ssv`` binds (parameter name -> value) and the notes on what it
    changed or left out (see the module's docstring)."""
    v = result.values()
    out, notes = {}, []
    for j in JOINTS:
        for n in ("K_v", "F_d"):
            name = f"{n}_{j}"
            if math.isfinite(v[name]) and v[name] >= 0.0:
                out[name] = float(v[name])
            else:
                notes.append(f"{name} = {v[name]:.4g} {PARAMETER_UNITS[n]} is not physical: params.ssv leaves it out "
                             f"(the SSP's own {getattr(getattr(ex, j), n):.4g} {PARAMETER_UNITS[n]} stays)")
        F_d = out.get(f"F_d_{j}", getattr(ex, j).F_d)
        F_s = v[f"F_s_{j}"]
        if not (math.isfinite(F_s) and F_s >= 0.0):
            notes.append(f"F_s_{j} = {F_s:.4g} N is not physical: params.ssv binds F_d_{j} = {F_d:.4g} N in its place")
            F_s = F_d
        elif F_s < F_d:
            notes.append(f"F_s_{j} = {F_s:.4g} N is below F_d_{j} = {F_d:.4g} N: params.ssv binds F_d (Eq. 9 wants "
                         f"F_s >= F_d)")
            F_s = F_d
        out[f"F_s_{j}"] = float(F_s)
    payload = v["payload"]
    if math.isfinite(payload):
        if payload < 0.0:
            notes.append(f"payload = {payload:.4g} kg is below 0: params.ssv binds 0 kg")
        out["payload"] = max(0.0, float(payload))
    ordered = {f"{n}_{j}": out[f"{n}_{j}"] for j in JOINTS for n in JOINT_PARAMS if f"{n}_{j}" in out}
    if "payload" in out:
        ordered["payload"] = out["payload"]
    return ordered, notes


def bound_machine(values: dict[str, float], ex: exc.Excavator) -> tuple[exc.Excavator, float]:
    """``(Excavator, payload)``: ``ex`` with the values ``params.ssv`` binds."""
    changes = {j: replace(getattr(ex, j), **{n: values[f"{n}_{j}"] for n in JOINT_PARAMS if f"{n}_{j}" in values})
               for j in JOINTS}
    return replace(ex, **changes), float(values.get("payload", 0.0))


def measured_pistons(rec, ex: exc.Excavator) -> np.ndarray:
    """Each piston's position [m] from the recorded angles (samples x joints)."""
    d = rec.data if hasattr(rec, "data") else rec
    q = np.column_stack([d[f"angle_{j}"].to_numpy(float) for j in JOINTS])
    return exc.pistons_from_angles(q, ex)


def _held(t: np.ndarray, values: np.ndarray):
    """``f(time) -> row``: ``values`` held from each sample's time ``t`` (from 0)."""
    def at(time: float):
        k = int(np.searchsorted(t, time + 1e-9, side="right")) - 1
        return values[min(max(k, 0), len(t) - 1)]
    return at


def simulate_machine(rec, ex: exc.Excavator, payload: float = 0.0, h: float = H) -> pd.DataFrame:
    """The machine ``ex`` with ``payload`` on the recording (see the module's
    docstring): ``t`` and per joint ``x_<j>`` [m], ``p_a_<j>``, ``p_b_<j>`` [Pa gauge]
    on the recording's samples."""
    from ..model.machine import Machine
    from ..model.reference import simulate_linkage
    d = rec.data if hasattr(rec, "data") else rec
    P_atm = float(getattr(rec, "P_atm", ex.P_atm))
    t = d["t"].to_numpy(float)
    t = t - t[0]
    fs = 1.0 / float(np.median(np.diff(t)))
    n0 = max(1, int(START_WINDOW * fs))
    x0 = np.clip(measured_pistons(d.iloc[:n0], ex).mean(axis=0), 0.0, ex.strokes)
    p_a0 = np.array([d[f"p_a_{j}"].iloc[:n0].mean() for j in JOINTS]) + P_atm
    p_b0 = np.array([d[f"p_b_{j}"].iloc[:n0].mean() for j in JOINTS]) + P_atm
    u = _held(t, d[[f"u_{j}" for j in JOINTS]].to_numpy(float))
    keys = [f"u_{j}" for j in JOINTS]
    command = lambda time: dict(zip(keys, u(time)))
    f_tip = None
    if all(f"f_tip_{c}" in d for c in "xyz"):
        forces = d[[f"f_tip_{c}" for c in "xyz"]].to_numpy(float)
        if np.any(forces):
            held = _held(t, forces)
            f_tip = lambda time: tuple(float(f) for f in held(time))
    sample = h * max(1, round(1e-3 / h))
    machine = Machine(ex=replace(ex, P_atm=P_atm), payload=payload, x0=tuple(x0), p_a0=tuple(p_a0),
                               p_b0=tuple(p_b0))
    sim = simulate_linkage(command, float(t[-1]), machine, h=h, sample=sample, f_tip=f_tip)
    ts = sim["time"].to_numpy()
    out = {"t": d["t"].to_numpy(float)}
    for j in JOINTS:
        out[f"x_{j}"] = np.interp(t, ts, sim[f"x_{j}"].to_numpy())
        for q in ("p_a", "p_b"):
            out[f"{q}_{j}"] = np.interp(t, ts, sim[f"{q}_{j}"].to_numpy()) - P_atm
    return pd.DataFrame(out)


def joint_nrmse(sim: pd.DataFrame, rec, ex: exc.Excavator) -> dict[str, dict[str, float]]:
    """Per joint, the NRMSE of x (from the recorded angle), p_a and p_b: RMS error over
    the channel's range in the recording (at least ``X_SPAN_MIN``, ``P_SPAN_MIN``)."""
    d = rec.data if hasattr(rec, "data") else rec
    x = measured_pistons(d, ex)
    out = {}
    for i, j in enumerate(JOINTS):
        row = {}
        for c, measured, floor in (("x", x[:, i], X_SPAN_MIN), ("p_a", d[f"p_a_{j}"].to_numpy(float), P_SPAN_MIN),
                                   ("p_b", d[f"p_b_{j}"].to_numpy(float), P_SPAN_MIN)):
            model = np.asarray(sim[f"{c}_{j}"], float)
            err = (model if c == "x" else as_sensed(measured, model)) - measured    # pressures as sensed
            row[c] = float(np.sqrt(np.mean(err ** 2)) / max(float(np.ptp(measured)), floor))
        out[j] = row
    return out


def _plot_joints(sim: pd.DataFrame, rec, ex: exc.Excavator, path, title: str = "") -> None:
    """Recorded and simulated x, p_a, p_b of every joint of the linkage (a row per joint)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d = rec.data
    t = d["t"].to_numpy(float)
    x = measured_pistons(d, ex)
    fig, axes = plt.subplots(len(JOINTS), 3, sharex=True, figsize=(12, 9))
    for i, j in enumerate(JOINTS):
        axes[i, 0].plot(t, 1e3 * x[:, i], lw=0.8, label="recorded")
        axes[i, 0].plot(t, 1e3 * sim[f"x_{j}"], lw=1.0, label="model, identified parameters")
        axes[i, 0].set_ylabel(f"{j}\nx [mm]")
        for k, q in ((1, "p_a"), (2, "p_b")):
            axes[i, k].plot(t, d[f"{q}_{j}"] / 1e5, lw=0.8)
            axes[i, k].plot(t, sim[f"{q}_{j}"] / 1e5, lw=1.0)
            axes[i, k].set_ylabel(f"{q} [bar gauge]")
    for k in range(3):
        axes[-1, k].set_xlabel("t [s]")
    axes[0, 0].legend(loc="best", fontsize=8)
    fig.suptitle(title or f"{Path(rec.path).name}: recorded and simulated response")
    fig.tight_layout()
    fig.savefig(path, dpi=100, format="png")
    plt.close(fig)


def parameter_table(result: FitResult, bound: dict[str, float], ex: exc.Excavator) -> dict:
    """``params.json``'s ``params``: name -> value, ci95 (``null`` ends where there is
    none), unit, joint, identified, cannot_tell, ssp_name, ssv_value."""
    why = cannot_tell(result)
    ssp = excavator_machine(ex).ssp_name
    finite = lambda z: float(z) if math.isfinite(z) else None
    return {k: {"value": finite(e.value), "ci95": [finite(e.ci95[0]), finite(e.ci95[1])], "unit": e.unit,
                "joint": param_joint(k), "identified": why[k] is None, "cannot_tell": why[k],
                "ssp_name": ssp(k), "ssv_value": bound.get(k)}
            for k, e in result.params.items()}


def read_params(path) -> dict[str, float]:
    """The values an excavator ``params.json`` (:func:`write_outputs`) binds
    (each parameter's ``ssv_value``: what the machine can have); ValueError naming the
    file for one that is not JSON, not the whole excavator's or binds nothing."""
    import json
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such file (--model names the params.json `boomfmi identify` "
                                f"wrote from the excavator's recordings)") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a params.json ({e})") from None
    if not isinstance(doc, dict) or doc.get("kind") != "excavator" or not isinstance(doc.get("params"), dict):
        raise ValueError(f"{path}: not the whole excavator's params.json (\"kind\": \"excavator\" and its "
                         f"\"params\", as `boomfmi identify` writes them from excavator recordings)")
    values = {}
    for name, p in doc["params"].items():
        v = p.get("ssv_value") if isinstance(p, dict) else None
        if v is None:
            continue
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise ValueError(f"{path}: params.{name}.ssv_value = {v!r} is not a finite number")
        values[name] = float(v)
    if not values:
        raise ValueError(f"{path}: binds no value (every ssv_value is null): nothing identified to simulate")
    return values


#: The tip force's columns of an excavator run file: the estimate and, per axis, the
#: interval of tip forces consistent with the recording (``physics.force_estimation``;
#: a side at ``+-force_estimation.F_BOUND`` is open: a stop or a sticking joint leaves
#: it unbounded).
RUN_FORCES = tuple(f"{k}_{a}" for k in ("f_tip_est", "f_tip_lo", "f_tip_hi") for a in "xyz")


def machine_run(rec, values: dict[str, float], ex: exc.Excavator | None = None) -> pd.DataFrame:
    """The excavator run file of a recording (the view's ``load_run``): the
    machine identified as ``values`` (:func:`read_params`) simulated on the
    recording's commands (:func:`simulate_machine`) beside the machine, the model's
    columns unsuffixed (``angle_<j>`` from its pistons, ``p_a_<j>``, ``p_b_<j>``), the
    recording's ``_measured``, its commands ``u_<j>`` and true ``f_tip_x/y/z`` where it
    has them, and :data:`RUN_FORCES` from the force estimator on the recording."""
    from ..physics.force_estimation import estimate_tip_force
    d = rec.data
    machine, payload = bound_machine(values, machine_for(rec, ex))
    sim = simulate_machine(rec, machine, payload)
    out = {"t": d["t"].to_numpy(float)}
    for j in JOINTS:
        out[f"u_{j}"] = d[f"u_{j}"].to_numpy(float)
    angles = exc.joint_angles(np.column_stack([sim[f"x_{j}"].to_numpy(float) for j in JOINTS]), machine)
    for i, j in enumerate(JOINTS):
        out[f"angle_{j}"] = angles[:, i]
        out[f"p_a_{j}"], out[f"p_b_{j}"] = sim[f"p_a_{j}"].to_numpy(float), sim[f"p_b_{j}"].to_numpy(float)
    for j in JOINTS:
        for q in ("angle", "p_a", "p_b"):
            out[f"{q}_{j}_measured"] = d[f"{q}_{j}"].to_numpy(float)
    if all(f"f_tip_{a}" in d for a in "xyz"):
        out.update({f"f_tip_{a}": d[f"f_tip_{a}"].to_numpy(float) for a in "xyz"})
    f, _, lo, hi = estimate_tip_force(d, machine, payload, P_atm=float(getattr(rec, "P_atm", machine.P_atm)),
                                      bounds=True)
    for k, arr in (("f_tip_est", f), ("f_tip_lo", lo), ("f_tip_hi", hi)):
        out.update({f"{k}_{a}": arr[:, i] for i, a in enumerate("xyz")})
    return pd.DataFrame(out)


def write_run(recording, params, out, progress=None) -> Path:
    """Write ``out``, the excavator run file (:func:`machine_run`) of the excavator
    ``recording`` with the identified ``params`` (params.json), beside the recording's
    sidecar values; as ``record`` writes, an existing ``out`` is replaced only once the
    whole run is written (``recording.RecordingWriter``), and ``out`` may not be one of
    the inputs."""
    from ..outputs import check_not_inputs
    from ..recording import sidecar_path, write_recording
    say = progress or (lambda text: None)
    out = Path(out)
    if out.suffix.lower() != ".csv":
        raise ValueError(f"{out}: the run file is a recording: give it the .csv suffix (its sidecar goes "
                         f"beside it as {out.with_suffix('.json').name})")
    check_not_inputs([out, sidecar_path(out)], [(Path(params), f"the model {params}"),
                                                 *recording_inputs([recording])])
    rec = read_checked([recording], "excavator", "recording")[0]
    values = read_params(params)
    say(f"simulating the identified machine on {rec.path} and estimating the tip force")
    run = machine_run(rec, values)
    notes = f"the machine identified in {params} beside the recording {rec.path} (boomfmi)"
    return write_recording(out, run, {"rig": dict(rec.rig), "notes": notes})


def plot_fit(values: dict, recs, path, sims: dict | None = None) -> None:
    """Recorded and simulated x, p_a, p_b with the identified ``values`` (the paper's
    Fig. 6): the boom's, one column per fit recording; the linkage's, a row per joint
    on the first recording (``sims``: its simulation by :func:`simulate_machine`,
    path -> frame, where already run)."""
    recs = list(recs) if isinstance(recs, (list, tuple)) else [recs]
    if machine_of(recs[0]).n > 1:
        machine, payload = bound_machine(values, machine_for(recs[0]))
        sim = (sims or {}).get(str(recs[0].path))
        _plot_joints(sim if sim is not None else simulate_machine(recs[0], machine, payload), recs[0], machine, path)
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, grid = plt.subplots(3, len(recs), sharex="col", figsize=(9 * len(recs), 7), squeeze=False)
    for k, rec in enumerate(recs):
        axes = grid[:, k]
        rig = rig_model(rec)
        sim = simulate_recording(values, rec, rig=rig)
        t = rec.data["t"].to_numpy()
        x_rec = recorded(rec, rig)["x"]
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
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def write_outputs(result: FitResult, recs, out, holdout=(), ex: exc.Excavator | None = None,
                  progress=None) -> dict:
    """Write ``out`` (params.json), ``params.ssv`` and ``params.png`` beside it, as one set
    (:class:`OutputSet`: all or none; a file this run does not write is removed, so no
    earlier run's passes for this one's), for the machine the recordings ``recs`` are of
    (one joint or four: see the module's docstring); ``holdout``: recordings (paths) not
    fitted on, the model's error reported on them; ``ex``: the excavator's linkage the
    identification assumed (default: the recordings').  ``doc["written"]`` lists the
    files."""
    say = progress or (lambda text: None)
    out = Path(out)
    machine = machine_of(recs[0])          # one joint (the boom rig) or the linkage's four
    linkage = machine.n > 1
    holds = read_checked(holdout, "excavator" if linkage else None, "holdout")   # the fit recordings' checks
    for h in holds:
        check_distinct(recs, h)
    if linkage:
        check_same_rig([*recs, *holds])
        doc, bound, units, plot, what = _linkage_doc(result, recs, holds, machine_for(recs[0], ex), say)
    else:
        doc, bound, units, plot, what = _boom_doc(result, recs, holds)
    ssp_name = machine.ssp_name
    names = (out.name, out.with_suffix(".ssv").name, out.with_suffix(".png").name)
    with OutputSet(out.parent, stale=names,
                   inputs=recording_inputs([*(r.path for r in recs), *(h.path for h in holds)])) as files:
        if bound is not None:
            write_ssv(files.path(names[1]), "identified", {ssp_name(k): (v, units[k]) for k, v in bound.items()},
                      f"{what} ({result.method}) from " + ", ".join(str(r.path) for r in recs))
        if plot is not None:
            plot(files.path(names[2]))
        doc["written"] = [str(p) for p in [out, *files.written()]]
        files.path(names[0]).write_text(dumps(doc, indent=2))
    return doc


def _boom_doc(result: FitResult, recs, holds):
    """The boom's params.json, what its params.ssv binds (none where a value is not
    physical), its units, its plot (none where the values cannot run)."""
    values = result.values()
    doc = {"method": result.method,
           "params": {k: {"value": e.value, "ci95": list(e.ci95), "unit": e.unit}
                      for k, e in result.params.items()},
           "warnings": result.warnings,
           "details": plain(result.details)}
    finite = {k: v for k, v in values.items() if math.isfinite(v)}
    doc["nrmse_fit"] = {str(r.path): nrmse(simulate_recording(finite, r), r) for r in recs} if _usable(finite) else {}
    for hr in holds:
        err = doc.setdefault("nrmse_holdout", {})[str(hr.path)] = nrmse(simulate_recording(finite, hr), hr)
        doc.setdefault("holdout_gap", {})[str(hr.path)] = beyond_noise(err, hr)
    physical = not any(w.startswith("not physical") for w in result.warnings)
    units = {k: result.params[k].unit for k in finite}      # params.ssv: none where a value is not physical
    plot = (lambda path: plot_fit(finite, recs, path)) if physical and _usable(finite) else None
    return doc, (finite if physical else None), units, plot, "identified by boomfmi"


def _usable(values: dict) -> bool:
    return all(k in values and values[k] > 0 for k in ("K_v", "F_d", "M")) and "F_L" in values


def _linkage_doc(result: FitResult, recs, holds, ex: exc.Excavator, say):
    """The whole excavator's params.json, what its params.ssv binds (:func:`ssv_values`),
    its units and its plot, each joint's error from the bound machine's simulation."""
    bound, notes = ssv_values(result, ex)
    machine, payload = bound_machine(bound, ex)
    doc = {"kind": "excavator",
           "method": result.method,
           "recordings": [str(r.path) for r in recs],
           "holdout": [str(h.path) for h in holds],
           "params": parameter_table(result, bound, ex),
           "ssp_component": SSP_COMPONENT,
           "warnings": [*result.warnings, *notes],
           "details": plain(result.details)}
    sims = {}
    for r in recs:
        say(f"simulating the identified machine on {r.path}")
        sims[str(r.path)] = simulate_machine(r, machine, payload)
    doc["nrmse_fit"] = {p: joint_nrmse(s, r, machine) for (p, s), r in zip(sims.items(), recs)}
    doc["nrmse_holdout"] = {}
    for h in holds:
        say(f"simulating the identified machine on the holdout {h.path}")
        doc["nrmse_holdout"][str(h.path)] = joint_nrmse(simulate_machine(h, machine, payload), h, machine)
    units = {k: PARAMETER_UNITS[k.rsplit("_", 1)[0] if k != "payload" else k] for k in bound}
    plot = lambda path: _plot_joints(sims[str(recs[0].path)], recs[0], machine, path)
    return doc, (bound or None), units, plot, "the whole excavator identified by boomfmi"


def summary_lines(doc: dict) -> list[str]:
    """The human summary ``boomfmi identify`` prints of a :func:`write_outputs` document:
    the parameters with their 95 % intervals (the excavator's per joint, "cannot tell"
    and why where the data cannot, and the payload), the warnings and each holdout's
    NRMSE (the boom's: whether it is a gap beyond the recording's noise; the
    excavator's: per joint)."""
    if doc.get("kind") == "excavator":
        return _joint_lines(doc)
    lines = [f"{doc['method']}: " + ", ".join(
        f"{k} = {p['value']:.4g} {p['unit']}"
        + (f" [{p['ci95'][0]:.4g}, {p['ci95'][1]:.4g}]" if p["ci95"][0] == p["ci95"][0] else "")
        for k, p in doc["params"].items())]
    lines.extend(f"warning: {w}" for w in doc["warnings"])
    fits = " ".join(doc["details"].get("recordings", []))
    for path, err in doc.get("nrmse_holdout", {}).items():
        lines.append(f"holdout {path}: NRMSE x {100 * err['x']:.2f} %, p_a {100 * err['p_a']:.2f} %, "
                     f"p_b {100 * err['p_b']:.2f} %")
        gap = doc["holdout_gap"][path]
        floor = (f"{100 * gap['threshold']:.2f} % ({NOISE_FACTOR:g} times the recording's noise floor, "
                 f"{100 * gap['noise_floor_sum']:.2f} %, plus {100 * ABS_FLOOR:g} %)")
        if gap["beyond_noise"]:
            lines.append(f"  large: {100 * gap['nrmse_sum']:.2f} % in all, beyond {floor}; the model misses an "
                         f"effect: `boomfmi diagnose {fits} --holdout {path} --out DIR` names it")
        else:
            lines.append(f"  within the noise: {100 * gap['nrmse_sum']:.2f} % in all, under {floor}")
    return lines


def _joint_lines(doc: dict) -> list[str]:
    """:func:`summary_lines` of the whole excavator's document."""
    lines = [f"{doc['method']}, per joint (95 % intervals):"]
    params = doc["params"]

    def one(name: str) -> str:
        p = params[name]
        short = name if p["joint"] is None else name.rsplit("_", 1)[0]
        lo, hi = p["ci95"]
        text = f"{short} = {p['value']:.4g} {p['unit']}" if p["value"] is not None else f"{short} = ?"
        text += f" [{lo:.4g}, {hi:.4g}]" if lo is not None and hi is not None else " [no interval]"
        return text + (f" (cannot tell: {p['cannot_tell']})" if p["cannot_tell"] else "")

    for j in JOINTS:
        entries = [one(f"{n}_{j}") for n in JOINT_PARAMS]
        lines.append(f"  {j:7s}" + entries[0])
        lines.extend(f"  {'':7s}" + e for e in entries[1:])
    lines.append("  " + one("payload"))
    lines.extend(f"warning: {w}" for w in doc["warnings"])
    for path, per in doc.get("nrmse_holdout", {}).items():
        lines.append(f"holdout {path}: NRMSE x / p_a / p_b per joint: " + "; ".join(
            f"{j} {100 * e['x']:.2f} / {100 * e['p_a']:.2f} / {100 * e['p_b']:.2f} %" for j, e in per.items()))
    return lines


__all__ = ["write_outputs", "plot_fit", "summary_lines", "cannot_tell", "param_joint", "parameter_table",
           "ssv_values", "bound_machine", "simulate_machine", "joint_nrmse", "measured_pistons", "sidecar_warnings",
           "read_params", "machine_run", "write_run", "RUN_FORCES", "SSP_COMPONENT"]
