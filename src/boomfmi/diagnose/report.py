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
from ..compare import CHANNELS, model_for, nrmse, recorded, rig_model, shrink, simulate_recording
from ..identify import identify_recordings
from ..identify.preprocess import prepare
from ..machine import assumption
from ..outputs import OutputSet
from ..recording import check_distinct, check_no_duplicates, check_same_rig, read_checked
from .attribute import ABS_FLOOR, CANDIDATES, NOISE_FACTOR, attribute, may_start_processes
from .confirm import agreement, confirm
from .localise import localise

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
                "fit_error": float(f"{c.fit_error:.6g}") if np.isfinite(c.fit_error) else None, "shrink": round(c.shrink, 4), "score": c.score}
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
        f"<tr><td>{e(c['name'])}</td><td>{_params_text(c['name'], c['params'])}</td>"
        f"<td>{c['shrink']:.3f}</td><td>{c['score']:.3f}</td>"
        f"<td>{' / '.join(f'{100 * v:.3f} %' for v in c['nrmse_holdout_after'].values())}</td></tr>"
        for c in doc.get("effects", []))
    where = "".join(
        f"<tr><td>{e(w['channel'])}</td><td>{e(w['regime'])}</td><td>{e(w['subsystem'])}</td>"
        f"<td>{100 * w['share']:.1f} %</td><td>{e(', '.join(f'{a:.2f} to {b:.2f}' for a, b in w['windows']))}</td></tr>"
        for w in doc.get("where", []))
    base = doc.get("baseline") or {}
    ci, units = base.get("ci95") or {}, base.get("units") or {}
    params = "".join(
        f"<tr><td>{e(k)}</td><td>{_number(v)}</td>"
        f"<td>{(_number(ci[k][0]) + ' to ' + _number(ci[k][1])) if k in ci else '&ndash;'}</td>"
        f"<td>{_unit(units.get(k, ''))}</td></tr>" for k, v in (base.get("params") or {}).items())
    params = ("<table><tr><th>parameter</th><th>value</th><th>95 % interval</th><th>unit</th></tr>"
              f"{params}</table>") if params else ""
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
<style>body{{font-family:sans-serif;max-width:980px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:4px 8px;font-size:13px}}.act{{font-size:1.3em;background:#eef4fa;padding:.6em}}</style>
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
baseline's own spread ({spread}).</p>
<table><tr><th>effect</th><th>fitted parameters</th><th>shrink</th><th>probability</th>
<th>holdout NRMSE after (p_a / p_b / x)</th></tr>{rows}</table>
{_next_experiment_html(doc, embedded)}
{conf}
</body></html>"""


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
    pct = lambda d: " / ".join(f"{100 * d[k]:.3f} %" for k in CHANNELS)
    text = (f"<h2>Confirmation through the FMUs</h2><p>The holdout recording through {e(c['ssp'])} "
            f"(co-simulated at 1 ms): baseline NRMSE p_a / p_b / x {pct(c['nrmse_holdout_baseline'])}")
    if "shrink" in c:
        text += (f"; with the verdict's options {pct(c['nrmse_holdout_after'])}, shrink {c['shrink']:.3f} "
                 f"against the reference's {c.get('reference_shrink', float('nan')):.3f}: "
                 + ("<b>they agree</b>" if c.get("agrees") else "<b>they disagree</b>"))
    return text + ".</p>"


__all__ = ["MIN_TRAVEL", "diagnose", "OUTPUTS", "action_sentence"]
