"""The sound identification of the load: every sample, every start, intervals.

Three stages, on every recording given together:

1. **Equation error on Eq. 8, through every mode** (:func:`equation_error`).  Each
   sample is classified as sliding (and which way) or resting (stuck, or held at a
   stop) from the position alone (:func:`motion_modes`; the speed that counts as
   motion is set by the recording's own position resolution).  While resting,
   friction or the stop balances the drive force, so Eq. 8 holds with a = v = 0 and a
   friction that needs no parameter; while sliding, the friction is F_d cos(phi)
   against the motion.  Every term is filtered alike by a state-variable filter, so
   the filtered equation holds at every sample (starts, stops, reversals, holds at the
   valve's centre), except within the filter's reach of an impact on a stop.  Least
   squares gives M, K_v, F_d and F_L: K_v, F_d and F_L well, M roughly (the mass shows
   only in transients of M / K_v, about 8 ms, which a filter slow enough for a
   quantised position blurs).
2. **Velocity output error over every sliding run** (:func:`velocity_error`).  Within
   each run of sliding one way, Eq. 8 is linear in the velocity; driven by the recorded
   pressures and position (phi), from the measured velocity at the run's start, it is
   one recursive filter (``physics.sliding_velocity``).  The simulated and the measured
   velocity, both low-passed alike, are matched over all runs (scipy's least_squares)
   for M, K_v, F_d and F_L together.  No drift (each run restarts, and the viscous
   friction forgets the start within milliseconds) and no static friction: the modes
   come from the recording.
3. **Static friction from every start** (:func:`static_friction`).  Each run that
   follows a rest (in mid-stroke after a hold, after a stop, or from an end stop)
   starts when the drive force reaches F_s cos(phi).  For every F_s on a grid, the run
   is simulated from that instant (stage 2's filter), between samples where the force
   crosses F_s between them, and its displacement matched to the measured position
   (a likelihood whose spread is the sensor's and MODEL_SHARE of the displacement);
   each start's evidence is blurred by how far the pressures' filter moves the drive
   force where it crosses each level (against a filter twice as fast: through a
   valve's step, whose corner it spreads, a wide band; on a smooth rise, little), and
   the posterior over F_s gives F_s and its interval.  The
   largest drive force the piston held at rest in mid-stroke is a lower bound.  Where
   the starts do not pin F_s down (the drive force jumps through the static band
   within a sample or two, as in a start under full pressure), the interval says so
   and F_s is reported as not identified: nothing else depends on it.  Its value is
   then the starts' upper edge (:func:`upper_edge`), not their flat evidence's mean.

Intervals: for stages 1 and 2 a bootstrap over the runs (blocks of correlated
residuals) of the linearised fit, for F_s the profile of its cost; each widened by
``SYSTEMATIC`` (a relative floor, calibrated on effect-free recordings of random rigs
and command designs, ``benchmarks/identification.py``: the share of the error that
the noise does not explain: sensor resolution, numerics, mode classification).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import maximum_filter1d, median_filter
from scipy.optimize import least_squares
from scipy.special import ndtr

from .. import physics as ph
from ..physics import effects as fx
from ..physics import reference_rig
from .preprocess import Prepared, lowpass

PARAMS = ("K_v", "F_s", "F_d", "F_L", "M")
PARAMETER_UNITS = {"K_v": "N.s/m", "F_s": "N", "F_d": "N", "F_L": "N", "M": "kg", "A_max": "m2",
         "c_sum": "N/Pa", "c_max": "N/Pa", "c_diff": "N/Pa"}
#: pressure_friction's coefficient for each seal-pressure law (``physics.effects.seal_pressure``)
PRESSURE_COEFFICIENT = {"sum": "c_sum", "max": "c_max", "diff": "c_diff"}
#: The widest 95 % interval, as a half-width relative to the value, with which the data
#: still tell a parameter (wider: identification warns that they cannot).
TELLS_WIDTH = 0.5
#: Relative floor of every interval's half-width (see the module's docstring).
SYSTEMATIC = {"K_v": 0.01, "F_s": 0.03, "F_d": 0.015, "F_L": 0.005, "M": 0.03}


@dataclass
class Estimate:
    value: float
    ci95: tuple[float, float]
    unit: str

    @property
    def relative_halfwidth(self) -> float:
        return (self.ci95[1] - self.ci95[0]) / 2.0 / abs(self.value) if self.value else math.inf

    @property
    def tells(self) -> bool:
        """Whether the interval is narrow enough for the data to tell the value
        (:data:`TELLS_WIDTH`; a NaN interval does not)."""
        return bool(self.relative_halfwidth < TELLS_WIDTH)


@dataclass
class FitResult:
    method: str
    params: dict[str, Estimate]
    warnings: list[str] = field(default_factory=list)
    details: dict = field(default_factory=dict)

    def values(self) -> dict[str, float]:
        return {k: e.value for k, e in self.params.items()}


def _widened(name: str, value: float, lo: float, hi: float) -> Estimate:
    """An estimate whose interval is at least ``SYSTEMATIC[name]`` of its value wide on
    either side (the statistical interval combined with the floor in quadrature)."""
    floor = SYSTEMATIC.get(name, 0.0) * abs(value)
    below = math.hypot(value - lo, floor)
    above = math.hypot(hi - value, floor)
    return Estimate(float(value), (float(value - below), float(value + above)), PARAMETER_UNITS[name])


def _dilate(mask: np.ndarray, n: int) -> np.ndarray:
    if n <= 0:
        return mask
    kernel = np.ones(2 * n + 1)
    return np.convolve(mask.astype(float), kernel, mode="same") > 0


def resolution(x_raw: np.ndarray) -> float:
    """The position sensor's resolution [m] as the recording shows it: the smallest
    step its readings take (the 5th percentile of the nonzero sample-to-sample
    changes, which noise only widens)."""
    steps = np.abs(np.diff(x_raw))
    steps = steps[steps > 1e-12]
    return float(np.percentile(steps, 5)) if len(steps) else 1e-5


#: Cut-off [Hz] of the filter the mode classification smooths the position with.  The
#: zero-phase filter spreads each stop and start over about 1 / (2 MODE_CUTOFF); what it
#: spreads into the sticking samples beside a run is taken for sliding at F_d (20 Hz:
#: 25 ms, F_d low and M high, the bucket's F_d by 5 %, docs/excavator.md).  The speed that
#: counts as motion rises with it on a coarse sensor (:func:`motion_modes`).
MODE_CUTOFF = 40.0


@dataclass
class Modes:
    """Where the piston slides, and which way, sample by sample.

    ``sliding``: the smoothed velocity is clearly beyond what the sensor's resolution
    and noise make of a resting piston; ``direction``: its sign (0 at rest);
    ``impacts``: samples where the piston arrives at a stop while moving (the stop's
    impulse is not in Eq. 8, so the samples around them are left out)."""
    sliding: np.ndarray
    direction: np.ndarray
    impacts: np.ndarray
    v_min: float
    x: np.ndarray              #: the smoothed position the classification used [m]
    v: np.ndarray              #: and its velocity [m/s]


def motion_modes(p: Prepared, L: float) -> Modes:
    """Classify every sample of a prepared recording (:class:`Modes`).  The speed that
    counts as motion is set by the recording's own position resolution (two
    resolution steps per period of the smoothing filter, and at least 2 mm/s): a coarse
    sensor needs a larger speed to tell motion from rest."""
    return modes_of(p.x_raw, p.t, p.fs, L)


def modes_of(x_raw: np.ndarray, t: np.ndarray, fs: float, L: float) -> Modes:
    """:func:`motion_modes` of the position readings ``x_raw`` [m] at times ``t`` [s]
    (sample rate ``fs`` [Hz]) of a piston of stroke ``L`` [m]."""
    xs = lowpass(x_raw, fs, MODE_CUTOFF)
    vs = np.gradient(xs, t)
    q = resolution(x_raw)
    v_min = max(0.002, 2.0 * q * MODE_CUTOFF)
    sliding = np.abs(vs) > v_min
    direction = np.sign(vs) * sliding
    margin = max(3.0 * q, 2e-4)
    at_stop = (xs < margin) | (xs > L - margin)
    impacts = np.flatnonzero(at_stop[1:] & ~at_stop[:-1] & sliding[:-1]) + 1
    return Modes(sliding, direction, impacts, v_min, xs, vs)


#: Cut-off [Hz] of the state-variable filter of the equation error.
EE_CUTOFF = 10.0
#: Periods of that cut-off over which a filtered sample still feels an impact on a stop.
REACH = 3.0


def correlation_samples(p: Prepared) -> float:
    """Samples over which the residuals of filtered data stay correlated: about one
    period of the low-pass filter's cut-off, fs / (2 cutoff) (20 at 1 kHz and 25 Hz).
    Interval widths from least squares are scaled by its square root."""
    return max(1.0, p.fs / (2.0 * p.cutoff))


def equation_rows(r: "Motion", cutoff: float = EE_CUTOFF, v_s: float = 0.0, pressure: str | None = None):
    """Eq. 8 over the whole recording, through a state-variable filter G (zero-phase
    low-pass at ``cutoff``), as rows ``X theta = y`` in theta = (M, K_v, F_d, F_L)::

        M G[a] + K_v G[v] + F_d G[s cos(phi) sign(v)] + F_L G[s sin(phi)] = G[s F_p]

    s is 1 while the piston slides and 0 while it sticks or rests at a stop: there the
    friction (or the stop) balances the drive force exactly, so Eq. 8 holds with
    F_c = F_p - F_L sin(phi) and a = v = 0, which is the row with s = 0.  Since every
    term is filtered alike, the equation holds at every sample, through every start,
    stop and reversal, and the filter can be slow (its noise is low) without biasing
    anything.  G[a] and G[v] are derivatives of G[x].  With a Stribeck velocity ``v_s``
    [m/s] > 0 (stribeck_friction) the sliding friction is ``F_d (1 - w) + F_s w``,
    w = exp(-|v| / v_s) at the measured speed, and theta gains F_s (a fifth column).
    With a seal-pressure law ``pressure`` (pressure_friction: ``"sum"``, ``"max"`` or ``"diff"``,
    ``physics.effects.seal_pressure``) the sliding friction is ``F_d + c p_seal`` and
    theta gains c [N/Pa] (a last column, linear as the others).  Samples within the filter's
    reach of the recording's ends or of an impact on a stop are left out (a stop's
    impulse is not in Eq. 8).  Returns ``(X, y, mask)``."""
    p, modes = r.p, r.modes
    s = modes.sliding.astype(float)
    G = lambda y: lowpass(y, p.fs, cutoff)
    xg = G(p.x_raw)
    vg = np.gradient(xg, p.t)
    ag = np.gradient(vg, p.t)
    friction = modes.direction * np.cos(p.phi)
    if v_s > 0.0:
        w = fx.stribeck_weight(modes.v, v_s)
        cols = [ag, vg, G(friction * (1.0 - w)), G(s * np.sin(p.phi)), G(friction * w)]
    else:
        cols = [ag, vg, G(friction), G(s * np.sin(p.phi))]
    if pressure is not None:
        cols.append(G(friction * r.seal(pressure)))
    X = np.column_stack(cols)
    y = G(s * r.F_p)
    reach = int(REACH * p.fs / cutoff)
    use = np.ones(len(y), bool)
    use[:reach] = use[-reach:] = False
    for i in modes.impacts:
        use[max(0, i - reach):i + reach] = False
    return X, y, use


def column_scale(X: np.ndarray) -> np.ndarray:
    """Each column's largest magnitude (1 for a column of zeros): what the least squares
    below divide the columns by, so that parameters of very different sizes (a mass in
    kg, a force in N) are solved on columns of one size."""
    scale = np.abs(X).max(axis=0)
    scale[scale == 0] = 1.0
    return scale


def scaled_lstsq(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The least-squares ``theta`` of ``y ~ X theta``, solved on the scaled columns
    (:func:`column_scale`)."""
    scale = column_scale(X)
    theta, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
    return theta / scale


