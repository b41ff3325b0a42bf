#!/usr/bin/env python3
"""Blind benchmark of the diagnosis on recordings of an independent simulator.

The cases are made by ``benchmarks/hybrid_rig.py``, a rig simulator written apart from
boomfmi's model and virtual rig (its own equations from the specs, an event-located
hybrid solve with scipy's ``solve_ivp``, its own forms of every effect, several per
mechanism), so that the diagnosis never meets its own numerics or its own effect laws.
Each case draws, from a seeded generator:

* the load within +-15 % of the reference rig (F_s at least 5 % above F_d);
* what is wrong: nothing, one effect of effects.md, a pair drawn among all of them, or
  a disturbance outside the vocabulary (an engine vibration on the boom, or a supply
  that sags while the valve draws air); each effect in one of its forms, its strength
  drawn on a log scale from barely there to strong;
* the command designs of the fit and the holdout recording, never the same: random
  steps, the paper's experiment, an operator's manoeuvres (holds at 5 V, reversals,
  runs into the ends, a chirp), a sine sweep;
* the angle sensor: 12 bit or 16 bit over 300 degrees (noise on either).

Scoring: an effect (or a disturbance) is *detectable* when the holdout with it and
without it differ by more than the diagnosis's own noise margin would allow
(``NOISE_FACTOR`` times the recording's noise floor plus ``ABS_FLOOR``; compared on
the noise-free signals that reach the sensors' converters, so that an effect on the
sensor path counts; until the second scoring they were the true state's, on which a
sensor lag could never show); the truth is the detectable part of what is wrong (``unexplained``
for a detectable disturbance, ``[]`` where nothing detectable is), and a verdict is
correct when it names exactly that, or everything that is wrong.  Prints the
confusion matrix, the share of correct verdicts (overall, per kind, per design and
per sensor), the false alarms on effect-free cases, and the median holdout shrink of
detectable single-effect cases; writes docs/diagnosis.md and docs/diagnosis.json.

The diagnoses run through ``boomfmi campaign``'s path (``boomfmi.campaign``: a machine
per case, on a Dask LocalCluster of ``--workers`` processes, each case's outputs in
``--cache``/campaign/cases/); the recordings are made before, in as many processes.

    python benchmarks/diagnosis_blind.py [--cases 60] [--workers 2] [--only 3 7] [--resume]
"""
from __future__ import annotations

import argparse
import json
import platform
import shutil
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from itertools import repeat
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import hybrid_rig as hr  # noqa: E402
from boomfmi.campaign import run_campaign, write_manifest  # noqa: E402
from boomfmi.diagnose.attribute import ABS_FLOOR, NOISE_FACTOR, noise_floor  # noqa: E402
from boomfmi.experiments import manoeuvres, paper_multistep, random_steps, sine_sweep  # noqa: E402
from boomfmi.recording import read_recording  # noqa: E402

EFFECTS = ("valve_dynamics", "valve_deadband", "heat_transfer", "piston_leakage",
           "stribeck_friction", "end_cushioning", "sensor_lag", "pressure_friction")
LOAD = ("K_v", "F_s", "F_d", "F_L", "M")
DURATION = 10.0
DESIGNS = {
    "random_steps": lambda seed: random_steps(seed, duration=DURATION),
    "paper": lambda seed: paper_multistep(),
    "manoeuvres": lambda seed: manoeuvres(seed, duration=DURATION),
    "sine_sweep": lambda seed: sine_sweep(seed, duration=DURATION),
}
SENSORS = {"12 bit": {"angle_bits": 12}, "16 bit": {"angle_bits": 16}}
#: what is wrong, case by case (cycled)
KINDS = ("none", "single", "single", "pair", "single", "none", "single", "pair", "single", "disturbance")


def _log(weak: float, strong: float, s: float) -> float:
    return float(weak * (strong / weak) ** s)


