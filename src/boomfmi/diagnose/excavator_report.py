"""``boomfmi diagnose`` on the whole excavator's recordings: ``diagnosis.json`` and a report.

Follows ``shared/spec/diagnosis-report.md`` as far as it applies to the per-joint
diagnosis of :mod:`boomfmi.diagnose.excavator` (read its docstring):

- each joint of each recording is cut off the linkage: its valve and chambers driven by
  its recorded command and its *measured* motion (the pneumatic cut), and, where
  ``diagnose/joint_load.py`` is installed, its load driven by its measured pressures and
  the other joints' measured motion (the load cut).  On the HOLD recordings a cut's gap
  against that recording's noise floor says whether the joint is flagged; on a flagged
  joint every candidate of the catalogue acting in that cut is fitted on the FIT
  recordings' cuts and scored on the holdouts' (``shrink`` = 1 - gap after / gap
  before, the holdouts' mean), pairs where the best single leaves a gap;
- the FIT recordings also identify the whole machine's baseline (each cylinder's K_v,
  F_s, F_d and the payload, ``identify.outputs``), reported with its 95 %
  intervals and its NRMSE per joint on the holdouts.  The cuts do not use it
  (``used_by_verdict``: false): the pneumatic cut runs on the measured motion, the load
  cut re-identifies its joint's load itself.

``diagnosis.json``: ``"kind": "excavator"``; ``baseline`` (``params``, ``ci95``,
``cannot_tell``, ``nrmse_holdout`` per joint and channel, averaged over the holdouts,
``warnings``); ``where``: one entry per joint and holdout, the most beyond its threshold
first: ``joint``, ``recording``, ``channel`` (the joint's pressure with the larger
error) and ``channel_gaps``, ``regime`` (``whole_recording``: the cut is not broken
down by regime), ``subsystem`` (the SSP's ``valve_<joint>, cylinder_<joint>``),
``gap``, ``noise_floor``, ``threshold``, ``flagged``, ``exercised`` (the piston moved
1 mm or its valve opened), ``windows`` (the three 50 ms spans where the cut's residual
is largest), ``position`` (the load cut's gap, where it runs); ``effects``: every
candidate fitted on a flagged joint, best first per joint and cut: ``name`` (``a+b``
for a pair), ``joint``, ``cut``, ``params`` and ``law`` (the parameters fitted),
``fit_gap`` (and ``fit_gap_before``), ``gap_before`` and ``gap_after`` on the holdouts
(and per holdout), ``shrink`` (the holdouts'), ``named``, ``not_fitted`` (why, where a
candidate could not be fitted); ``verdict``: ``"<effect>@<joint>"`` or
``"unexplained@<joint>"``, the joint furthest beyond its threshold first, ``[]`` where
no joint's cut exceeds its noise; ``confirmation`` where ``confirm.confirm_machine``
is installed: the named effects through ``excavator.ssp``.  ``report.html`` is one
self-contained page (its figures inline), with no request to any other place.
"""
from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path

import numpy as np

from .._json import dumps, plain
from ..compare import as_sensed
from ..identify import identify_recs
from ..identify.outputs import (bound_machine, cannot_tell, joint_nrmse as excavator_nrmse, measured_pistons,
                                simulate_machine, ssv_values)
from ..identify.preprocess import machine_for
from ..physics import reference_rig
from ..physics.linkage import JOINTS
from ..outputs import OutputSet
from ..recording import check_distinct, check_no_duplicates, check_same_rig, read_checked
from .attribute import ABS_FLOOR, MIN_SHRINK, NOISE_FACTOR
from .excavator import _span, diagnose_excavator, joint_cut, joint_pressures
from .localise import _windows
from .report import OUTPUTS

MIN_TRAVEL = 1e-3     #: [m] a piston that moves this much was exercised (the boom's diagnose.report)
NOTE = ("Each joint is cut off the linkage: its valve and chambers run on the recorded command and measured motion "
        "(the pneumatic cut), and where the load cut is installed its load runs on the measured pressures and the "
        "other joints' measured motion, re-identified on the fit recordings. The candidates are fitted on the fit "
        "recordings' cuts and scored on the holdouts'. The whole machine's baseline identified on the fit "
        "recordings is reported with its error on each holdout; the cuts do not use it.")


