#!/usr/bin/env python3
"""Blind benchmark of the diagnosis on virtual-rig cases.

Each case draws, from a seeded generator: load parameters within +-15 % of the
reference rig (so the baseline must be re-identified), and either no effect, one
effect of effects.md at a realistic magnitude (the virtual rig's own forms, drawn
within ``boomfmi.rig.config.EFFECT_RANGES``), a pair of effects, or a disturbance
outside the vocabulary (an engine vibration).  The virtual rig (noise and
quantisation on) records a fit run and a holdout run of different random step
commands; ``boomfmi.diagnose`` sees only the recordings.  Prints the confusion matrix,
the share of correct verdicts and the median holdout shrink of single-effect cases,
and writes docs/diagnosis.md.

    python benchmarks/diagnosis_blind.py [--cases 30] [--workers 2]
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from boomfmi.diagnose import diagnose  # noqa: E402
from boomfmi.experiments import random_steps  # noqa: E402
from boomfmi.physics import reference_rig  # noqa: E402
from boomfmi.recording import write_recording  # noqa: E402
from boomfmi.rig.config import EFFECT_RANGES  # noqa: E402
from boomfmi.rig.offline import run_offline  # noqa: E402

EFFECTS = ("valve_dynamics", "valve_deadband", "heat_transfer", "piston_leakage",
           "stribeck_friction", "end_cushioning", "sensor_lag")
LOAD = ("K_v", "F_s", "F_d", "F_L", "M")


def draw_case(i: int, seed: int):
    rng = np.random.default_rng(seed * 1000 + i)
    params = {k: float(getattr(reference_rig, k) * rng.uniform(0.85, 1.15)) for k in LOAD}
    params["F_s"] = max(params["F_s"], 1.05 * params["F_d"])
    kind = ["none", "single", "single", "single", "single", "pair", "vibration"][i % 7]
    effects, truth, disturbance = {}, [], None
    if kind == "single":
        names = [EFFECTS[(i // 7 * 4 + i % 7) % len(EFFECTS)]]
    elif kind == "pair":
        names = list(rng.choice(EFFECTS, size=2, replace=False))
    else:
        names = []
    for n in names:
        effects[n] = {p: float(rng.uniform(lo, hi)) for p, (lo, hi) in EFFECT_RANGES[n].items()}
        if n == "stribeck_friction":
            effects[n]["F_brk"] = float(rng.uniform(1.2, 1.8) * params["F_s"])
    truth = sorted(names)
    if kind == "vibration":
        disturbance = {"type": "vibration", "amplitude": float(rng.uniform(150, 300)),
                       "frequency": float(rng.uniform(5, 15))}
        truth = ["unexplained"]
    return {"case": i, "kind": kind, "params": params, "effects": effects,
            "disturbance": disturbance, "truth": truth, "seed": seed * 1000 + i}


def run_case(case: dict) -> dict:
    cfg = {"params": case["params"], "effects": case["effects"], "seed": case["seed"]}
    if case["disturbance"]:
        cfg["disturbance"] = case["disturbance"]
    fit, hold = random_steps(case["seed"], duration=10.0), random_steps(case["seed"] + 500, duration=10.0)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        write_recording(d / "fit.csv", run_offline(cfg, fit, fit.duration))
        write_recording(d / "hold.csv", run_offline(dict(cfg, seed=case["seed"] + 7), hold, hold.duration))
        t = time.perf_counter()
        doc = diagnose([d / "fit.csv"], [d / "hold.csv"], d / "out", workers=1)   # sees only the recordings
        wall = time.perf_counter() - t
    verdict = sorted(doc["verdict"])
    best = doc["effects"][0] if doc["effects"] else None
    shrink = next((e["shrink"] for e in doc["effects"] if e["name"] in case["truth"]), None)
    return dict(case, verdict=verdict, correct=verdict == case["truth"], wall=wall,
                best=best["name"] if best else None, shrink_true=shrink,
                shrink_best=best["shrink"] if best else None)


def label(names):
    return "+".join(names) if names else "none"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=30)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", type=int, nargs="*", help="run only these case numbers (for a look at them)")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "diagnosis.md")
    args = ap.parse_args(argv)
    cases = [draw_case(i, args.seed) for i in (args.only or range(args.cases))]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        results = []
        for r in pool.map(run_case, cases):
            results.append(r)
            print(f"case {r['case']:2d} {r['kind']:9s} truth {label(r['truth']):40s} verdict {label(r['verdict']):40s} "
                  f"{'ok' if r['correct'] else 'WRONG'}  ({r['wall']:.0f} s)", flush=True)
    labels = sorted({label(r["truth"]) for r in results} | {label(r["verdict"]) for r in results})
    matrix = {t: {v: 0 for v in labels} for t in labels}
    for r in results:
        matrix[label(r["truth"])][label(r["verdict"])] += 1
    correct = sum(r["correct"] for r in results) / len(results)
    single = [r["shrink_true"] for r in results if r["kind"] == "single" and r["shrink_true"] is not None]
    median_shrink = statistics.median(single) if single else float("nan")
    walls = [r["wall"] for r in results]
    print(f"correct verdicts: {100 * correct:.1f} % of {len(results)}; median holdout shrink "
          f"(single effects): {median_shrink:.2f}; diagnosis time median {statistics.median(walls):.0f} s")
    lines = ["# Diagnosis: blind benchmark", "",
             f"Made by `python benchmarks/diagnosis_blind.py --cases {args.cases}` on {platform.machine()} / "
             f"Python {platform.python_version()} ({time.perf_counter() - t0:.0f} s wall, {args.workers} workers).", "",
             "Each case: load parameters within +-15 % of the reference rig; no effect, one effect, a pair,",
             "or an engine vibration outside the vocabulary; the virtual rig's own effect forms at",
             "realistic magnitudes; noise and quantisation on; one 10 s fit recording and one 10 s",
             "holdout recording of different random step commands. The diagnosis sees only the recordings.", "",
             f"**Correct verdicts: {100 * correct:.1f} %** (target 90 %); **median holdout shrink of",
             f"single-effect cases: {median_shrink:.2f}** (target 0.6); median diagnosis time "
             f"{statistics.median(walls):.0f} s (one fit, one holdout recording).", "",
             "## Confusion matrix (rows: truth, columns: verdict)", "",
             "| truth \\ verdict | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for t in labels:
        lines.append(f"| {t} | " + " | ".join(str(matrix[t][v]) or "" for v in labels) + " |")
    lines += ["", "## Cases", "", "| case | kind | truth | verdict | best candidate | its shrink | shrink of the truth |",
              "|---|---|---|---|---|---|---|"]
    for r in results:
        st = "" if r["shrink_true"] is None else f"{r['shrink_true']:.2f}"
        sb = "" if r["shrink_best"] is None else f"{r['shrink_best']:.2f}"
        lines.append(f"| {r['case']} | {r['kind']} | {label(r['truth'])} | {label(r['verdict'])} | {r['best']} | {sb} | {st} |")
    args.out.write_text("\n".join(lines) + "\n")
    (args.out.with_suffix(".json")).write_text(json.dumps(results, indent=1, default=str))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
