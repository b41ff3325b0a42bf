"""``boomfmi diagnose``: the gap's place and cause, as ``diagnosis.json`` and a report.

Follows ``shared/spec/diagnosis-report.md``: FIT recordings identify the baseline and
fit each candidate effect; HOLD recordings are never fitted on and every figure of
shrink is measured on them.  Writes ``diagnosis.json``, ``report.html`` (readable on its
own: the verdict first, then before/after overlays per channel, the residual by regime
and subsystem, the candidate table) and the PNGs it shows.
"""
from __future__ import annotations

import base64
import html
import io
import json
import os
import time
from pathlib import Path

import numpy as np

from concurrent.futures import ProcessPoolExecutor

from .._json import dumps, plain
from ..compare import CHANNELS, as_sensed, model_for, nrmse, recorded, rig_model, shrink, simulate_recording
from ..identify import identify_recordings, identify_recs
from ..identify.outputs import bound_machine, cannot_tell, joint_nrmse, measured_pistons, simulate_machine, ssv_values
from ..identify.preprocess import machine_for, machine_of, prepare
from ..machine import assumption
from ..outputs import OutputSet
from ..physics import reference_rig
from ..physics.linkage import JOINTS
from ..recording import check_distinct, check_no_duplicates, check_same_rig, common_kind, read_checked
from .attribute import ABS_FLOOR, CANDIDATES, MIN_SHRINK, NOISE_FACTOR, attribute, may_start_processes
from .confirm import agreement, confirm
from .joints import _span, diagnose_joints, joint_cut, joint_pressures
from .localise import _windows, localise

MIN_TRAVEL = 1e-3     #: [m] a recording whose piston moves less than this cannot be judged


