#!/usr/bin/env python3
"""The bench tools on real measurements: a pneumatic cylinder's friction tests with
eleven seal designs, and leak-down tests of closed chambers
(``../shared/realdata/cylinder-friction-leak/``, CC0; Zillen, Vallery, Smit 2021).

Friction: for each seal design, every law (eq9, stribeck, pressure) is fitted on some
of its tests and scored on others it was not fitted on:

* designs tested at five or more pressures: fitted at the odd pressures (1, 3, 5, 7
  bar), scored at the even ones (2, 4, 6 bar): interpolation in pressure, and a test
  session of its own (the even-pressure files were sampled at about 60 Hz);
* the others: fitted on the first half of every test's strokes, scored on the second.

Held-out files (``transfer_rows``): every law scored on whole files it was not fitted
on, leaving one pressure out and one seal design out, beside the within-file floor
and the error left once the session's constants (F_0, A_eff) are refitted on the
held-out file: the figures to quote, and how much of them is the session's drift.

``O-ring_*`` files are byte-identical to ``Circle_*`` and are counted once (as Circle).

Leak-down: every run of the single-run files (``zillen2021-leak`` preset) and every
column of the two ``Resultaten_*`` repeat files (pressure change since the start,
decimal comma; the unit is read as mbar, see docs/real-data.md) is fitted with the
laminar and orifice laws, with and without thermal relaxation.  The chambers' volumes
are not published: the leak sizes are given for a 1 L chamber (a conductance or area
in proportion to the volume).

Writes ``docs/real-data.md`` and prints the figures; the bench's own outputs (JSON,
HTML, plots) go to ``--work`` (default: a temporary folder).

    python benchmarks/real_bench.py [--out docs/real-data.md] [--work DIR] [--n-boot 200]
"""
from __future__ import annotations

import argparse
import hashlib
import math
import platform
import re
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from boomfmi.bench import run_friction, run_leak  # noqa: E402
from boomfmi.foreign import read_options  # noqa: E402

DATA = ROOT.parent / "shared" / "realdata" / "cylinder-friction-leak"
#: Bores (README of the data): 25.7 mm for the *257 designs, 25 mm (or its area) for the rest.
AREA_257 = 5.187e-4
AREA_25 = 4.909e-4
#: The repeat files' start pressure: they hold changes only; the single runs start at 7.3 to 7.8 bar.
REPEAT_START = "7.5 bar"
VOLUME = 1e-3


def seal_files() -> dict[str, list[tuple[float, Path]]]:
    """Each seal design's tests as (pressure [bar], path), duplicates by content dropped."""
    seals, seen = defaultdict(list), {}
    for path in sorted((DATA / "friction").glob("*.csv")):
        m = re.fullmatch(r"(.+?)_(\d+)bar(_\w+)?", path.stem)
        if not m:
            continue
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        if digest in seen:
            continue
        seen[digest] = path
        seals[m.group(1)].append((float(m.group(2)), path))
    seals.pop("O-ring", None)          # (every O-ring file is a Circle file; dropped above by content anyway)
    return dict(seals)


def split(tests):
    """(FIT, HOLD, how): odd and even pressures where there are five or more, else
    stroke halves."""
    pressures = sorted({p for p, _ in tests})
    if len(pressures) >= 5:
        fit = [path for p, path in tests if int(p) % 2 == 1]
        hold = [path for p, path in tests if int(p) % 2 == 0]
        return fit, hold, (f"fit {', '.join(f'{p:g}' for p in pressures if int(p) % 2)} bar, "
                           f"scored {', '.join(f'{p:g}' for p in pressures if not int(p) % 2)} bar")
    return [path for _, path in tests], [], (f"{', '.join(f'{p:g}' for p in pressures)} bar: fit first half of "
                                             f"the strokes, scored second half")


def per_bar(value: float) -> float:
    return value * 1e5


