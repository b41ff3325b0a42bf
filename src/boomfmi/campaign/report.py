"""A campaign's outputs: ``campaign.json``, ``campaign.html`` and the trend plots.

``campaign.json`` holds ``run`` (the engine, counts, wall time, the workers lost with
a case and why), ``cases`` (each case: machine, date, status, its folder, verdict or
error, the identified parameters with their intervals, each effect's size, its
attempts: each one's worker, outcome and why the case ran again) and ``machines`` (each machine's last verdict,
trends and flags: :func:`~.trend.machine_trends`).  ``campaign.html`` is readable on
its own: the fleet table first (machine, last date and verdict, flags), then each
flag, each machine's trend plot (``trend_<machine>.png``) and every case with a link
to its report.
"""
from __future__ import annotations

import html
from pathlib import Path

from .._json import dumps
from ..outputs import OutputSet
from .manifest import slug
from .trend import machine_trends


def write_campaign(out: Path, manifest, records: list[dict], run: dict) -> dict:
    out = Path(out)
    cases, by_machine = [], {}      # by_machine: each machine's rows, and its cases as machine_trends takes them
    for case, rec in zip(manifest.cases, records):
        s = rec.get("summary") or {}
        row = {"machine": case.machine, "date": case.date, "status": rec["status"],
               "folder": (Path("cases") / case.folder).as_posix(), "resumed": bool(rec.get("resumed")),
               "worker": rec.get("worker"), "wall_s": rec.get("wall_s"), "error": rec.get("error"),
               "attempts": rec.get("attempts") or [],
               "recordings": rec.get("recordings"),
               "judgeable": s.get("judgeable"), "verdict": s.get("verdict"), "reason": s.get("reason"),
               "params": s.get("params"), "nrmse_holdout": s.get("nrmse_holdout"),
               "gap_threshold": s.get("gap_threshold"),
               "effects": {n: {"gain": e["gain"], "shrink": e["shrink"], "params": e["params"]}
                           for n, e in (s.get("effects") or {}).items()}}
        cases.append(row)
        by_machine.setdefault(case.machine, []).append(
            (row, {"date": case.date, "status": rec["status"], "summary": rec.get("summary")}))
    machines, units = {}, {}
    for m in manifest.machines:
        mine = [row for row, _ in by_machine[m]]
        units[m] = {k: p.get("unit") for c in mine for k, p in (c["params"] or {}).items()}
        trends = machine_trends([dated for _, dated in by_machine[m]])
        last = mine[-1]
        machines[m] = {"cases": len(mine), "failed": sum(c["status"] != "done" for c in mine),
                       "last": {"date": last["date"], "status": last["status"], "verdict": last["verdict"],
                                "error": last["error"], "judgeable": last["judgeable"]},
                       "flags": trends.pop("flags"), "trends": trends,
                       "plot": f"trend_{slug(m)}.png"}
    doc = {"run": run, "machines": machines, "cases": cases}
    stale = [p.name for p in out.glob("trend_*.png")] if out.is_dir() else []
    with OutputSet(out, stale=stale + ["campaign.json", "campaign.html"]) as files:
        for m, info in machines.items():
            _plot(files.path(info["plot"]), m, info["trends"], units[m])
        files.path("campaign.html").write_text(_html(doc))
        files.path("campaign.json").write_text(dumps(doc, indent=1))
    return doc


