#!/usr/bin/env python3
"""The teleoperation system in real time at 1 kHz against the virtual rig.

Starts ``boomfmi rig serve`` (real time, 1 kHz, the soft-soil contact scenario) as its
own process, then runs ``build/teleoperation.ssp`` here through boomfmi's master with
the hardware bridge in udp mode: the model, the bridge and the force estimator at a
1 ms communication step, paced to the wall clock by the bridge, under three of the
operator's digging cycles (30 s).  Both processes ask for the real-time FIFO scheduler
(``--priority``, as a test rig's host would run them); where that is not permitted
they run on the normal one, and the first line says which.  Prints the bridge's missed
deadlines (steps begun more than a step late), lost answers and the estimator's force
range.

A shared machine stalls now and then (on a virtual machine, the host deschedules it),
and every stall of S ms costs any 1 kHz loop about S missed steps, whatever it does.
So that a figure can be read against the machine it was measured on, ``--floor``
measures before each run, for as long and under the same scheduling, two loops that
count missed steps exactly as the bridge does:

* the **bare floor**: a loop paced like the bridge that does nothing;
* the **link floor**: a loop that makes the bridge's exchange with a fresh rig process
  and nothing else: the rig, the link and the pacing, without the FMUs.

The co-simulation's misses over the link floor's are what the FMUs and the master add.
``--repeat N`` makes N such rounds and prints each and the medians.

    python benchmarks/teleoperation_realtime.py [--cycles 3] [--repeat 1] [--floor] [--doc docs/realtime.md]
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
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

DT = 1e-3


@contextmanager
def rig_process(config: Path, priority: int):
    """A real-time ``boomfmi rig serve`` on a free loopback port; yields (port, the
    line saying how it is scheduled, a dict that gets its summary once stopped)."""
    rig = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0",
                            "--config", str(config), "--priority", str(priority)],
                           env=dict(os.environ, PYTHONPATH=str(ROOT / "src")), stdout=subprocess.PIPE, text=True)
    stopped = {}
    try:
        lines = [rig.stdout.readline() for _ in range(2 if priority else 1)]
        port = int(re.search(r":(\d+) ", lines[-1]).group(1))
        yield port, lines[0].strip() if priority else "normal scheduler", stopped
    finally:
        rig.send_signal(signal.SIGTERM)
        stopped["summary"] = rig.communicate(timeout=10)[0].strip()


def count_misses(lateness: np.ndarray) -> int:
    """Steps begun more than a step late: the bridge's ``deadline_misses``."""
    return int(np.count_nonzero(lateness > DT))


def paced_loop(duration: float, work=None) -> np.ndarray:
    """Run ``work(t)`` (or nothing) once per 1 ms slot for ``duration`` s, paced and
    catching up exactly as the bridge does; return each step's lateness [s]."""
    from boomfmi.link.client import wait_until
    n = int(round(duration / DT))
    late = np.empty(n)
    gc.collect()
    gc.disable()
    try:
        t0 = time.perf_counter()
        for k in range(n):
            late[k] = time.perf_counter() - (t0 + k * DT)
            if work is not None:
                work(k * DT)
            wait_until(t0 + (k + 1) * DT)
    finally:
        gc.enable()
    return late


def link_floor(port: int, duration: float) -> np.ndarray:
    """The paced loop making the bridge's exchange (a mid-range command, the rig's
    latest sample back) with the rig at ``port``, and nothing else."""
    from boomfmi.link.client import RigClient
    from boomfmi.link.protocol import load_key
    client = RigClient("127.0.0.1", port, load_key(), timeout=0.05)
    try:
        return paced_loop(duration, lambda t: client.exchange(5.0, t, DT))
    finally:
        client.close()


def cosim_run(port: int, duration: float, cycle):
    """The teleoperation system against the rig at ``port``; returns (result, wall [s])."""
    from boomfmi.system.master import CoSimulation
    params = {"hardware_bridge.mode": "udp", "hardware_bridge.rig": f"udp://127.0.0.1:{port}",
              "boom_load.x0": 0.0}
    with CoSimulation(ROOT / "build" / "teleoperation.ssp", DT, parameters=[params]) as cosim:
        u_names = [n for n in cosim.inputs if n.endswith(".u")]
        gc.collect()
        gc.disable()           # a collection pause would be a missed deadline; the run allocates little
        t0 = time.perf_counter()
        try:
            result = cosim.simulate(duration, lambda t: dict.fromkeys(u_names, cycle(t % cycle.duration)["u"]))
        finally:
            gc.enable()
        return result, time.perf_counter() - t0


def share(misses: int, steps: int) -> str:
    return f"{misses} of {steps} ({100 * misses / steps:.3f} %)"