def friction_rows(work: Path, n_boot: int):
    rows = []
    for seal, tests in sorted(seal_files().items()):
        area = AREA_257 if seal.endswith("257") else AREA_25
        fit, hold, how = split(tests)
        print(f"friction {seal}: {how}", flush=True)
        doc = run_friction(fit, hold, area, read_options("zillen2021"), work / "friction" / seal,
                           split=not hold, n_boot=n_boot)
        L = doc["laws"]
        P, I = L["pressure"]["parameters"], L["pressure"]["intervals"]
        row = {"seal": seal, "how": how, "area": area, "chosen": doc["chosen"],
               "rmse": {law: L[law]["rmse_holdout_N"] for law in L},
               "c_d": per_bar(P["c_d"]), "c_d_ci": [per_bar(v) for v in I["c_d"]],
               "F_d0": P["F_d0"], "F_d0_ci": I["F_d0"],
               "c_s_pos": per_bar(P["c_s_pos"]), "c_s_pos_ci": [per_bar(v) for v in I["c_s_pos"]],
               "c_s_neg": per_bar(P["c_s_neg"]), "c_s_neg_ci": [per_bar(v) for v in I["c_s_neg"]],
               "F_s0_pos": P["F_s0_pos"], "F_s0_neg": P["F_s0_neg"],
               "K_v": P["K_v"], "K_v_ci": I["K_v"], "A_ratio": P["A_eff"] / area, "F_0": P["F_0"],
               "ratio_7_1": (P["F_d0"] + 7e5 * P["c_d"]) / (P["F_d0"] + 1e5 * P["c_d"]),
               "gains": doc["choice"]["comparisons"], "warnings": doc["warnings"]}
        rows.append(row)
        print(f"  holdout RMSE eq9 {row['rmse']['eq9']:.2f} N, stribeck {row['rmse']['stribeck']:.2f} N, "
              f"pressure {row['rmse']['pressure']:.2f} N; chosen {row['chosen']}; "
              f"F_d(p) = {row['F_d0']:.2f} N + {row['c_d']:.2f} N/bar p "
              f"(c_d [{row['c_d_ci'][0]:.2f}, {row['c_d_ci'][1]:.2f}]); static c_s + {row['c_s_pos']:.2f}, "
              f"- {row['c_s_neg']:.2f} N/bar; A_eff/A {row['A_ratio']:.3f}", flush=True)
    return rows


# ------------------------------------------------------------------ held-out files
# leave one seal out fits on the designs of the same bore (A_eff is one per fit)
def _bore(seal: str) -> float:
    return AREA_257 if seal.endswith("257") else AREA_25


def _sse(fit, d) -> tuple[float, int]:
    from boomfmi.bench import friction as fb
    r = d.F - fb.predict(fit, d)
    return float(r @ r), len(r)


def _session_refit(fit, d):
    """The law with its friction kept and only the session's constants (the load cell's
    offset F_0 and the effective area A_eff: the pressure sensor's and force sensor's
    calibration of the day) refitted on ``d``."""
    from dataclasses import replace
    from scipy.optimize import least_squares
    from boomfmi.bench import friction as fb
    P = fit.params

    def res(q):
        return d.F - fb.predict(replace(fit, params={**P, "A_eff": q[0], "F_0": q[1]}), d)
    q = least_squares(res, [P["A_eff"], P["F_0"]], x_scale=[P["A_eff"], 1.0]).x
    return replace(fit, params={**P, "A_eff": float(q[0]), "F_0": float(q[1])})


def _rms(parts) -> float:
    sse, n = map(sum, zip(*parts))
    return math.sqrt(sse / n)


