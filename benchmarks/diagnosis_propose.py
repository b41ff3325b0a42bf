#!/usr/bin/env python3
"""The next experiment, demonstrated: ambiguous diagnoses decided by the proposed recording.

Each case is a virtual rig (``rig.offline.run_offline``) with one effect of effects.md
switched on at a size or under command designs that show it only faintly (a spool lag or
a sensor's lag under slow ramps, which barely tell one delay from the other; a small leak
or deadband near what the noise hides; the air's heat exchange under sweeps).  Not every
case ends ambiguous: those whose first diagnosis decides are listed as such (``--screen``
says which are, before the proposed recordings are made).  For each case:

1. record the fit and holdout recordings, diagnose them (``diagnose.diagnose`` with
   ``propose=``: the next experiment's command CSV);
2. where the diagnosis proposes an experiment (its two most probable explanations
   within a factor of 10, or ``unexplained`` among them), run that CSV on the same
   virtual rig (read by ``experiments.profile``, as ``boomfmi record --experiment`` reads
   it; the sensors' noise drawn anew), and diagnose again with the new recording added
   to the fit recordings (``--add fit``, the default: the effects' parameters are fitted
   where they show, and the evidence of the fit counts it) or as a further holdout
   (``--add holdout``: it tests the first fits' predictions, which recordings that hardly
   showed the effect pinned poorly);
3. print the verdict before and after against the truth.

    python benchmarks/diagnosis_propose.py [--cases NAME ...] [--workers 2] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from boomfmi.diagnose import diagnose  # noqa: E402
from boomfmi.experiments import manoeuvres, profile, random_steps, sine_sweep, slow_ramps  # noqa: E402
from boomfmi.recording import write_recording  # noqa: E402
from boomfmi.rig.offline import run_offline  # noqa: E402

NOISE = {"p_sigma": 500.0, "alpha_sigma": 0.0002, "quantise": True}

#: case -> (rig configuration, the true verdict, [(fit or holdout, command)])
CASES = {
    "spool_lag_on_ramps": ({"effects": {"valve_dynamics": {"f_n": 70.0, "zeta": 0.7}}, "seed": 61},
                           ["valve_dynamics"],
                           [("fit", slow_ramps(61, duration=8.0)), ("holdout", slow_ramps(62, duration=8.0))]),
    "spool_lag_weak": ({"effects": {"valve_dynamics": {"f_n": 100.0, "zeta": 0.7}}, "seed": 73},
                       ["valve_dynamics"],
                       [("fit", slow_ramps(73, duration=8.0)), ("holdout", slow_ramps(74, duration=8.0))]),
    "sensor_lag_on_ramps": ({"effects": {"sensor_lag": {"delay": 0.002, "tau": 0.003}}, "seed": 69},
                            ["sensor_lag"],
                            [("fit", slow_ramps(69, duration=8.0)), ("holdout", slow_ramps(70, duration=8.0))]),
    "tiny_leak": ({"effects": {"piston_leakage": {"A_leak": 7e-9}}, "seed": 63}, ["piston_leakage"],
                  [("fit", sine_sweep(63, duration=8.0)), ("holdout", sine_sweep(64, duration=8.0))]),
    "tiny_deadband": ({"effects": {"valve_deadband": {"overlap": 0.07, "edge": 0.03}}, "seed": 65},
                      ["valve_deadband"],
                      [("fit", random_steps(65, duration=8.0)), ("holdout", random_steps(66, duration=8.0))]),
    "heat_on_sweeps": ({"effects": {"heat_transfer": {"h_w": 15.0}}, "seed": 67}, ["heat_transfer"],
                       [("fit", sine_sweep(67, duration=8.0)), ("holdout", sine_sweep(68, duration=8.0))]),
    "spool_lag_on_ramps_2": ({"effects": {"valve_dynamics": {"f_n": 80.0, "zeta": 0.7}}, "seed": 75},
                             ["valve_dynamics"],
                             [("fit", slow_ramps(75, duration=8.0)), ("holdout", slow_ramps(76, duration=8.0))]),
    "sensor_lag_on_ramps_2": ({"effects": {"sensor_lag": {"delay": 0.001, "tau": 0.004}}, "seed": 77},
                              ["sensor_lag"],
                              [("fit", slow_ramps(77, duration=8.0)), ("holdout", slow_ramps(78, duration=8.0))]),
    "sensor_lag_on_ramps_3": ({"effects": {"sensor_lag": {"delay": 0.003, "tau": 0.002}}, "seed": 79},
                              ["sensor_lag"],
                              [("fit", slow_ramps(79, duration=8.0)), ("holdout", slow_ramps(80, duration=8.0))]),
    "spool_lag_on_ramps_3": ({"effects": {"valve_dynamics": {"f_n": 60.0, "zeta": 0.8}}, "seed": 81},
                             ["valve_dynamics"],
                             [("fit", slow_ramps(81, duration=8.0)), ("holdout", slow_ramps(82, duration=8.0))]),
    "sensor_lag_on_sweeps": ({"effects": {"sensor_lag": {"delay": 0.002, "tau": 0.002}}, "seed": 83},
                             ["sensor_lag"],
                             [("fit", slow_ramps(83, duration=8.0)), ("holdout", sine_sweep(84, duration=8.0))]),
    "leak_near_noise": ({"effects": {"piston_leakage": {"A_leak": 9e-9}}, "seed": 85}, ["piston_leakage"],
                        [("fit", sine_sweep(85, duration=8.0)), ("holdout", sine_sweep(86, duration=8.0))]),
    "deadband_near_noise": ({"effects": {"valve_deadband": {"overlap": 0.05, "edge": 0.02}}, "seed": 87},
                            ["valve_deadband"],
                            [("fit", random_steps(87, duration=8.0)), ("holdout", random_steps(88, duration=8.0))]),
    "heat_on_sweeps_2": ({"effects": {"heat_transfer": {"h_w": 40.0}}, "seed": 89}, ["heat_transfer"],
                         [("fit", sine_sweep(89, duration=8.0)), ("holdout", sine_sweep(90, duration=8.0))]),
}


def record(cfg: dict, cmd, path: Path, seed: int) -> Path:
    return write_recording(path, run_offline(dict(cfg, noise=NOISE, seed=seed), cmd, cmd.duration))


def run_case(name: str, folder: Path, workers: int, add: str = "fit", screen: bool = False) -> dict:
    cfg, truth, runs = CASES[name]
    d = folder / name
    d.mkdir(parents=True, exist_ok=True)
    fit, hold = [], []
    for i, (role, cmd) in enumerate(runs):
        path = record(cfg, cmd, d / f"{role}{i}.csv", cfg["seed"] + 10 * i)
        (fit if role == "fit" else hold).append(path)
    t0 = time.perf_counter()
    done = d / "before" / "diagnosis.json"
    if done.exists() and (d / "next.csv").exists():     # a run before, on the same recordings: reused
        doc, wall = json.loads(done.read_text()), float("nan")
    else:
        doc = diagnose(fit, hold, d / "before", workers=workers, propose=d / "next.csv")
        wall = time.perf_counter() - t0
    out = {"case": name, "truth": truth, "before": doc["verdict"], "p_before": doc.get("probabilities", {}),
           "wall_before_s": wall, "proposed": None, "after": None}
    n = doc.get("next_experiment") or {}
    if not n.get("needed") or screen:
        out["screened"] = bool(n.get("needed"))
        return out
    out["proposed"] = {k: n.get(k) for k in ("design", "params", "hypotheses", "separation", "seconds")}
    new = record(cfg, profile(str(d / "next.csv")), d / "proposed.csv", cfg["seed"] + 99)
    t0 = time.perf_counter()
    fit2, hold2 = ([*fit, new], hold) if add == "fit" else (fit, [*hold, new])
    doc2 = diagnose(fit2, hold2, d / f"after_{add}", workers=workers)
    out.update(after=doc2["verdict"], p_after=doc2.get("probabilities", {}), wall_after_s=time.perf_counter() - t0)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--add", choices=("fit", "holdout"), default="fit",
                    help="the proposed recording joins the fit recordings (default) or the holdouts")
    ap.add_argument("--screen", action="store_true",
                    help="only the first diagnoses (kept in --out, reused by a later run): which cases are ambiguous")
    ap.add_argument("--out", type=Path, default=None, help="folder for the recordings and reports (default: a temporary one)")
    args = ap.parse_args(argv)
    folder = args.out or Path(tempfile.mkdtemp(prefix="diagnosis_propose_"))
    print(f"{os.cpu_count()} cores, {args.workers} workers; the proposed recording added to the "
          f"{args.add} recordings; outputs in {folder}")
    ambiguous = decided = turned = 0
    for name in args.cases:
        r = run_case(name, folder, args.workers, args.add, args.screen)
        top = lambda p: ", ".join(f"{k} {v:.2f}" for k, v in list(p.items())[:3])
        line = (f"{name}: truth {r['truth']}; before {r['before']} ({top(r['p_before'])}; "
                f"{r['wall_before_s']:.0f} s incl. the proposal)")
        if r["proposed"] is None:
            print(line + ("; AMBIGUOUS (screen only)" if r.get("screened") else
                          "; not ambiguous: no experiment proposed"), flush=True)
            continue
        ambiguous += 1
        ok = r["after"] == r["truth"]
        decided += ok
        turned += ok and r["before"] != r["truth"]
        p = r["proposed"]
        print(line + f"\n  proposed {p['design']} {p['params']} to tell {p['hypotheses'][0]} from "
                     f"{p['hypotheses'][1]} (separation {p['separation']:.3g}, proposed in {p['seconds'] or float('nan'):.1f} s); after {r['after']} "
                     f"({top(r['p_after'])}): {'CORRECT' if ok else 'wrong'}", flush=True)
    print(f"ambiguous cases decided correctly by the proposed experiment: {decided} of {ambiguous} "
          f"({turned} of them wrong before)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