def diagnose(fit_paths, hold_paths, out_dir, workers: int | None = None, ssp=None, progress=None,
             baseline=None, machine=None, propose=None) -> dict:
    """Run the diagnosis and write its outputs into ``out_dir`` (as one set: all of them
    or, on an error or interrupt, none; a PNG this run does not draw is removed); return
    the JSON document.  ``workers``: processes for the candidates' fits (default: one
    per core); ``ssp``: the boom's system for the FMUs' confirmation (default
    build/excavator_boom.ssp); ``progress(text)``: told of each stage as it starts.
    ``baseline``: the baseline's identification on ``fit_paths`` where the caller wants
    it too (a campaign's case writes it as params.json): ``identify_recordings(fit_paths,
    "fit")``'s ``(FitResult, recordings)``, or a callable returning them, called only
    where the recordings can be judged (a memoised one then gives the caller the same);
    default: identified here.  ``machine``: a ``machine.MachineFile`` the recordings are of
    (default: their sidecars, else the reference rig, which is then said).

    The machine is the recordings' (their kind, as ``identify`` reads it): the boom rig
    (one joint) is judged whole, as below; a machine of several joints (the whole
    excavator's recordings) joint by joint (:func:`_diagnose_joints`,
    ``diagnose.joints``), which refuses ``ssp`` and ``propose`` (the boom's) naming them.

    Where the two most probable explanations are close (``propose.ambiguous``), the
    experiment that would tell them apart is proposed (``doc["next_experiment"]``, its
    predictions in ``next_experiment.png``, shown in the report); ``propose``: a path to
    write its command CSV to (``propose.write_command_csv``), proposed between the two
    most probable however far apart they are (``doc["next_experiment"]["needed"]`` says
    whether they were close)."""
    say = progress or (lambda text: None)
    if not hold_paths:
        raise ValueError("diagnose needs at least one holdout recording (--holdout): shrink is measured there")
    out = Path(out_dir)
    if common_kind([*fit_paths, *hold_paths]) == "excavator":      # a machine of several joints: per joint
        return _diagnose_joints(fit_paths, hold_paths, out, workers, ssp, say, baseline, machine, propose)
    fit_recs = read_checked(fit_paths, role="fit recording", machine=machine)
    hold_recs = read_checked(hold_paths, role="holdout", machine=machine)
    assumed = assumption(fit_recs + hold_recs, machine)
    if assumed:
        say(f"warning: {assumed}")
    check_same_rig(fit_recs + hold_recs)
    check_no_duplicates(fit_recs)
    check_no_duplicates(hold_recs, "holdout")
    for h in hold_recs:
        check_distinct(fit_recs, h)
    still = [str(r.path) for r in fit_recs + hold_recs if float(np.ptp(recorded(r)["x"])) < MIN_TRAVEL]
    if still:
        doc = {"judgeable": False,
               "reason": f"no motion in {', '.join(still)}: the piston moves less than "
                         f"{MIN_TRAVEL * 1e3:g} mm, so neither the load nor any effect can be judged",
               "baseline": None, "where": [], "effects": [], "verdict": []}
        _write(out, doc, None, None, None)
        return doc

    say(f"identifying the baseline on {len(fit_recs)} fit recording(s)")
    if baseline is None:
        result, _, _ = identify_recordings(fit_paths, "fit", machine=machine)
    else:
        result, _ = baseline() if callable(baseline) else baseline
    for w in result.warnings:
        say(f"warning (baseline): {w}")
    values = result.values()
    say(f"fitting and scoring {len(CANDIDATES)} candidate effects (this is the long part)")
    att = attribute(values, fit_recs, hold_recs, workers=workers,
                    intervals={k: e.ci95 for k, e in result.params.items()})
    say(f"verdict {att.verdict}; localising the gap, confirming through the FMUs, drawing the report")
    hold = hold_recs[0]
    verdict_fx, verdict_values = {}, values
    if att.verdict and att.verdict != ["unexplained"]:
        best = att.candidates[0]
        verdict_fx = best.params if "+" in best.name else {best.name: best.params}
        verdict_values = best.values or values      # a friction effect's own load
    # the FMUs confirm the result in another process while the report is drawn here (in
    # this one, after it, where it may start none: a daemon process, or a Dask worker of
    # any kind, whose cases must be rescheduled at once if it is killed)
    pool = ProcessPoolExecutor(1) if may_start_processes() else None
    confirming = pool.submit(confirm, values, verdict_fx, hold, ssp, verdict_values) if pool else None
    proposal = _next_experiment(att, values, hold_recs, workers, propose is not None, say)
    rig = rig_model(hold)            # the holdout's rig, from its sidecar, for all that follows
    prep = prepare(hold, geometry=rig.geometry, P_atm=rig.P_atm)
    base_sim = simulate_recording(values, hold, rig=rig)
    abs_sim = base_sim.copy()
    abs_sim["p_a"] += rig.P_atm
    abs_sim["p_b"] += rig.P_atm
    loc = localise(prep, abs_sim, model_for(values, {}, rig)) if att.gap else None
    effects = [{"name": c.name, "params": c.params,
                **({"baseline_params": {k: round(v, 6) for k, v in c.values.items()}} if c.values else {}),
                "nrmse_holdout_after": {k: round(v, 6) for k, v in c.holdout.items()},
                "fit_error": float(f"{c.fit_error:.6g}") if np.isfinite(c.fit_error) else None, "shrink": round(c.shrink, 4), "score": c.score,
                **({"refused_by_load_fit": True} if c.name in att.refused else {}),
                **({"holdout_told": list(c.holdout_told)} if c.holdout_told else {})}
               for c in att.candidates]
    doc = {"judgeable": True,
           "baseline": {"params": {k: round(v, 6) for k, v in values.items()},
                        "ci95": {k: [_finite(z) for z in e.ci95] for k, e in result.params.items()},
                        "units": {k: e.unit for k, e in result.params.items()},
                        "nrmse_holdout": {k: round(v, 6) for k, v in att.baseline_holdout.items()},
                        "warnings": result.warnings},
           "noise_floor": {k: round(v, 6) for k, v in att.noise.items()},
           "baseline_spread": {k: round(v, 6) for k, v in att.spread.items()},
           "gap_threshold": round(att.beyond_noise, 6),
           "gap_beyond_noise": att.gap,
           "told_by_load_fit": att.told,
           "refused_by_load_fit": att.refused,
           "unexplained_threshold": round(att.threshold, 6),
           "probabilities": {k: round(v, 4) for k, v in att.probabilities.items()},
           "effective_samples": {k: round(v, 1) for k, v in att.effective_samples.items()},
           "effective_samples_fit": round(att.fit_samples, 1),
           "fit_error_baseline": float(f"{att.fit_error:.6g}") if np.isfinite(att.fit_error) else None,
           "where": loc.where if loc else [],
           "effects": effects,
           "verdict": att.verdict}
    if proposal is not None:
        doc["next_experiment"] = {**proposal[0].summary(), "needed": proposal[1]}
    after_sim = simulate_recording(verdict_values, hold, effects=verdict_fx, rig=rig) if verdict_fx else None
    try:
        doc["confirmation"] = (confirming.result() if pool else
                               confirm(values, verdict_fx, hold, ssp, verdict_values))
    except Exception as e:            # a failing confirmation is reported, not fatal
        doc["confirmation"] = {"error": f"{type(e).__name__}: {e}"}
    finally:
        if pool:
            pool.shutdown()
    if after_sim is not None and "shrink" in doc["confirmation"]:
        doc["confirmation"] = agreement(doc["confirmation"], shrink(nrmse(base_sim, hold), nrmse(after_sim, hold)))
    if proposal is not None and propose is not None:
        doc["next_experiment"]["csv"] = str(propose)
    _write(out, doc, hold, base_sim, after_sim, loc, proposal[0] if proposal else None)
    if proposal is not None and propose is not None:
        from ..recording import recording_inputs
        from .propose import write_command_csv
        write_command_csv(proposal[0], propose, inputs=recording_inputs([*fit_paths, *hold_paths]))
    return doc


def _next_experiment(att, values: dict, hold_recs, workers, always: bool, say):
    """``(Proposal, needed)`` for the two most probable explanations where they are close
    (``needed``), or ``always``; None where there is nothing to tell apart (no catalogue
    set among the probabilities)."""
    from .attribute import set_name
    from .propose import Hypothesis, ambiguous, noise_sigma, propose
    pair = ambiguous(att.probabilities)
    needed = pair is not None
    if pair is None and always:
        pair = ambiguous(att.probabilities, factor=float("inf"))
    if pair is None:
        return None
    hyps = []
    for name in pair:
        c = next((c for c in att.candidates if set_name(c) == name), None)
        if c is None:
            hyps.append(Hypothesis(name, values))          # none: the baseline as identified
        else:
            hyps.append(Hypothesis(name, c.values or values, c.params if "+" in c.name else {c.name: c.params}))
    p = att.probabilities
    reason = (f"{pair[0]} ({p.get(pair[0], 0.0):.2g}) against {pair[1]} ({p.get(pair[1], 0.0):.2g})"
              + (f"; unexplained ({p.get('unexplained', 0.0):.2g}) has no model: its most probable named "
                 "explanation against the baseline" if "unexplained" in list(p)[:2] else ""))
    say(f"proposing the experiment that tells {pair[0]} from {pair[1]}")
    t0 = time.perf_counter()
    proposal = propose(hyps, hold_recs[0], noise_sigma(hold_recs), workers=workers or os.cpu_count() or 1,
                       reason=reason)
    proposal.seconds = time.perf_counter() - t0
    return proposal, needed