def transfer_rows(laws=("eq9", "stribeck", "pressure"), only=None):
    """Every law scored on whole files it never saw, two ways, with what of the error is
    the session and what the law:

    * leave one pressure out: per seal design, each pressure's files held out in turn,
      the law fitted on the design's other pressures (its own sessions: each file is one
      run of the rig);
    * leave one seal out: each design held out, the law fitted on every other design of
      the same bore.

    For each held-out file also: ``within``, the law fitted on the file's own first half
    of the strokes and scored on its second (the floor: the same session, the law's own
    scatter), and ``session``, the transferred law with only F_0 and A_eff refitted on
    the file (what is left once the session's offset and calibration are taken out).
    RMSEs are over every held-out sample [N].  ``only``: the designs to hold out (default
    every one; the others of their bore are still fitted on)."""
    from boomfmi.bench import friction as fb
    opts = read_options("zillen2021")
    runs = {seal: [(p, fb.load_run(path, opts)) for p, path in sorted(tests)]
            for seal, tests in sorted(seal_files().items())}
    held_seals = [seal for seal in runs if only is None or seal in only]
    within = {}
    for seal in held_seals:
        for _, r in runs[seal]:
            first, second = fb.split_strokes(r)
            d1, d2 = fb.combine([first]), fb.combine([second])
            within[r.path] = {law: _sse(fb.fit_law(law, d1, A_fixed=_bore(seal)), d2) for law in laws}
    rows = []
    for mode in ("pressure", "seal"):
        for seal in held_seals:
            rs = runs[seal]
            groups = ([[r for p2, r in rs if p2 == p] for p in sorted({p for p, _ in rs})] if mode == "pressure"
                      else [[r for _, r in rs]])
            acc = {law: {"held": [], "session": [], "within": []} for law in laws}
            for held in groups:
                if mode == "pressure":
                    train = [r for _, r in rs if all(r is not h for h in held)]
                else:
                    train = [r for s2, rs2 in runs.items() if s2 != seal and _bore(s2) == _bore(seal)
                             for _, r in rs2]
                d_fit = fb.combine(train)
                for law in laws:
                    fit = fb.fit_law(law, d_fit)
                    for h in held:
                        d_h = fb.combine([h])
                        acc[law]["held"].append(_sse(fit, d_h))
                        acc[law]["session"].append(_sse(_session_refit(fit, d_h), d_h))
                        acc[law]["within"].append(within[h.path][law])
            row = {"mode": mode, "seal": seal, "files": sum(len(g) for g in groups),
                   "pressures": sorted({p for p, _ in rs}),
                   "rmse": {law: {k: _rms(v) for k, v in a.items()} for law, a in acc.items()}}
            rows.append(row)
            P = row["rmse"]["pressure"]
            print(f"held-out files, leave one {mode} out, {seal}: pressure law {P['held']:.2f} N "
                  f"(session constants refitted {P['session']:.2f} N; within-file floor {P['within']:.2f} N)",
                  flush=True)
    return rows