def describe_run(result, wall: float, duration: float) -> list[str]:
    steps = len(result) - 1
    misses = int(result["hardware_bridge.deadline_misses"].iloc[-1])
    lost = int(result["hardware_bridge.lost_packets"].iloc[-1])
    late = result["hardware_bridge.lateness"].to_numpy()[1:]
    f = result["force_estimator.f_est"]
    lines = [f"{steps} steps of 1 ms over {duration:g} s of simulated time in {wall:.2f} s wall "
             f"(real-time factor {duration / wall:.3f})",
             f"missed deadlines: {share(misses, steps)}; lost answers: {lost}",
             f"lateness at a step's start: median {1e3 * np.median(late):.2f} ms, 99.9th percentile "
             f"{1e3 * np.percentile(late, 99.9):.2f} ms, longest {1e3 * late.max():.1f} ms"]
    missed = late > DT
    starts = np.flatnonzero(missed & ~np.r_[False, missed[:-1]])
    if len(starts):
        lines.append(f"the misses come in {len(starts)} episodes (a stall, then the steps that catch up), "
                     f"at t = {', '.join(f'{DT * (k + 1):.2f}' for k in starts[:12])}"
                     f"{' ...' if len(starts) > 12 else ''} s")
    lines.append(f"f_est from {f.min():.0f} to {f.max():.0f} N; the rig's true f_ext from "
                 f"{result['hardware_bridge.f_ext'].min():.0f} to {result['hardware_bridge.f_ext'].max():.0f} N")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=3, help="digging cycles of 10 s")
    ap.add_argument("--config", type=Path, default=ROOT / "examples" / "rig" / "contact_soft.json")
    ap.add_argument("--priority", type=int, default=50,
                    help="SCHED_FIFO priority of the rig and the co-simulation where permitted; 0: normal scheduler")
    ap.add_argument("--floor", action="store_true",
                    help="before each run, measure the bare floor and the link floor for as long as the run")
    ap.add_argument("--repeat", type=int, default=1, help="rounds to make (each: floors if asked, then the run)")
    ap.add_argument("--doc", type=Path, help="also write what is printed to this Markdown file")
    args = ap.parse_args(argv)
    if args.cycles < 1 or args.repeat < 1:
        ap.error("--cycles and --repeat must be at least 1")
    from boomfmi.experiments import dig
    from boomfmi.rig.server import realtime_priority

    printed: list[str] = []

    def say(line: str = "") -> None:
        print(line, flush=True)
        printed.append(line)

    os.environ["BOOMFMI_LINK_KEY"] = os.urandom(16).hex()
    cosim_scheduling = realtime_priority(args.priority) if args.priority else "normal scheduler"
    cycle = dig()
    duration = args.cycles * cycle.duration
    steps = int(round(duration / DT))
    say(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
        f"rig and co-simulation in separate processes over loopback; co-simulation: {cosim_scheduling}")
    figures = {"co-simulation": [], "link floor": [], "bare floor": []}
    for r in range(args.repeat):
        if args.repeat > 1:
            say(f"\nround {r + 1} of {args.repeat}")
        if args.floor:
            bare = count_misses(paced_loop(duration))
            with rig_process(args.config, args.priority) as (port, _, _):
                link = count_misses(link_floor(port, duration))
            figures["bare floor"].append(bare)
            figures["link floor"].append(link)
            say(f"bare floor (a paced loop doing nothing, {duration:g} s): missed {share(bare, steps)}")
            say(f"link floor (the bridge's exchange with a rig and nothing else): missed {share(link, steps)}")
        with rig_process(args.config, args.priority) as (port, rig_scheduling, stopped):
            result, wall = cosim_run(port, duration, cycle)
        figures["co-simulation"].append(int(result["hardware_bridge.deadline_misses"].iloc[-1]))
        if r == 0:
            say(f"rig: {rig_scheduling}")
        say("\n".join(describe_run(result, wall, duration)))
        say(stopped["summary"])
    if args.repeat > 1:
        say(f"\nmedians over {args.repeat} rounds of {steps} steps:")
        for name, got in figures.items():
            if got:
                say(f"  {name}: {100 * np.median(got) / steps:.3f} % missed "
                    f"(rounds: {', '.join(f'{100 * g / steps:.3f}' for g in got)} %)")
    if args.floor:
        link, cosim = sum(figures["link floor"]), sum(figures["co-simulation"])
        ratio = f"{cosim / link:.2f}" if link else "n/a (no link-floor misses)"
        say(f"co-simulation's misses over the link floor's, all rounds: {cosim} / {link} = {ratio}")
    if args.doc:
        about = __doc__.split("\n\n", 1)[1].rsplit("\n\n", 1)[0]
        args.doc.write_text(
            "# The teleoperation system in real time\n\n" + about + "\n\nThe target: at most 0.1 % "
            "missed deadlines over 30 s at 1 kHz.\n\n"
            f"`python benchmarks/teleoperation_realtime.py {' '.join(argv if argv is not None else sys.argv[1:])}`, "
            f"{time.strftime('%Y-%m-%d %H:%M')}:\n\n```\n" + "\n".join(printed).strip() + "\n```\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
