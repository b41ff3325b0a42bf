"""``boomfmi diagnose`` on the whole excavator's recordings: ``diagnosis.json`` and a report.

Follows ``shared/spec/diagnosis-report.md`` as far as it applies to the per-joint
diagnosis of :mod:`boomfmi.diagnose.excavator` (read its docstring):

- each HOLD recording is cut per joint: the joint's valve and chambers driven by its
  recorded command and its *measured* motion; the joint's gap (the NRMSE of its two
  pressures, summed) against its noise floor says whether that joint is flagged, and on
  a flagged joint every candidate effect of the cut (valve deadband, end cushioning,
  piston leakage) is fitted there, the best named if it removes ``MIN_SHRINK`` of the
  gap, else ``unexplained``;
- the FIT recordings identify the baseline (each cylinder's K_v, F_s, F_d and the
  payload, ``identify.excavator_outputs``), reported with its 95 % intervals and the
  whole identified machine's NRMSE per joint on the holdouts.  **The cut needs no
  identified load** (it runs on the measured motion), so the baseline does not change
  the verdict; it is required for the same command line as the boom's and tells how
  far the whole identified machine is from each holdout.

``diagnosis.json``: ``"kind": "excavator"``; ``baseline`` (``params``, ``ci95``,
``cannot_tell``, ``nrmse_holdout`` per joint and channel, averaged over the holdouts,
``warnings``); ``where``: one entry per joint and holdout, the most beyond its threshold
first: ``joint``, ``recording``, ``channel`` (the joint's pressure with the larger
error) and ``channel_gaps``, ``regime`` (``whole_recording``: the cut is not broken
down by regime), ``subsystem`` (the SSP's ``valve_<joint>, cylinder_<joint>``),
``gap``, ``noise_floor``, ``threshold``, ``flagged``, ``exercised`` (the piston moved
1 mm or its valve opened), ``windows`` (the three 50 ms spans where the cut's residual
is largest); ``effects``: every candidate fitted on a flagged joint, best first per
joint, with ``params``, ``gap_after`` and ``shrink`` (no ``score``: the cut names the
best candidate by its shrink alone); ``verdict``: ``"<effect>@<joint>"`` or
``"unexplained@<joint>"`` over all holdouts (the joint with the largest gap first),
``[]`` where no joint's gap exceeds its noise.  ``report.html`` is one self-contained
page (its figures inline), with no request to any other place.
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
from ..identify.excavator_outputs import (bound_machine, cannot_tell, excavator_nrmse, identify_recs, machine_for,
                                          measured_pistons, simulate_machine, ssv_values)
from ..physics import reference_rig
from ..physics.excavator import JOINTS
from ..outputs import OutputSet
from ..recording import check_distinct, check_no_duplicates, check_same_rig, read_checked
from .attribute import ABS_FLOOR, MIN_SHRINK, NOISE_FACTOR
from .excavator import _span, diagnose_excavator, joint_cut, joint_pressures
from .localise import _windows
from .report import OUTPUTS

MIN_TRAVEL = 1e-3     #: [m] a piston that moves this much was exercised (the boom's diagnose.report)
NOTE = ("The per-joint cut runs each joint's valve and chambers on the holdout's recorded command and measured "
        "motion: it needs no identified load, so the baseline identified on the fit recordings does not change "
        "the verdict; it is reported with the whole identified machine's error on each holdout.")


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

    say(f"identifying the baseline per joint on {len(fit_recs)} fit recording(s) (reported; the per-joint cut "
        f"does not use it)")
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

    where, effects, figures, verdicts = [], [], [], {}
    for h in hold_recs:
        say(f"localising and attributing per joint on {h.path} (this is the long part)")
        hx = machine_for(h, ex)
        found = diagnose_excavator(h.data, hx)
        verdicts[str(h.path)] = found.verdict
        travel = np.ptp(measured_pistons(h, hx), axis=0)
        curves = {}
        for i, j in enumerate(JOINTS):
            f = found.joints[j]
            cut = joint_cut(h.data, j, hx)
            pa, pb = joint_pressures(cut, j, hx)
            best = f.candidates[0] if f.verdict and f.verdict != "unexplained" else None
            after = joint_pressures(cut, j, hx, {best[0]: _settings(best[0], best[1])}) if best else None
            curves[j] = (cut, pa, pb, after, best)
            # as the cut's gap compares them (each pressure as its sensor reads it)
            ea, eb = ((as_sensed(m, s) - m) / _span(m) for m, s in ((cut.p_a_raw, pa), (cut.p_b_raw, pb)))
            gaps = {f"p_a_{j}": float(np.sqrt(np.mean(ea ** 2))), f"p_b_{j}": float(np.sqrt(np.mean(eb ** 2)))}
            u = h.data[f"u_{j}"].to_numpy(float)
            opened = bool(np.any(np.abs(u - reference_rig.u_centre) > 0.5))
            where.append({"joint": j, "recording": str(h.path), "channel": max(gaps, key=gaps.get),
                          "channel_gaps": gaps, "regime": "whole_recording",
                          "subsystem": f"valve_{j}, cylinder_{j}", "gap": f.gap, "noise_floor": f.noise,
                          "threshold": NOISE_FACTOR * f.noise + ABS_FLOOR, "flagged": f.flagged,
                          "exercised": bool(travel[i] >= MIN_TRAVEL or opened), "travel_mm": float(1e3 * travel[i]),
                          "finding": f.verdict,
                          "windows": _windows(cut.t, ea ** 2 + eb ** 2, np.ones(len(cut.t), bool))})
            for name, params, gap_after, shrink in f.candidates:
                effects.append({"name": name, "joint": j, "recording": str(h.path), "params": params,
                                "gap_before": f.gap, "gap_after": gap_after, "shrink": shrink})
        figures.append((str(h.path), _figure(h, curves)))
    where.sort(key=lambda w: -(w["gap"] - w["threshold"]))
    verdict = _combined(verdicts, where)
    warnings = []
    if len({tuple(sorted(v)) for v in verdicts.values()}) > 1:
        warnings.append("the holdouts disagree: " + "; ".join(f"{p}: {v}" for p, v in verdicts.items())
                        + "; the verdict lists every finding of any of them")
    doc = {"kind": "excavator",
           "judgeable": True,
           "method": "per-joint pneumatic cut (boomfmi.diagnose.excavator)",
           "note": NOTE,
           "fit_recordings": [str(r.path) for r in fit_recs],
           "holdout_recordings": [str(h.path) for h in hold_recs],
           "baseline": baseline,
           "noise_factor": NOISE_FACTOR, "abs_floor": ABS_FLOOR, "min_shrink": MIN_SHRINK,
           "where": where,
           "effects": effects,
           "verdict": verdict,
           "verdict_by_recording": verdicts,
           "warnings": warnings}
    doc = plain(doc)
    with OutputSet(Path(out_dir), stale=OUTPUTS) as files:
        files.path("report.html").write_text(_html(doc, figures))
        files.path("diagnosis.json").write_text(dumps(doc, indent=2))
    return doc


def _settings(name: str, fitted: dict) -> dict:
    """A candidate's full settings as ``diagnose.excavator`` fitted it: the fitted
    parameter, the others at the catalogue's start."""
    from ..model import EFFECTS
    return {**{p.name: p.start for p in EFFECTS[name].parameters if not p.switch}, **fitted}


