#!/usr/bin/env python3
"""Time of one diagnosis, end to end, on two cases of the virtual rig.

Each case is two fit recordings and one holdout recording; the script times
``boomfmi.diagnose.diagnose`` on them, end to end (reading, baseline identification,
localisation, every candidate's fit and score, pairs where they are tried, the
report).  Target: under 60 s each on the 2-core machine (idle).

* ``heat``: heat transfer on, load parameters off the reference by a few per cent,
  noise on; three runs of 10 s of different random step commands.
* ``pair``: a valve deadband and a piston leak together (issue 35's example of a pair
  where neither effect alone explains the gap); three runs of 13 s, of different
  designs: random steps and slow ramps around the valve's centre to fit, an operator's
  manoeuvres held out.  The diagnosis tries pairs here.

    python benchmarks/diagnosis_speed.py [--case heat|pair|all]
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from boomfmi.diagnose import diagnose  # noqa: E402
from boomfmi.experiments import manoeuvres, random_steps, slow_ramps  # noqa: E402
from boomfmi.recording import write_recording  # noqa: E402
from boomfmi.rig.offline import run_offline  # noqa: E402


#: case -> (rig configuration, [(fit or holdout, command)]): the commands' seeds differ
CASES = {
    "heat": ({"params": {"K_v": 2950.0, "M": 21.5, "F_L": 270.0}, "effects": {"heat_transfer": {}}, "seed": 31},
             [("fit", random_steps(41, duration=10.0)), ("fit", random_steps(42, duration=10.0)),
              ("holdout", random_steps(43, duration=10.0))]),
    "pair": ({"params": {"K_v": 2900.0, "F_d": 88.0}, "seed": 35,
              "effects": {"valve_deadband": {"overlap": 0.4, "edge": 0.15}, "piston_leakage": {"A_leak": 2e-8}}},
             [("fit", random_steps(51, duration=13.0)), ("fit", slow_ramps(52, duration=13.0)),
              ("holdout", manoeuvres(53, duration=13.0))]),
}


def run_case(name: str) -> tuple[float, dict, float]:
    """(wall time [s] of the diagnosis, its document, the recordings' length [s])."""
    cfg, runs = CASES[name]
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        fit, hold = [], []
        for i, (role, cmd) in enumerate(runs):
            path = write_recording(d / f"{name}{i}.csv", run_offline(dict(cfg, seed=cfg["seed"] + i), cmd, cmd.duration))
            (fit if role == "fit" else hold).append(path)
        t = time.perf_counter()
        doc = diagnose(fit, hold, d / "out")
        return time.perf_counter() - t, doc, runs[0][1].duration


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=[*CASES, "all"], default="all")
    args = ap.parse_args(argv)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    for name in (CASES if args.case == "all" else [args.case]):
        wall, doc, duration = run_case(name)
        pairs = sum("+" in c["name"] for c in doc.get("effects", []))     # a pair's name: "a+b"
        print(f"{name}: diagnosis of 2 fit + 1 holdout recordings of {duration:g} s: {wall:.1f} s wall "
              f"(target 60 s); {pairs} pair(s) among the candidates reported; verdict {doc['verdict']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
