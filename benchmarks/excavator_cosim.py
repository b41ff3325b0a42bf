#!/usr/bin/env python3
"""The whole excavator's co-simulation error against its monolithic reference, over the
digging cycle.

Runs build/excavator.ssp (four valves, four cylinders, the linkage) through boomfmi's
master at 1 ms (Gauss-Seidel and Jacobi; --steps for others) and prints the NRMSE (RMS
error over the reference's range) of every joint's piston position x and chamber
pressures p_a, p_b against ``model.reference.simulate_linkage`` (the same physics as one
system, 50 us steps, every coupling tight).  The reference's own error is gauged by
halving its step (--check-reference; a 25 us run beside the 50 us one).  With --out,
appends the tables to docs/cosim-accuracy.md under "## The whole excavator" (replacing
that section if present).

    python benchmarks/excavator_cosim.py [--check-reference] [--out docs/cosim-accuracy.md]
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

from boomfmi.experiments import digging_cycle  # noqa: E402
from boomfmi.model.reference import simulate_excavator_reference  # noqa: E402
from boomfmi.physics.linkage import JOINTS  # noqa: E402
from boomfmi.system import simulate_ssp  # noqa: E402

SECTION = "## The whole excavator"


def channels(j: str):
    """(reference column, co-simulation column) of joint ``j``'s x, p_a and p_b."""
    return ((f"x_{j}", f"linkage.x_{j}"), (f"p_a_{j}", f"cylinder_{j}.p_a"), (f"p_b_{j}", f"cylinder_{j}.p_b"))


def nrmse_table(co, ref, ref_is_cosim: bool = False) -> dict[str, float]:
    """NRMSE of each joint's x, p_a, p_b (keys ``x_boom``...) of ``co`` (a co-simulation
    result, or a reference frame with ``ref_is_cosim``) against ``ref``, on their common
    times."""
    r = ref.set_index(np.round(ref["time"].to_numpy(), 7))
    c = co.set_index(np.round(co["time"].to_numpy(), 7))
    idx = r.index.intersection(c.index)
    if len(idx) < 0.9 * len(r):
        raise ValueError(f"only {len(idx)} of {len(r)} reference times in the co-simulation")
    out = {}
    for j in JOINTS:
        for name, col in channels(j):
            err = c.loc[idx, name if ref_is_cosim else col].to_numpy() - r.loc[idx, name].to_numpy()
            out[name] = float(np.sqrt(np.mean(err ** 2)) / (r[name].max() - r[name].min()))
    return out


def table_lines(title: str, table: dict[str, float], wall: float | None, stop: float) -> list[str]:
    lines = [f"### {title}", "", "| joint | x | p_a | p_b |", "|---|---|---|---|"]
    for j in JOINTS:
        lines.append(f"| {j} | " + " | ".join(f"{100 * table[f'{q}_{j}']:.4f} %" for q in ("x", "p_a", "p_b")) + " |")
    worst = max(table, key=table.get)
    lines += ["", f"Worst: {worst} {100 * table[worst]:.4f} %"
              + (f"; {wall:.1f} s wall for {stop:g} s simulated." if wall else "."), ""]
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ssp", type=Path, default=ROOT / "build" / "excavator.ssp")
    ap.add_argument("--steps", default="0.001", help="communication steps [s], comma-separated")
    ap.add_argument("--algorithms", default="gauss-seidel,jacobi")
    ap.add_argument("--check-reference", action="store_true", help="also run the reference at half its step")
    ap.add_argument("--out", type=Path, help="append the tables to this Markdown file (docs/cosim-accuracy.md)")
    args = ap.parse_args(argv)

    prof = digging_cycle()
    stop = prof.duration
    t = time.perf_counter()
    ref = simulate_excavator_reference(prof, stop)
    print(f"reference: fixed 50 us steps, {stop:g} s in {time.perf_counter() - t:.1f} s wall")
    lines = [SECTION, "",
             "`build/excavator.ssp` (four `valve`, four `cylinder`, one `linkage`) against the monolithic",
             "reference `boomfmi.model.reference.simulate_linkage` (the same physics functions as one system,",
             "fixed 50 us steps, valves, chambers and linkage coupled every step), over the digging cycle",
             f"(`digging_cycle`, {stop:g} s), NRMSE of every joint's x, p_a, p_b.  Made by",
             "`python benchmarks/excavator_cosim.py --check-reference --out docs/cosim-accuracy.md` on "
             f"{platform.machine()} / Python {platform.python_version()}.", ""]
    if args.check_reference:
        t = time.perf_counter()
        fine = simulate_excavator_reference(prof, stop, h=2.5e-5)
        wall = time.perf_counter() - t
        own = nrmse_table(ref, fine, ref_is_cosim=True)
        print("reference 50 us against 25 us: " + "  ".join(f"{k} {100 * v:.4f} %" for k, v in own.items()))
        lines += table_lines("The reference's own error: 50 us against 25 us steps", own, wall, stop)
    verdict = True
    inputs = lambda s: {f"valve_{k[2:]}.u": u for k, u in prof(s).items()}   # noqa: E731
    for algorithm in args.algorithms.split(","):
        for h in (float(s) for s in args.steps.split(",")):
            t = time.perf_counter()
            co = simulate_ssp(args.ssp, stop_time=stop, step=h, algorithm=algorithm, inputs=inputs)
            wall = time.perf_counter() - t
            table = nrmse_table(co, ref)
            print(f"{algorithm:12s} h = {h * 1e3:5.2f} ms  " + "  ".join(f"{k} {100 * v:.4f} %" for k, v in table.items())
                  + f"   ({wall:.1f} s wall)")
            lines += table_lines(f"{algorithm}, {h * 1e3:g} ms", table, wall, stop)
            if algorithm == "gauss-seidel" and abs(h - 1e-3) < 1e-12:
                verdict = max(table.values()) < 0.01
                lines += [f"At 1 ms with Gauss-Seidel every joint's x, p_a and p_b is "
                          f"{'below' if verdict else 'NOT below'} 1 % NRMSE.", ""]
    if args.out:
        text = args.out.read_text() if args.out.is_file() else ""
        head = text.split(SECTION)[0].rstrip("\n")
        args.out.write_text((head + "\n\n" if head else "") + "\n".join(lines))
        print(f"wrote {args.out}")
    return 0 if verdict else 1


if __name__ == "__main__":
    sys.exit(main())
