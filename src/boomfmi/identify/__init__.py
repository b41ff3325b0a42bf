"""Identification of a machine's parameters from its recordings, one joint (the boom
rig) or four (the whole excavator).

``fit`` is the sound method (all samples, least squares, intervals) on the boom's load
and ``joints`` the same stages per joint of the excavator's linkage; ``paper`` the
paper's method as written (the boom's).  :func:`identify_recordings` reads, prepares and
fits the recordings of either machine (by their kind); ``outputs.write_outputs`` writes
``params.json``, the SSP parameter set ``params.ssv`` that ``boomfmi simulate --params``
takes, and a plot like the paper's Fig. 6.
"""
from __future__ import annotations

import math

from ..recording import check_no_duplicates, check_same_rig, common_kind, read_checked
from .fit import DEADBAND_WIDEST, SPOOL_LAG, FitResult, fill_rates, identify
from .joints import identify_joints
from .outputs import cannot_tell, plot_fit, read_params, sidecar_warnings, summary_lines, write_outputs, write_run
from .paper import identify_paper
from .preprocess import CUTOFF, machine_for, machine_of, prepare_machine
from ..machine import assumption


def identify_recordings(paths, method: str = "fit", with_A_max: bool = False,
                        cutoff: float = CUTOFF, eq13: str = "printed", machine=None, progress=None):
    """Read, validate and prepare the recordings, then identify the machine they are of
    (their kind: the boom's or the whole excavator's; a mix is refused naming each
    kind's files); returns ``(FitResult, recordings, prepared)``, ``prepared`` the boom's
    prepared recordings or the excavator's linkage the identification assumed (the
    recordings' sidecar values on ``excavator.md``'s).  ``machine``: a
    ``machine.MachineFile`` the recordings are of (default: each one's sidecar, else
    the reference machine, which the result's warnings then say).  The excavator is
    identified by the fit per joint (``identify.joints``): ``method="paper"`` and
    ``with_A_max`` are the boom's."""
    if method not in ("fit", "paper"):
        raise ValueError(f"unknown method {method!r}: 'paper' or 'fit'")
    linkage = common_kind(paths) == "excavator"
    if linkage:
        _fit_per_joint(method, with_A_max)
        (progress or (lambda text: None))(f"identifying the whole excavator per joint on {len(paths)} recording(s)")
        recs = read_checked(paths, "excavator", "fit recording", machine=machine)
    else:
        recs = read_checked(paths, machine=machine)
    check_same_rig(recs)
    check_no_duplicates(recs)
    result, recs, prepared = identify_recs(recs, method, with_A_max, cutoff, eq13)
    assumed = assumption(recs, machine)
    if assumed:
        result.warnings.append(assumed)
    if linkage:
        return result, recs, prepared
    result.details["recordings"] = [str(p) for p in paths]      # as given
    _check_physical(result, paths)
    if method == "fit":
        _check_time_scale(prepared, machine_of(recs[0]).model, paths, result)
    return result, recs, prepared


def identify_recs(recs, method: str = "fit", with_A_max: bool = False, cutoff: float = CUTOFF,
                  eq13: str = "printed", ex=None):
    """:func:`identify_recordings` on recordings already read and checked (without its
    checks of the result, and the assumption's warning): ``(FitResult, recs,
    prepared)``; ``ex``: the excavator's linkage to assume (default: the recordings')."""
    machine = machine_of(recs[0])          # one joint (the boom rig) or the linkage's four
    if machine.n > 1:
        _fit_per_joint(method, with_A_max)
        ex = machine.ex if ex is None else machine_for(recs[0], ex)
        result = identify_joints(recs, ex, cutoff)
        result.details["recordings"] = [str(r.path) for r in recs]
        result.details["cutoff_Hz"] = cutoff
        result.warnings.extend(sidecar_warnings(recs))
        return result, recs, ex
    rig = machine.model
    preps = [prepare_machine(r, machine, cutoff)[0] for r in recs]
    if method == "fit":
        result = identify(preps, rig.cylinder, P_atm=rig.P_atm, with_A_max=with_A_max,
                          valve=rig.valve, gas=rig.gas)
    else:
        result = identify_paper(preps, rig.cylinder, P_atm=rig.P_atm, eq13=eq13)
    result.details["recordings"] = [str(r.path) for r in recs]
    result.details["cutoff_Hz"] = cutoff
    return result, recs, preps


def _fit_per_joint(method: str, with_A_max: bool) -> None:
    """Refuse the boom's own options for the linkage, which the fit per joint identifies."""
    if method != "fit" or with_A_max:
        raise ValueError("the whole excavator's recordings are identified by the fit per joint (K_v, F_s, F_d of "
                         "each cylinder and the payload): --method paper and --a-max are the boom's")


class TimeScaleError(ValueError):
    """Recordings whose chambers fill and empty far slower or faster than the rig's
    valve allows (:func:`_check_time_scale`): a time or pressure scale taken to be
    wrong."""


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
    raise TimeScaleError(f"identification from {names}: the chambers fill and empty "
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


__all__ = ["identify_recordings", "identify_recs", "write_outputs", "summary_lines", "cannot_tell", "plot_fit",
           "read_params", "write_run", "FitResult", "TimeScaleError"]
