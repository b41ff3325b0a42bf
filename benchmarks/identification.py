#!/usr/bin/env python3
"""Identification accuracy on virtual-rig recordings: the sound fit and the paper's method.

For the reference rig's parameters and ten random sets within +-20 % of them (K_v, F_s,
F_d, F_L, M), the virtual rig (no extra effects, sensor noise and quantisation on)
records the paper's multistep experiment; both methods identify the parameters from
that recording alone.  The identified model then runs the holdout experiment
(``holdout_multistep``, not used for fitting), against the rig's recording of it.
Prints and writes docs/identification.md: the relative error of each parameter by
method, and the holdout NRMSE of x.

    python benchmarks/identification.py [--sets 10] [--out docs/identification.md]
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from boomfmi.experiments import holdout_multistep, paper_multistep  # noqa: E402
from boomfmi.compare import nrmse, simulate_recording  # noqa: E402
from boomfmi.identify.fit import identify  # noqa: E402
from boomfmi.identify.paper import identify_paper  # noqa: E402
from boomfmi.identify.preprocess import prepare  # noqa: E402
from boomfmi.physics import reference_rig  # noqa: E402
from boomfmi.recording import Recording  # noqa: E402
from boomfmi.rig.offline import run_offline  # noqa: E402

NAMES = ("K_v", "F_s", "F_d", "F_L", "M")


def parameter_sets(n: int, seed: int = 2026):
    rng = np.random.default_rng(seed)
    sets = [{k: getattr(reference_rig, k) for k in NAMES}]
    while len(sets) < n + 1:
        s = {k: getattr(reference_rig, k) * rng.uniform(0.8, 1.2) for k in NAMES}
        if s["F_s"] > s["F_d"]:                        # static friction above Coulomb
            sets.append(s)
    return sets


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=10)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "identification.md")
    args = ap.parse_args(argv)
    fit_cmd, hold_cmd = paper_multistep(), holdout_multistep()
    rows = []
    t_all = time.perf_counter()
    for i, truth in enumerate(parameter_sets(args.sets)):
        cfg = {"params": truth, "seed": 100 + i}
        fit_rec = Recording(Path(f"set{i}_fit.csv"), run_offline(cfg, fit_cmd, fit_cmd.duration))
        hold_rec = Recording(Path(f"set{i}_hold.csv"), run_offline(dict(cfg, seed=200 + i), hold_cmd, hold_cmd.duration))
        prep = [prepare(fit_rec)]
        t = time.perf_counter()
        sound = identify(prep)
        t_fit = time.perf_counter() - t
        results = {"fit": sound.values(),
                   "paper (Eq. 13 printed)": identify_paper(prep, eq13="printed").values(),
                   "paper (Eq. 13 derived)": identify_paper(prep, eq13="derived").values()}
        cond = identify_paper(prep).details["condition_number"]
        holdout = nrmse(simulate_recording(results["fit"], hold_rec), hold_rec)["x"]
        rows.append((i, truth, results, holdout, cond, t_fit, sound.warnings))
        err = {k: 100 * (results["fit"][k] / truth[k] - 1) for k in NAMES}
        print(f"set {i:2d}: fit " + "  ".join(f"{k} {v:+6.2f}%" for k, v in err.items())
              + f"  | holdout NRMSE x {100 * holdout:.2f} %  ({t_fit:.1f} s)")
    methods = list(rows[0][2])
    lines = ["# Identification accuracy", "",
             "Made by `python benchmarks/identification.py` on "
             f"{platform.machine()} / Python {platform.python_version()} "
             f"({time.perf_counter() - t_all:.0f} s).", "",
             "Data: the virtual rig (`boomfmi.rig`, no extra effects; sensor noise 500 Pa and",
             "2e-4 rad, 12-bit quantisation) records the paper's multistep experiment (9 s) for",
             f"the reference rig's parameters (set 0) and {args.sets} random sets within +-20 % of",
             "them. Each method identifies K_v, F_s, F_d, F_L, M from that one recording. The",
             "sound method's model then runs `holdout_multistep` (other step levels, retracting",
             "at 8 V; not used for fitting) against the rig's recording of it.", "",
             "## Relative error of each parameter [%]", ""]
    for m in methods:
        lines += [f"### {m}", "", "| set | " + " | ".join(NAMES) + " |", "|---|" + "---|" * len(NAMES)]
        worst = {k: 0.0 for k in NAMES}
        for i, truth, res, *_ in rows:
            e = {k: 100 * (res[m][k] / truth[k] - 1) for k in NAMES}
            for k in NAMES:
                worst[k] = max(worst[k], abs(e[k])) if np.isfinite(e[k]) else np.inf
            lines.append(f"| {i} | " + " | ".join(f"{e[k]:+.2f}" for k in NAMES) + " |")
        lines.append("| **max abs** | " + " | ".join(f"**{worst[k]:.2f}**" for k in NAMES) + " |")
        lines.append("")
    lines += ["## The sound method on the holdout experiment", "",
              "| set | NRMSE of x | paper method's Eq. 16 condition number | fit time [s] | warnings |",
              "|---|---|---|---|---|"]
    for i, truth, res, hold, cond, t_fit, warns in rows:
        lines.append(f"| {i} | {100 * hold:.2f} % | {cond:.0f} | {t_fit:.1f} | {'; '.join(warns) or '-'} |")
    worst_fit = max(abs(r[2]['fit'][k] / r[1][k] - 1) for r in rows for k in NAMES)
    worst_hold = max(r[3] for r in rows)
    lines += ["", f"Sound method: every parameter within {100 * worst_fit:.2f} % of the truth "
              f"(target 5 %); holdout NRMSE of x at most {100 * worst_hold:.2f} % (target 2 %).", "",
              "The paper's method fails for reasons the paper's own numbers show: its starts of",
              "motion are seen only once the piston has visibly moved, while the pressures race",
              "on (a start from the upper stop sweeps the static band in about a millisecond),",
              "so F_StartP and F_StartN, hence F_L and F_s by Eq. 13, are off; and the three",
              "'constant acceleration' states are nearly alike (all at about the same speed,",
              "accelerations near zero), so Eq. 16 is badly conditioned and M, and with it",
              "K_v and F_d, come out anywhere, negative included. Eq. 13 as printed has the",
              "wrong sign for F_StartN as Eq. 14 defines it (docs/paper-errata.md, 8.1); the",
              "derived form is shown beside it.", ""]
    args.out.write_text("\n".join(lines))
    print(f"worst parameter error (fit): {100 * worst_fit:.2f} %, worst holdout NRMSE x: {100 * worst_hold:.2f} %")
    print(f"wrote {args.out}")
    return 0 if worst_fit < 0.05 and worst_hold < 0.02 else 1


if __name__ == "__main__":
    sys.exit(main())