def diagnose_excavator_recordings(fit_paths, hold_paths, out_dir, progress=None) -> dict:
    """Run the per-joint diagnosis on excavator recordings and write ``out_dir``'s
    ``diagnosis.json`` and ``report.html`` (as one set); return the JSON document.
    ``progress(text)``: told of each stage as it starts."""
    say = progress or (lambda text: None)
    if not hold_paths:
        raise ValueError("diagnose needs at least one holdout recording (--holdout): the joints are judged there")
    fit_recs = read_checked(fit_paths, "excavator", "fit recording")
    hold_recs = read_checked(hold_paths, "excavator", "holdout")
    check_no_duplicates(fit_recs)
    check_no_duplicates(hold_recs, "holdout")
    for h in hold_recs:
        check_distinct(fit_recs, h)
    check_same_rig([*fit_recs, *hold_recs])

    say(f"identifying the baseline per joint on {len(fit_recs)} fit recording(s) (reported; the per-joint cuts "
        f"do not use it)")
    result, _, ex = identify_recs(fit_recs)
    for w in result.warnings:
        say(f"warning (baseline): {w}")
    bound, notes = ssv_values(result, ex)
    machine, payload = bound_machine(bound, ex)
    per_hold = {}
    for h in hold_recs:
        say(f"simulating the identified machine on {h.path}")
        per_hold[str(h.path)] = excavator_nrmse(simulate_machine(h, machine, payload), h, machine)
    why = cannot_tell(result)
    baseline = {"params": {k: e.value for k, e in result.params.items()},
                "ci95": {k: [float(z) if np.isfinite(z) else None for z in e.ci95] for k, e in result.params.items()},
                "units": {k: e.unit for k, e in result.params.items()},
                "cannot_tell": {k: v for k, v in why.items() if v},
                "nrmse_holdout": {j: {c: float(np.mean([per_hold[p][j][c] for p in per_hold]))
                                      for c in ("x", "p_a", "p_b")} for j in JOINTS},
                "nrmse_holdout_by_recording": per_hold,
                "warnings": [*result.warnings, *notes],
                "used_by_verdict": False}

    hx = machine_for(hold_recs[0], ex)
    say(f"cutting each joint off the linkage, fitting the candidates on the {len(fit_recs)} fit recording(s) and "
        f"scoring them on the {len(hold_recs)} holdout(s) (this is the long part)")
    found = diagnose_excavator(fit_recs, hold_recs, hx, progress=say)
    where, effects, figures = [], [], []
    named = {j: _named(f) for j, f in found.joints.items()}
    for k, h in enumerate(hold_recs):
        travel = np.ptp(measured_pistons(h, hx), axis=0)
        curves = {}
        for i, j in enumerate(JOINTS):
            f = found.joints[j]
            cut = joint_cut(h, j, hx)
            pa, pb = joint_pressures(cut, j, hx)
            best = named[j]
            after = joint_pressures(cut, j, hx, best.params) if best else None
            curves[j] = (cut, pa, pb, after, best)
            # as the cut's gap compares them (each pressure as its sensor reads it)
            ea, eb = ((as_sensed(m, s) - m) / _span(m) for m, s in ((cut.p_a_raw, pa), (cut.p_b_raw, pb)))
            gaps = {f"p_a_{j}": float(np.sqrt(np.mean(ea ** 2))), f"p_b_{j}": float(np.sqrt(np.mean(eb ** 2)))}
            u = h.data[f"u_{j}"].to_numpy(float)
            opened = bool(np.any(np.abs(u - reference_rig.u_centre) > 0.5))
            pc = f.pressures
            entry = {"joint": j, "recording": str(h.path), "channel": max(gaps, key=gaps.get),
                     "channel_gaps": gaps, "regime": "whole_recording",
                     "subsystem": f"valve_{j}, cylinder_{j}", "gap": pc.gaps[k], "noise_floor": pc.noises[k],
                     "threshold": pc.thresholds[k], "flagged": pc.gaps[k] > pc.thresholds[k],
                     "exercised": bool(travel[i] >= MIN_TRAVEL or opened), "travel_mm": float(1e3 * travel[i]),
                     "finding": ", ".join(f.verdict) or None,
                     "windows": _windows(cut.t, ea ** 2 + eb ** 2, np.ones(len(cut.t), bool))}
            lc = f.position
            if lc is not None:
                entry["position"] = {"gap": lc.gaps[k], "noise_floor": lc.noises[k], "threshold": lc.thresholds[k],
                                     "flagged": lc.gaps[k] > lc.thresholds[k], "subsystem": f"linkage ({j})",
                                     "finding": ", ".join(lc.verdict) or None,
                                     "gap_own_load": lc.own_gaps[k] if lc.own_gaps else None,
                                     "spread_of_the_load": lc.spreads[k] if lc.spreads else None,
                                     "model_error": lc.model_error}
            where.append(entry)
        figures.append((str(h.path), _figure(h, curves)))
    for j, f in found.joints.items():
        for cut in f.cuts:
            for c in cut.candidates:
                named = any(cut is n for n in f.named_cuts) and c is cut.candidates[0]
                effects.append(_effect_entry(j, cut, c, named))
    where.sort(key=lambda w: -(w["gap"] - w["threshold"]) / w["threshold"])
    verdict = found.verdict
    doc = {"kind": "excavator",
           "judgeable": True,
           "method": "per-joint cuts, fitted on the fit recordings and scored on the holdouts "
                     "(boomfmi.diagnose.excavator)",
           "note": NOTE,
           "fit_recordings": [str(r.path) for r in fit_recs],
           "holdout_recordings": [str(h.path) for h in hold_recs],
           "baseline": baseline,
           "noise_factor": NOISE_FACTOR, "abs_floor": ABS_FLOOR, "min_shrink": MIN_SHRINK,
           "where": where,
           "effects": effects,
           "verdict": verdict,
           "warnings": list(found.notes)}
    confirmation = _confirm(found, bound, hold_recs, say)
    if confirmation is not None:
        doc["confirmation"] = confirmation
    doc = plain(doc)
    with OutputSet(Path(out_dir), stale=OUTPUTS) as files:
        files.path("report.html").write_text(_html(doc, figures))
        files.path("diagnosis.json").write_text(dumps(doc, indent=2))
    return doc


