#!/usr/bin/env python3
"""The teleoperation system in real time at 1 kHz against the virtual rig.

Starts ``boomfmi rig serve`` (real time, 1 kHz, the soft-soil contact scenario) as its
own process, then runs ``build/teleoperation.ssp`` here through boomfmi's master with
the hardware bridge in udp mode: the model, the bridge and the force estimator at a
1 ms communication step, paced to the wall clock by the bridge, under three of the
operator's digging cycles (30 s).  Both processes ask for the real-time FIFO scheduler
(``--priority``, as a test rig's host would run them); where that is not permitted
they run on the normal one, and the first line says which.  Prints the bridge's missed deadlines (steps begun
more than a step late), lost answers and the estimator's force range.

    python benchmarks/teleoperation_realtime.py [--cycles 3]
"""
from __future__ import annotations

import argparse
import gc
import os
import platform
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))


def machine_floor(duration: float, dt: float = 1e-3) -> str:
    """What the machine alone allows: a bare loop paced like the bridge (sleep to
    0.3 ms before each slot, then spin), doing nothing, under the same scheduling.
    Counts the slots it woke in more than a step late: stalls no workload can avoid."""
    import time
    from boomfmi.link.client import wait_until
    t0 = time.perf_counter()
    late, worst, n = 0, 0.0, int(duration / dt)
    for k in range(1, n + 1):
        deadline = t0 + k * dt
        wait_until(deadline)
        lag = time.perf_counter() - deadline
        worst = max(worst, lag)
        if lag > dt:
            late += 1
            t0 += lag                  # no work to catch up on: start afresh
    return (f"the machine's floor (a bare 1 kHz loop, same scheduling, {duration:g} s): "
            f"{late} stalls of over a step, longest {1e3 * worst:.1f} ms")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=3, help="digging cycles of 10 s")
    ap.add_argument("--config", type=Path, default=ROOT / "examples" / "rig" / "contact_soft.json")
    ap.add_argument("--priority", type=int, default=50,
                    help="SCHED_FIFO priority of the rig and the co-simulation where permitted; 0: normal scheduler")
    ap.add_argument("--floor", action="store_true",
                    help="first measure the machine's own stalls with a bare loop for as long as the run")
    args = ap.parse_args(argv)
    from boomfmi.experiments import dig
    from boomfmi.rig.server import realtime_priority
    from boomfmi.system.master import CoSimulation

    key = os.urandom(16).hex()
    os.environ["BOOMFMI_LINK_KEY"] = key
    rig = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0",
                            "--config", str(args.config), "--priority", str(args.priority)],
                           env=dict(os.environ, PYTHONPATH=str(ROOT / "src")), stdout=subprocess.PIPE, text=True)
    lines = [rig.stdout.readline() for _ in range(2 if args.priority else 1)]
    port = int(re.search(r":(\d+) ", lines[-1]).group(1))
    scheduling = (f"rig: {lines[0].strip()}; co-simulation: {realtime_priority(args.priority)}"
                  if args.priority else "normal scheduler for both")
    cycle = dig()
    duration = args.cycles * cycle.duration
    floor = machine_floor(duration) if args.floor else None
    params = {"hardware_bridge.mode": "udp", "hardware_bridge.rig": f"udp://127.0.0.1:{port}",
              "boom_load.x0": 0.0}
    try:
        with CoSimulation(ROOT / "build" / "teleoperation.ssp", 1e-3, parameters=[params]) as cosim:
            u_names = [n for n in cosim.inputs if n.endswith(".u")]
            gc.collect()
            gc.disable()           # a collection pause would be a missed deadline; the run allocates little
            t0 = time.perf_counter()
            try:
                result = cosim.simulate(duration, lambda t: dict.fromkeys(u_names, cycle(t % cycle.duration)["u"]))
            finally:
                gc.enable()
            wall = time.perf_counter() - t0
    finally:
        rig.send_signal(signal.SIGTERM)
        summary = rig.communicate(timeout=10)[0].strip()
    steps = len(result) - 1
    misses = int(result["hardware_bridge.deadline_misses"].iloc[-1])
    lost = int(result["hardware_bridge.lost_packets"].iloc[-1])
    f = result["force_estimator.f_est"]
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
          f"rig and co-simulation in separate processes over loopback; {scheduling}")
    print(f"{steps} steps of 1 ms over {duration:g} s of simulated time in {wall:.2f} s wall "
          f"(real-time factor {duration / wall:.3f})")
    print(f"missed deadlines: {misses} of {steps} ({100 * misses / steps:.3f} %); lost answers: {lost}")
    late = result["hardware_bridge.lateness"].to_numpy()[1:]
    print(f"lateness at a step's start: median {1e3 * np.median(late):.2f} ms, 99.9th percentile "
          f"{1e3 * np.percentile(late, 99.9):.2f} ms, longest {1e3 * late.max():.1f} ms")
    missed = late > 1e-3
    starts = np.flatnonzero(missed & ~np.r_[False, missed[:-1]])
    if len(starts):
        print(f"the misses come in {len(starts)} episodes (a stall, then the steps that catch up), "
              f"at t = {', '.join(f'{1e-3 * (k + 1):.2f}' for k in starts[:12])}{' ...' if len(starts) > 12 else ''} s")
    print(f"f_est from {f.min():.0f} to {f.max():.0f} N; the rig's true f_ext from "
          f"{result['hardware_bridge.f_ext'].min():.0f} to {result['hardware_bridge.f_ext'].max():.0f} N")
    if floor:
        print(floor)
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
