#!/usr/bin/env python3
"""Round trip of the rig link over loopback in a 10 s real-time loop at 1 kHz.

Starts ``boomfmi rig serve`` (real time, the reference rig) as its own process, then
runs a 1 kHz loop here: at the start of every 1 ms slot it sends an authenticated
command and waits for the answer.  Prints the round-trip p50 / p99 / max and the share
of slots whose answer came after the slot's end (a missed deadline).

    python benchmarks/link_latency.py [--seconds 10]
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

from boomfmi.link.client import RigClient  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args(argv)
    key = os.urandom(16).hex()
    rig = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0"],
                           env=dict(os.environ, BOOMFMI_LINK_KEY=key, PYTHONPATH=str(ROOT / "src")),
                           stdout=subprocess.PIPE, text=True)
    port = int(re.search(r":(\d+) ", rig.stdout.readline()).group(1))
    client = RigClient("127.0.0.1", port, key.encode(), timeout=0.02)
    n = int(args.seconds * 1000)
    rtt = np.full(n, np.nan)
    missed = late_starts = 0
    start = time.perf_counter() + 0.01
    gc.disable()              # a real-time loop allocates little; a collection pause would be a miss
    try:
        for k in range(n):
            slot = start + k * 1e-3
            while time.perf_counter() < slot:
                pass
            t0 = time.perf_counter()
            late_starts += t0 > slot + 1e-3
            sample = client.exchange(1.0 if (k // 2000) % 2 == 0 else 9.0, k * 1e-3)
            t1 = time.perf_counter()
            if sample is not None:
                rtt[k] = t1 - t0
            if sample is None or t1 > slot + 1e-3:
                missed += 1
    finally:
        gc.enable()
        client.close()
        rig.send_signal(signal.SIGTERM)
        summary = rig.communicate(timeout=10)[0].strip()
    ok = rtt[~np.isnan(rtt)] * 1e6
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
          f"rig and client in separate processes over loopback")
    print(f"{n} exchanges at 1 kHz over {args.seconds:g} s, {n - ok.size} unanswered")
    print(f"round trip: p50 {np.percentile(ok, 50):.0f} us, p99 {np.percentile(ok, 99):.0f} us, "
          f"max {ok.max():.0f} us")
    print(f"missed deadlines: {missed} of {n} ({100 * missed / n:.3f} %); round trips over 1 ms: "
          f"{int((ok > 1000).sum())}; slots begun a whole slot late (after an earlier stall): {late_starts}")
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