def effect_params(name: str, form: str, s: float, rng, load: dict) -> dict:
    """The hybrid rig's parameters of ``name`` in ``form`` at strength ``s`` (0: barely
    there, 1: strong; log scale in the parameter that sets the strength)."""
    u = lambda lo, hi: float(rng.uniform(lo, hi))
    if name == "valve_dynamics":
        if form == "first_order":
            return {"tau": _log(2e-4, 0.015, s)}
        if form == "second_order":
            return {"f_n": _log(400.0, 30.0, s), "zeta": u(0.5, 1.2)}
        return {"tau": _log(3e-4, 0.01, s), "rate": _log(3000.0, 150.0, s)}
    if name == "valve_deadband":
        d = _log(0.02, 0.6, s)
        return {"d": d} if form == "overlap" else {"d": d, "w": d * u(0.2, 0.5)}
    if name == "heat_transfer":
        return {"h_c": _log(1.0, 150.0, s)} if form == "wall" else {"n": 1.4 - 0.4 * s}
    if name == "piston_leakage":
        if form == "laminar":
            return {"C": _log(2e-13, 5e-11, s)}
        if form == "orifice":
            return {"A": _log(1e-10, 3e-8, s)}
        return {"C": _log(1e-13, 2e-11, s), "A": _log(5e-11, 1.5e-8, s)}
    if name == "stribeck_friction":
        return {"F_brk": load["F_d"] * u(1.3, 2.0), "v_s": _log(2e-4, 0.03, s)}
    if name == "end_cushioning":
        out = {"l_c": _log(0.002, 0.02, s), "A_n": _log(1.5e-6, 2e-7, s)}
        if form == "sensed_port":
            out["V_p"] = u(3e-6, 1e-5)
        return out
    if name == "sensor_lag":
        if form == "first_order":
            return {"tau": _log(2e-4, 0.02, s)}
        return {"delay": _log(2e-4, 0.01, s), "tau": _log(2e-4, 0.01, s)}
    if name == "pressure_friction":
        if form == "linear":
            return {"c": _log(0.003, 0.25, s), "asym": u(0.8, 1.25)}
        return {"c_p": _log(0.003, 0.3, s), "c_r": _log(0.003, 0.3, s) * u(0.3, 1.0)}
    raise ValueError(name)