def _finite(z) -> float | None:
    return round(float(z), 6) if np.isfinite(z) else None


#: every file a diagnosis writes; those a run does not write are removed with its set
OUTPUTS = ("diagnosis.json", "report.html", *(f"overlay_{c}.png" for c in CHANNELS), "residual_breakdown.png",
           "next_experiment.png")


def _write(out: Path, doc: dict, hold, base_sim, after_sim, loc=None, proposal=None) -> None:
    with OutputSet(out, stale=OUTPUTS) as files:
        images = []
        if hold is not None:
            images = _plots(files, hold, base_sim, after_sim, loc, doc)
        embedded = {n: base64.b64encode(files.path(n).read_bytes()).decode("ascii") for n in images}
        if proposal is not None:
            from .propose import plot_proposal
            plot_proposal(proposal, files.path("next_experiment.png"))
            embedded["next_experiment.png"] = base64.b64encode(files.path("next_experiment.png").read_bytes()) \
                .decode("ascii")
        chart = _candidates_chart(doc)
        if chart:
            embedded["candidates"] = chart
        files.path("report.html").write_text(_html(doc, images, embedded))
        files.path("diagnosis.json").write_text(dumps(doc, indent=2))


def _plots(files: OutputSet, hold, base_sim, after_sim, loc, doc) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    t = hold.data["t"].to_numpy()
    m = recorded(hold)
    names = []
    scale = {"x": (1e3, "x [mm]"), "p_a": (1e-5, "p_a [bar gauge]"), "p_b": (1e-5, "p_b [bar gauge]")}
    for c in CHANNELS:
        f, label = scale[c]
        fig, ax = plt.subplots(figsize=(9, 3))
        ax.plot(t, f * m[c], lw=0.8, color="k", label="holdout recording")
        ax.plot(t, f * base_sim[c], lw=1.0, label="baseline model")
        if after_sim is not None:
            ax.plot(t, f * after_sim[c], lw=1.0, label="with " + " + ".join(doc["verdict"]))
        ax.set_xlabel("t [s]")
        ax.set_ylabel(label)
        ax.legend(loc="best", fontsize=8)
        fig.tight_layout()
        name = f"overlay_{c}.png"
        fig.savefig(files.path(name), dpi=100, format="png")
        plt.close(fig)
        names.append(name)
    if loc is not None:
        fig, axes = plt.subplots(1, 2, figsize=(9, 3))
        for ax, (title, shares) in zip(axes, (("by regime", loc.regime_share), ("by subsystem", loc.subsystem_share))):
            ax.bar(list(shares), list(shares.values()))
            ax.set_title(f"share of the residual {title}")
            ax.tick_params(axis="x", rotation=30)
        fig.tight_layout()
        fig.savefig(files.path("residual_breakdown.png"), dpi=100, format="png")
        plt.close(fig)
        names.append("residual_breakdown.png")
    return names


def action_sentence(doc: dict) -> str:
    """One sentence a technician can act on, from the diagnosis ``doc`` (plain text)."""
    from ..model import EFFECTS
    verdict = doc.get("verdict") or []
    if not doc.get("judgeable", True):
        return f"Record again with the boom moving: {doc.get('reason', 'the recordings cannot be judged')}."
    if not verdict and not doc.get("gap_beyond_noise"):
        return "Nothing to fix: the model matches the machine within the recordings' own noise."
    if not verdict:
        return ("Nothing the recordings can show: the gap lies within what the baseline's own uncertainty leaves "
                "open; record longer or livelier motion (starts, reversals, runs to the ends) to narrow it.")
    if any("@" in v for v in verdict):          # a machine of several joints: "<effect>@<joint>"
        return _joints_action(doc)
    if verdict == ["unexplained"]:
        w = (doc.get("where") or [{}])[0]
        place = (f", mostly in {w['channel']} during {w['regime'].replace('_', ' ')} ({w['subsystem']})"
                 if w else "")
        return (f"The model misses something that none of its candidate effects explains{place}: inspect that "
                "part of the machine and record it again in that regime.")
    shrink = next((c.get("shrink") for c in doc.get("effects", []) if c.get("name") == " + ".join(verdict)
                   or c.get("name") == verdict[0]), None)
    named = " and ".join(verdict)
    how = f" (it removes {100 * shrink:.0f} % of the gap on the holdout)" if shrink is not None else ""
    advice = "; ".join(EFFECTS[v].advice for v in verdict if v in EFFECTS and EFFECTS[v].advice)
    return f"Most likely cause: {named}{how}. {advice[:1].upper() + advice[1:]}." if advice else \
        f"Most likely cause: {named}{how}."