def held_out_section(tr, fr) -> list[str]:
    """docs/real-data.md's lines on the laws scored on whole files of other sessions."""
    if not tr:
        return []
    L = ["### On files of other sessions: the figures to quote", "",
         "Every file is one session of the rig (mounted, pressurised, zeroed, run). A law fitted on some "
         "files and scored on a whole file it never saw is what a user of the law gets on another day: "
         "**leave one pressure out** (per design, each pressure's files held out in turn, the law fitted on "
         "the design's other pressures; 1 and 7 bar held out are extrapolations) and **leave one seal out** "
         "(each design held out, the law fitted on all other designs of the same bore). Beside each: the "
         "same transferred law with only the session's constants refitted on the held-out file (the load "
         "cell's offset F_0 and the effective area A_eff: the day's zero and calibration), and the "
         "within-file floor (the law fitted on the file's own first half of the strokes, scored on its "
         "second). Held-out RMSE squared = session part + law part: the session's share is "
         "(held^2 - refitted^2) / held^2 of the mean squared error; what remains above the floor is the "
         "law's own transfer error. RMSE [N] over every held-out sample:", "",
         "| seal design | pressures [bar] | one pressure out: eq9 / stribeck / pressure | pressure law, "
         "F_0 and A_eff refitted | within-file floor | share in F_0 + p A_eff | one seal out: pressure law | "
         "F_0 and A_eff refitted | share in F_0 + p A_eff |",
         "|---|---|---|---|---|---|---|---|---|"]
    share = lambda r: (r["held"] ** 2 - r["session"] ** 2) / r["held"] ** 2   # noqa: E731
    by = {(r["mode"], r["seal"]): r for r in tr}
    seals = sorted({r["seal"] for r in tr})
    for seal in seals:
        a, b = by[("pressure", seal)], by[("seal", seal)]
        A, B = a["rmse"], b["rmse"]
        L.append(f"| {seal} | {', '.join(f'{p:g}' for p in a['pressures'])} | {A['eq9']['held']:.2f} / "
                 f"{A['stribeck']['held']:.2f} / **{A['pressure']['held']:.2f}** | {A['pressure']['session']:.2f} | "
                 f"{A['pressure']['within']:.2f} | {100 * share(A['pressure']):.0f} % | "
                 f"{B['pressure']['held']:.2f} | {B['pressure']['session']:.2f} | {100 * share(B['pressure']):.0f} % |")
    lopo = np.array([by[("pressure", s)]["rmse"]["pressure"]["held"] for s in seals])
    floor = np.array([by[("pressure", s)]["rmse"]["pressure"]["within"] for s in seals])
    sess = np.array([by[("pressure", s)]["rmse"]["pressure"]["session"] for s in seals])
    loso = np.array([by[("seal", s)]["rmse"]["pressure"]["held"] for s in seals])
    loso_s = np.array([by[("seal", s)]["rmse"]["pressure"]["session"] for s in seals])
    sh = (lopo ** 2 - sess ** 2) / lopo ** 2
    L += ["", f"Leave one pressure out, the pressure law's error on another session's file is "
          f"{np.median(lopo / floor):.2f} times the within-file floor (median over the designs; "
          f"{(lopo / floor).min():.2f} to {(lopo / floor).max():.2f}); of its mean squared error "
          f"{100 * np.median(sh):.0f} % (median; {100 * sh.min():.0f} to {100 * sh.max():.0f} %) is the "
          f"session's offset and calibration, which a zero and an area check on the day remove: refitted, "
          f"the error is {np.median(sess / floor):.2f} times the floor, so the law itself transfers across "
          f"pressures. (The refit takes out whatever acts alike in both directions, F_0 + p A_eff: the "
          f"session's drift, and any error of the law's that looks like it; the friction, which changes "
          f"sign with the direction, it leaves to the law.) Leave one seal out, a law from the other designs "
          f"misses by {np.median(loso):.1f} N (median), {np.median(loso_s):.1f} N once F_0 and A_eff are "
          f"refitted: the designs differ mostly in what acts alike both ways (their effective area, "
          f"A_eff / A from {min(r['A_ratio'] for r in fr):.3f} to {max(r['A_ratio'] for r in fr):.3f} in the "
          f"table below at {AREA_25 * 1e5:.0f} N/bar of nominal area, and the day's zero), which a new seal's "
          f"own zero and area check gives; the friction carried over from the other designs is then "
          f"{np.median(loso_s / floor):.2f} times the floor (median; {(loso_s / floor).min():.2f} to "
          f"{(loso_s / floor).max():.2f}).", ""]
    return L


def leak_runs():
    """(label, path, read options, p_start) of every leak-down run, and the repeat
    files' columns left out as copies of an earlier one (label, its original)."""
    from boomfmi.foreign import read_with
    runs = [(path.stem, path, read_options("zillen2021-leak"), None)
            for path in sorted((DATA / "airchamber_leakage").glob("*.csv")) if not path.stem.startswith("Resultaten")]
    seen, copies = {}, []
    for path in sorted((DATA / "airchamber_leakage").glob("Resultaten_*.csv")):
        header = path.read_text(encoding="utf-8").splitlines()[0].split(";")
        for name in header[1:]:
            opts = read_options(map=f"t={header[0]}:s,dp={name}:mbar", delimiter="semicolon", decimal=",",
                                header=True)
            label = f"{path.stem.replace('Resultaten_', '')}: {name}"
            key = read_with(path, opts).columns["dp"].tobytes()
            if key in seen:
                copies.append((label, seen[key]))
                continue
            seen[key] = label
            runs.append((label, path, opts, REPEAT_START))
    return runs, copies


