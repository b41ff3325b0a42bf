"""Identification of the model's parameters from recordings.

``fit`` is the sound method (all samples, least squares, intervals); ``paper`` the
paper's method as written.  :func:`identify_recordings` reads, prepares and fits;
:func:`write_outputs` writes ``params.json``, the SSP parameter set ``params.ssv`` that
``boomfmi simulate --params`` takes, and a plot like the paper's Fig. 6.
"""
from __future__ import annotations

import math
from pathlib import Path

from .._json import dumps, plain
from ..compare import nrmse, recorded, rig_model, simulate_recording
from ..outputs import OutputSet
from ..recording import check_distinct, check_no_duplicates, check_same_rig, read_checked, recording_inputs
from ..system.ssv import write_ssv
from .fit import DEADBAND_WIDEST, SPOOL_LAG, FitResult, fill_rates, identify
from .paper import identify_paper
from .preprocess import CUTOFF, beyond_noise, prepare
from ..machine import assumption

#: Where each identified parameter lives in the SSP system.
SSP_NAMES = {"K_v": "boom_load.K_v", "F_s": "boom_load.F_s", "F_d": "boom_load.F_d",
             "F_L": "boom_load.F_L", "M": "boom_load.M", "A_max": "valve.A_max"}


def identify_recordings(paths, method: str = "fit", with_A_max: bool = False,
                        cutoff: float = CUTOFF, eq13: str = "printed", machine=None):
    """Read, validate and prepare the recordings, then identify; returns
    ``(FitResult, recordings, prepared)``.  ``machine``: a ``machine.MachineFile`` the
    recordings are of (default: each one's sidecar, else the reference rig, which the
    result's warnings then say)."""
    if method not in ("fit", "paper"):
        raise ValueError(f"unknown method {method!r}: 'paper' or 'fit'")
    recs = read_checked(paths, machine=machine)
    check_same_rig(recs)
    check_no_duplicates(recs)
    rig = rig_model(recs[0])
    preps = [prepare(r, cutoff, geometry=rig.geometry, P_atm=rig.P_atm) for r in recs]
    if method == "fit":
        result = identify(preps, rig.cylinder, P_atm=rig.P_atm, with_A_max=with_A_max,
                          valve=rig.valve, gas=rig.gas)
    else:
        result = identify_paper(preps, rig.cylinder, P_atm=rig.P_atm, eq13=eq13)
    result.details["recordings"] = [str(p) for p in paths]
    result.details["cutoff_Hz"] = cutoff
    assumed = assumption(recs, machine)
    if assumed:
        result.warnings.append(assumed)
    _check_physical(result, paths)
    if method == "fit":
        _check_time_scale(preps, rig, paths, result)
    return result, recs, preps


#: The valve's area the chambers' filling and emptying imply, over the rig's A_max,
#: beyond which a recording's time or pressure scale is taken to be wrong.
FLOW_SCALE = 3.0


def _check_time_scale(preps, rig, paths, result) -> None:
    """The chambers fill and empty at the rate the rig's valve allows (Eq. 1 and 7).  A
    recording whose time runs ten times slow, or whose pressures are in the wrong unit,
    fails this where the load's equations alone would fit it with values no machine has
    but that look plausible one by one.

    Only what the recording can tell is judged (``fit.fill_rates``): the flows at
    openings beyond the widest dead band a valve has, held on one side of the centre
    for the spool's lag, against Eq. 1 at that opening.  It refuses when even crediting
    such a dead band and lag (and the estimate's 95 % interval) the fastest chamber
    fills FLOW_SCALE times slower than the valve allows, or when even without them the
    slowest fills FLOW_SCALE times faster.  Small openings (slow ramps around the
    centre, long holds) fill slowly by nature and tell nothing: where a recording holds
    no other, the check says so in a warning and does not refuse."""
    rates = fill_rates(preps, rig.cylinder, rig.valve, rig.gas)
    a_ref = rig.valve.A_max
    if not rates.at_least:
        result.warnings.append(
            f"the time scale was not checked against the valve: the recordings hold no opening wider than "
            f"{DEADBAND_WIDEST:g} V from the centre held for {1e3 * SPOOL_LAG:.0f} ms (50 samples at least), "
            f"and smaller openings fill slowly whatever the time scale")
        return
    names = ", ".join(str(p) for p in paths)
    slow = max(e.ci95[1] for e in rates.at_least.values()) < a_ref / FLOW_SCALE
    fast = min(e.ci95[0] for e in rates.at_most.values()) > a_ref * FLOW_SCALE
    if not (slow or fast):
        return
    nominal = (max if slow else min)(e.value for e in rates.nominal.values())
    bound = (max(e.ci95[1] for e in rates.at_least.values()) if slow
             else min(e.ci95[0] for e in rates.at_most.values()))
    ratio = nominal / a_ref
    raise ValueError(f"identification from {names}: the chambers fill and empty "
                     f"{ratio:.2g} times as fast as the rig's valve allows (the pressures imply an orifice "
                     f"of {nominal:.3g} m2, the rig's A_max is {a_ref:.3g} m2; "
                     + (f"at most {bound / a_ref:.2g} times even with a {DEADBAND_WIDEST:g} V dead band"
                        if slow else f"at least {bound / a_ref:.2g} times even with no dead band")
                     + f", over {sum(rates.samples.values())} samples at openings wider than "
                     f"{DEADBAND_WIDEST:g} V); no machine has such "
                     f"values: check the recordings' units (t in s, pressures in Pa gauge), or give the rig's "
                     f"own valve and supply in the recording's sidecar")