def _joints_action(doc: dict) -> str:
    """:func:`action_sentence` for the findings per joint (``<effect>@<joint>``,
    ``unexplained@<joint>``): each named effect on its joint with what it removes of that
    joint's holdout gap and the catalogue's advice; the joints no candidate explains,
    where their gap lies."""
    from ..model import EFFECTS
    named, unexplained = [], []
    for v in doc["verdict"]:
        name, joint = v.rsplit("@", 1)
        (unexplained if name == "unexplained" else named).append((name, joint))
    parts = []
    for name, joint in named:
        shrink = next((c.get("shrink") for c in doc.get("effects", []) if c.get("named") and c.get("joint") == joint
                       and name in c.get("name", "").split("+")), None)
        how = f" (it removes {100 * shrink:.0f} % of that joint's gap on the holdout)" if shrink is not None else ""
        advice = EFFECTS[name].advice if name in EFFECTS else ""
        parts.append(f"{name} on the {joint}{how}" + (f": {advice}" if advice else ""))
    text = f"Most likely cause: {'; '.join(parts)}." if parts else ""
    for joint in unexplained:
        w = next((w for w in doc.get("where", []) if w.get("joint") == joint[1]), {})
        place = f", mostly in {w['channel']} ({w['subsystem']})" if w else ""
        text += (f"{' ' if text else ''}The model misses something on the {joint[1]} that none of its candidate "
                 f"effects explains{place}: inspect that joint and record it again.")
    return text


def _number(v) -> str:
    return "&ndash;" if v is None else f"{v:.4g}"


def _unit(u: str) -> str:
    return html.escape(u).replace(".", "&middot;") if u and u != "1" else ""


def _params_text(name: str, params: dict) -> str:
    """An effect's fitted parameters with their units (the catalogue's)."""
    from ..model import EFFECTS
    units = {p.name: p.unit for e in name.split(" + ") if e in EFFECTS for p in EFFECTS[e].parameters}
    flat = {}
    for k, v in params.items():
        if isinstance(v, dict):                   # a pair: {effect: {parameter: value}}
            flat.update({f"{k}.{q}": w for q, w in v.items()})
            units.update({f"{k}.{p.name}": p.unit for p in EFFECTS[k].parameters} if k in EFFECTS else {})
        else:
            flat[k] = v
    return ", ".join(f"{html.escape(k)} = {_number(v)} {_unit(units.get(k, ''))}".rstrip() for k, v in flat.items())


def _candidates_chart(doc: dict) -> str | None:
    """A bar chart of each explanation's probability (base64 PNG: the candidate sets,
    ``none`` and ``unexplained``; ``attribute``'s evidence), the verdict's bar dark."""
    probs = doc.get("probabilities") or {}
    if not probs:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(probs)[::-1]
    values = [float(probs[n]) for n in names]
    verdict = doc.get("verdict") or []
    named = "none" if not verdict else " + ".join(verdict)
    colours = ["#1f4e79" if n == named else "#9dbbd6" for n in names]
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(names) + 1.0))
    ax.barh(names, values, color=colours)
    ax.set_xlim(0.0, 1.0)
    ax.set_xlabel("probability of the explanation, given the fit and holdout recordings")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, dpi=90, format="png")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _img(name: str, embedded: dict | None) -> str:
    e = html.escape
    src = f"data:image/png;base64,{embedded[name]}" if embedded and name in embedded else e(name)
    return f'<p><img src="{src}" alt="{e(name)}" title="{e(name)}" style="max-width:100%"></p>'


def _params_table(base: dict) -> str:
    """The baseline's parameters: value, 95 % interval, unit (and, where the
    identification says so, why it cannot tell one)."""
    e = html.escape
    ci, units = base.get("ci95") or {}, base.get("units") or {}
    why = base.get("cannot_tell")
    params = "".join(
        f"<tr><td>{e(k)}</td><td>{_number(v)}</td>"
        f"<td>{(_number(ci[k][0]) + ' to ' + _number(ci[k][1])) if k in ci else '&ndash;'}</td>"
        f"<td>{_unit(units.get(k, ''))}</td>" + (f"<td>{e(why.get(k, ''))}</td>" if why is not None else "")
        + "</tr>" for k, v in (base.get("params") or {}).items())
    return ("<table><tr><th>parameter</th><th>value</th><th>95 % interval</th><th>unit</th>"
            + ("<th>cannot tell</th>" if why is not None else "") + f"</tr>{params}</table>") if params else ""


#: the report page's style (the boom's and a machine's of several joints alike)
_STYLE = """<style>body{font-family:sans-serif;max-width:980px;margin:2em auto}table{border-collapse:collapse}
td,th{border:1px solid #ccc;padding:4px 8px;font-size:13px}.act{font-size:1.3em;background:#eef4fa;padding:.6em}</style>"""


