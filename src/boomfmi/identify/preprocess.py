"""Preprocessing of recordings: the paper's second-order low-pass filter, x from alpha
by Eq. 12, and velocity and acceleration estimates.

Offline the filter runs forwards and backwards (zero phase: no delay, squared
magnitude, so an effective fourth order); ``causal=True`` gives the plain second-order
filter a controller could run online.  Derivatives are central differences of the
filtered position.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, filtfilt, lfilter

from .. import physics as ph
from ..recording import Recording

#: Default cut-off of the low-pass filter [Hz] (the paper does not give its own).
CUTOFF = 25.0


def lowpass(y: np.ndarray, fs: float, cutoff: float = CUTOFF, causal: bool = False) -> np.ndarray:
    """Second-order Butterworth low-pass at ``cutoff`` [Hz] of samples at ``fs`` [Hz]."""
    b, a = butter(2, cutoff / (fs / 2.0))
    if causal:
        return lfilter(b, a, y - y[0]) + y[0]
    return filtfilt(b, a, y, padtype="odd", padlen=min(len(y) - 1, 3 * max(len(a), len(b)) * 10))


@dataclass
class Prepared:
    """A recording ready for identification: every signal filtered alike, SI units,
    pressures absolute."""
    t: np.ndarray
    u: np.ndarray
    p_a: np.ndarray        #: filtered, absolute [Pa]
    p_b: np.ndarray
    x: np.ndarray          #: filtered piston position [m] from alpha by Eq. 12
    v: np.ndarray          #: [m/s]
    a: np.ndarray          #: [m/s^2]
    phi: np.ndarray        #: cylinder angle [rad], Eq. 10, from the filtered x
    x_raw: np.ndarray      #: unfiltered Eq. 12 position [m]
    p_a_raw: np.ndarray    #: unfiltered absolute pressures [Pa]
    p_b_raw: np.ndarray
    fs: float
    cutoff: float = CUTOFF  #: the low-pass filter's cut-off [Hz]
    source: str = ""

    @property
    def dt(self) -> float:
        return 1.0 / self.fs


def prepare(rec: Recording, cutoff: float = CUTOFF, geometry: ph.Geometry | None = None,
            P_atm: float | None = None) -> Prepared:
    """Filter a recording and derive x, v, a and phi, at the recording's rig (its
    sidecar's geometry and P_atm) unless ``geometry`` or ``P_atm`` are given."""
    d = rec.data
    t = d["t"].to_numpy(dtype=float)
    steps = np.diff(t)
    fs = 1.0 / float(np.median(steps))
    if np.max(np.abs(steps - 1.0 / fs)) > 0.1 / fs:
        raise ValueError(f"{rec.path}: samples are not evenly spaced (median step {1e3 / fs:.3f} ms); "
                         f"resample before identification")
    P_atm = rec.P_atm if P_atm is None else P_atm
    geometry = rec.rig_tuple(ph.Geometry) if geometry is None else geometry
    p_a_raw = d["p_a"].to_numpy(dtype=float) + P_atm
    p_b_raw = d["p_b"].to_numpy(dtype=float) + P_atm
    x_raw = ph.x_from_alpha(d["alpha"].to_numpy(dtype=float), geometry)
    x = lowpass(x_raw, fs, cutoff)
    v = np.gradient(x, t)
    a = np.gradient(v, t)
    return Prepared(t=t, u=d["u"].to_numpy(dtype=float), p_a=lowpass(p_a_raw, fs, cutoff),
                    p_b=lowpass(p_b_raw, fs, cutoff), x=x, v=v, a=a,
                    phi=ph.phi_from_x(np.clip(x, 0.0, None), geometry), x_raw=x_raw,
                    p_a_raw=p_a_raw, p_b_raw=p_b_raw, fs=fs, cutoff=cutoff, source=str(rec.path))


#: A holdout error (the NRMSE summed over x, p_a, p_b) beyond NOISE_FACTOR times the
#: noise floor (summed likewise) plus ABS_FLOOR is a gap the model does not explain.
NOISE_FACTOR = 3.0
ABS_FLOOR = 0.002


def beyond_noise(errors: dict, rec) -> dict:
    """Whether the ``errors`` (channel -> NRMSE) of a model against ``rec`` are a gap
    beyond its noise: ``beyond_noise``, ``nrmse_sum``, ``noise_floor_sum``, ``threshold``."""
    noise = float(sum(noise_floor(rec).values()))
    threshold = NOISE_FACTOR * noise + ABS_FLOOR
    total = float(sum(errors.values()))
    return {"beyond_noise": total > threshold, "nrmse_sum": total, "noise_floor_sum": noise, "threshold": threshold}


def noise_floor(rec) -> dict:
    """Each channel's measurement noise over its range (x, p_a, p_b: the NRMSE a
    perfect model would still show): the RMS of what a 50 Hz low-pass removes.  The
    floor ``identify`` judges a holdout error against and ``diagnose`` its gaps."""
    from ..compare import CHANNELS, recorded
    m = recorded(rec)
    fs = 1.0 / float(np.median(np.diff(rec.data["t"].to_numpy(float))))
    return {c: float(np.std(m[c] - lowpass(m[c], fs, 50.0)) / max(float(np.ptp(m[c])), 1e-12)) for c in CHANNELS}
