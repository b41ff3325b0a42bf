"""The exact first-order lag, one step at a time: the valve's spool
(``effects.spool_lag_step``), the sensors (``effects.sensor_lag_step``) and the force
estimate's low-pass all take it."""
from __future__ import annotations

import math


def first_order_step(y: float, target: float, dt: float, tau: float) -> float:
    """``y`` after ``dt`` [s] of ``y' = (target - y) / tau`` with ``target`` held: exact,
    ``target + (y - target) exp(-dt / tau)``; ``tau <= 0`` [s] passes the target."""
    if tau <= 0.0:
        return target
    return target + (y - target) * math.exp(-dt / tau)