def _html(doc: dict, images: list[str], embedded: dict | None = None) -> str:
    """The report: one sentence to act on, the verdict, the parameters with units and
    intervals, the candidates as a bar chart, the overlays, where the gap lies.  With
    ``embedded`` (name -> base64 PNG) the page holds its figures and can be mailed alone."""
    e = html.escape
    verdict = doc["verdict"]
    if not doc.get("judgeable", True):
        headline = f"Cannot be judged: {e(doc['reason'])}"
    elif verdict == [] and not doc.get("gap_beyond_noise"):
        headline = ("No gap beyond the recordings' noise: the baseline model explains them (holdout error "
                    f"{100 * sum((doc['baseline'] or {}).get('nrmse_holdout', {}).values()):.2f} % "
                    f"against a threshold of {100 * doc.get('gap_threshold', 0.0):.2f} %, summed over p_a, p_b, x); "
                    "no candidate effect was fitted.")
    elif verdict == []:
        headline = ("A gap beyond the recordings' noise but within what the baseline's own uncertainty leaves "
                    f"open (holdout error {100 * sum((doc['baseline'] or {}).get('nrmse_holdout', {}).values()):.2f} % "
                    f"against {100 * doc.get('unexplained_threshold', 0.0):.2f} %, summed over p_a, p_b, x), "
                    "and no candidate effect explains it: no finding.")
    elif verdict == ["unexplained"]:
        headline = "A gap that no candidate effect explains (see where it lies below)."
    elif doc.get("told_by_load_fit"):
        headline = ("<b>" + ", ".join(e(v) for v in verdict) + "</b>, told by the load's own fit: the friction "
                    "moves with the chambers' pressure sample by sample (the velocity fit misses the recorded "
                    "velocities less with it), while the outputs' gap "
                    f"({100 * sum((doc['baseline'] or {}).get('nrmse_holdout', {}).values()):.2f} %) stays within "
                    "what the noise or the baseline's uncertainty allows: the baseline's F_d holds the seals' "
                    "friction at the recordings' mean pressure.")
    else:
        headline = "The gap is explained by: " + ", ".join(f"<b>{e(v)}</b>" for v in verdict)
        best = (doc.get("effects") or [None])[0]
        if best and best["name"] == " + ".join(verdict):
            headline += f", fitted as {_params_text(best['name'], best['params'])}"
    rows = "".join(
        f"<tr><td>{e(c['name'])}</td><td>{_params_text(c['name'], c['params'])}"
        + (f" ({e(', '.join(c['holdout_told']))}: told by the holdout, which the fit recordings cannot tell; "
           "the shrink is not held out for it)" if c.get("holdout_told") else "") + "</td>"
        f"<td>{c['shrink']:.3f}</td><td>{c['score']:.3f}</td>"
        f"<td>{' / '.join(f'{100 * v:.3f} %' for v in c['nrmse_holdout_after'].values())}</td></tr>"
        for c in doc.get("effects", []))
    where = "".join(
        f"<tr><td>{e(w['channel'])}</td><td>{e(w['regime'])}</td><td>{e(w['subsystem'])}</td>"
        f"<td>{100 * w['share']:.1f} %</td><td>{e(', '.join(f'{a:.2f} to {b:.2f}' for a, b in w['windows']))}</td></tr>"
        for w in doc.get("where", []))
    base = doc.get("baseline") or {}
    params = _params_table(base)
    before = " / ".join(f"{100 * v:.3f} %" for v in (base.get("nrmse_holdout") or {}).values())
    warnings = "".join(f"<li>{e(w)}</li>" for w in base.get("warnings") or [])
    warnings = f"<p><b>Warnings of the baseline's identification:</b></p><ul>{warnings}</ul>" if warnings else ""
    imgs = "".join(_img(n, embedded) for n in images)
    chart = (f"<h2>How probable each explanation is</h2>{_img('candidates', embedded)}"
             if embedded and "candidates" in embedded else "")
    noise = ", ".join(f"{e(k)} {100 * v:.3f} %" for k, v in (doc.get("noise_floor") or {}).items())
    spread = ", ".join(f"{e(k)} {100 * v:.3f} %" for k, v in (doc.get("baseline_spread") or {}).items())
    conf = _confirmation_html(doc.get("confirmation"))
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>boomfmi diagnosis</title>
{_STYLE}
</head><body>
<h1>Diagnosis of the sim-to-real gap</h1>
<p class="act">{e(action_sentence(doc))}</p>
<p>{headline}</p>
<h2>Baseline</h2><p>Re-identified on the fit recordings (values with their 95 % intervals):</p>{params}
<p>Holdout NRMSE p_a / p_b / x: {before}.</p>{warnings}
{chart}
<h2>Before and after, on the holdout recording</h2>{imgs}
<h2>Where the gap lies</h2><table><tr><th>channel</th><th>regime</th><th>subsystem</th><th>share</th><th>windows [s]</th></tr>{where}</table>
<h2>Candidate effects, best first</h2><p>Candidates are fitted beyond a gap (summed NRMSE) of {100 * doc.get("gap_threshold", 0.0):.3f} %:
{NOISE_FACTOR:g} times the noise floor ({noise}) and {100 * ABS_FLOOR:g} %;
a gap no candidate explains is "unexplained" beyond {100 * doc.get("unexplained_threshold", 0.0):.3f} %, which adds the
baseline's own spread ({spread}).{_refused_html(doc)}</p>
<table><tr><th>effect</th><th>fitted parameters</th><th>shrink</th><th>probability</th>
<th>holdout NRMSE after (p_a / p_b / x)</th></tr>{rows}</table>
{_next_experiment_html(doc, embedded)}
{conf}
</body></html>"""


def _refused_html(doc: dict) -> str:
    """The candidates the load's own fit does not tell (``doc["refused_by_load_fit"]``)."""
    names = doc.get("refused_by_load_fit") or []
    if not names:
        return ""
    return (" Not weighed, as the load's own fit does not tell them (a law of the load that its "
            "velocity fit, on the recorded pressures, does not need): "
            + ", ".join(html.escape(n) for n in names) + ".")


