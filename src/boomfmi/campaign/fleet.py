"""A virtual fleet: N machines recorded every week for W weeks, with known changes.

For tests and the demo of ``boomfmi campaign``.  Each machine is the virtual rig
(:mod:`boomfmi.rig`, its own effect forms) with its own load (each of K_v, F_s, F_d,
F_L, M within +-8 % of the reference rig) and its own sensor noise.  Every week it runs
a fit and a holdout experiment (random steps, :func:`boomfmi.experiments.random_steps`,
new commands each week).  What happens to it is one of

=========== ============================================================== ===========
kind        from its onset week on (week ``o``; ``n = week - o``)           flagged as
=========== ============================================================== ===========
none        nothing: the machine does not change                           (nothing)
leak        the piston seal leaks, and the leak grows: an orifice of        piston_leakage
            ``6e-9 * 1.6**n`` m^2 across the piston
friction    the seal's friction rises: F_s and F_d ``* (1 + 0.07 (n + 1))``  F_d (or F_s)
valve       the valve goes sluggish: an overdamped spool (zeta 1.5) whose   valve_dynamics
            natural frequency falls, ``40 / 1.25**n`` Hz
=========== ============================================================== ===========

Kinds go round the machines in the order of :data:`KINDS` (of 8 machines, 3 do not
change); each changing machine's onset week is drawn between the second and the last
week.  :func:`make_fleet` writes the recordings, ``manifest.csv`` and ``truth.json``
(each machine's kind, onset date, load and weekly rig configuration);
:func:`score_fleet` checks a campaign's flags against the truth.
"""
from __future__ import annotations

import json
import os
from concurrent.futures import ProcessPoolExecutor
from datetime import date, timedelta
from pathlib import Path

import numpy as np

from ..identify.fit import PARAMS
from ..physics import reference_rig
from .manifest import write_manifest

KINDS = ("none", "leak", "friction", "valve", "none", "leak", "friction", "none")
#: the flag that names each kind's change (any of them)
EXPECTED = {"leak": ("piston_leakage",), "friction": ("F_d", "F_s"), "valve": ("valve_dynamics",)}
DURATION = 7.0          #: [s] of each experiment
START = "2025-01-06"    #: the first week's date (a Monday)


def plan_fleet(machines: int = 8, weeks: int = 6, seed: int = 20, start: str = START) -> dict:
    """The fleet's truth: machine name -> kind, onset (week and date), load, and each
    week's date, rig configuration and command seeds."""
    if machines < 1 or weeks < 2:
        raise ValueError(f"a fleet needs 1 or more machines and 2 or more weeks (given {machines}, {weeks})")
    rng = np.random.default_rng(seed)
    day0 = date.fromisoformat(start)
    plan = {}
    for i in range(machines):
        name = f"m{i + 1:02d}"
        kind = KINDS[i % len(KINDS)]
        load = {k: float(getattr(reference_rig, k) * rng.uniform(0.92, 1.08)) for k in PARAMS}
        load["F_s"] = max(load["F_s"], 1.1 * load["F_d"])
        onset = int(rng.integers(1, weeks)) if kind != "none" else None
        plan_weeks = []
        for w in range(weeks):
            n = None if onset is None or w < onset else w - onset
            params, effects = dict(load), {}
            if n is not None and kind == "leak":
                effects["piston_leakage"] = {"A_leak": 6e-9 * 1.6 ** n}
            elif n is not None and kind == "friction":
                params["F_s"] = load["F_s"] * (1 + 0.07 * (n + 1))
                params["F_d"] = load["F_d"] * (1 + 0.07 * (n + 1))
            elif n is not None and kind == "valve":
                effects["valve_dynamics"] = {"f_n": 40.0 / 1.25 ** n, "zeta": 1.5}
            base = seed * 100_000 + i * 100 + w * 2
            plan_weeks.append({"date": (day0 + timedelta(weeks=w)).isoformat(), "week": w,
                               "config": {"params": params, "effects": effects},
                               "fit_seed": base, "holdout_seed": base + 1})
        plan[name] = {"kind": kind, "onset_week": onset,
                      "onset": plan_weeks[onset]["date"] if onset is not None else None,
                      "load": load, "weeks": plan_weeks}
    return plan


def _record(job) -> str:
    from ..experiments import random_steps
    from ..recording import write_recording
    from ..rig.offline import run_offline
    path, config, seed, duration = job
    cmd = random_steps(seed, duration=duration)
    partial = path.with_name(path.stem + ".partial.csv")        # in place only when whole
    write_recording(partial, run_offline(dict(config, seed=seed), cmd, duration))
    os.replace(partial, path)
    return str(path)


