#!/usr/bin/env python3
"""The solver's longest step where a recorded command ramps, against its numerical error.

``compare.simulate_recording`` follows a command that moves a little each sample as a
ramp, and bounds the solver's step there (``compare.MAX_STEP``), or a state at rest
would stride over the command's moves.  The bound sets most of the diagnosis's time:
at 2 ms the solver takes ~6500 steps on a 13 s recording whatever its tolerance.  This
script measures what a longer bound costs in accuracy: on recordings of the virtual
rig (five command designs, three seeds, heat transfer on), the model with four effect
sets is solved at the fits' and the scoring's tolerances (``diagnose.attribute``'s
``FIT_RTOL``, ``RTOL``) with each bound, and compared with a solve at rtol 1e-7 and a
0.5 ms bound.  The error is the RMS over the channel's range, as a share of that
recording's noise floor (``identify.preprocess.noise_floor``: the NRMSE a perfect model
still shows), the worst channel of x, p_a, p_b.

    python benchmarks/solver_step.py [--bounds 0.002 0.005 0.01 0.02] [--seeds 1 2 3]
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from boomfmi.compare import MAX_STEP, simulate_recording  # noqa: E402
from boomfmi.diagnose.attribute import FIT_RTOL, RTOL  # noqa: E402
from boomfmi.experiments import joystick, manoeuvres, random_steps, sine_sweep, slow_ramps  # noqa: E402
from boomfmi.identify.preprocess import noise_floor  # noqa: E402
from boomfmi.recording import read_recording, write_recording  # noqa: E402
from boomfmi.rig.offline import run_offline  # noqa: E402

DESIGNS = {"random steps": random_steps, "slow ramps": slow_ramps, "manoeuvres": manoeuvres,
           "sine sweep": sine_sweep, "joystick": joystick}
#: the effect sets the model is solved with (as a fit would try them)
EFFECT_SETS = {"none": None,
               "deadband + leak": {"valve_deadband": {"width_ext": 0.1, "width_ret": 0.1},
                                   "piston_leakage": {"C": 3e-12}},
               "heat": {"heat_transfer": {"h": 20.0}},
               "spool lag": {"valve_dynamics": {"tau": 0.008}}}
RIG = {"params": {"K_v": 2900.0, "F_d": 88.0}, "effects": {"heat_transfer": {}}}
DURATION = 13.0
FINE = dict(rtol=1e-7, max_step=5e-4)


def worst_share(sim, ref, floor: dict) -> float:
    """The worst channel's RMS difference over its range, as a share of its noise floor."""
    return max(float(np.sqrt(np.mean((sim[c] - ref[c]) ** 2)) / (np.ptp(ref[c]) or 1.0)) / max(floor[c], 1e-9)
               for c in ("p_a", "p_b", "x"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bounds", type=float, nargs="+", default=[0.002, 0.005, MAX_STEP, 0.02])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = ap.parse_args(argv)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
          f"compare.MAX_STEP = {MAX_STEP * 1e3:g} ms")
    rtols = {"fit": FIT_RTOL, "score": RTOL}
    worst = {(d, r, b): 0.0 for d in DESIGNS for r in rtols for b in args.bounds}
    wall = {(r, b): 0.0 for r in rtols for b in args.bounds}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for k, (design, make) in enumerate(DESIGNS.items()):
                cmd = make(60 + 10 * seed + k, duration=DURATION)
                path = write_recording(Path(tmp) / f"{k}_{seed}.csv", run_offline(dict(RIG, seed=seed), cmd, DURATION))
                rec = read_recording(path)
                values = dict(RIG["params"])          # the model at the rig's load (the effects differ)
                floor = noise_floor(rec)
                for fx in EFFECT_SETS.values():
                    ref = simulate_recording(values, rec, effects=fx, **FINE)
                    for r, rtol in rtols.items():
                        for b in args.bounds:
                            t = time.perf_counter()
                            sim = simulate_recording(values, rec, effects=fx, rtol=rtol, max_step=b)
                            wall[r, b] += time.perf_counter() - t
                            worst[design, r, b] = max(worst[design, r, b], worst_share(sim, ref, floor))
                print(f"  seed {seed}, {design}: done", flush=True)
    n = len(args.seeds) * len(EFFECT_SETS)
    head = " | ".join(f"{b * 1e3:g} ms" for b in args.bounds)
    for r, rtol in rtols.items():
        print(f"\nworst error / noise floor, rtol {rtol:g} ({r}), over {n} solves per design:")
        print(f"| design | {head} |")
        print("|---|" + "---|" * len(args.bounds))
        for d in DESIGNS:
            print(f"| {d} | " + " | ".join(f"{worst[d, r, b]:.3f}" for b in args.bounds) + " |")
        base = wall[r, args.bounds[0]]
        print("| time, relative to the first bound | " + " | ".join(f"{wall[r, b] / base:.2f}" for b in args.bounds)
              + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