def _next_experiment_html(doc: dict, embedded: dict | None) -> str:
    """The proposed experiment (``doc["next_experiment"]``) and its plot."""
    n = doc.get("next_experiment")
    if not n:
        return ""
    e = html.escape
    text = lambda ps: ", ".join(f"{e(k)} = {e(str(v))}" for k, v in ps.items())
    params = text(n["params"]) or "as defined"
    a, b = n["hypotheses"]
    why = (f"The two most probable explanations are close: {e(n['reason'])}." if n.get("needed") else
           f"Asked for (the two most probable explanations are not close: {e(n['reason'])}).")
    others = "; ".join(f"{e(d['design'])}" + (f" ({text(d['params'])})" if d["params"] else "")
                       + f": {d['separation']:.3g}" for d in n["designs"][1:])
    csv = f" Its command is in {e(n['csv'])} (t [s], u [V]; <code>boomfmi record --experiment FILE</code>)." \
        if n.get("csv") else ""
    return (f"<h2>The next experiment</h2><p>{why} Recording <b>{e(n['design'])}</b> ({params}, "
            f"{n['duration_s']:g} s) tells <b>{e(a)}</b> from <b>{e(b)}</b> best of the designs tried: its two "
            f"predictions differ by an expected log-likelihood ratio of {n['separation']:.3g} over the sensors' "
            f"noise (the others: {others}).{csv}</p>{_img('next_experiment.png', embedded)}")


def _confirmation_html(c: dict | None) -> str:
    if not c:
        return ""
    e = html.escape
    if "skipped" in c or "error" in c:
        return f"<h2>Confirmation through the FMUs</h2><p>Not done: {e(c.get('skipped') or c.get('error'))}.</p>"
    if "shrink_by_joint" in c:                  # a machine of several joints (confirm.confirm_machine)
        rows = "".join(f"<tr><td>{e(j)}</td><td>{v:.3f}</td></tr>" for j, v in c["shrink_by_joint"].items())
        return (f"<h2>Confirmation through the FMUs</h2><p>{e(Path(c['ssp']).name)} on {e(Path(c['recording']).name)} "
                f"with the named effects: holdout shrink {c['shrink']:.3f} over the joints with effects.</p>"
                f"<table><tr><th>joint</th><th>shrink</th></tr>{rows}</table>")
    pct = lambda d: " / ".join(f"{100 * d[k]:.3f} %" for k in CHANNELS)
    text = (f"<h2>Confirmation through the FMUs</h2><p>The holdout recording through {e(c['ssp'])} "
            f"(co-simulated at 1 ms): baseline NRMSE p_a / p_b / x {pct(c['nrmse_holdout_baseline'])}")
    if "shrink" in c:
        text += (f"; with the verdict's options {pct(c['nrmse_holdout_after'])}, shrink {c['shrink']:.3f} "
                 f"against the reference's {c.get('reference_shrink', float('nan')):.3f}: "
                 + ("<b>they agree</b>" if c.get("agrees") else "<b>they disagree</b>"))
    return text + ".</p>"


# ------------------------------------------------------------- a machine of several joints
#: what ``diagnosis.json`` says of the per-joint diagnosis (``"note"``)
JOINTS_NOTE = ("Each joint is cut off the linkage: its valve and chambers run on the recorded command and measured "
               "motion (the pneumatic cut), and where the load cut is installed its load runs on the measured "
               "pressures and the other joints' measured motion, re-identified on the fit recordings. The candidates "
               "are fitted on the fit recordings' cuts and scored on the holdouts'. The whole machine's baseline "
               "identified on the fit recordings is reported with its error on each holdout; the cuts do not use it.")