def _plot(path, machine: str, trends: dict, units: dict) -> None:
    """The machine's trend plot: each parameter's value and interval by date (``units``:
    each one's unit, as its cases' summaries give it), then each effect's size."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.pyplot as plt
    from datetime import datetime
    params = list(trends["parameters"])         # machine_trends': identify.fit.PARAMS's order
    effects = {n: s for n, s in trends["effects"].items() if any(p["in_verdict"] or p["gain"] > p["margin"] for p in s)}
    rows = len(params) + 1
    fig, axes = plt.subplots(rows, 1, figsize=(8, 1.6 * rows + 0.6), sharex=True, squeeze=False)
    axes = axes[:, 0]
    for ax, k in zip(axes, params):
        pts = [p for p in trends["parameters"][k] if p["value"] is not None]
        for p in pts:
            t = datetime.fromisoformat(p["date"])
            lo, hi = p["ci95"] if p["ci95"] and None not in p["ci95"] else (p["value"], p["value"])
            color = "tab:red" if p["move"] else "tab:blue" if p.get("identified", True) else "0.6"
            ax.errorbar([t], [p["value"]], yerr=[[max(p["value"] - lo, 0.0)], [max(hi - p["value"], 0.0)]],
                        fmt="o", ms=4, color=color, capsize=3, mfc=color if p.get("identified", True) else "none")
        ref_date = (trends.get("parameter_reference") or {}).get(k)
        ref = next((p for p in pts if p["date"] == ref_date), None)
        if ref and ref["ci95"] and None not in ref["ci95"]:
            ax.axhspan(ref["ci95"][0], ref["ci95"][1], color="tab:blue", alpha=0.12, lw=0)
        ax.set_ylabel(f"{k} [{units.get(k) or ''}]", fontsize=8)
        ax.tick_params(labelsize=7)
    ax = axes[-1]
    for n, series in effects.items():
        ts = [datetime.fromisoformat(p["date"]) for p in series]
        line, = ax.plot(ts, [100 * p["gain"] for p in series], "-", lw=1, label=n)
        for p, t in zip(series, ts):
            ax.errorbar([t], [100 * p["gain"]], yerr=[100 * p["margin"]], fmt="o" if p["in_verdict"] else "x",
                        ms=5 if p["in_verdict"] else 4, color="tab:red" if p["move"] else line.get_color(), capsize=3)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_ylabel("effect size:\nholdout error\nremoved [%]", fontsize=8)
    ax.tick_params(labelsize=7)
    if effects:
        ax.legend(fontsize=7, loc="upper left")
    else:
        ax.text(0.5, 0.5, "no effect named, nor beyond its margin, on any date", transform=ax.transAxes,
                ha="center", va="center", fontsize=8, color="0.4")
    ax.set_xticks([datetime.fromisoformat(d) for d in trends["dates"]])
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%Y-%m-%d"))
    fig.autofmt_xdate()
    axes[0].set_title(f"{machine}: parameters with 95 % intervals (band: the reference date's; red: moved;\n"
                      f"grey: not identified that date) and effects (o: in the verdict)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90, format="png")
    plt.close(fig)


def _verdict(v) -> str:
    if v is None:
        return "-"
    return "none (no gap)" if v == [] else " + ".join(v)


def _attempts_html(c: dict) -> str:
    """The worker a case ran on and, where it ran more than once, each attempt: its
    worker, its outcome and why the case was run again."""
    e = html.escape
    tries = c.get("attempts") or []
    if len(tries) <= 1:
        return e(c.get("worker") or "-")
    return (f"{e(c.get('worker') or '-')}<br><b>{len(tries)} attempts</b>:<ol>"
            + "".join(f"<li>on {e(a['worker'] or '-')}"
                      + (f" from {e(a['started'])}" if a.get("started") else "")
                      + f": {e(a['outcome'])}" + (f" ({e(a['reason'])})" if a.get("reason") else "") + "</li>"
                      for a in tries) + "</ol>")


def _html(doc: dict) -> str:
    e = html.escape
    run = doc["run"]
    rows = []
    for m, info in doc["machines"].items():
        last = info["last"]
        verdict = (f"failed: {e(last['error'] or '')}" if last["status"] != "done" else
                   e(_verdict(last["verdict"])) if last["judgeable"] else "not judgeable")
        flags = "<br>".join(f"<b>{e(f['name'])}</b> {e(f['direction'])} from {e(f['date'])}"
                            + (" (provisional)" if f.get("status") == "provisional" else "") for f in info["flags"])
        style = ' style="background:#fde2e2"' if info["flags"] else ""
        failed = f" ({info['failed']} failed)" if info["failed"] else ""
        rows.append(f"<tr{style}><td><a href=\"#m-{e(slug(m))}\">{e(m)}</a></td><td>{info['cases']}"
                    f"{failed}</td><td>{e(last['date'])}</td>"
                    f"<td>{verdict}</td><td>{flags or 'none'}</td></tr>")
    flagged = sum(bool(i["flags"]) for i in doc["machines"].values())
    sections = []
    for m, info in doc["machines"].items():
        items = "".join(f"<li>{e(f['text'])}" + (f" (also {e(', '.join(f['dates'][1:]))})" if len(f["dates"]) > 1 else "")
                        + "</li>" for f in info["flags"])
        sections.append(f'<h3 id="m-{e(slug(m))}">{e(m)}</h3>'
                        + (f"<ul>{items}</ul>" if items else "<p>No flag: nothing moved beyond its interval "
                           f"since the reference date {e(str(info['trends']['reference']))}.</p>")
                        + f'<p><img src="{e(info["plot"])}" alt="trends of {e(m)}" style="max-width:100%"></p>')
    case_rows = []
    for c in doc["cases"]:
        link = f'<a href="{e(c["folder"])}/report.html">report</a>' if c["status"] == "done" else ""
        what = (f"<b>failed</b>: {e(c['error'] or '')}" if c["status"] != "done" else
                e(_verdict(c["verdict"])) if c["judgeable"] else f"not judgeable: {e(c['reason'] or '')}")
        params = ", ".join(f"{k} {p['value']:.4g}" for k, p in (c.get("params") or {}).items()
                           if p.get("value") is not None)
        wall = "" if c["wall_s"] is None else f"{c['wall_s']:.0f} s"
        case_rows.append(f"<tr><td>{e(c['machine'])}</td><td>{e(c['date'])}</td><td>{what}</td><td>{e(params)}</td>"
                         f"<td>{wall}"
                         f"{' (earlier run)' if c['resumed'] else ''}</td><td>{_attempts_html(c)}</td>"
                         f"<td>{link}</td></tr>")
    lost = run.get("workers_lost") or {}
    lost_html = ("" if not lost else
                 f"<p style=\"font-size:1.2em\"><b>{len(lost)} worker(s) lost</b> while running cases; "
                 f"{run.get('cases_retried', 0)} case(s) run again elsewhere (see their attempts below):</p><ul>"
                 + "".join(f"<li>{e(w)}: {e(r)}</li>" for w, r in lost.items()) + "</ul>")
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>boomfmi campaign</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:4px 8px;font-size:13px;vertical-align:top}}</style></head><body>
<h1>Campaign: {len(doc['machines'])} machine(s), {run['cases']} case(s)</h1>
<p style="font-size:1.2em">{flagged} machine(s) flagged; {run['failed']} case(s) failed.</p>
{lost_html}
<h2>Fleet</h2>
<table><tr><th>machine</th><th>cases</th><th>last date</th><th>last verdict</th><th>trend flags</th></tr>
{''.join(rows)}</table>
<p>A flag: a parameter whose 95 % interval no longer overlaps the reference date's (the machine's first
judged date), or an effect the diagnosis names that it did not name on the reference date, or whose size
(the holdout error it removes) moved beyond both dates' noise margins; flagged where the next date shows the
move again, or, provisionally, where it is on the newest date. Manifest {e(run['manifest'])};
run on {e(run['scheduler'])} ({e(str(run['address']))}, {run['worker_threads']} worker thread(s)) in
{run['wall_s']:.0f} s: {run['ran']} case(s) run, {run['resumed']} done before.</p>
<h2>Machines</h2>{''.join(sections)}
<h2>Cases</h2>
<table><tr><th>machine</th><th>date</th><th>verdict</th><th>baseline</th><th>time</th><th>worker (attempts)</th><th></th></tr>
{''.join(case_rows)}</table>
</body></html>"""


__all__ = ["write_campaign"]