def leak_rows(work: Path):
    from boomfmi.bench import parse_pressure
    rows = []
    runs, copies = leak_runs()
    for k, (label, path, opts, p_start) in enumerate(runs):
        print(f"leak {label}", flush=True)
        doc = run_leak([path], VOLUME, opts, work / "leak" / f"{k:02d}_{path.stem}",
                       p_start=parse_pressure(p_start) if p_start else None)
        r = doc["runs"][0]
        best = r["laws"][r["chosen"]]
        size = r["size"]
        row = {"label": label, "start": r["start_s"], "duration": r["duration_s"], "drop": 1e3 * r["drop_bar"],
               "chosen": r["chosen"], "family": r["laminar_vs_orifice"], "size": size,
               "noise": r["noise_Pa"], "rmse": best["rmse_Pa"], "over": best["rmse_over_noise"],
               "params": best["parameters"], "C": r["laws"]["laminar"]["parameters"]["C"],
               "A": r["laws"]["orifice"]["parameters"]["A"],
               "excluded": {law: L["at_bound"] for law, L in r["laws"].items() if L["at_bound"]}}
        rows.append(row)
        print(f"  {row['chosen']} ({row['family']}), {size['name']} = {size['value']:.3g} "
              f"[{size['ci95'][0]:.3g}, {size['ci95'][1]:.3g}] {size['unit']} per litre, drop {row['drop']:.1f} mbar "
              f"in {row['duration']:.0f} s, RMSE {row['rmse']:.0f} Pa ({row['over']:.2f} x noise)", flush=True)
    return rows, copies


def fmt_ci(lo, hi, digits=2):
    return f"[{lo:.{digits}f}, {hi:.{digits}f}]"