def _diagnose_joints(fit_paths, hold_paths, out: Path, workers, ssp, say, baseline, machine, propose) -> dict:
    """:func:`diagnose` on the recordings of a machine of several joints (the whole
    excavator's), joint by joint (``diagnose.joints``: each joint cut off the linkage,
    a pneumatic cut and a load cut); writes ``out``'s ``diagnosis.json`` and
    ``report.html`` as one set and returns the JSON document.

    ``diagnosis.json`` follows the boom's (``shared/spec/diagnosis-report.md``) with
    these additions: ``"kind": "excavator"``; ``baseline``: ``params``, ``ci95``,
    ``units``, ``cannot_tell``, ``nrmse_holdout`` per joint and channel (the holdouts'
    mean) and per recording, ``warnings``, ``used_by_verdict`` (false: the cuts do not
    use it); ``where``: one entry per joint and holdout, the most beyond its threshold
    first: ``joint``, ``recording``, ``channel`` (the joint's pressure with the larger
    error) and ``channel_gaps``, ``regime`` (``whole_recording``), ``subsystem``
    (``valve_<joint>, cylinder_<joint>``), ``share`` (the joint's part of the holdout's
    squared normalised pressure residual over all joints), ``gap``, ``noise_floor``,
    ``threshold``, ``flagged``, ``exercised`` (the piston moved ``MIN_TRAVEL`` or its
    valve opened), ``travel_mm``, ``finding``, ``windows`` (the three 50 ms spans where
    the cut's residual is largest), ``position`` (the load cut's, where it runs);
    ``effects``: every candidate fitted on a flagged joint, best first per joint and
    cut: ``name`` (``a+b`` for a pair), ``joint``, ``cut``, ``params``, ``law``,
    ``fit_gap`` (and ``fit_gap_before``), ``gap_before`` and ``gap_after`` on the
    holdouts (and per holdout), ``shrink``, ``named``, ``not_fitted`` (why); ``verdict``:
    ``"<effect>@<joint>"`` or ``"unexplained@<joint>"``, the joint furthest beyond its
    threshold first, ``[]`` where no joint's cut exceeds its noise; ``confirmation``: the
    named effects through ``excavator.ssp`` (``confirm.confirm_machine``)."""
    refused = [f"{option} ({what})" for option, what, given in (
        ("--ssp", "the boom's SSP for confirming a one-joint verdict; a machine of several joints is confirmed "
                  "through build/excavator.ssp", ssp is not None),
        ("--propose", "the boom's next experiment; the per-joint diagnosis proposes none", propose is not None))
        if given]
    if refused:
        raise ValueError("the whole excavator's recordings are diagnosed joint by joint, which cannot honour "
                         + "; ".join(refused) + ": leave it out")
    fit_recs = read_checked(fit_paths, "excavator", "fit recording", machine=machine)
    hold_recs = read_checked(hold_paths, "excavator", "holdout", machine=machine)
    check_no_duplicates(fit_recs)
    check_no_duplicates(hold_recs, "holdout")
    for h in hold_recs:
        check_distinct(fit_recs, h)
    check_same_rig([*fit_recs, *hold_recs])

    say(f"identifying the baseline per joint on {len(fit_recs)} fit recording(s) (reported; the per-joint cuts "
        f"do not use it)")
    if baseline is None:
        result, _, ex = identify_recs(fit_recs)
    else:
        result, _ = baseline() if callable(baseline) else baseline
        ex = machine_of(fit_recs[0]).ex           # the linkage identify_recs assumes
    for w in result.warnings:
        say(f"warning (baseline): {w}")
    bound, notes = ssv_values(result, ex)
    linkage, payload = bound_machine(bound, ex)
    per_hold = {}
    for h in hold_recs:
        say(f"simulating the identified machine on {h.path}")
        per_hold[str(h.path)] = joint_nrmse(simulate_machine(h, linkage, payload), h, linkage)
    why = cannot_tell(result)
    base = {"params": {k: e.value for k, e in result.params.items()},
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
    found = diagnose_joints(fit_recs, hold_recs, hx, workers=workers, progress=say)
    where, effects, figures = [], [], []
    named = {j: _named_candidate(f) for j, f in found.joints.items()}
    for k, h in enumerate(hold_recs):
        travel = np.ptp(measured_pistons(h, hx), axis=0)
        curves, entries, squares = {}, [], {}
        for i, j in enumerate(JOINTS):
            f = found.joints[j]
            cut = joint_cut(h, j, hx)
            pa, pb = joint_pressures(cut, j, hx)
            best = named[j]
            after = joint_pressures(cut, j, hx, best.params) if best else None
            curves[j] = (cut, pa, pb, after, best)
            # as the cut's gap compares them (each pressure as its sensor reads it)
            ea, eb = ((as_sensed(m, s) - m) / _span(m) for m, s in ((cut.p_a_raw, pa), (cut.p_b_raw, pb)))
            squares[j] = float(np.sum(ea ** 2 + eb ** 2))
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
            entries.append(entry)
        total = sum(squares.values())
        for entry in entries:
            entry["share"] = squares[entry["joint"]] / total if total > 0 else 0.0
        where += entries
        figures.append((str(h.path), _joints_figure(h, curves)))
    for j, f in found.joints.items():
        for cut in f.cuts:
            for c in cut.candidates:
                is_named = any(cut is n for n in f.named_cuts) and c is cut.candidates[0]
                effects.append(_joint_effect(j, cut, c, is_named))
    where.sort(key=lambda w: -(w["gap"] - w["threshold"]) / w["threshold"])
    doc = {"kind": "excavator",
           "judgeable": True,
           "method": "per-joint cuts, fitted on the fit recordings and scored on the holdouts "
                     "(boomfmi.diagnose.joints)",
           "note": JOINTS_NOTE,
           "fit_recordings": [str(r.path) for r in fit_recs],
           "holdout_recordings": [str(h.path) for h in hold_recs],
           "baseline": base,
           "noise_factor": NOISE_FACTOR, "abs_floor": ABS_FLOOR, "min_shrink": MIN_SHRINK,
           "where": where,
           "effects": effects,
           "verdict": found.verdict,
           "warnings": list(found.notes)}
    confirmation = _confirm_joints(found, bound, hold_recs, say)
    if confirmation is not None:
        doc["confirmation"] = confirmation
    doc = plain(doc)
    with OutputSet(out, stale=OUTPUTS) as files:
        files.path("report.html").write_text(_joints_html(doc, figures))
        files.path("diagnosis.json").write_text(dumps(doc, indent=2))
    return doc


def _named_candidate(f):
    """The pneumatic cut's named candidate of a joint (single or pair), or None."""
    c = f.pressures
    if c.verdict and c.verdict != ["unexplained"] and c.candidates:
        return c.candidates[0]
    return None


def _joint_effect(joint: str, cut, c, named: bool) -> dict:
    """One candidate fitted on a joint's cut as ``diagnosis.json`` lists it."""
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
    if c.told:
        entry["holdout_told"] = list(c.told)
    return entry


def _confirm_joints(found, values: dict, hold_recs, say):
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


def _joints_figure(h, curves) -> str:
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


def _joints_html(doc: dict, figures) -> str:
    """The report of a machine of several joints: the page of :func:`_html` (one
    sentence to act on first, the findings, the parameters with units and intervals,
    the overlays embedded) with a section per joint."""
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
        f"<td>{e(w['channel'])}</td><td>{100 * w['share']:.1f} %</td>"
        f"<td>{'yes' if w['exercised'] else 'no'} ({w['travel_mm']:.1f} mm)</td>"
        f"<td>{e(', '.join(f'{a:.2f} to {b:.2f}' for a, b in w['windows']))}</td></tr>" for w in doc["where"])
    effects = "".join(
        f"<tr><td>{e(c['joint'])}</td><td>{e(c['cut'])}</td><td>{e(c['name'])}{' (named)' if c['named'] else ''}</td>"
        + (f"<td colspan=\"5\">not fitted: {e(c['not_fitted'])}</td></tr>" if c.get("not_fitted") else
           f"<td>{_params_text(c['name'].replace('+', ' + '), c['params'])}"
           + (f" ({e(', '.join(c['holdout_told']))}: told by the holdout, which the fit recordings cannot tell; "
              "the shrink is not held out for it)" if c.get("holdout_told") else "") + "</td>"
           f"<td>{_pct(c['fit_gap_before'])} &rarr; {_pct(c['fit_gap'])}</td>"
           f"<td>{_pct(c['gap_before'])}</td><td>{_pct(c['gap_after'])}</td><td>{c['shrink']:.3f}</td></tr>")
        for c in doc["effects"]) or \
        '<tr><td colspan="8">none: no joint was flagged</td></tr>'
    b = doc["baseline"]
    nrmse = "".join(f"<tr><td>{e(j)}</td>" + "".join(f"<td>{_pct(r[c])}</td>" for c in ("x", "p_a", "p_b"))
                    + "</tr>" for j, r in b["nrmse_holdout"].items())
    warnings = "".join(f"<li>{e(w)}</li>" for w in [*doc["warnings"], *b["warnings"]])
    warnings = f"<h2>Warnings</h2><ul>{warnings}</ul>" if warnings else ""
    imgs = "".join(f'<h3>{e(Path(p).name)}</h3><p><img src="data:image/png;base64,{png}" '
                   f'alt="pressures of {e(Path(p).name)}" style="max-width:100%"></p>' for p, png in figures)
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>boomfmi diagnosis: per joint</title>
{_STYLE}
</head><body>
<h1>Diagnosis of the sim-to-real gap, per joint</h1>
<p class="act">{e(action_sentence(doc))}</p>
<p>{headline}</p>
<p>Fit recordings: {e(', '.join(doc['fit_recordings']))}. Holdout recordings: {e(', '.join(doc['holdout_recordings']))}.</p>
<h2>Baseline</h2><p>{e(doc['note'])}</p>{_params_table(b)}
<p>The identified machine (monolithic reference, from each holdout's first state) against the holdouts, NRMSE:</p>
<table><tr><th>joint</th><th>x</th><th>p_a</th><th>p_b</th></tr>{nrmse}</table>
<h2>Where: each joint's gap</h2>
<p>Each joint's valve and chambers run on its recorded command and its measured motion (the linkage cut off), so a
pressure gap that remains is that joint's own (and, where the load cut is installed, its load on the measured pressures
and the other joints' measured motion: a position gap). The gap is the NRMSE of its two pressures, summed; a joint is
flagged beyond {doc['noise_factor']:g} times its noise floor plus {100 * doc['abs_floor']:g} %. On a flagged joint each
candidate of the cut is fitted on the fit recordings and scored on the holdouts; the best is named if it removes at
least {100 * doc['min_shrink']:.0f} % of the holdouts' gap (or a pair, each paying for itself), else "unexplained".</p>
<table><tr><th>joint</th><th>holdout</th><th>gap</th><th>noise floor</th><th>threshold</th><th>flagged</th>
<th>finding</th><th>larger error</th><th>share</th><th>exercised (travel)</th><th>windows [s]</th></tr>{where}</table>
<h2>Candidate effects on the flagged joints</h2>
<p>Fitted on the fit recordings' cuts (their gap before &rarr; after), scored on the holdouts' (never fitted on).</p>
<table><tr><th>joint</th><th>cut</th><th>effect</th><th>fitted parameters</th><th>fit gap</th><th>holdout gap before</th>
<th>holdout gap after</th><th>holdout shrink</th></tr>{effects}</table>
<h2>Before and after: pressures, recorded and from each joint's cut</h2>{imgs}
{_confirmation_html(doc.get("confirmation"))}
{warnings}
</body></html>"""


def summary_lines(doc: dict) -> list[str]:
    """The human summary ``boomfmi diagnose`` prints for a machine of several joints:
    the baseline's holdout error, each joint's gap against its noise, the findings, the
    verdict and the sentence to act on."""
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
    lines.append(action_sentence(doc))
    return lines


__all__ = ["MIN_TRAVEL", "diagnose", "OUTPUTS", "action_sentence", "summary_lines"]