def draw_case(i: int, seed: int) -> dict:
    rng = np.random.default_rng(seed * 1000 + i)
    load = {k: float(hr.PLANT_DEFAULTS[k] * rng.uniform(0.85, 1.15)) for k in LOAD}
    load["F_s"] = max(load["F_s"], 1.05 * load["F_d"])
    kind = KINDS[i % len(KINDS)]
    names = []
    if kind == "single":
        before = sum(KINDS[j % len(KINDS)] == "single" for j in range(i))   # every effect in turn
        names = [EFFECTS[before % len(EFFECTS)]]
    elif kind == "pair":
        names = [EFFECTS[j] for j in rng.choice(len(EFFECTS), size=2, replace=False)]
    effects = {}
    for n in names:
        form = str(rng.choice(list(hr.EFFECT_FORMS[n])))
        effects[n] = {"form": form, **effect_params(n, form, float(rng.uniform()), rng, load)}
    disturbances = {}
    if kind == "disturbance":
        if (i // len(KINDS)) % 2 == 0:
            disturbances["vibration"] = {"form": "sinusoidal", "amplitude": float(rng.uniform(20.0, 150.0)),
                                         "frequency": float(rng.uniform(8.0, 40.0))}
        else:
            disturbances["supply_sag"] = {"form": "reservoir", "V_r": _log(2e-3, 1e-4, float(rng.uniform())),
                                          "G": float(rng.uniform(5e-9, 2e-8))}
    order = list(DESIGNS)
    fit_design = order[i % 4]
    hold_design = order[(i + 1 + (i // 4) % 3) % 4]
    sensor = list(SENSORS)[i % 2]
    return {"case": i, "kind": kind, "load": load, "effects": effects, "disturbances": disturbances,
            "fit_design": fit_design, "hold_design": hold_design, "sensor": sensor,
            "seed": seed * 1000 + i}


def _plant(case: dict, effects=None, disturbances=None) -> hr.Plant:
    return hr.Plant(**case["load"], effects=case["effects"] if effects is None else effects,
                    disturbances=case["disturbances"] if disturbances is None else disturbances,
                    sensors=dict(SENSORS[case["sensor"]]))


#: bump when what the differences are measured on changes (the cache re-measures them)
SCORING = 2


def _true_errors(with_it, without) -> float:
    """Summed NRMSE (angle, p_a, p_b) between two runs' noise-free sensed signals (what
    reaches the converters, through the sensor path: an effect on the sensors shows,
    which it does not in the true state), over the first's ranges."""
    total = 0.0
    for col in ("alpha_sensed", "p_a_sensed", "p_b_sensed"):
        a, b = with_it[col].to_numpy(), without[col].to_numpy()
        span = float(np.ptp(a)) or 1.0
        total += float(np.sqrt(np.mean((a - b) ** 2)) / span)
    return total


def case_dir(case: dict, cache: Path) -> Path:
    """The case's folder in ``cache``: its recordings and what was measured on them."""
    return cache / f"case{case['case']:03d}_{case['seed']}"


def make_recordings(case: dict, cache: Path) -> dict:
    """Simulate (or take from ``cache``) the case's fit and holdout recordings and
    measure, on each, how much each thing that is wrong changes its noise-free sensed signals."""
    d = case_dir(case, cache)
    meta = d / "meta.json"
    info = json.loads(meta.read_text()) if meta.exists() else {}
    if "difference_fit" in info and info.get("scoring") == SCORING and info.get("case") == case:
        return info
    info = {"case": case}
    d.mkdir(parents=True, exist_ok=True)
    fit_p = DESIGNS[case["fit_design"]](case["seed"])
    hold_p = DESIGNS[case["hold_design"]](case["seed"] + 500)
    plant = _plant(case)
    t0 = time.perf_counter()
    runs = {"fit": (fit_p, case["seed"]), "hold": (hold_p, case["seed"] + 1)}
    for key, (prof, seed) in runs.items():
        frame = hr.simulate(plant, prof, seed=seed)
        hr.write(d / f"{key}.csv", frame)
        noise = sum(noise_floor(read_recording(d / f"{key}.csv")).values())
        diffs = {}
        for n in case["effects"]:
            without = hr.simulate(_plant(case, {k: v for k, v in case["effects"].items() if k != n}), prof, seed=seed)
            diffs[n] = _true_errors(frame, without)
        for n in case["disturbances"]:
            diffs[n] = _true_errors(frame, hr.simulate(_plant(case, disturbances={}), prof, seed=seed))
        suffix = "" if key == "hold" else "_fit"
        info["difference" + suffix] = diffs
        info["margin" + suffix] = NOISE_FACTOR * noise + ABS_FLOOR
    info["simulation_s"] = time.perf_counter() - t0
    info["scoring"] = SCORING
    meta.write_text(json.dumps(info, indent=1))
    return info


def truth_of(case: dict, info: dict, fit_too: bool = True) -> tuple[list, list]:
    """(what is wrong, as the diagnosis names it; its detectable part).  Detectable:
    beyond the noise margin on the holdout and, with ``fit_too`` (the issue's rule: a
    fit of the true model must be able to tell it from noise), on the fit recording
    too, which the effect's parameters are fitted on."""
    def seen(n):
        on_hold = info["difference"][n] > info["margin"]
        return on_hold and (not fit_too or info["difference_fit"][n] > info["margin_fit"])
    full = sorted(case["effects"]) + (["unexplained"] if case["disturbances"] else [])
    out = sorted(n for n in case["effects"] if seen(n))
    if any(seen(n) for n in case["disturbances"]):
        out.append("unexplained")
    return full, out


def score_case(case: dict, info: dict, doc: dict, wall: float) -> dict:
    """The case's row: what is wrong, its detectable part, the verdict (``doc``: the
    case's diagnosis.json) and whether it is correct."""
    full, seen = truth_of(case, info)
    _, seen_hold = truth_of(case, info, fit_too=False)
    verdict = sorted(doc["verdict"])
    correct = verdict == seen or verdict == full
    correct_hold = verdict == seen_hold or verdict == full
    shrink = next((e["shrink"] for e in doc["effects"] if e["name"] in case["effects"]), None)
    best = doc["effects"][0] if doc["effects"] else None
    return dict(case, truth=full, detectable=seen, verdict=verdict, correct=correct, wall=wall,
                correct_holdout_rule=correct_hold, detectable_holdout_rule=seen_hold,
                difference=info["difference"], margin=info["margin"],
                difference_fit=info["difference_fit"], margin_fit=info["margin_fit"],
                best=best["name"] if best else None, shrink_best=best["shrink"] if best else None,
                shrink_true=shrink, baseline=doc.get("baseline", {}).get("params"),
                gap=doc.get("gap_beyond_noise"), threshold=doc.get("gap_threshold"),
                nrmse_before=doc.get("baseline", {}).get("nrmse_holdout"),
                candidates=[{k: e[k] for k in ("name", "params", "shrink")} for e in doc.get("effects", [])],
                warnings=doc.get("baseline", {}).get("warnings", []))


def label(names) -> str:
    return "+".join(names) if names else "none"


def _share(rows) -> str:
    return f"{100 * sum(r['correct'] for r in rows) / len(rows):.0f} % of {len(rows)}" if rows else "-"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--seed", type=int, default=16)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", type=int, nargs="*", help="run only these case numbers (for a look at them)")
    ap.add_argument("--cache", type=Path, default=ROOT / "build" / "blind",
                    help="where the cases' recordings are kept (made once, reused)")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "diagnosis.md")
    ap.add_argument("--resume", action="store_true",
                    help="keep the diagnoses of an earlier run whose recordings are the same (default: diagnose "
                         "anew, as the benchmark measures the code as it is)")
    args = ap.parse_args(argv)
    cases = [draw_case(i, args.seed) for i in (args.only if args.only is not None else range(args.cases))]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:        # the independent simulator's recordings
        infos = list(pool.map(make_recordings, cases, repeat(args.cache)))
    # the diagnoses through boomfmi campaign's path: a machine per case, on a Dask LocalCluster
    manifest = write_manifest(args.cache / "campaign_manifest.csv", [
        {"machine": f"case{c['case']:03d}", "date": "2000-01-01", "role": role,
         "recording": case_dir(c, args.cache) / name}
        for c in cases for role, name in (("fit", "fit.csv"), ("holdout", "hold.csv"))])
    campaign = args.cache / "campaign"
    if not args.resume:
        shutil.rmtree(campaign, ignore_errors=True)
    doc = run_campaign(manifest, campaign, workers=args.workers,
                       progress=lambda text: print(text, end="", file=sys.stderr, flush=True))
    results = []
    for c, info, row in zip(cases, infos, doc["cases"]):
        if row["status"] != "done":
            raise RuntimeError(f"case {c['case']}: the diagnosis failed: {row['error']}")
        r = score_case(c, info, json.loads((campaign / row["folder"] / "diagnosis.json").read_text()), row["wall_s"])
        results.append(r)
        print(f"case {r['case']:2d} {r['kind']:11s} {r['fit_design']:>12s} -> {r['hold_design']:12s} {r['sensor']:6s} "
              f"truth {label(r['truth']):38s} detectable {label(r['detectable']):38s} "
              f"verdict {label(r['verdict']):38s} {'ok' if r['correct'] else 'WRONG'} ({r['wall']:.0f} s)",
              flush=True)
    labels = sorted({label(r["detectable"]) for r in results} | {label(r["verdict"]) for r in results})
    matrix = {t: {v: 0 for v in labels} for t in labels}
    for r in results:
        matrix[label(r["detectable"])][label(r["verdict"])] += 1
    correct = sum(r["correct"] for r in results) / len(results)
    correct_hold = sum(r["correct_holdout_rule"] for r in results) / len(results)
    clean = [r for r in results if not r["effects"] and not r["disturbances"]]
    false_alarms = sum(r["verdict"] != [] for r in clean)
    singles = [r["shrink_true"] for r in results
               if r["kind"] == "single" and r["detectable"] and r["shrink_true"] is not None]
    median_shrink = statistics.median(singles) if singles else float("nan")
    undetectable = sum(1 for r in results if r["truth"] and not r["detectable"])
    walls = [r["wall"] for r in results]
    print(f"correct verdicts: {100 * correct:.1f} % of {len(results)} ({100 * correct_hold:.1f} % where only the "
          f"holdout decides what is detectable); false alarms on effect-free cases: "
          f"{false_alarms} of {len(clean)}; median holdout shrink (detectable single effects): {median_shrink:.2f}; "
          f"undetectable cases: {undetectable}; diagnosis time median {statistics.median(walls):.0f} s")
    lines = ["# Diagnosis: blind benchmark", "",
             f"Made by `python benchmarks/diagnosis_blind.py --cases {len(results)}` on {platform.machine()} / "
             f"Python {platform.python_version()} ({time.perf_counter() - t0:.0f} s wall, {args.workers} workers).", "",
             "The recordings come from `benchmarks/hybrid_rig.py`, a simulator written apart from boomfmi's",
             "model and virtual rig (an event-located hybrid solve, its own forms of every effect). Each case:",
             "the load within +-15 % of the reference rig; nothing wrong, one effect, a pair among all",
             "effects, or a disturbance outside the vocabulary (vibration, a sagging supply); every effect",
             "in one of its forms at a strength drawn on a log scale from barely there to strong; one",
             f"{DURATION:g} s fit and one holdout recording of different command designs; a 12 or 16 bit",
             "angle sensor. An effect is *detectable* (the issue's rule: a fit of the true model can tell it",
             "from noise) when the recordings with and without it differ beyond the diagnosis's own noise",
             "margin on the fit recording, which it is fitted on, and on the holdout (compared without noise",
             "on the signals that reach the sensors, so that a sensor lag counts); a verdict is correct",
             "when it names the detectable part of what is wrong, or all of it.", "",
             f"**Correct verdicts: {100 * correct:.1f} %** (target 95 %; {100 * correct_hold:.1f} % if the holdout",
             "alone decided what is detectable); **false alarms on effect-free cases:",
             f"{false_alarms} of {len(clean)}** (target 0); **median holdout shrink of detectable single-effect",
             f"cases: {median_shrink:.2f}** (target 0.8); {undetectable} case(s) where what is wrong is not",
             f"detectable; median diagnosis time {statistics.median(walls):.0f} s.", "",
             "## Correct verdicts by kind, design and sensor", "",
             "| group | correct |", "|---|---|"]
    for kind in dict.fromkeys(KINDS):
        lines.append(f"| kind: {kind} | {_share([r for r in results if r['kind'] == kind])} |")
    for design in DESIGNS:
        lines.append(f"| fit design: {design} | {_share([r for r in results if r['fit_design'] == design])} |")
    for design in DESIGNS:
        lines.append(f"| holdout design: {design} | {_share([r for r in results if r['hold_design'] == design])} |")
    for sensor in SENSORS:
        lines.append(f"| angle sensor: {sensor} | {_share([r for r in results if r['sensor'] == sensor])} |")
    lines += ["", "## Confusion matrix (rows: detectable truth, columns: verdict)", "",
              "| truth \\ verdict | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for t in labels:
        lines.append(f"| {t} | " + " | ".join(str(matrix[t][v]) for v in labels) + " |")
    lines += ["", "## Cases", "",
              "| case | kind | fit -> holdout | sensor | truth (forms) | detectable | verdict | best | its shrink | shrink of the truth |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        forms = ", ".join(f"{n} ({p['form']})" for n, p in {**r["effects"], **r["disturbances"]}.items()) or "none"
        st = "" if r["shrink_true"] is None else f"{r['shrink_true']:.2f}"
        sb = "" if r["shrink_best"] is None else f"{r['shrink_best']:.2f}"
        lines.append(f"| {r['case']} | {r['kind']} | {r['fit_design']} -> {r['hold_design']} | {r['sensor']} | {forms} | "
                     f"{label(r['detectable'])} | {label(r['verdict'])} {'' if r['correct'] else '(wrong)'} | "
                     f"{r['best']} | {sb} | {st} |")
    args.out.write_text("\n".join(lines) + "\n")
    args.out.with_suffix(".json").write_text(json.dumps(results, indent=1, default=str))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