def _normal_solve(G: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The least-squares solution from the normal equations ``G theta = r`` (``G`` the
    scaled columns' Gram matrix): by Cholesky, or where a resample leaves ``G``
    singular (a column it never excites), its minimum-norm solution, as ``lstsq`` gives."""
    try:
        c = np.linalg.cholesky(G)
        return np.linalg.solve(c.T, np.linalg.solve(c, r))
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(G, r, rcond=None)[0]


def block_bootstrap(X: np.ndarray, y: np.ndarray, fs: float, n_boot: int = 200, block: float = 0.1,
                    seed: int = 0) -> np.ndarray:
    """The least squares of ``y ~ X theta`` on ``n_boot`` moving-block resamples of the
    rows (blocks of ``block`` [s] of rows at ``fs`` [Hz]: neighbouring samples' errors
    are correlated, so rows are drawn a block at a time), ``(n_boot, p)``; 95 %
    intervals are their 2.5 and 97.5 percentiles.  Each resample is solved by its
    normal equations on the scaled columns (:func:`column_scale`, :func:`_normal_solve`):
    the same least squares as an SVD's, a tenth of its time on these 10^4 rows."""
    scale = column_scale(X)
    Xs = X / scale
    rng = np.random.default_rng(seed)
    b = max(1, int(block * fs))
    n = len(y)
    starts = np.arange(0, max(1, n - b))
    boots = []
    for _ in range(n_boot):
        picks = rng.choice(starts, size=max(1, n // b))
        idx = (picks[:, None] + np.arange(b)[None, :]).ravel()
        idx = idx[idx < n]
        Xb = Xs[idx]
        boots.append(_normal_solve(Xb.T @ Xb, Xb.T @ y[idx]) / scale)
    return np.array(boots)


def equation_error(motions: list["Motion"], n_boot: int = 200, block: float = 0.1, seed: int = 0,
                   cutoff: float = EE_CUTOFF, v_s: float = 0.0, pressure: str | None = None):
    """Stage 1: M, K_v, F_d, F_L (and F_s, with a Stribeck velocity ``v_s``; and the
    pressure coefficient, with a seal-pressure law ``pressure``) by least squares on
    :func:`equation_rows` of every recording; 95 % intervals from a moving-block
    bootstrap of the rows."""
    X, y = [], []
    for r in motions:
        Xi, yi, use = equation_rows(r, cutoff, v_s, pressure)
        X.append(Xi[use])
        y.append(yi[use])
    X, y = np.vstack(X), np.concatenate(y)
    if len(y) < 50 or np.ptp(X[:, 2]) == 0.0:
        raise ValueError("too few samples in motion to identify the load: the recordings hold almost no motion")
    theta = scaled_lstsq(X, y)
    cond = float(np.linalg.cond(X / column_scale(X)))
    boots = block_bootstrap(X, y, motions[0].p.fs, n_boot, block, seed)
    lo, hi = np.percentile(boots, [2.5, 97.5], axis=0)
    names = ("M", "K_v", "F_d", "F_L") + (("F_s",) if v_s > 0.0 else ()) + \
        ((PRESSURE_COEFFICIENT[pressure],) if pressure is not None else ())
    est = {k: _widened(k, theta[j], min(lo[j], theta[j]), max(hi[j], theta[j])) for j, k in enumerate(names)}
    residual = y - X @ theta
    return est, {"samples": len(y), "condition_number": cond,
                 "rms_residual_N": float(np.sqrt(np.mean(residual**2)))}


def _load_along(load_at, load: ph.Load, v: np.ndarray, p_a: np.ndarray, p_b: np.ndarray) -> ph.Load:
    """``load_at(load, v, p_a, p_b)`` at every sample, each field a float or an array of
    v's shape: called once on the arrays, else sample by sample (a form on floats only)."""
    try:
        out = load_at(load, v, p_a, p_b)
        if all(np.ndim(f) == 0 or np.shape(f) == v.shape for f in out):
            return ph.Load(*(np.asarray(f, float) if np.ndim(f) else float(f) for f in out))
    except (TypeError, ValueError):
        pass
    each = [load_at(load, float(a), float(b), float(c)) for a, b, c in zip(v, p_a, p_b)]
    return ph.Load(*(np.array(f, float) for f in zip(*each)))


def load_with_effect(motions: list["Motion"], start: dict, load_at, cutoff: float = EE_CUTOFF) -> dict:
    """Stage 1 with a friction-stage effect in the load, for an effect no linear column
    holds: M, K_v, F_d, F_L by nonlinear least squares of :func:`equation_rows`' equation
    error, the load at each sample ``load_at(load, v, p_a, p_b)`` (the effect's form at
    the smoothed speed and the recorded absolute pressures: arrays, or floats sample by
    sample), from ``start`` (the effect-free fit; F_s keeps its excess over F_d there).
    A field the effect makes vary multiplies its filtered column (M, K_v) or its
    unfiltered term before the filter (F_d, F_L), so that a constant one gives
    :func:`equation_rows`' row exactly.  Returns ``start`` with the four (and F_s) anew."""
    names = ("M", "K_v", "F_d", "F_L")
    excess = max(start.get("F_s", start["F_d"]) - start["F_d"], 0.0)
    rows = []
    for r in motions:
        p, modes = r.p, r.modes
        G = lambda y, fs=p.fs: lowpass(y, fs, cutoff)
        vg = np.gradient(G(p.x_raw), p.t)
        _, y, use = equation_rows(r, cutoff)
        rows.append((G, np.gradient(vg, p.t), vg, modes.direction * np.cos(p.phi),
                     modes.sliding * np.sin(p.phi), y, use, modes.v, p.p_a_raw, p.p_b_raw))
    if sum(int(u.sum()) for *_, u, _v, _a, _b in rows) < 50:
        raise ValueError("too few samples in motion to identify the load: the recordings hold almost no motion")
    z0 = np.array([float(start[k]) for k in names])
    scale = np.where(np.abs(z0) > 0.0, np.abs(z0), 1.0)
    spread = float(np.std(np.concatenate([y[u] for *_, y, u, _v, _a, _b in rows]))) or 1.0

    def residuals(z):
        M, K_v, F_d, F_L = z * scale
        load = ph.Load(K_v=K_v, F_s=F_d + excess, F_d=F_d, F_L=F_L, M=M)
        out = []
        for G, ag, vg, friction, sin, y, use, v, pa, pb in rows:
            ld = _load_along(load_at, load, v, pa, pb)
            smooth = lambda f: G(f) if np.ndim(f) else f
            pred = smooth(ld.M) * ag + smooth(ld.K_v) * vg + G(ld.F_d * friction) + G(ld.F_L * sin)
            out.append((pred - y)[use] / spread)
        return np.concatenate(out)
    res = least_squares(residuals, z0 / scale, method="lm")
    found = dict(zip(names, (float(v) for v in res.x * scale)))
    return {**start, **found, "F_s": found["F_d"] + excess}


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs of True in ``mask`` as (first, end) index pairs."""
    d = np.diff(np.concatenate(([0], mask.astype(int), [0])))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


#: Cut-off [Hz] of the low-pass filter through which velocities are compared.
VE_CUTOFF = 30.0


@dataclass
class Motion:
    """One prepared recording as every stage reads it, built once (:func:`motion`)."""
    p: Prepared
    modes: Modes
    spans: list            #: (first, end, direction) of each sliding run long enough to use
    F_p: np.ndarray        #: the pneumatic force [N] at each sample
    v_meas: np.ndarray     #: the measured velocity, low-passed [m/s]
    reach: int             #: samples at each run's ends left out of the velocity comparison
    L: float               #: the stroke [m]
    P_atm: float = reference_rig.P_atm   #: the atmosphere [Pa]

    def seal(self, pressure: str) -> np.ndarray:
        """The seals' pressure [Pa] at each sample by law ``pressure`` (pressure_friction,
        ``physics.effects.seal_pressure``), from the recorded pressures."""
        return fx.seal_pressure(self.p.p_a_raw, self.p.p_b_raw, self.P_atm, pressure)


def motion(p: Prepared, cyl: ph.Cylinder, P_atm: float) -> Motion:
    """Classify ``p``'s samples and cut its sliding runs (one direction each)."""
    modes = motion_modes(p, cyl.L)
    reach = int(round(p.fs / VE_CUTOFF))
    spans = [(i0, i1, d) for d in (1.0, -1.0) for i0, i1 in runs(modes.direction == d) if i1 - i0 > 3 * reach]
    spans.sort()
    return Motion(p, modes, spans, ph.piston_force(p.p_a_raw, p.p_b_raw, cyl, P_atm),
                  lowpass(np.gradient(p.x_raw, p.t), p.fs, VE_CUTOFF), reach, cyl.L, P_atm)


def _net_force(r: Motion, i0: int, i1: int, d: float, F_d: float, F_L: float,
               F_s: float = 0.0, v_s: float = 0.0, c: float = 0.0, pressure: str | None = None) -> np.ndarray:
    """The force that drives a run, each sample's value the mean of it and the next
    (the force held over a sample interval, centred: a held sample would lag it).
    With ``v_s`` > 0 the Coulomb level follows the Stribeck curve at the measured
    speed (the series-parallel form: the recursion stays linear); with a seal-pressure
    law ``pressure`` it rises by ``c`` [N/Pa] times the seals' recorded pressure."""
    phi = r.p.phi[i0:i1 + 1]
    level = F_d
    if v_s > 0.0:
        w = fx.stribeck_weight(r.modes.v[i0:i1 + 1], v_s)
        level = F_d * (1.0 - w) + F_s * w
    if pressure is not None and c != 0.0:
        level = level + c * r.seal(pressure)[i0:i1 + 1]
    F = r.F_p[i0:i1 + 1] - F_L * np.sin(phi) - d * level * np.cos(phi)
    if len(F) > i1 - i0:
        return 0.5 * (F[:-1] + F[1:])
    return np.concatenate((0.5 * (F[:-1] + F[1:]), F[-1:]))


def _run_velocity(r: Motion, theta, v_s: float = 0.0, F_s: float = 0.0, pressure: str | None = None) -> np.ndarray:
    """Stage 2's simulated velocity over every run of one recording (0 elsewhere);
    theta = (M, K_v, F_d, F_L[, c]), c with a seal-pressure law ``pressure``."""
    M, K_v, F_d, F_L = theta[:4]
    c = theta[4] if pressure is not None else 0.0
    v = np.zeros(len(r.p.t))
    for i0, i1, d in r.spans:
        v[i0:i1] = ph.sliding_velocity(r.modes.v[i0], _net_force(r, i0, i1, d, F_d, F_L, F_s, v_s, c, pressure),
                                       K_v, M, r.p.dt)
    return v


def velocity_error(all_runs: list[Motion], start: dict, n_boot: int = 300, seed: int = 0, v_s: float = 0.0,
                   pressure: str | None = None):
    """Stage 2: M, K_v, F_d, F_L (and the pressure coefficient, with a seal-pressure
    law ``pressure``; with a Stribeck velocity ``v_s`` the curve's static end F_s is
    held at ``start``'s) by velocity output error over every sliding run, from
    ``start`` (stage 1); intervals from a bootstrap over the runs of the linearised
    fit.  Returns ``(estimates, details)`` or ``(None, details)`` without usable runs."""
    names = ("M", "K_v", "F_d", "F_L") + ((PRESSURE_COEFFICIENT[pressure],) if pressure is not None else ())
    F_s = start["F_s"] if v_s > 0.0 else 0.0     # the Stribeck curve's static end, from the starts
    theta0 = np.array([start[k] for k in names])
    if pressure is not None and not theta0[4] > 0.0:
        theta0[4] = 1e-6         # a coefficient the equation error left at or below 0: a small one
    # a start outside physics (the equation error on very little motion) is replaced:
    # K_v from its magnitude, M for a 10 ms mechanical time constant, F_d 50 N
    theta0[1] = abs(theta0[1]) or 1000.0
    if not theta0[0] > 0.0:
        theta0[0] = 0.01 * theta0[1]
    if not theta0[2] > 0.0:
        theta0[2] = 50.0
    masks, labels = [], []
    for j, r in enumerate(all_runs):
        m = np.zeros(len(r.p.t), bool)
        lab = np.full(len(r.p.t), -1)
        for k, (i0, i1, _) in enumerate(r.spans):
            m[i0 + r.reach:i1 - r.reach] = True
            lab[i0:i1] = k + 1000 * j
        masks.append(m)
        labels.append(lab[m])
    labels = np.concatenate(labels)
    if len(labels) < 100:
        return None, {"runs": int(sum(len(r.spans) for r in all_runs))}

    def residuals(z):
        theta = theta0 * np.exp(z)
        return np.concatenate([(lowpass(_run_velocity(r, theta, v_s, F_s, pressure), r.p.fs, VE_CUTOFF) - r.v_meas)[m]
                               for r, m in zip(all_runs, masks)])

    res = least_squares(residuals, np.zeros(len(names)), diff_step=1e-4, x_scale=1.0, max_nfev=50)
    # a second start, from a neutral mass (a 10 ms mechanical time constant): the
    # equation error's M can be far off where the recording holds few transients
    # (every run ending on a stop, whose neighbourhood the equation error leaves out)
    neutral = np.zeros(len(names))
    neutral[0] = math.log(0.01 * theta0[1] / theta0[0])
    if abs(neutral[0]) > 0.1:
        other = least_squares(residuals, neutral, diff_step=1e-4, x_scale=1.0, max_nfev=50)
        if other.cost < res.cost:
            res = other
    theta = theta0 * np.exp(res.x)
    # bootstrap over the runs of the linearised problem around the optimum
    J, f = res.jac, res.fun
    groups = np.unique(labels)
    index = {g: np.flatnonzero(labels == g) for g in groups}
    rng = np.random.default_rng(seed)
    boots = []
    for _ in range(n_boot):
        pick = np.concatenate([index[g] for g in rng.choice(groups, size=len(groups))])
        dz, *_ = np.linalg.lstsq(J[pick], -f[pick], rcond=None)
        boots.append(theta * np.exp(np.clip(dz, -5.0, 5.0)))
    lo, hi = np.percentile(np.array(boots), [2.5, 97.5], axis=0)
    est = {k: _widened(k, theta[j], min(lo[j], theta[j]), max(hi[j], theta[j])) for j, k in enumerate(names)}
    return est, {"runs": int(len(groups)), "samples": int(len(f)), "evaluations": int(res.nfev),
                 "rms_velocity_m_s": float(np.sqrt(np.mean(f ** 2)))}


#: A start is a run after at least REST_BEFORE [s] of rest; the instant it starts is
#: looked for from START_BACK [s] before the run is seen to START_AFTER after it.
REST_BEFORE = 0.03
#: Cut-off [Hz] of the zero-phase filter of the pressures whose force a start must reach.
#: At the other stages' 25 Hz the filter smears the valve step's corner (flat, then a
#: fast rise) back in time: the force seems to reach each level early, and F_s came out
#: 5 % high wherever a start follows a step closely; a higher cut-off lets more of the
#: noise's peaks into the running maximum that a start must pass (early again).  60 Hz
#: of 25, 60 and 100 Hz tried on benchmarks/identification.py and the excavator's.
START_CUTOFF = 60.0
#: Samples either side of a level's crossing over which the filter's displacement of
#: the force (:func:`static_friction`) counts for that level.
CROSSING_REACH = 2
SETTLE = 0.02
START_BACK = 0.15
START_AFTER = 0.06
#: Rests this close [m] to a stop do not bound F_s; F_s is looked for up to GRID_TOP F_d.
STOP_ZONE = 1e-3
GRID_TOP = 4.0
#: How closely [m] the start's simulation can follow the piston (numerics, the other
#: parameters' errors), and how many samples' misfits count as one (their errors are
#: correlated): the likelihood's spread and tempering.
MODEL_SPREAD = 2e-6
#: and its share of the displacement simulated from the start: a start's displacement
#: from rest, ``x = F t^2 / (2 M)`` for an excess force F, is no surer than the mass
#: (M's systematic share, :data:`SYSTEMATIC`).  Without it, on a steep rise of the drive
#: force a displacement a few tenths of a per cent off moved the start by a sample and
#: F_s by 1 to 3 %, low on average (benchmarks/excavator_identification.py --noise-seeds).
MODEL_SHARE = SYSTEMATIC["M"]
TEMPER = 4.0
OUTLIER = 1e-4   #: probability of a reading no model explains (a glitch)
STRAY = 0.05     #: probability that a start is not what the model makes of it
#: F_s's 95 % interval is reported as identifying it when narrower than this share of
#: its value on either side.
IDENTIFIED_WIDTH = 0.10
#: How far the starts' combined (tempered) log-posterior must fall above its best to mark
#: F_s's upper edge where the starts do not pin it down (:func:`upper_edge`): half a
#: unit of the untempered log-likelihood, one standard error.
EDGE_DROP = 0.5 / TEMPER


def _starts(r: Motion):
    """Runs of ``r`` that follow a rest: (first sample of the search window, run start,
    end of the comparison window, direction, run end).  The rest counts from SETTLE
    after the motion before it fell below the threshold speed (the piston is still
    creeping to a stop there), and must last REST_BEFORE from then."""
    out = []
    fs = r.p.fs
    settle, rest, back = int(SETTLE * fs), int(REST_BEFORE * fs), int(START_BACK * fs)
    for i0, i1, d in r.spans:
        moving = np.flatnonzero(r.modes.sliding[:i0])
        j = max(0, i0 - back, (int(moving[-1]) + 1 + settle) if len(moving) else 0)
        if i0 - j < rest:
            continue
        out.append((j, i0, min(i1, i0 + int(START_AFTER * fs)), d, i1))
    return out


def _static_level(p_a, p_b, phi, cyl: ph.Cylinder, P_atm: float, F_L: float, c: float, pressure: str | None):
    """The static level [N] the drive force of pressures ``p_a``, ``p_b`` [Pa] would
    have to pass at each sample (Eq. 9: ``(F_p - F_L sin(phi)) / cos(phi)``) and the
    seals' share of it, ``c`` [N/Pa] times their pressure by law ``pressure`` (0
    without)."""
    level = (ph.piston_force(p_a, p_b, cyl, P_atm) - F_L * np.sin(phi)) / np.cos(phi)
    return level, (c * fx.seal_pressure(p_a, p_b, P_atm, pressure) if c else 0.0)


def static_friction(motions: list[Motion], base: dict, cyl: ph.Cylinder, P_atm: float,
                    n_grid: int = 400, v_s: float = 0.0, pressure: str | None = None):
    """Stage 3: F_s from every start (see the module's docstring).  With a Stribeck
    velocity ``v_s`` > 0 the friction after a start falls from F_s towards F_d along
    the Stribeck curve (at the measured speed), so each candidate F_s is simulated on
    its own.  With a seal-pressure law ``pressure`` (pressure_friction) both levels
    rise by ``base``'s coefficient times the seals' pressure, and F_s is the level at
    none.  ``base["M"]`` is the moving mass [kg], or one array per motion of the mass at
    each sample (a linkage's joint, whose mass moves with its posture: each start then
    runs with the mass where it starts).  ``base["F_unsure"]`` (optional, one array per
    motion) [N]: how far the net force at each sample may be off at most (a linkage's
    terms from every joint's filtered motion: their whole size); a rest's force counts
    towards the lower bound only beyond it (the bound cuts off every level below it, so
    it must hold whatever the terms' error).  ``base["F_error"]`` (optional, likewise;
    default ``F_unsure``) [N]: the scale of that error; a start's evidence is blurred by
    its root mean square over the start (a likelihood's width: blurred by the terms'
    whole size, the excavator arm's F_s came out 1.25 % low on average).
    Returns ``(Estimate or None, identified, details)``."""
    M, K_v, F_d, F_L = (base[k] for k in ("M", "K_v", "F_d", "F_L"))
    error = base.get("F_error", base.get("F_unsure"))
    mass_at = (lambda ri, j: float(M[ri][j])) if isinstance(M, (list, tuple)) else (lambda ri, j: float(M))
    c = base.get(PRESSURE_COEFFICIENT[pressure], 0.0) if pressure is not None else 0.0
    events, lower = [], 0.0
    for ri, r in enumerate(motions):
        p = r.p
        # the static level the drive force needs at each sample (a start's: in the
        # run's direction, from the pressures filtered at START_CUTOFF: unfiltered, the
        # running maximum below would pick the noise's peaks; at the other stages' 25 Hz,
        # the filter smears the valve step's corner back before the start)
        filtered_at = lambda f: _static_level(lowpass(p.p_a_raw, p.fs, f), lowpass(p.p_b_raw, p.fs, f),
                                              p.phi, cyl, P_atm, F_L, c, pressure)
        fc = min(START_CUTOFF, 0.4 * p.fs)
        level_start, raised_start = filtered_at(fc)
        # how far the filter moves the force at each sample: what a filter twice as fast
        # keeps and it does not (a valve step's corner, which it spreads over a few
        # milliseconds, and the noise between the two); small on a smooth rise
        filtered_off = np.abs(level_start - filtered_at(min(2.0 * fc, 0.45 * p.fs))[0])
        level, raised = _static_level(p.p_a, p.p_b, p.phi, cyl, P_atm, F_L, c, pressure)
        # the largest drive force held at rest in mid-stroke (away from the last
        # samples before a start): a lower bound of F_s
        # (a rest within STOP_ZONE of the stops, or of the extremes the recording
        # reaches, may be a stop's: its reading carries the sensor's offset there)
        xs = r.modes.x
        low, high = max(0.0, float(xs.min())) + STOP_ZONE, min(r.L, float(xs.max())) - STOP_ZONE
        held = ~_dilate(r.modes.sliding, int(START_BACK * p.fs)) & (xs > low) & (xs < high)
        edge = int(0.1 * p.fs)          # the filter's reach at the recording's ends
        held[:edge] = held[-edge:] = False
        if held.any():
            smooth = median_filter(level, size=int(0.02 * p.fs) | 1, mode="nearest")   # local: no reach into a start
            unsure = base["F_unsure"][ri] / np.cos(p.phi) if "F_unsure" in base else 0.0
            lower = max(lower, float(np.max((np.abs(smooth) - raised - unsure)[held])))
        for j, i0, ie, d, i1 in _starts(r):
            need = d * level_start[j:ie] - (raised_start[j:ie] if c else 0.0)
            rest = p.x_raw[j:max(j + 1, i0 - int(0.01 * p.fs))]
            q = _quantum(p.x_raw[j:min(len(p.x_raw), ie + int(0.05 * p.fs))])
            spread = float(np.std(rest))
            if q < FINEST_QUANTUM * max(spread, MODEL_SPREAD):
                # a lattice far finer than the noise (a file's decimals) is no converter's
                # rounding, and its bins, narrow against the likelihood's spread, would
                # bring each reading's probability down towards the outlier floor
                q = 0.0
            # a start's drive force is unsure by the linkage's terms' error over its window:
            # its root mean square (the largest overstates it two to three times: the terms
            # peak where the other joints accelerate hardest, not all through a start)
            unsure_start = (float(np.sqrt(np.mean((error[ri] / np.cos(p.phi))[j:ie + 1] ** 2)))
                            if error is not None else 0.0)
            events.append(dict(need=need, n=ie - j, r=r, j=j, ie=ie, d=d, t=float(p.t[i0]),
                               reading=float(np.median(rest)), q=q, spread=spread,
                               filtered_off=filtered_off[j:ie],
                               M=mass_at(ri, j), unsure=unsure_start))
    if not events:
        return None, False, {"starts": 0, "lower_bound_N": lower}
    hi_level = max(float(np.max(e["need"])) for e in events)
    if v_s > 0.0:
        n_grid = min(n_grid, 120)
    grid = np.linspace(F_d, max(min(hi_level, GRID_TOP * F_d), 1.5 * F_d), n_grid)
    total = np.zeros(n_grid)
    each, impossible = [], 0
    for e in events:
        need, n, r, j, ie, d = e["need"], e["n"], e["r"], e["j"], e["ie"], e["d"]
        dt = r.p.dt
        reached = np.maximum.accumulate(need)
        # first sample at which the drive force exceeds each F_s; beyond the window:
        # the window's last start (the run is seen to move, so it started by then)
        k = np.searchsorted(reached, grid, side="right")
        # between samples: the crossing's fraction of the interval before sample k
        prev = reached[np.clip(k - 1, 0, n - 1)]
        step = reached[np.clip(k, 0, n - 1)] - prev
        frac = np.where((k > 0) & (k < n) & (step > 0), (grid - prev) / np.where(step > 0, step, 1.0), 1.0)
        k = np.clip(k, 0, n - 1)
        readings = r.p.x_raw[j:ie]
        like = lambda moved: _start_likelihood(moved, readings, e["reading"], e["q"], e["spread"]) / TEMPER

        def moved_from(starts, F_net):
            # the run simulated from rest at each start sample, as positions
            out = np.zeros((len(starts), n))
            for row, (s0, F) in enumerate(zip(starts, F_net)):
                if s0 < n - 1:
                    v = ph.sliding_velocity(0.0, F[s0:], K_v, e["M"], dt)
                    out[row, s0 + 1:] = np.cumsum(0.5 * (v[:-1] + v[1:])) * dt
            return out
        if v_s <= 0.0:
            # each level's start between samples, simulated: the run from the sample
            # after its crossing, plus what the force held over the crossing's remainder
            # of the interval adds (Eq. 8 is linear in the velocity while sliding one way)
            F_net = _net_force(r, j, ie, d, F_d, F_L, c=c, pressure=pressure)
            ll = like(_started_between(moved_from(range(n), [F_net] * n), k, frac, F_net, K_v, e["M"], dt))
        else:
            # each candidate F_s its own friction history: from it at rest, falling
            # towards F_d along the Stribeck curve as the measured speed grows
            nets = [_net_force(r, j, ie, d, F_d, F_L, g, v_s, c, pressure) for g in grid]
            ll_late = like(moved_from(k, nets))
            ll_early = like(moved_from(np.clip(k - 1, 0, n - 1), nets))
            with np.errstate(invalid="ignore"):        # 0 x -inf where a crossing sits on a sample
                ll = (1.0 - frac) * ll_early + frac * ll_late
            ll = np.where(frac >= 1.0, ll_late, np.where(frac <= 0.0, ll_early, ll))
        # each start's evidence as a distribution over the grid, mixed with a little of
        # the uniform one: a start that no other agrees with (a rest that was no rest,
        # a start the sensor saw late) cannot veto all the others
        ll = np.where(np.isnan(ll), -np.inf, ll)
        if not np.isfinite(ll).any():      # no level makes this start's motion (it ran away at each): it tells nothing
            impossible += 1
            continue
        post = np.exp(ll - np.max(ll))
        post /= post.sum()
        # a start whose drive force is unsure by u tells F_s only to within u; and each
        # level only to within how far the filter moved the force where it crosses it
        # (the largest over the samples around the crossing: through a valve's step, a
        # wide band of levels)
        around = maximum_filter1d(e["filtered_off"], 2 * CROSSING_REACH + 1, mode="nearest")[k]
        width = np.hypot(e["unsure"], around)
        if np.any(width > 0.0):
            post = _blurred(post, width / (grid[1] - grid[0]))
        total += np.log((1.0 - STRAY) * post + STRAY / n_grid)
        each.append({"t_s": round(e["t"], 4), "F_s_N": float(grid[int(np.argmax(ll))])})
    if not each:               # every start left out: none tells F_s
        return None, False, {"starts": 0, "starts_impossible": impossible, "lower_bound_N": lower}
    # the posterior over the grid (uniform prior above the largest force held at rest)
    total[grid < lower] = -np.inf
    if not np.isfinite(total).any():
        total[:] = 0.0
    w = np.exp(total - np.max(total))
    w /= w.sum()
    cdf = np.cumsum(w)
    F_s = float(w @ grid)
    lo_F = float(grid[min(np.searchsorted(cdf, 0.025), n_grid - 1)])
    hi_F = float(grid[min(np.searchsorted(cdf, 0.975), n_grid - 1)])
    # starts that disagree beyond what each one's own evidence allows (a rest that was
    # no rest, a start the sensor saw late, a static level that differs from start to
    # start) leave the combined posterior falsely sharp: the interval is at least the
    # spread of the starts' own levels (robust: 1.4826 times their median absolute
    # deviation) over the root of their number
    spread = start_spread([x["F_s_N"] for x in each])
    if spread > 0.0:
        half = 1.96 * spread / math.sqrt(len(each))
        lo_F, hi_F = min(lo_F, F_s - half), max(hi_F, F_s + half)
    est = _widened("F_s", F_s, min(lo_F, F_s), max(hi_F, F_s))
    identified = hi_F < grid[-2] and est.relative_halfwidth < IDENTIFIED_WIDTH
    if not identified:
        # evidence too flat to pin F_s: its mean sits where the flat's lower end (the
        # grid's floor, a rest's bound) puts it; the starts' upper edge is what they tell
        edge = upper_edge(grid, total)
        if edge is not None:
            est = _widened("F_s", edge, min(lo_F, edge), max(hi_F, edge))
    # the levels whose combined evidence is within a 95 % likelihood ratio of the best
    # (log within 1.92): each start bounds F_s sharply from above (a later start cannot
    # make the motion seen) and only softly from below (an earlier one creeps within the
    # sensor's noise), so the posterior is flat-topped with the truth near its upper
    # edge, which its percentiles cut off; a caller may widen the interval to this range
    keep = grid[np.log(np.maximum(w, 1e-300)) >= np.log(w.max()) - 1.92]
    return est, identified, {"starts": len(each), "starts_impossible": impossible, "each": each,
                             "lower_bound_N": lower, "grid_N": [float(grid[0]), float(grid[-1])],
                             "likelihood_range_N": [float(keep[0]), float(keep[-1])]}


def upper_edge(grid: np.ndarray, log_post: np.ndarray, drop: float | None = None) -> float | None:
    """F_s read off the starts' combined log-posterior ``log_post`` over ``grid``: the
    level above its best where it has fallen by ``drop`` (default :data:`EDGE_DROP`),
    linearly between grid points; None where it never falls that far above its best
    (no edge on the grid).

    Each start bounds F_s sharply from above (a later start cannot make the motion
    seen) and only softly from below (an earlier start with a small excess force moves
    the piston less than the sensor's quantum or noise, which the rest's unknown offset
    within a quantum absorbs): where the starts do not pin F_s down, their evidence is
    flat from a lower end (the grid's floor F_d, or a rest's bound) up to an edge near
    the truth, and the posterior mean sits mid-flat, low by half the flat's width, which
    grows with the quantum and noise.  The edge does not move with the width."""
    drop = EDGE_DROP if drop is None else drop
    lp = np.where(np.isfinite(log_post), log_post, -np.inf)
    top = int(np.argmax(lp))
    beyond = np.flatnonzero(lp[top:] < lp[top] - drop)
    if not len(beyond):
        return None
    i = top + int(beyond[0])            # the first grid level beyond the edge
    a, b = lp[i - 1] - lp[top] + drop, lp[i - 1] - lp[i]
    return float(grid[i - 1] + (a / b if np.isfinite(b) and b > 0.0 else 0.0) * (grid[i] - grid[i - 1]))


def _started_between(moved: np.ndarray, k: np.ndarray, frac: np.ndarray, F_net: np.ndarray,
                     K_v: float, M: float, dt: float) -> np.ndarray:
    """The displacements [m] of starts between samples: for each level, its run from
    rest at sample ``k`` (row ``k`` of ``moved``, one row per start sample), plus the
    velocity and displacement the net force ``F_net[k-1]`` [N] gives it over the
    remainder ``(1 - frac) dt`` of the interval from its crossing to sample ``k`` (Eq. 8
    from rest), carried on as a free response (Eq. 8's velocity is linear in its initial
    value while sliding one way: ``v[k+m] = e^m v_k``, ``e = exp(-K_v dt / M)``,
    integrated by the trapezoid as ``moved``'s rows are).  Where the crossing falls in
    the window's last interval or beyond (``frac`` 1), the row as it is."""
    n = moved.shape[1]
    tau = (1.0 - frac) * dt
    v_k = -np.expm1(-K_v * tau / M) * F_net[np.clip(k - 1, 0, n - 1)] / K_v
    decay = ph.sliding_velocity(1.0, np.zeros(n), K_v, M, dt)        # e^m from 1 at the start
    free = np.concatenate(([0.0], np.cumsum(0.5 * (decay[:-1] + decay[1:])) * dt))
    since = np.arange(n)[None, :] - k[:, None]
    extra = np.where(since >= 0, (0.5 * v_k * tau)[:, None] + v_k[:, None] * free[np.clip(since, 0, n - 1)], 0.0)
    return moved[k] + extra


def _blurred(post: np.ndarray, width) -> np.ndarray:
    """A distribution over an even grid convolved with a normal distribution of standard
    deviation ``width`` [grid steps]: one value, or one per grid point (the spread of
    the mass at that point; mass beyond the grid's ends kept at them)."""
    n = len(post)
    k = np.arange(n)
    w = np.maximum(np.broadcast_to(np.asarray(width, float), (n,)), 1e-9)
    kernel = np.exp(-0.5 * ((k[:, None] - k[None, :]) / w[None, :]) ** 2)
    out = kernel @ (post / kernel.sum(axis=0))
    return out / out.sum()


def start_spread(levels) -> float:
    """The spread [N] of the static levels the starts put F_s at, each on its own: 1.4826
    times their median absolute deviation (a standard deviation that a few stray starts
    do not inflate); 0 with fewer than two starts."""
    levels = np.asarray(levels, float)
    if len(levels) < 2:
        return 0.0
    return float(1.4826 * np.median(np.abs(levels - np.median(levels))))


def _start_likelihood(moved: np.ndarray, readings: np.ndarray, reading: float, q: float, spread: float):
    """Log-likelihood of the position ``readings`` over a start's window under each
    simulated displacement (rows of ``moved``, from the rest), for a sensor that adds
    noise of ``spread`` [m] and rounds to a quantum ``q`` [m] (0: no rounding).  The
    piston's true resting position relative to the reading levels (``reading`` is the
    reading at rest) is unknown: uniform over a quantum (two where noise makes the
    rest flicker), and marginalised, not profiled: a profile would favour starts that
    one offset or another can excuse."""
    # the simulation's spread: MODEL_SPREAD, and MODEL_SHARE of the displacement itself
    # (a simulated start from rest is no surer than the mass it accelerates); a start
    # that ran away (displacements beyond any float's square) is impossible,
    # log-likelihood -inf, not an overflow warning
    with np.errstate(over="ignore", invalid="ignore"):
        sigma = np.sqrt(spread ** 2 + (q / 20.0) ** 2 + MODEL_SPREAD ** 2 + (MODEL_SHARE * moved) ** 2)
        if q <= 0.0:
            ll = -np.sum((reading + moved - readings) ** 2 / (2.0 * sigma ** 2) + np.log(sigma), axis=1)
            return np.where(np.isnan(ll), -np.inf, ll)
    span = 1.0 if spread < q / 4.0 else 2.0
    lls = []
    with np.errstate(invalid="ignore"):         # a run away: inf over inf, its rows nan
        for offset in np.linspace(-0.5, 0.5, 11) * q * span:
            mu = reading + offset + moved
            prob = ndtr((readings + q / 2.0 - mu) / sigma) - ndtr((readings - q / 2.0 - mu) / sigma)
            lls.append(np.sum(np.log(prob + OUTLIER), axis=1))
        lls = np.array(lls)
        lls = np.where(np.isnan(lls), -np.inf, lls)    # impossible, as without a quantum
        top = lls.max(axis=0)
        out = top + np.log(np.mean(np.exp(lls - top), axis=0))
    return np.where(np.isfinite(top), out, -np.inf)


def _quantum(x: np.ndarray) -> float:
    """The step [m] between the position readings around a start (0 where they are not
    quantised): the smallest gap between distinct readings, where the readings lie on
    its lattice (every gap between neighbouring distinct readings within
    ``LATTICE_SLACK`` per step of a whole number of steps, at most ``LATTICE_STEPS``:
    the sensor's rounding, levels a fast run skips included), however many levels the
    motion passes through; or, where the linkage stretches the step along a long start,
    on a step that follows the position as a straight line (then the step at the first
    reading, the rest, is returned).  A count of
    distinct readings cannot tell: a fast start passes a level a sample, and a window
    on a 12-bit angle then held more levels than a third of its samples, so the
    rounding went unseen, each start's likelihood took the reading for exact, and the
    starts put F_s up to three times too high."""
    finite = x[np.isfinite(x)]
    levels = np.unique(finite)
    if len(levels) < 2:
        return 0.0
    gaps = np.diff(levels)
    q = float(gaps.min())
    if _on_lattice(gaps / q):
        return q
    # a lattice stretched along the travel: an angle's quantum maps to a position's
    # through the linkage, whose ratio changes along a long start (7 % over 14 mm, 82
    # levels, on the boom), beyond the slack against the smallest gap.  The step is
    # read as a straight line in the position through the gaps of one step, every gap
    # is held to it where it lies, and the step returned is the one at the rest
    mid = 0.5 * (levels[:-1] + levels[1:])
    one = np.round(gaps / q) == 1
    if np.count_nonzero(one) < STRETCH_FIT_MIN:       # (distinct levels: their midpoints differ)
        return 0.0
    step_at = np.polynomial.Polynomial.fit(mid[one], gaps[one], 1)
    q_mid = step_at(mid)
    if np.any(q_mid <= 0.0) or not _on_lattice(gaps / q_mid):
        return 0.0
    return float(step_at(finite[0]))


def _on_lattice(steps: np.ndarray) -> bool:
    """Whether gaps, in steps of the quantum, are whole numbers of it (within
    ``LATTICE_SLACK`` per step, at most ``LATTICE_STEPS``)."""
    whole = np.round(steps)
    return bool(np.all(whole <= LATTICE_STEPS) and np.all(np.abs(steps - whole) <= LATTICE_SLACK * whole))


#: how far [steps] a gap between neighbouring readings may be from a whole number of
#: the quantum, per step (an angle's quantum maps to a position's through the linkage,
#: which stretches it by about 1 % over a start's few millimetres)
LATTICE_SLACK = 0.05
#: a lattice finer than this share of the rest's noise (or of MODEL_SPREAD) is not taken
#: for a converter's rounding (a file's decimals: 1e-7 m against 3 um of noise)
FINEST_QUANTUM = 0.1
#: the fewest one-step gaps through which a stretched lattice's step is read as a line
STRETCH_FIT_MIN = 5
#: the most steps between neighbouring readings on the lattice (a run that skips levels:
#: 10 quanta a sample is 2 m/s for a 12-bit angle on the boom; readings that are not
#: rounded have gaps hundreds of times their smallest).  At 10 steps the slack is half a
#: step, so a gap of 10 is not held to the lattice; held tighter (a quarter step at
#: most, 8 steps), a 16-bit angle's fast starts lose their quantum and F_s moves by up
#: to half on 4 of the calibration suite's 60 16-bit cases, both ways, untested
LATTICE_STEPS = 10


def breakaways(p: Prepared, L: float, rest: float = 0.05, lead: float = 0.08, q: float = 4e-4):
    """Indices where the piston, after resting at least ``rest`` seconds, has moved more
    than ``q`` [m] (a few quanta of the angle sensor) from its resting position.  The
    rest is looked for ``lead`` seconds earlier: a start is slow, and the samples just
    before the departure already move."""
    x = p.x_raw
    n_rest, n_lead = int(rest * p.fs), int(lead * p.fs)
    events = []
    i = n_rest + n_lead
    while i < len(x):
        window = x[i - n_lead - n_rest:i - n_lead]
        if np.ptp(window) < q and abs(x[i] - np.median(window)) > q:
            events.append(i)
            i += int(0.3 * p.fs)
        else:
            i += 1
    return events


def simulate_load(p: Prepared, load: ph.Load, cyl: ph.Cylinder, geom: ph.Geometry, P_atm: float,
                  i0: int, i1: int, x0: float, substeps: int = 4) -> np.ndarray:
    """The boom alone from rest at ``x0``, driven by the recorded pressures over samples
    i0..i1 (the measured signals in place of the cylinder's): x at each sample.  Between
    samples the pressures are interpolated linearly (held over ``substeps`` parts of the
    sample interval, each at its midpoint value): a held sample would lag a fast
    pressure rise by half a sample and bias the start of motion."""
    xs = np.empty(i1 - i0)
    x, v = x0, 0.0
    pa, pb = p.p_a_raw, p.p_b_raw
    h = p.dt / substeps
    weights = [(j + 0.5) / substeps for j in range(substeps)]
    last = len(pa) - 1
    for k in range(i0, i1):
        xs[k - i0] = x
        a0, b0 = float(pa[k]), float(pb[k])
        a1, b1 = float(pa[min(k + 1, last)]), float(pb[min(k + 1, last)])
        for w in weights:
            x, v = ph.advance_load(x, v, h, a0 + w * (a1 - a0), b0 + w * (b1 - b0), 0.0,
                                   cyl, geom, load, P_atm, h)
    return xs


def fit_A_max(preps: list[Prepared], cyl: ph.Cylinder, valve: ph.Valve, gas: ph.Gas):
    """The valve's A_max from the chambers' mass balance: the measured inflow
    ``(V dp/dt + k p dV/dt) / (k R T)`` against Eq. 1's flow per unit area."""
    X, y = [], []
    unit = valve._replace(A_max=1.0)
    for p in preps:
        mdot_a, mdot_b = ph.chamber_inflows(p.p_a, p.p_b, np.gradient(p.p_a, p.t), np.gradient(p.p_b, p.t),
                                            p.x, p.v, cyl, gas)
        g_a, g_b = ph.chamber_flows(p.u, p.p_a, p.p_b, unit, gas)
        m = _dilate(np.abs(np.diff(p.u, prepend=p.u[0])) > 0, int(0.02 * p.fs))
        use = ~m & (np.abs(p.u - valve.u_centre) > 0.5)
        for g, md in ((g_a, mdot_a), (g_b, mdot_b)):
            sel = use & (np.abs(g) > 0.05 * np.abs(g).max())
            X.append(g[sel])
            y.append(md[sel])
    X, y = np.concatenate(X), np.concatenate(y)
    if len(y) < 50:
        return None
    A = float(X @ y / (X @ X))
    r = y - A * X
    se = math.sqrt(float(r @ r) / max(len(y) - 1, 1) / float(X @ X) * correlation_samples(preps[0]))
    return Estimate(A, (A - 1.96 * se, A + 1.96 * se), "m2")


#: The widest dead band (spool overlap) a proportional valve is taken to have [V]:
#: the time-scale check credits any opening up to it as possibly closed.
DEADBAND_WIDEST = 0.75
#: The longest the spool may take to follow the command [s]: the check takes the
#: smallest (and largest) opening the command held over this time before each sample.
SPOOL_LAG = 0.03


@dataclass
class FillRate:
    """How fast the chambers fill and empty, as an orifice area [m^2] against Eq. 1's
    flow at the recorded opening and pressures, per chamber (``"A"``, ``"B"``).
    ``nominal``: at the opening the command gives; ``at_least``: what the valve's area
    must at least be for the recorded flows even if the valve had a dead band of
    ``DEADBAND_WIDEST`` and lagged ``SPOOL_LAG`` (each an Estimate with its 95 %
    interval); ``at_most``: what it can at most be with no dead band and the widest
    opening of the lag window.  ``samples``: the informative samples per chamber
    (the opening beyond the widest dead band, one side of the centre throughout the
    lag window)."""
    nominal: dict
    at_least: dict
    at_most: dict
    samples: dict


def _window_extremes(a: np.ndarray, n: int):
    """Smallest and largest of ``a`` over each sample and the ``n`` before it."""
    if n <= 0:
        return a, a
    pad = np.concatenate((np.full(n, a[0]), a))
    w = np.lib.stride_tricks.sliding_window_view(pad, n + 1)
    return w.min(axis=1), w.max(axis=1)


def fill_rates(preps: list[Prepared], cyl: ph.Cylinder, valve: ph.Valve, gas: ph.Gas,
               deadband: float = DEADBAND_WIDEST, lag: float = SPOOL_LAG) -> FillRate:
    """The chambers' measured filling and emptying (Eq. 7 solved for the flows) against
    what the valve allows at the recorded opening and pressures (Eq. 1), over the
    samples where the opening is known well enough to tell: beyond ``deadband`` from
    the centre and on one side of it over the last ``lag`` seconds.  Small openings
    (a slow ramp around the centre, a long hold) tell nothing about the valve's area:
    a dead band, a lagging spool or an uneven opening law change their flow by any
    factor, so they are not used."""
    X = {c: {"nominal": [], "at_least": [], "at_most": []} for c in "AB"}
    Y = {c: [] for c in "AB"}
    full = valve._replace(A_max=1.0)
    span = valve.u_span
    for p in preps:
        mdot = ph.chamber_inflows(p.p_a, p.p_b, np.gradient(p.p_a, p.t), np.gradient(p.p_b, p.t),
                                  p.x, p.v, cyl, gas)
        s = p.u - valve.u_centre
        lo, hi = _window_extremes(s, int(round(lag * p.fs)))
        one_side = (lo > 0) | (hi < 0)
        smallest = np.where(one_side, np.minimum(np.abs(lo), np.abs(hi)), 0.0)
        largest = np.maximum(np.abs(lo), np.abs(hi))
        opening = {"nominal": np.minimum(np.abs(s) / span, 1.0),
                   "at_least": np.clip((smallest - deadband) / (span - deadband), 0.0, 1.0),
                   "at_most": np.minimum(largest / span, 1.0)}
        wide = valve.u_centre + np.sign(s) * span           # full opening on the command's side
        g_full = ph.chamber_flows(wide, p.p_a, p.p_b, full, gas)
        for c, g, md in zip("AB", g_full, mdot):
            g_least = opening["at_least"] * g
            sel = one_side & (opening["at_least"] > 0) & (np.abs(g_least) > 0.05 * np.abs(g_least).max(initial=0.0))
            for k in X[c]:
                X[c][k].append(opening[k][sel] * g[sel])
            Y[c].append(md[sel])
    out = {"nominal": {}, "at_least": {}, "at_most": {}}
    samples = {}
    corr = correlation_samples(preps[0])
    for c in "AB":
        y = np.concatenate(Y[c])
        samples[c] = len(y)
        if len(y) < 50:
            continue
        for k, xs in X[c].items():
            x = np.concatenate(xs)
            A = float(x @ y / (x @ x))
            r = y - A * x
            se = math.sqrt(float(r @ r) / max(len(y) - 1, 1) / float(x @ x) * corr)
            out[k][c] = Estimate(A, (A - 1.96 * se, A + 1.96 * se), "m2")
    return FillRate(out["nominal"], out["at_least"], out["at_most"], samples)


def identify(preps: list[Prepared], cyl: ph.Cylinder = ph.Cylinder(), P_atm: float = reference_rig.P_atm,
             with_A_max: bool = False, valve: ph.Valve = ph.Valve(), gas: ph.Gas = ph.Gas(),
             v_s: float = 0.0, pressure: str | None = None) -> FitResult:
    """The sound method on prepared recordings (prepared at their rig's geometry: phi
    comes with them); see the module's docstring.  ``v_s`` > 0 [m/s]: the load
    with stribeck_friction at that Stribeck velocity (every stage with the Stribeck
    curve; F_s from the starts before and after stage 2).  ``pressure`` (``"sum"``,
    ``"max"`` or ``"diff"``): the load with pressure_friction by that seal-pressure law, its
    coefficient (``c_sum``, ``c_max`` or ``c_diff`` [N/Pa]) identified with the load in every
    stage (it is one more linear term of Eq. 8)."""
    motions = [motion(p, cyl, P_atm) for p in preps]       # classified once, read by every stage
    est, info = equation_error(motions, v_s=v_s, pressure=pressure)
    details = {"equation_error": info}
    warnings = []
    values = lambda: {k: e.value for k, e in est.items()}
    if v_s > 0.0:        # F_s from the starts first: the sliding alone hardly holds it
        F_s, identified, info3 = static_friction(motions, values(), cyl, P_atm, v_s=v_s, pressure=pressure)
        if F_s is not None:
            est["F_s"] = F_s
        else:
            est["F_s"] = Estimate(max(est["F_d"].value, est.get("F_s", est["F_d"]).value), (math.nan, math.nan), "N")
    refined, info2 = velocity_error(motions, values(), v_s=v_s, pressure=pressure)
    details["velocity_error"] = info2
    if refined is None:
        warnings.append("too few runs of motion for the velocity fit: the load is from the equation error alone")
    else:
        est.update(refined)
    F_s, identified, info3 = static_friction(motions, values(), cyl, P_atm, v_s=v_s, pressure=pressure)
    details["static_friction"] = dict(info3, identified=bool(identified))
    if F_s is None:
        warnings.append("no start of motion from rest: F_s cannot be identified; F_d is used in its place")
        F_s = Estimate(est["F_d"].value, (math.nan, math.nan), "N")
    elif not identified:
        warnings.append(f"the data cannot tell F_s: the starts they hold put it anywhere in "
                        f"[{F_s.ci95[0]:.4g}, {F_s.ci95[1]:.4g}] N (a start informs F_s only where the drive "
                        f"force rises slowly through the static level, as after a hold with a small opening); "
                        f"the model uses {F_s.value:.4g} N, and no other parameter depends on it")
    est["F_s"] = F_s
    if with_A_max:
        a_max = fit_A_max(preps, cyl, valve, gas)
        if a_max is None:
            warnings.append("the valve is hardly ever open: A_max cannot be identified")
        else:
            est["A_max"] = a_max
    for k, e in est.items():
        if k != "F_s" and not e.tells:
            warnings.append(f"the data cannot identify {k}: its 95 % interval "
                            f"[{e.ci95[0]:.4g}, {e.ci95[1]:.4g}] {e.unit} is wider than half its value")
    ordered = {k: est[k] for k in (*PARAMS, "A_max", *PRESSURE_COEFFICIENT.values()) if k in est}
    return FitResult("fit", ordered, warnings, details)

__all__ = [
    "PARAMS", "PARAMETER_UNITS", "PRESSURE_COEFFICIENT", "TELLS_WIDTH", "SYSTEMATIC", "Estimate", "FitResult",
    "resolution", "MODE_CUTOFF", "Modes", "motion_modes", "modes_of", "EE_CUTOFF", "REACH", "correlation_samples",
    "equation_rows", "equation_error", "load_with_effect", "runs", "VE_CUTOFF", "Motion", "motion",
    "velocity_error", "REST_BEFORE", "START_CUTOFF", "SETTLE", "START_BACK", "START_AFTER", "STOP_ZONE",
    "GRID_TOP", "MODEL_SPREAD", "TEMPER", "OUTLIER", "STRAY", "IDENTIFIED_WIDTH", "EDGE_DROP",
    "static_friction", "upper_edge", "start_spread", "breakaways", "simulate_load", "fit_A_max",
    "DEADBAND_WIDEST", "SPOOL_LAG", "FillRate", "fill_rates", "identify",
]