def _named(f):
    """The pneumatic cut's named candidate of a joint (single or pair), or None."""
    c = f.pressures
    if c.verdict and c.verdict != ["unexplained"] and c.candidates:
        return c.candidates[0]
    return None


def _effect_entry(joint: str, cut, c, named: bool) -> dict:
    """One fitted candidate as ``diagnosis.json`` lists it."""
    entry = {"name": c.name, "joint": joint, "cut": cut.kind,
             "params": c.params.get(c.name, {}) if "+" not in c.name else c.params,
             "law": {n: sorted(q) for n, q in c.params.items()},
             "fit_gap": c.fit_gap, "fit_gap_before": cut.fit_gap,
             "gap_before": cut.gap, "gap_after": float(np.mean(c.hold_gaps)) if c.hold_gaps else None,
             "holdout_gaps_before": list(cut.gaps), "holdout_gaps_after": list(c.hold_gaps),
             "shrink": c.shrink if c.not_fitted is None else None, "named": named}
    if c.values is not None:
        entry["values"] = c.values
    if c.not_fitted is not None:
        entry["not_fitted"] = c.not_fitted
    return entry


def _confirm(found, values: dict, hold_recs, say):
    """The named effects through ``excavator.ssp`` (``confirm.confirm_machine``) on the
    first holdout: the baseline's ``values`` (the SSV's), and with each joint's named
    effects, a friction effect's joint with the load it was re-identified with.  None
    where no effect is named; where the SSP cannot run them, the reason."""
    from ..physics import ParameterError
    from .confirm import confirm_machine
    effects_by_joint, effect_values = {}, dict(values)
    for j, f in found.joints.items():
        for cut in f.named_cuts:
            if cut.candidates:
                best = cut.candidates[0]
                effects_by_joint.setdefault(j, {}).update(best.params)
                if best.values:
                    effect_values.update({f"{k}_{j}": float(v) for k, v in best.values.items()
                                          if k in ("K_v", "F_s", "F_d")})
    if not effects_by_joint:
        return None
    say(f"confirming the named effects through excavator.ssp on {hold_recs[0].path}")
    try:
        return confirm_machine(values, effects_by_joint, hold_recs[0], effect_values=effect_values)
    except (ParameterError, ValueError, RuntimeError, OSError) as e:
        return {"effects": effects_by_joint, "skipped": f"the SSP could not run the named effects: {e}"}