def write_doc(out: Path, fr, lk, copies, n_boot: int, tr=()) -> None:
    L = ["# Real data: a cylinder's friction and leak-down tests", "",
         f"Made by `python benchmarks/real_bench.py` on {platform.machine()} / Python {platform.python_version()}, "
         f"{n_boot} bootstrap replicates. Data: `../shared/realdata/cylinder-friction-leak/` (CC0; "
         "Zillen, Vallery, Smit 2021, TU Delft: a 3D-printed single-chamber cylinder, 25 mm bore (25.7 mm for "
         "the *257 designs), driven back and forth at 5 to 15 mm/s at a regulated gauge pressure of 1 to 7 "
         "bar; position, pressure and rod force at 100 Hz). Read with `--preset zillen2021` (`t=1:ms,x=5:mm,"
         "p_gauge=6:bar,F=7:N`, tab, 15 start-up rows skipped) and `--preset zillen2021-leak`.", "",
         "## Friction", "",
         "`boomfmi bench friction` (`src/boomfmi/bench/friction.py`) fits, with the effective area A_eff and "
         "the load cell's offset F_0, three laws of the friction `F_f = F - p A_eff - F_0`: `eq9` (the paper's "
         "Eq. 9: static F_s, Coulomb F_d, viscous K_v), `stribeck` (`F_d + (F_s - F_d) exp(-|v|/v_s)`, the "
         "model's `stribeck_friction` form) and `pressure` (`F_d(p) = F_d0 + c_d p`, static "
         "`F_s(p) = F_s0 + c_s p`, p gauge), each with separate static levels for the two directions. One "
         "Coulomb level serves both directions: force data cannot tell a Coulomb level higher one way from "
         "an offset F_0 (constant part) or an area error (part proportional to p), so F_0 and A_eff hold it. "
         "A law is chosen over a simpler one only where it lowers the holdout's mean squared error with a "
         "95 % interval (bootstrap over the holdout strokes) above zero. Intervals: wild cluster bootstrap "
         "(clusters: the FIT files), 95 %.", "",
         *held_out_section(tr, fr),
         "### Within the same files: the choice of law", "",
         "Holdout RMSE of the rod force (every holdout sample, reversals included) as the law is chosen: for "
         "most designs on the second half of the strokes of the same files it was fitted on (the same "
         "session: **within-file** figures; on other sessions' files, see above), for designs "
         "tested at five or more pressures on the even pressures' files; the chosen law, and the "
         "pressure law's Coulomb coefficient c_d with its 95 % interval:", "",
         "| seal design | fit / holdout | RMSE eq9 [N] | RMSE stribeck [N] | RMSE pressure [N] | chosen | "
         "c_d [N/bar] | F_d0 [N] | F_d(7 bar) / F_d(1 bar) | A_eff / A |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    for r in fr:
        L.append(f"| {r['seal']} | {r['how']} | {r['rmse']['eq9']:.2f} | {r['rmse']['stribeck']:.2f} | "
                 f"{r['rmse']['pressure']:.2f} | **{r['chosen']}** | {r['c_d']:.2f} {fmt_ci(*r['c_d_ci'])} | "
                 f"{r['F_d0']:.2f} {fmt_ci(*r['F_d0_ci'])} | {r['ratio_7_1']:.1f} | {r['A_ratio']:.3f} |")
    chosen = defaultdict(list)
    for r in fr:
        chosen[r["chosen"]].append(r["seal"])
    c_all = np.array([r["c_d"] for r in fr])
    summary = "; ".join(f"{law} for {len(s)} of {len(fr)} designs ({', '.join(s)})" for law, s in chosen.items())
    L += ["", f"Chosen: {summary}.", "",
          "### The form of pressure-dependent friction the data chose", "",
          "The Coulomb (sliding) level grows linearly with the chamber's gauge pressure, the same for both "
          "directions:", "", "    F_d(p) = F_d0 + c_d * p_gauge", "",
          f"with c_d between {c_all.min():.2f} and {c_all.max():.2f} N/bar over the designs (median "
          f"{np.median(c_all):.2f} N/bar; per Pa: {np.median(c_all) * 1e-5:.3g} N/Pa, an effective contact "
          "area times a friction coefficient) and F_d0 of a few newtons. The static (breakaway) levels, from "
          "the largest friction within 1 mm after each reversal, grow alike:", "",
          "| seal design | c_s, v > 0 [N/bar] | c_s, v < 0 [N/bar] | F_s0 +/- [N] | K_v [N s/m] | F_0 [N] |",
          "|---|---|---|---|---|---|"]
    for r in fr:
        L.append(f"| {r['seal']} | {r['c_s_pos']:.2f} {fmt_ci(*r['c_s_pos_ci'])} | {r['c_s_neg']:.2f} "
                 f"{fmt_ci(*r['c_s_neg_ci'])} | {r['F_s0_pos']:.2f} / {r['F_s0_neg']:.2f} | {r['K_v']:.0f} "
                 f"{fmt_ci(*r['K_v_ci'], 0)} | {r['F_0']:.2f} |")
    L += ["", "The rig's reversals are short (the drive reverses the rod within about 0.1 s) and show no "
          "breakaway peak above the sliding level: the static level is the Coulomb level at the same "
          "pressure within the intervals, and it scales with pressure as the Coulomb level does. Where the "
          "static coefficients' intervals are wide, the breakaways alone do not pin them down.", "",
          "Warnings of the fits:", ""]
    warns = [f"- {r['seal']}: {w}" for r in fr for w in r["warnings"]]
    L += warns or ["- none"]
    L += ["", "## Leak-down", "",
          "`boomfmi bench leak` (`src/boomfmi/bench/leak.py`) fits each run from the moment the chamber was "
          "closed (found where a record starts on the supply's plateau) with the laminar leak "
          "(`mdot = C (p - P_atm)`, the model's `piston_leakage`) and the orifice leak (Eq. 1 through an area "
          "A, the model's valve equation), each also with the thermal relaxation of freshly charged air "
          "(temperature `dT0` above ambient relaxing with time constant `tau`, at most a third of the run; "
          "the air also cools as it expands). The law is the one with the least information criterion "
          "`n_eff ln(RSS/n) + k ln n_eff` (n_eff: the residuals' independent samples' worth); laminar and "
          "orifice count as indistinguishable below a difference of 10 (the laminar law is then taken); a fit "
          "ending on a bound of dT0, tau or p0 is not chosen. The chambers' volumes are not published: sizes "
          f"are for a {VOLUME * 1e3:g} L chamber and scale with the volume (C and A in proportion). Intervals: "
          "95 %, Jacobian with a Newey-West sandwich.", "",
          "The `Resultaten_*` files hold pressure changes since the start of repeated runs, unit not stated "
          "(the authors' script treats them as kPa). Read as mbar they agree with the single runs (SLA Prusa "
          "-92 at 130 s against Prusa.csv's 97 mbar drop at 140 s; Formlabs -33 against 39; Ultimaker 0.1 mm "
          "-106 against 103), as kPa they would be ten times larger: mbar it is, from an assumed start of "
          f"{REPEAT_START} gauge.", "",
          "| run | closed at [s] | drop [mbar] in [s] | chosen | laminar vs orifice | leak size (1 L) | "
          "95 % interval | RMSE / noise | thermal (dT0, tau) |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in lk:
        s = r["size"]
        if s["name"] == "A":
            size = f"A = {s['value'] * 1e6:.3g} mm^2 (d = {s['diameter_m'] * 1e6:.0f} um)"
            ci = fmt_ci(s["ci95"][0] * 1e6, s["ci95"][1] * 1e6, 3)
        else:
            size = f"C = {s['value']:.3g} kg/(s Pa)"
            ci = f"[{s['ci95'][0]:.3g}, {s['ci95'][1]:.3g}]"
        th = (f"{r['params']['dT0']:.2f} K, {r['params']['tau']:.1f} s" if "tau" in r["params"] else "")
        L.append(f"| {r['label']} | {r['start']:.1f} | {r['drop']:.1f} in {r['duration']:.0f} | **{r['chosen']}** | "
                 f"{r['family']} | {size} | {ci} | {r['over']:.2f} | {th} |")
    fams = defaultdict(int)
    for r in lk:
        fams[r["family"]] += 1
    L += ["", "Laminar against orifice: " + ", ".join(f"{v} {k}" for k, v in sorted(fams.items())) + ". Thermal "
          f"relaxation chosen in {sum(r['chosen'].endswith('thermal') for r in lk)} of {len(lk)} runs. A drop of a "
          "few per cent is the same exponential under either law; only the chambers that empty (Ultimaker "
          "0.15 and 0.20 mm) tell them apart.", ""]
    if copies:
        L += ["Columns of the repeat files that hold the same values as an earlier one, counted once: "
              + "; ".join(f"{a} (= {b})" for a, b in copies) + ".", ""]
    excl = ["- " + r["label"] + ": " + ", ".join(f"{law} ({', '.join(b)} at its bound)"
                                              for law, b in r["excluded"].items())
            for r in lk if r["excluded"]]
    if excl:
        L += ["Fits not chosen because a parameter ended on its bound:", ""] + excl + [""]
    out.write_text("\n".join(L) + "\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "real-data.md")
    ap.add_argument("--work", type=Path, default=None, help="folder for the bench's own outputs")
    ap.add_argument("--n-boot", type=int, default=200)
    args = ap.parse_args()
    if not DATA.is_dir():
        print(f"no real data at {DATA}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        fr = friction_rows(work, args.n_boot)
        tr = transfer_rows()
        lk, copies = leak_rows(work)
        write_doc(args.out, fr, lk, copies, args.n_boot, tr)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
