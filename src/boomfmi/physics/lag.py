"""The exact first-order lag, one step at a time: the valve's spool
(``effects.spool_lag_step``), the sensors (``effects.sensor_lag_step``) and the force
estimate's low-pass all take it; and the pure delay of a signal (the sensors' dead
time, ``effects.sensor_lag``'s second law): :class:`DelayLine` one sample at a time,
:func:`delayed` along a whole signal."""
from __future__ import annotations

import bisect
import math

import numpy as np


def first_order_step(y: float, target: float, dt: float, tau: float) -> float:
    """``y`` after ``dt`` [s] of ``y' = (target - y) / tau`` with ``target`` held: exact,
    ``target + (y - target) exp(-dt / tau)``; ``tau <= 0`` [s] passes the target."""
    if tau <= 0.0:
        return target
    return target + (y - target) * math.exp(-dt / tau)


class DelayLine:
    """A signal ``delay`` [s] late, one sample at a time: :meth:`push` the signal's
    value at time t, :meth:`read` its value at t - delay (linear between the samples
    pushed, the first value before them).  Keeps only what a read still needs."""

    def __init__(self, delay: float):
        self.delay = float(delay)
        self.times: list = []
        self.values: list = []

    def push(self, t: float, value) -> None:
        self.times.append(float(t))
        self.values.append(value)
        # drop samples older than the one before t - delay
        cut = bisect.bisect_left(self.times, t - self.delay) - 1
        if cut > 0:
            del self.times[:cut], self.values[:cut]

    def read(self, t: float):
        """The value at ``t - delay``; a tuple of channels is interpolated channel by
        channel."""
        s = t - self.delay
        times, values = self.times, self.values
        i = bisect.bisect_right(times, s)
        if i == 0:
            return values[0]
        if i >= len(times):
            return values[-1]
        w = (s - times[i - 1]) / (times[i] - times[i - 1])
        a, b = values[i - 1], values[i]
        if isinstance(a, tuple):
            return tuple(x + w * (y - x) for x, y in zip(a, b))
        return a + w * (b - a)


def delayed(y, t, delay: float):
    """The signal ``y`` (a NumPy array on times ``t`` [s]) ``delay`` [s] late: y(t -
    delay), linear between samples, the first value before the signal starts."""
    if delay <= 0.0:
        return y
    return np.interp(np.asarray(t, float) - delay, t, y)


__all__ = ["first_order_step", "DelayLine", "delayed"]
