#!/usr/bin/env python3
"""Time of one diagnosis: two fit recordings and one holdout recording of 10 s each.

The virtual rig (heat transfer on, load parameters off the reference by a few per
cent, noise on) records three runs of different random step commands; the script
times ``boomfmi.diagnose.diagnose`` on them, end to end (reading, baseline
identification, localisation, every candidate's fit and score, the report).
Target: under 60 s on the 2-core machine.

    python benchmarks/diagnosis_speed.py
"""
from __future__ import annotations

import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from boomfmi.diagnose import diagnose  # noqa: E402
from boomfmi.experiments import random_steps  # noqa: E402
from boomfmi.recording import write_recording  # noqa: E402
from boomfmi.rig.offline import run_offline  # noqa: E402


def main() -> int:
    cfg = {"params": {"K_v": 2950.0, "M": 21.5, "F_L": 270.0}, "effects": {"heat_transfer": {}}, "seed": 31}
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        paths = []
        for i, seed in enumerate((41, 42, 43)):
            cmd = random_steps(seed, duration=10.0)
            paths.append(write_recording(d / f"run{i}.csv", run_offline(dict(cfg, seed=seed), cmd, cmd.duration)))
        t = time.perf_counter()
        doc = diagnose(paths[:2], paths[2:], d / "out")
        wall = time.perf_counter() - t
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    print(f"diagnosis of 2 fit + 1 holdout recordings of 10 s: {wall:.1f} s wall (target 60 s); "
          f"verdict {doc['verdict']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