def _figure(h, curves) -> str:
    """Each joint's recorded pressures, the cut's and (on a named finding) the cut's with
    that effect, as a PNG in base64."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(JOINTS), 2, sharex=True, figsize=(10, 9))
    for i, j in enumerate(JOINTS):
        cut, pa, pb, after, best = curves[j]
        P_atm = h.P_atm
        for k, (q, m, s) in enumerate((("p_a", cut.p_a_raw, pa), ("p_b", cut.p_b_raw, pb))):
            ax = axes[i, k]
            ax.plot(cut.t, (m - P_atm) / 1e5, lw=0.8, color="k", label="holdout recording")
            ax.plot(cut.t, (s - P_atm) / 1e5, lw=1.0, label="cut, no effect")
            if after is not None:
                ax.plot(cut.t, (after[k] - P_atm) / 1e5, lw=1.0, label=f"with {best.name}")
            ax.set_ylabel(f"{j}\n{q} [bar gauge]" if k == 0 else f"{q} [bar gauge]")
            if i == 0 or after is not None:
                ax.legend(loc="best", fontsize=7)
    for k in range(2):
        axes[-1, k].set_xlabel("t [s]")
    fig.suptitle(f"{Path(h.path).name}: each joint's pressures, recorded and from its cut")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, dpi=90, format="png")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _pct(v) -> str:
    return f"{100 * v:.2f} %"


def _html(doc: dict, figures) -> str:
    e = html.escape
    verdict = doc["verdict"]
    if not verdict:
        headline = "No joint's gap exceeds its noise: the model's pneumatics explain every joint."
    else:
        headline = "Findings: " + ", ".join(f"<b>{e(v)}</b>" for v in verdict)
    where = "".join(
        f"<tr><td>{e(w['joint'])}</td><td>{e(Path(w['recording']).name)}</td><td>{_pct(w['gap'])}</td>"
        f"<td>{_pct(w['noise_floor'])}</td><td>{_pct(w['threshold'])}</td>"
        f"<td>{'yes' if w['flagged'] else 'no'}</td><td>{e(w['finding'] or '')}</td>"
        f"<td>{e(w['channel'])}</td><td>{'yes' if w['exercised'] else 'no'} ({w['travel_mm']:.1f} mm)</td>"
        f"<td>{e(str(w['windows']))}</td></tr>" for w in doc["where"])
    effects = "".join(
        f"<tr><td>{e(c['joint'])}</td><td>{e(c['cut'])}</td><td>{e(c['name'])}{' (named)' if c['named'] else ''}</td>"
        + (f"<td colspan=\"5\">not fitted: {e(c['not_fitted'])}</td></tr>" if c.get("not_fitted") else
           f"<td>{e(json.dumps(c['params']))}</td><td>{_pct(c['fit_gap_before'])} &rarr; {_pct(c['fit_gap'])}</td>"
           f"<td>{_pct(c['gap_before'])}</td><td>{_pct(c['gap_after'])}</td><td>{c['shrink']:.3f}</td></tr>")
        for c in doc["effects"]) or \
        '<tr><td colspan="8">none: no joint was flagged</td></tr>'
    b = doc["baseline"]
    rows = []
    for k, v in b["params"].items():
        lo, hi = b["ci95"][k]
        interval = f"[{lo:.4g}, {hi:.4g}]" if lo is not None and hi is not None else "no interval"
        rows.append(f"<tr><td>{e(k)}</td><td>{v:.4g} {e(b['units'][k])}</td><td>{interval}</td>"
                    f"<td>{e(b['cannot_tell'].get(k, ''))}</td></tr>")
    nrmse = "".join(f"<tr><td>{e(j)}</td>" + "".join(f"<td>{_pct(r[c])}</td>" for c in ("x", "p_a", "p_b"))
                    + "</tr>" for j, r in b["nrmse_holdout"].items())
    warnings = "".join(f"<li>{e(w)}</li>" for w in [*doc["warnings"], *b["warnings"]])
    warnings = f"<h2>Warnings</h2><ul>{warnings}</ul>" if warnings else ""
    imgs = "".join(f'<h3>{e(Path(p).name)}</h3><p><img src="data:image/png;base64,{png}" '
                   f'alt="pressures of {e(Path(p).name)}" style="max-width:100%"></p>' for p, png in figures)
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>boomfmi diagnosis: the whole excavator</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:4px 8px;font-size:13px}}</style></head><body>
<h1>Diagnosis per joint of the whole excavator</h1>
<p style="font-size:1.3em">{headline}</p>
<p>Fit recordings: {e(', '.join(doc['fit_recordings']))}. Holdout recordings: {e(', '.join(doc['holdout_recordings']))}.</p>
<h2>Where: each joint's gap</h2>
<p>Each joint's valve and chambers run on its recorded command and its measured motion (the linkage cut off), so a
pressure gap that remains is that joint's own (and, where the load cut is installed, its load on the measured pressures
and the other joints' measured motion: a position gap). The gap is the NRMSE of its two pressures, summed; a joint is
flagged beyond {doc['noise_factor']:g} times its noise floor plus {100 * doc['abs_floor']:g} %. On a flagged joint each
candidate of the cut is fitted on the fit recordings and scored on the holdouts; the best is named if it removes at
least {100 * doc['min_shrink']:.0f} % of the holdouts' gap (or a pair, each paying for itself), else "unexplained".</p>
<table><tr><th>joint</th><th>holdout</th><th>gap</th><th>noise floor</th><th>threshold</th><th>flagged</th>
<th>finding</th><th>larger error</th><th>exercised (travel)</th><th>largest residual [s]</th></tr>{where}</table>
<h2>Candidate effects on the flagged joints</h2>
<p>Fitted on the fit recordings' cuts (their gap before &rarr; after), scored on the holdouts' (never fitted on).</p>
<table><tr><th>joint</th><th>cut</th><th>effect</th><th>fitted parameters</th><th>fit gap</th><th>holdout gap before</th>
<th>holdout gap after</th><th>holdout shrink</th></tr>{effects}</table>
<h2>Baseline</h2><p>{e(doc['note'])}</p>
<table><tr><th>parameter</th><th>value</th><th>95 % interval</th><th>cannot tell</th></tr>{''.join(rows)}</table>
<p>The identified machine (monolithic reference, from each holdout's first state) against the holdouts, NRMSE:</p>
<table><tr><th>joint</th><th>x</th><th>p_a</th><th>p_b</th></tr>{nrmse}</table>
{_confirmation_html(doc.get("confirmation"))}
{warnings}
<h2>Pressures, recorded and from each joint's cut</h2>{imgs}
</body></html>"""