def make_fleet(out, machines: int = 8, weeks: int = 6, seed: int = 20, duration: float = DURATION,
               workers: int | None = None, progress=None) -> Path:
    """Write the fleet into ``out``: ``truth.json`` (the plan), ``<machine>/<date>_fit.csv``
    and ``_holdout.csv`` (each moved into place when whole), then ``manifest.csv``.
    Recordings already there under the same plan are kept (a run that was stopped
    goes on where it was).  Returns the manifest's path."""
    out = Path(out)
    plan = plan_fleet(machines, weeks, seed)
    truth = {"seed": seed, "machines_n": machines, "weeks": weeks, "duration_s": duration, "machines": plan}
    truth_path = out / "truth.json"
    try:
        same = json.loads(truth_path.read_text()) == json.loads(json.dumps(truth))
    except (OSError, ValueError):
        same = False
    rows, jobs = [], []
    for m, info in plan.items():
        for wk in info["weeks"]:
            for role, key in (("fit", "fit_seed"), ("holdout", "holdout_seed")):
                path = out / m / f"{wk['date']}_{role}.csv"
                rows.append({"machine": m, "date": wk["date"], "role": role, "recording": path})
                if not (same and path.is_file()):
                    jobs.append((path, wk["config"], wk[key], duration))
    out.mkdir(parents=True, exist_ok=True)
    for m in plan:
        (out / m).mkdir(exist_ok=True)
    truth_path.write_text(json.dumps(truth, indent=1))     # the plan the recordings follow
    say = progress or (lambda text: None)
    if jobs:
        say(f"recording {len(jobs)} experiments of {duration:g} s on the virtual rig")
        n = min(workers or os.cpu_count() or 1, len(jobs))
        if n > 1:
            with ProcessPoolExecutor(n) as pool:
                for k, p in enumerate(pool.map(_record, jobs), 1):
                    say(f"{k}/{len(jobs)} {p}")
        else:
            for k, job in enumerate(jobs, 1):
                say(f"{k}/{len(jobs)} {_record(job)}")
    return write_manifest(out / "manifest.csv", rows)


def score_fleet(campaign: dict, truth: dict) -> dict:
    """A campaign's flags against the fleet's truth.  Per machine: its kind and onset,
    its first flag (date, name) and every flag; ``ok`` where a changing machine's first
    flag that names its change is dated on its onset date or within 7 days after, and
    no flag is dated before the onset (or where an unchanged machine has no flag,
    provisional ones included).  A flag's date is the first date of the move: run
    week by week, the campaign raises it that week, as provisional, and confirms it
    the next (:func:`~.trend.persistent`).  Totals: onsets flagged in time, flags on
    unchanged machines, flags before an onset."""
    rows = {}
    for m, info in truth["machines"].items():
        flags = (campaign["machines"].get(m) or {}).get("flags", [])
        first = min(flags, key=lambda f: f["date"]) if flags else None
        row = {"kind": info["kind"], "onset": info["onset"],
               "flags": [{k: f.get(k) for k in ("name", "date", "status", "confirmed_by")} for f in flags],
               "first_flag": first["date"] if first else None}
        if info["onset"] is None:
            row["ok"] = not flags
        else:
            onset = date.fromisoformat(info["onset"])
            named = [f for f in flags if f["name"] in EXPECTED[info["kind"]]]
            first_named = min((date.fromisoformat(f["date"][:10]) for f in named), default=None)
            row["delay_days"] = (first_named - onset).days if first_named else None
            row["early"] = bool(first and date.fromisoformat(first["date"][:10]) < onset)
            row["in_time"] = first_named is not None and 0 <= (first_named - onset).days <= 7
            row["ok"] = row["in_time"] and not row["early"]
        rows[m] = row
    onsets = [r for r in rows.values() if r["onset"]]
    return {"machines": rows,
            "onsets": len(onsets), "onsets_flagged_in_time": sum(r["in_time"] for r in onsets),
            "flags_before_onset": sum(r["early"] for r in onsets),
            "unchanged": sum(r["onset"] is None for r in rows.values()),
            "unchanged_flagged": sum(r["onset"] is None and not r["ok"] for r in rows.values()),
            "all_ok": all(r["ok"] for r in rows.values())}

__all__ = ["KINDS", "EXPECTED", "DURATION", "START", "plan_fleet", "make_fleet", "score_fleet"]
