"""Record the virtual rig without a link: the plant stepped in-process.

For benchmarks and tests that need many recordings fast (identification, diagnosis):
the same plant the rig server runs, driven by a command profile, returned in the
recording format with the true ``f_ext`` and ``x``.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import pandas as pd

from .config import config_machine, load_config
from .plant import VirtualRig


def run_offline(config, command: Callable[[float], dict], duration: float, dt: float = 1e-3) -> pd.DataFrame:
    """Step a virtual rig (``config``: see :func:`boomfmi.rig.load_config`) under
    ``command(t) -> {"u": V}`` for ``duration`` seconds; one row per sample, t0 included.
    A row holds the sample measured at t and the command applied from t on.

    An excavator's configuration (``"machine": "excavator"``) runs
    :func:`boomfmi.rig.excavator.run_excavator_offline` instead: ``command(t)`` returns
    ``{"u_<joint>": V}`` and the rows are in the excavator recording's columns, plus
    the true tip force, x and v per joint."""
    if config_machine(config) == "excavator":
        from .excavator import run_excavator_offline
        return run_excavator_offline(config, command, duration, dt)
    plant = VirtualRig(load_config(config))
    n = int(round(duration / dt))
    rows = np.empty((n + 1, 7))
    s = plant.measure()
    for k in range(n + 1):            # a row: the sample at t_k and the command from t_k on
        u = float(command(k * dt)["u"])
        rows[k] = (s.t, u, s.p_a, s.p_b, s.alpha, s.f_ext, s.x)
        if k < n:
            s = plant.step(u, dt)
    df = pd.DataFrame(rows, columns=["t", "u", "p_a", "p_b", "alpha", "f_ext", "x"])
    df["t"] = np.round(df["t"].to_numpy(), 9)
    return df
