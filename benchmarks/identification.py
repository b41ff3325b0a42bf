#!/usr/bin/env python3
"""Identification accuracy: the sound fit and the paper's method, and the sound fit on
every command design, sensor and simulator.

Part 1: for the reference rig's parameters and ten random sets within +-20 % of them
(K_v, F_s, F_d, F_L, M), the virtual rig (no extra effects, sensor noise and
quantisation on) records the paper's multistep experiment; both methods identify the
parameters from that recording alone.  The identified model then runs the holdout
experiment (``holdout_multistep``, not used for fitting), against the rig's recording.

Part 2: effect-free recordings of random rigs (load within +-15 %) on each command
design (random steps, the paper's experiment, an operator's manoeuvres, a sine
sweep), from the virtual rig (its 12-bit angle sensor over 180 degrees) and from the
independent simulator ``benchmarks/hybrid_rig.py`` (a 12-bit and a 16-bit angle sensor
over 300 degrees); the sound method identifies each from that one recording.  For
every parameter: the largest error, and how often its 95 % interval covers the truth
(F_s's error where the data identify it; where they do not, the method says so).

Prints and writes docs/identification.md.

    python benchmarks/identification.py [--sets 10] [--rigs 4] [--out docs/identification.md]
    python benchmarks/identification.py --noise-seeds 0 1 2 3 4 5 6 7 8 9

Part 3 (``--noise-seeds``, run alone, nothing written): the reference rig's load on
``hybrid_rig.py``, one command design under each sensor noise seed and each of three
sensor variants (:data:`NOISE_VARIANTS`): does the identification hold over noise draws?
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
sys.path.insert(0, str(ROOT / "benchmarks"))

import hybrid_rig as hr  # noqa: E402
from boomfmi.experiments import (holdout_multistep, manoeuvres, paper_multistep, random_steps,  # noqa: E402
                                 sine_sweep)
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
    ap.add_argument("--rigs", type=int, default=4, help="random rigs per design and sensor in part 2")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "identification.md")
    ap.add_argument("--noise-seeds", type=int, nargs="+", default=None,
                    help="part 3 only: the boom on hybrid_rig.py, one load and one command design under each "
                         "of these sensor noise seeds and each sensor variant (nothing written)")
    args = ap.parse_args(argv)
    if args.noise_seeds is not None:
        return 0 if noise_draws(args.noise_seeds) else 1
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
        told = sound.details["static_friction"].get("identified", False)
        rows.append((i, truth, results, holdout, cond, t_fit, sound.warnings, told))
        err = {k: 100 * (results["fit"][k] / truth[k] - 1) for k in NAMES}
        print(f"set {i:2d}: fit " + "  ".join(f"{k} {v:+6.2f}%" for k, v in err.items())
              + f"{'' if told else ' (F_s not identified)'}  | holdout NRMSE x {100 * holdout:.2f} %  ({t_fit:.1f} s)")
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
        for i, truth, res, *_, told in rows:
            e = {k: 100 * (res[m][k] / truth[k] - 1) for k in NAMES}
            for k in NAMES:
                if m == "fit" and k == "F_s" and not told:
                    continue             # the sound fit said it cannot tell F_s here
                worst[k] = max(worst[k], abs(e[k])) if np.isfinite(e[k]) else np.inf
            lines.append(f"| {i} | " + " | ".join(f"{e[k]:+.2f}" + ("*" if m == "fit" and k == "F_s" and not told else "")
                                                   for k in NAMES) + " |")
        lines.append("| **max abs** | " + " | ".join(f"**{worst[k]:.2f}**" for k in NAMES) + " |")
        if m == "fit":
            lines.append("")
            lines.append("\\* the fit says the data cannot tell F_s within +-10 % (its interval, reported, "
                         "holds the truth); not counted in the maximum.")
        lines.append("")
    lines += ["## The sound method on the holdout experiment", "",
              "| set | NRMSE of x | paper method's Eq. 16 condition number | fit time [s] | warnings |",
              "|---|---|---|---|---|"]
    for i, truth, res, hold, cond, t_fit, warns, _ in rows:
        lines.append(f"| {i} | {100 * hold:.2f} % | {cond:.0f} | {t_fit:.1f} | {'; '.join(warns) or '-'} |")
    worst_fit = max(abs(r[2]['fit'][k] / r[1][k] - 1) for r in rows for k in NAMES if k != "F_s" or r[7])
    worst_hold = max(r[3] for r in rows)
    lines += ["", f"Sound method: every parameter within {100 * worst_fit:.2f} % of the truth (F_s where identified) "
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
    part2, ok2 = designs_sensors(args.rigs)
    lines += part2
    args.out.write_text("\n".join(lines))
    print(f"worst parameter error (fit): {100 * worst_fit:.2f} %, worst holdout NRMSE x: {100 * worst_hold:.2f} %")
    print(f"wrote {args.out}")
    return 0 if worst_fit < 0.05 and worst_hold < 0.02 and ok2 else 1


DURATION = 10.0
DESIGNS = {"random_steps": lambda s: random_steps(s, duration=DURATION), "paper": lambda s: paper_multistep(),
           "manoeuvres": lambda s: manoeuvres(s, duration=DURATION), "sine_sweep": lambda s: sine_sweep(s, duration=DURATION)}
SOURCES = {"virtual rig, 12 bit / 180 deg": None,
           "hybrid_rig, 12 bit / 300 deg": {"angle_bits": 12},
           "hybrid_rig, 16 bit / 300 deg": {"angle_bits": 16}}


def _record(source, load, design, seed):
    prof = DESIGNS[design](seed)
    if SOURCES[source] is None:
        df = run_offline({"params": load, "seed": seed}, prof, prof.duration)
    else:
        df = hr.simulate(hr.Plant(**load, sensors=dict(SOURCES[source])), prof, seed=seed)[["t", "u", "p_a", "p_b", "alpha"]]
    return Recording(Path(f"{design}_{seed}.csv"), df)


def designs_sensors(rigs: int, seed: int = 1616):
    """Part 2 (see the module's docstring): (markdown lines, every target met)."""
    rng = np.random.default_rng(seed)
    rows = []
    for source in SOURCES:
        for design in DESIGNS:
            for j in range(rigs):
                load = {k: float(getattr(reference_rig, k) * rng.uniform(0.85, 1.15)) for k in NAMES}
                load["F_s"] = max(load["F_s"], 1.05 * load["F_d"])
                case_seed = int(rng.integers(1 << 30))
                rec = _record(source, load, design, case_seed)
                t = time.perf_counter()
                res = identify([prepare(rec)])
                wall = time.perf_counter() - t
                told = res.details["static_friction"].get("identified", False)
                err = {k: res.params[k].value / load[k] - 1 for k in NAMES}
                cover = {k: res.params[k].ci95[0] <= load[k] <= res.params[k].ci95[1] for k in NAMES}
                rows.append(dict(source=source, design=design, load=load, err=err, cover=cover,
                                 F_s_identified=told, wall=wall))
                print(f"{source:30s} {design:13s} " + "  ".join(
                    f"{k} {100 * err[k]:+6.2f}%{'' if cover[k] else '!'}" for k in NAMES)
                    + f"  F_s {'identified' if told else 'not identified'} ({wall:.1f} s)", flush=True)
    lines = ["## Every command design, sensor and simulator (effect-free)", "",
             f"{len(rows)} recordings of {DURATION:g} s ({rigs} random rigs per design and source; the load within",
             "+-15 % of the reference rig), each identified alone. Error: the largest relative error",
             "over the cases (F_s: over the cases where the method says the data identify it); coverage:",
             "the share of cases whose 95 % interval holds the truth.", "",
             "| source | design | " + " | ".join(f"max error {k}" for k in NAMES) + " | F_s identified |",
             "|---|---|" + "---|" * (len(NAMES) + 1)]
    for source in SOURCES:
        for design in DESIGNS:
            sel = [r for r in rows if r["source"] == source and r["design"] == design]
            cells = []
            for k in NAMES:
                errs = [abs(r["err"][k]) for r in sel if k != "F_s" or r["F_s_identified"]]
                cells.append(f"{100 * max(errs):.2f} %" if errs else "-")
            lines.append(f"| {source} | {design} | " + " | ".join(cells)
                         + f" | {sum(r['F_s_identified'] for r in sel)} of {len(sel)} |")
    worst = {k: max((abs(r["err"][k]) for r in rows if k != "F_s" or r["F_s_identified"]), default=0.0) for k in NAMES}
    coverage = {k: sum(r["cover"][k] for r in rows) / len(rows) for k in NAMES}
    lines += ["", "| | " + " | ".join(NAMES) + " |", "|---|" + "---|" * len(NAMES),
              "| largest error | " + " | ".join(f"{100 * worst[k]:.2f} %" for k in NAMES) + " |",
              "| 95 % interval coverage | " + " | ".join(f"{100 * coverage[k]:.0f} %" for k in NAMES) + " |", "",
              f"F_s identified in {sum(r['F_s_identified'] for r in rows)} of {len(rows)} recordings; where it is not,",
              "identify says so and reports its interval (the starts such a recording holds are too fast",
              "to place the static level). Targets: every parameter within 5 %, coverage at least 90 %.", ""]
    ok = all(w < 0.05 for w in worst.values()) and all(c >= 0.9 for c in coverage.values())
    print("part 2: largest errors " + ", ".join(f"{k} {100 * w:.2f} %" for k, w in worst.items())
          + "; coverage " + ", ".join(f"{k} {100 * c:.0f} %" for k, c in coverage.items()))
    return lines, ok


#: Part 3's sensor variants on hybrid_rig.py, as the excavator's benchmark has them:
#: its own sensors (12-bit angle over 300 degrees, 1e-4 rad and 500 Pa of noise, 12-bit
#: pressures), twice their noise, and a fifth of the angle's and two fifths of the
#: pressures' noise without converters.
NOISE_VARIANTS = {
    "standard": {},
    "noisy": {"angle_noise": 2.0 * hr.SENSOR_DEFAULTS["angle_noise"], "p_noise": 2.0 * hr.SENSOR_DEFAULTS["p_noise"]},
    "fine": {"angle_noise": 0.25 * hr.SENSOR_DEFAULTS["angle_noise"], "p_noise": 0.4 * hr.SENSOR_DEFAULTS["p_noise"],
             "angle_bits": None, "p_bits": None},
}
#: Part 3's command design and its seed (the same commands under every noise draw).
NOISE_DESIGN, NOISE_DESIGN_SEED = "random_steps", 1


def noise_draws(seeds) -> bool:
    """Part 3: the reference rig's load on hybrid_rig.py, the same commands
    (``NOISE_DESIGN``) under each noise seed and sensor variant, each recording
    identified alone; per parameter the largest error, the mean signed error (F_s's
    target within +-1 %), the misses not flagged (beyond 5 % where identify does not say
    it cannot tell) and the 95 % intervals' coverage (target 90 %).  Every target met?"""
    load = {k: float(getattr(reference_rig, k)) for k in NAMES}
    prof = DESIGNS[NOISE_DESIGN](NOISE_DESIGN_SEED)
    every, ok = [], True
    for variant, sensors in NOISE_VARIANTS.items():
        rows = []
        for seed in seeds:
            t = time.perf_counter()
            df = hr.simulate(hr.Plant(**load, sensors=dict(sensors)), prof, seed=seed)[["t", "u", "p_a", "p_b", "alpha"]]
            res = identify([prepare(Recording(Path(f"noise_{variant}_{seed}.csv"), df))])
            told = res.details["static_friction"].get("identified", False)
            flag = {k: (not told) if k == "F_s" else not res.params[k].tells for k in NAMES}
            rows.append((res.params, flag))
            print(f"{variant} sensors, noise seed {seed} ({time.perf_counter() - t:.0f} s): " + "  ".join(
                f"{k} {100 * (res.params[k].value / load[k] - 1):+.2f}%"
                + ("" if res.params[k].ci95[0] <= load[k] <= res.params[k].ci95[1] else "!") + ("?" if flag[k] else "")
                for k in NAMES), flush=True)
        print(f"{variant} sensors over {len(seeds)} noise seeds ({NOISE_DESIGN}({NOISE_DESIGN_SEED}); "
              "! the interval misses the truth, ? cannot tell):")
        ok &= _noise_lines(rows, load)
        every += rows
    print(f"every variant, {len(every)} runs:")
    ok &= _noise_lines(every, load)
    print(f"part 3 targets (within 5 % or flagged, F_s's mean error within +-1 %, coverage >= 90 %): "
          f"{'met' if ok else 'NOT met'}")
    return ok


def _noise_lines(rows, truth) -> bool:
    ok = True
    for k in NAMES:
        errs = np.array([100.0 * (p[k].value / truth[k] - 1) for p, _ in rows])
        cover = np.mean([p[k].ci95[0] <= truth[k] <= p[k].ci95[1] for p, _ in rows])
        misses = sum(abs(e) > 5.0 and not f[k] for e, (_, f) in zip(errs, rows))
        mean_ok = k != "F_s" or abs(errs.mean()) <= 1.0
        ok &= misses == 0 and cover >= 0.9 and mean_ok
        print(f"  {k:4s} worst {np.max(np.abs(errs)):6.2f} %  mean {errs.mean():+6.2f} %"
              f"{'' if mean_ok else ' (OVER +-1 %)':14s} unflagged misses {misses:2d}  coverage {100 * cover:5.1f} %"
              f"{'' if cover >= 0.9 else ' (UNDER 90 %)':13s} cannot tell {sum(f[k] for _, f in rows)}/{len(rows)}")
    return ok


if __name__ == "__main__":
    sys.exit(main())
