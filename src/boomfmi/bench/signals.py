"""Signal processing for the bench: velocity from a measured position, noise levels,
strokes.

A bench's samples need not be evenly spaced (a LabVIEW loop at 100 Hz that now and then
takes 30 ms), so the velocity is a local linear regression of the position on the
actual sample times, Gaussian-weighted with a bandwidth in seconds, after a running
median of five samples that removes a position sensor's single-sample spikes.
"""
from __future__ import annotations

import math

import numpy as np

#: Bandwidth of the velocity's Gaussian kernel [s].  A bench's strokes last seconds and
#: reverse within about 0.1 s; 0.03 s keeps a reversal while averaging some ten samples
#: at 100 Hz.
SMOOTH = 0.03
#: A sample counts as at rest where |v| is below this many standard deviations of the
#: velocity's noise (from the position's own noise).
REST_SIGMAS = 3.0


def robust_noise(y: np.ndarray) -> float:
    """Standard deviation of white noise on a smooth signal ``y``, from its second
    differences (a median absolute deviation, so steps and spikes do not count)."""
    d2 = np.diff(np.asarray(y, dtype=float), 2)
    if d2.size == 0:
        return 0.0
    return float(np.median(np.abs(d2 - np.median(d2))) / 0.6745 / math.sqrt(6.0))


def running_median(y: np.ndarray, size: int = 5) -> np.ndarray:
    """Running median over ``size`` samples (the ends take the nearest values)."""
    from scipy.ndimage import median_filter
    return median_filter(np.asarray(y, dtype=float), size=size, mode="nearest")


def local_slope(t: np.ndarray, y: np.ndarray, bandwidth: float = SMOOTH):
    """The derivative of ``y`` by a Gaussian-weighted local linear regression on the
    sample times ``t`` [s] (bandwidth [s]); returns ``(dy/dt, g)`` where ``g`` is the
    factor of each estimate's noise: std(dy/dt) = g * std(noise of y)."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(t)
    dt_min = float(np.min(np.diff(t))) if n > 1 else 1.0
    half = int(min(n - 1, max(1, math.ceil(3.0 * bandwidth / max(dt_min, 1e-12)))))
    offsets = np.arange(-half, half + 1)
    idx = np.arange(n)[:, None] + offsets[None, :]
    valid = (idx >= 0) & (idx < n)
    idx = np.clip(idx, 0, n - 1)
    tau = t[idx] - t[:, None]
    w = np.where(valid, np.exp(-0.5 * (tau / bandwidth) ** 2), 0.0)
    sw = w.sum(axis=1)
    tbar = (w * tau).sum(axis=1) / sw
    ybar = (w * y[idx]).sum(axis=1) / sw
    dtau = tau - tbar[:, None]
    s = (w * dtau * dtau).sum(axis=1)
    s = np.where(s > 0, s, np.inf)
    slope = (w * dtau * (y[idx] - ybar[:, None])).sum(axis=1) / s
    gain = np.sqrt(((w * dtau) ** 2).sum(axis=1)) / s
    return slope, gain


def velocity(t: np.ndarray, x: np.ndarray, bandwidth: float = SMOOTH):
    """Velocity [m/s] from position ``x`` [m] at times ``t`` [s], and the speed below
    which a sample is at rest (REST_SIGMAS standard deviations of the estimate's noise,
    from the position's own noise): ``(v, v_rest)``."""
    v, _ = local_slope(t, running_median(x), bandwidth)
    # the velocity's noise: the same estimate of white noise of the position's level
    noise = np.random.default_rng(0).normal(0.0, robust_noise(x), len(x))
    v_noise, _ = local_slope(t, running_median(noise), bandwidth)
    return v, REST_SIGMAS * float(np.std(v_noise))


def stroke_ids(v: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Each sample's stroke number (0, 1, ...): a stroke is a stretch of motion one way,
    from one reversal to the next; samples at rest belong to the stroke before them
    (those before the first motion to the first stroke)."""
    direction = np.where(rest, 0.0, np.sign(v))
    moving = np.flatnonzero(direction != 0)
    if moving.size == 0:
        return np.zeros(len(v), dtype=int)
    filled = direction.copy()
    filled[: moving[0]] = direction[moving[0]]
    last = np.maximum.accumulate(np.where(filled != 0, np.arange(len(v)), 0))
    filled = filled[last]
    change = np.concatenate([[0], (np.diff(filled) != 0).astype(int)])
    return np.cumsum(change)


__all__ = ["SMOOTH", "REST_SIGMAS", "robust_noise", "running_median", "local_slope", "velocity", "stroke_ids"]