def _confirmation_html(c) -> str:
    """The confirmation through ``excavator.ssp`` as a section (empty without one)."""
    if not c:
        return ""
    e = html.escape
    if "skipped" in c:
        return f"<h2>Confirmation through the FMUs</h2><p>Skipped: {e(c['skipped'])}</p>"
    rows = "".join(f"<tr><td>{e(j)}</td><td>{v:.3f}</td></tr>" for j, v in c.get("shrink_by_joint", {}).items())
    return (f"<h2>Confirmation through the FMUs</h2><p>{e(Path(c['ssp']).name)} on {e(Path(c['recording']).name)} "
            f"with the named effects: holdout shrink {c['shrink']:.3f} over the joints with effects.</p>"
            f"<table><tr><th>joint</th><th>shrink</th></tr>{rows}</table>")


def summary_lines(doc: dict) -> list[str]:
    """The human summary ``boomfmi diagnose`` prints for the excavator: the baseline's
    holdout error, each joint's gap against its noise, the findings and the verdict."""
    lines = []
    b = doc["baseline"]
    lines.extend(f"warning (baseline): {w}" for w in b["warnings"])
    lines.append("baseline (identified on the fit recordings; the per-joint cuts do not use it): holdout NRMSE "
                 "x / p_a / p_b: " + "; ".join(f"{j} {100 * r['x']:.2f} / {100 * r['p_a']:.2f} / {100 * r['p_b']:.2f} %"
                                              for j, r in b["nrmse_holdout"].items()))
    effects = {}
    for c in doc["effects"]:           # the named (else the best) candidate of each joint
        if c.get("not_fitted") is None and (c["named"] or c["joint"] not in effects):
            if c["named"] or c["cut"] == "pressures":
                effects[c["joint"]] = c
    for rec in doc["holdout_recordings"]:
        lines.append(f"holdout {rec}: each joint's gap (NRMSE of p_a + p_b) against its threshold:")
        for j in JOINTS:
            w = next(w for w in doc["where"] if w["joint"] == j and w["recording"] == rec)
            text = (f"  {j:7s}gap {_pct(w['gap']):>8s} (noise floor {_pct(w['noise_floor'])}, threshold "
                    f"{_pct(w['threshold'])})")
            pos = w.get("position")
            if pos:
                text += f"; position {_pct(pos['gap'])} (threshold {_pct(pos['threshold'])})"
            if w["flagged"] or (pos and pos["flagged"]):
                c = effects.get(j)
                text += f"  FLAGGED: {w['finding']}"
                if c:
                    flat = {k: v for k, v in c["params"].items() if not isinstance(v, dict)} or \
                        {f"{n}.{k}": v for n, q in c["params"].items() for k, v in q.items()}
                    text += (f" (best candidate {c['name']}: holdout shrink {c['shrink']:.2f}, "
                             + ", ".join(f"{k} = {v:.3g}" for k, v in flat.items()) + ")")
            lines.append(text)
    lines.extend(f"warning: {w}" for w in doc["warnings"])
    c = doc.get("confirmation")
    if c:
        lines.append(f"confirmation through {c.get('ssp', 'excavator.ssp')}: "
                     + (f"skipped: {c['skipped']}" if "skipped" in c else f"holdout shrink {c['shrink']:.2f}"))
    lines.append(f"verdict: {doc['verdict']}")
    return lines


__all__ = ["diagnose_excavator_recordings", "summary_lines", "OUTPUTS"]