#: Identified parameters that no machine has below these values (M and A_max: above)
PHYSICAL_MIN = {"K_v": 0.0, "F_s": 0.0, "F_d": 0.0, "M": 0.0, "A_max": 0.0}


def _check_physical(result: FitResult, paths) -> None:
    """Non-physical values (a negative mass, negative friction) from the sound fit are an
    error: the recording is not what it claims (its time or pressure scale, most
    often).  The paper's method gives such values by itself (docs/identification.md):
    for it they are loud warnings, and :func:`write_outputs` writes no parameter set.
    An interval of zero width is never a result: it is reported as unknown."""
    bad = [f"{k} = {e.value:.4g} {e.unit}" for k, e in result.params.items()
           if k in PHYSICAL_MIN and math.isfinite(e.value)
           and (e.value < PHYSICAL_MIN[k] or (k in ("M", "A_max") and e.value <= 0))]
    if bad and result.method == "fit":
        raise ValueError(f"identification from {', '.join(str(p) for p in paths)} gave {', '.join(bad)}: no machine "
                         f"has such values; check the recordings' units (t in s, pressures in Pa gauge) and "
                         f"that they hold motion in both directions")
    if bad:
        result.warnings.append(f"not physical: {', '.join(bad)}; no parameter set (.ssv) is written")
    for k, e in result.params.items():
        lo, hi = e.ci95
        if math.isfinite(lo) and math.isfinite(hi) and hi - lo <= 0.0:
            result.params[k] = type(e)(e.value, (math.nan, math.nan), e.unit)
            result.warnings.append(f"the 95 % interval of {k} could not be computed (zero width): "
                                   f"treat {k} as unknown in its precision")


def plot_fit(values: dict, recs, path) -> None:
    """Recorded and simulated x, p_a, p_b over each fit recording (the paper's Fig. 6):
    one column per recording, in one figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    recs = list(recs) if isinstance(recs, (list, tuple)) else [recs]
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


def write_outputs(result: FitResult, recs, out, holdout=()) -> dict:
    """Write ``out`` (params.json), ``params.ssv`` and ``params.png`` beside it, as one set
    (:class:`OutputSet`: all or none; a file this run does not write is removed, so no
    earlier run's passes for this one's).  ``doc["written"]`` lists the files."""
    out = Path(out)
    holds = read_checked(holdout, role="holdout")     # the same checks as the fit recordings'
    for h in holds:
        check_distinct(recs, h)
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
    names = (out.name, out.with_suffix(".ssv").name, out.with_suffix(".png").name)
    with OutputSet(out.parent, stale=names,
                   inputs=recording_inputs([*(r.path for r in recs), *(h.path for h in holds)])) as files:
        if physical:
            write_ssv(files.path(names[1]), "identified",
                      {SSP_NAMES[k]: (v, result.params[k].unit) for k, v in finite.items()},
                      f"identified by boomfmi ({result.method}) from " + ", ".join(str(r.path) for r in recs))
        if physical and _usable(finite):
            plot_fit(finite, recs, files.path(names[2]))
        doc["written"] = [str(p) for p in [out, *files.written()]]
        files.path(names[0]).write_text(dumps(doc, indent=2))
    return doc


def _usable(values: dict) -> bool:
    return all(k in values and values[k] > 0 for k in ("K_v", "F_d", "M")) and "F_L" in values


__all__ = ["identify_recordings", "write_outputs", "FitResult"]