def _combined(verdicts: dict, where: list) -> list:
    """Every holdout's findings once, the joint with the largest gap first."""
    gap = {}
    for w in where:
        gap[w["joint"]] = max(gap.get(w["joint"], 0.0), w["gap"])
    seen = []
    for v in verdicts.values():
        seen.extend(x for x in v if x not in seen)
    return sorted(seen, key=lambda x: -gap.get(x.rpartition("@")[2], 0.0))


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
                ax.plot(cut.t, (after[k] - P_atm) / 1e5, lw=1.0, label=f"with {best[0]}")
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
        f"<tr><td>{e(c['joint'])}</td><td>{e(Path(c['recording']).name)}</td><td>{e(c['name'])}</td>"
        f"<td>{e(json.dumps(c['params']))}</td><td>{_pct(c['gap_before'])}</td><td>{_pct(c['gap_after'])}</td>"
        f"<td>{c['shrink']:.3f}</td></tr>" for c in doc["effects"]) or \
        '<tr><td colspan="7">none: no joint was flagged</td></tr>'
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
pressure gap that remains is that joint's own. The gap is the NRMSE of its two pressures, summed; a joint is flagged
beyond {doc['noise_factor']:g} times its noise floor plus {100 * doc['abs_floor']:g} %. On a flagged joint each candidate
of the cut is fitted and the best is named if it removes at least {100 * doc['min_shrink']:.0f} % of the gap, else
"unexplained" (an effect outside the cut, such as friction, which acts through the linkage).</p>
<table><tr><th>joint</th><th>holdout</th><th>gap</th><th>noise floor</th><th>threshold</th><th>flagged</th>
<th>finding</th><th>larger error</th><th>exercised (travel)</th><th>largest residual [s]</th></tr>{where}</table>
<h2>Candidate effects on the flagged joints</h2>
<table><tr><th>joint</th><th>holdout</th><th>effect</th><th>fitted parameters</th><th>gap before</th>
<th>gap after</th><th>shrink</th></tr>{effects}</table>
<h2>Baseline</h2><p>{e(doc['note'])}</p>
<table><tr><th>parameter</th><th>value</th><th>95 % interval</th><th>cannot tell</th></tr>{''.join(rows)}</table>
<p>The identified machine (monolithic reference, from each holdout's first state) against the holdouts, NRMSE:</p>
<table><tr><th>joint</th><th>x</th><th>p_a</th><th>p_b</th></tr>{nrmse}</table>
{warnings}
<h2>Pressures, recorded and from each joint's cut</h2>{imgs}
</body></html>"""


def summary_lines(doc: dict) -> list[str]:
    """The human summary ``boomfmi diagnose`` prints for the excavator: the baseline's
    holdout error, each joint's gap against its noise, the findings and the verdict."""
    lines = []
    b = doc["baseline"]
    lines.extend(f"warning (baseline): {w}" for w in b["warnings"])
    lines.append("baseline (identified on the fit recordings; the per-joint cut does not use it): holdout NRMSE "
                 "x / p_a / p_b: " + "; ".join(f"{j} {100 * r['x']:.2f} / {100 * r['p_a']:.2f} / {100 * r['p_b']:.2f} %"
                                              for j, r in b["nrmse_holdout"].items()))
    effects = {(c["recording"], c["joint"]): c for c in reversed(doc["effects"])}   # the best of each joint
    for rec in doc["holdout_recordings"]:
        lines.append(f"holdout {rec}: each joint's gap (NRMSE of p_a + p_b) against its threshold:")
        for j in JOINTS:
            w = next(w for w in doc["where"] if w["joint"] == j and w["recording"] == rec)
            text = (f"  {j:7s}gap {_pct(w['gap']):>8s} (noise floor {_pct(w['noise_floor'])}, threshold "
                    f"{_pct(w['threshold'])})")
            if w["flagged"]:
                c = effects.get((rec, j))
                text += f"  FLAGGED: {w['finding']}"
                if c:
                    text += (f" (best candidate {c['name']}: shrink {c['shrink']:.2f}, "
                             + ", ".join(f"{k} = {v:.3g}" for k, v in c["params"].items()) + ")")
            lines.append(text)
    lines.extend(f"warning: {w}" for w in doc["warnings"])
    lines.append(f"verdict: {doc['verdict']}")
    return lines


__all__ = ["diagnose_excavator_recordings", "summary_lines", "OUTPUTS"]
