"""Record the virtual rig without a link: the plant stepped in-process.

For benchmarks and tests that need many recordings fast (identification, diagnosis):
the same plant the rig server runs, driven by a command profile, returned in the
recording format with the true ``f_ext`` and ``x``; the excavator's
(:func:`run_excavator_offline`) in the excavator recording's columns (:data:`COLUMNS`)
with the true tip force, x and v per joint.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import pandas as pd

from .config import config_machine, load_config
from .plant import JOINTS, ExcavatorRig, ExcavatorSample, VirtualRig, commands

#: Columns of :func:`run_excavator_offline` (the excavator recording's, then the truth).
COLUMNS = (("t",) + tuple(f"{q}_{j}" for q in ("u", "p_a", "p_b", "angle") for j in JOINTS)
           + ("f_tip_x", "f_tip_y", "f_tip_z") + tuple(f"{q}_{j}" for q in ("x", "v") for j in JOINTS))


def run_offline(config, command: Callable[[float], dict], duration: float, dt: float = 1e-3) -> pd.DataFrame:
    """Step a virtual rig (``config``: see :func:`boomfmi.rig.load_config`) under
    ``command(t) -> {"u": V}`` for ``duration`` seconds; one row per sample, t0 included.
    A row holds the sample measured at t and the command applied from t on.

    An excavator's configuration (``"machine": "excavator"``) runs
    :func:`run_excavator_offline` instead: ``command(t)`` returns
    ``{"u_<joint>": V}`` and the rows are in the excavator recording's columns, plus
    the true tip force, x and v per joint."""
    if config_machine(config) == "excavator":
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


def sample_row(s: ExcavatorSample, u) -> list:
    """One row of :data:`COLUMNS` from the sample ``s`` and the commands ``u`` applied
    from its time on."""
    return [s.t, *u, *s.p_a, *s.p_b, *s.angle, *s.f_tip, *s.x, *s.v]


def run_excavator_offline(config, command, duration: float, dt: float = 1e-3) -> pd.DataFrame:
    """Step an excavator rig (``config``: see :func:`load_excavator_config`) under
    ``command(t) -> {"u_<joint>": V}`` (e.g. ``experiments.digging_cycle()``) for
    ``duration`` seconds; one row per sample, t0 included, in :data:`COLUMNS`: the
    excavator recording's columns (the sample measured at t and the commands applied
    from t on) plus the true tip force, x and v per joint.

    A closed-loop profile (``command.closed_loop`` true, e.g.
    :class:`boomfmi.experiments.JointTrajectoryController`) is called as
    ``command(t, angles)`` with the joint angles measured at ``t`` (noise and ADC
    included): a controller that is part of the experiment, as an operator is."""
    plant = ExcavatorRig(config)
    n = int(round(duration / dt))
    rows = np.empty((n + 1, len(COLUMNS)))
    s = plant.measure()
    closed = bool(getattr(command, "closed_loop", False))
    if closed and hasattr(command, "reset"):
        command.reset()
    for k in range(n + 1):
        u = commands(command(k * dt, s.angle) if closed else command(k * dt))
        rows[k] = sample_row(s, u)
        if k < n:
            s = plant.step(u, dt)
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    df["t"] = np.round(df["t"].to_numpy(), 9)
    return df


__all__ = ["COLUMNS", "run_offline", "sample_row", "run_excavator_offline"]
