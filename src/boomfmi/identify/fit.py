"""The sound identification of the load: all samples, least squares, intervals.

Three stages, each on every recording given:

1. **Equation error on Eq. 8.**  While the piston slides (away from the stops and from
   the instants it starts or stops), Eq. 8 is linear in the unknowns::

       P_a A_a - P_b A_b - P_atm (A_a - A_b) = M a + K_v v + F_d cos(phi) sign(v) + F_L sin(phi)

   Every signal is low-pass filtered alike (``preprocess``), so the filtered equation
   holds too; ordinary least squares gives M, K_v, F_d and F_L.
2. **Breakaway by output error.**  F_s is where the drive force stands when the piston
   starts to move; a start is only seen once the piston has moved a quantum or two,
   milliseconds after the fact, while the pressure races on.  So F_s is fitted instead:
   the boom alone (``physics.advance_load``) is simulated through every start, driven by
   the recorded pressures, and F_s is the value whose simulated starts best match the
   recorded position.  Only starts where the drive force takes at least ``SLOW_START``
   to cross the static band (2 F_s cos(phi)) are used: in a faster one a fraction of a
   millisecond of timing moves F_s by tens of newtons (a start from the upper stop, where
   cos(phi) is small and both chambers change at once, is the typical case).
3. **Output error on the whole trajectory** (``refine=True``): K_v, F_d, F_L and M
   together, F_s held, simulating the boom driven by the recorded pressures through
   every start and matching the recorded position (scipy's least_squares), from stages
   1 and 2.

Intervals are 95 % intervals from a moving-block bootstrap of stage 1 (residuals of
filtered data are correlated, which ordinary least-squares intervals ignore) and, for
F_s and after stage 3, from the Jacobian with the residuals' correlation length.  A
parameter whose interval is wider than half its value gets a warning: the data cannot
identify it.
"""
from __future__ import annotations

import math
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from .. import physics as ph
from ..physics import reference_rig
from .preprocess import Prepared

PARAMS = ("K_v", "F_s", "F_d", "F_L", "M")
UNITS = {"K_v": "N.s/m", "F_s": "N", "F_d": "N", "F_L": "N", "M": "kg", "A_max": "m2"}


@dataclass
class Estimate:
    value: float
    ci95: tuple[float, float]
    unit: str

    @property
    def relative_halfwidth(self) -> float:
        return (self.ci95[1] - self.ci95[0]) / 2.0 / abs(self.value) if self.value else math.inf


@dataclass
class FitResult:
    method: str
    params: dict[str, Estimate]
    warnings: list[str] = field(default_factory=list)
    details: dict = field(default_factory=dict)

    def values(self) -> dict[str, float]:
        return {k: e.value for k, e in self.params.items()}


def _dilate(mask: np.ndarray, n: int) -> np.ndarray:
    if n <= 0:
        return mask
    kernel = np.ones(2 * n + 1)
    return np.convolve(mask.astype(float), kernel, mode="same") > 0


def sliding_samples(p: Prepared, L: float, v_min: float = 0.01, margin: float = 0.002,
                    guard: float = 0.04) -> np.ndarray:
    """Samples where Eq. 8's sliding branch holds cleanly: |v| > v_min, the piston
    ``margin`` away from both stops, and ``guard`` seconds from any stop contact, stick
    or reversal (the filter smears those over a few tens of milliseconds)."""
    n_guard = int(round(guard * p.fs))
    at_stop = (p.x_raw <= margin) | (p.x_raw >= L - margin)
    slow = np.abs(p.v) <= v_min
    reversal = np.zeros_like(slow)
    reversal[1:] = np.sign(p.v[1:]) != np.sign(p.v[:-1])
    bad = _dilate(at_stop | slow | reversal, n_guard)
    return ~bad


def correlation_samples(p: Prepared) -> float:
    """Samples over which the residuals of filtered data stay correlated: about one
    period of the low-pass filter's cut-off, fs / (2 cutoff) (20 at 1 kHz and 25 Hz).
    Interval widths from least squares are scaled by its square root."""
    return max(1.0, p.fs / (2.0 * p.cutoff))


def equation_error(preps: list[Prepared], cyl: ph.Cylinder, P_atm: float, L: float,
                   n_boot: int = 200, block: float = 0.1, seed: int = 0):
    """Stage 1: M, K_v, F_d, F_L by least squares on Eq. 8 over sliding samples."""
    X, y, groups = [], [], []
    for i, p in enumerate(preps):
        m = sliding_samples(p, L)
        cos_s = np.cos(p.phi) * np.sign(p.v)
        X.append(np.column_stack([p.a, p.v, cos_s, np.sin(p.phi)])[m])
        y.append(ph.piston_force(p.p_a, p.p_b, cyl, P_atm)[m])
        groups.append(np.full(m.sum(), i))
    X, y = np.vstack(X), np.concatenate(y)
    if len(y) < 50:
        raise ValueError("too few sliding samples to identify the load: the recordings hold almost no motion")
    scale = np.abs(X).max(axis=0)
    scale[scale == 0] = 1.0
    theta, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
    theta /= scale
    cond = float(np.linalg.cond(X / scale))
    # moving-block bootstrap of the rows (blocks of correlated residuals)
    rng = np.random.default_rng(seed)
    fs = preps[0].fs
    b = max(1, int(block * fs))
    n = len(y)
    starts = np.arange(0, max(1, n - b))
    boots = []
    for _ in range(n_boot):
        picks = rng.choice(starts, size=max(1, n // b))
        idx = (picks[:, None] + np.arange(b)[None, :]).ravel()
        idx = idx[idx < n]
        th, *_ = np.linalg.lstsq(X[idx] / scale, y[idx], rcond=None)
        boots.append(th / scale)
    boots = np.array(boots)
    lo, hi = np.percentile(boots, [2.5, 97.5], axis=0)
    names = ("M", "K_v", "F_d", "F_L")
    est = {k: Estimate(float(theta[j]), (float(lo[j]), float(hi[j])), UNITS[k]) for j, k in enumerate(names)}
    residual = y - X @ theta
    return est, {"samples": int(n), "condition_number": cond,
                 "rms_residual_N": float(np.sqrt(np.mean(residual**2)))}


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


#: Departure from the resting reading [m] below which samples do not enter the output
#: error: the resting reading carries the angle sensor's quantisation as an offset.
DEPARTED = 2e-4


def _rest(p: Prepared, i0: int, L: float) -> tuple[float, float]:
    """(start position for the simulation, resting reading) of a window from i0: the
    median reading over 50 ms, snapped onto a stop when within DEPARTED of it."""
    reading = float(np.median(p.x_raw[i0:i0 + int(0.05 * p.fs)]))
    x0 = 0.0 if reading < DEPARTED else (L if reading > L - DEPARTED else reading)
    return x0, reading


#: Shortest time [s] the drive force may take to cross the static band for a start to
#: inform F_s.
SLOW_START = 0.005


def _crossing_time(p: Prepared, i: int, band: float, cyl, P_atm, F_L) -> float:
    """Time [s] the drive force needs to cross ``band`` [N] at its rate around sample i."""
    F = ph.drive_force(p.p_a, p.p_b, p.phi, 0.0, cyl, ph.Load(F_L=F_L), P_atm)
    j0, j1 = max(0, i - int(0.03 * p.fs)), max(1, i - int(0.005 * p.fs))
    rate = abs(float(np.mean(np.gradient(F[j0:j1 + 1], p.t[j0:j1 + 1]))))
    return band / rate if rate > 0 else np.inf


def _windows(preps, L, before=0.2, after=0.1, base=None, cyl=None, P_atm=None):
    out = []
    for p in preps:
        for i in breakaways(p, L):
            if base is not None:
                band = 2.0 * base["F_d"] * float(np.cos(p.phi[i]))
                if _crossing_time(p, i, band, cyl, P_atm, base["F_L"]) < SLOW_START:
                    continue
            i0 = max(0, i - int(before * p.fs))
            i1 = min(len(p.t), i + int(after * p.fs))
            x0, reading = _rest(p, i0, L)
            moved = np.abs(p.x_raw[i0:i1] - reading) > DEPARTED
            out.append((p, i0, i1, x0, moved))
    return out


_SCAN: dict = {}


def _run_part(args):
    k, theta = args
    return _SCAN["part"](k, theta)


class _Parts:
    """``part(k, theta)`` for k = 0 .. n - 1 evaluated side by side in forked workers
    (each inherits ``part`` and its data once; only parameters and results cross), or
    in turn where the platform does not fork.  A context manager: ``with _Parts(part, n)
    as run: run(theta) -> [part(0, theta), ...]``."""

    def __init__(self, part, n: int):
        self.part, self.n, self.pool = part, n, None
        if n > 1 and "fork" in multiprocessing.get_all_start_methods():
            _SCAN["part"] = part
            self.pool = ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("fork"))

    def __call__(self, theta) -> list:
        if self.pool is None:
            return [self.part(k, theta) for k in range(self.n)]
        return list(self.pool.map(_run_part, [(k, theta) for k in range(self.n)]))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.pool is not None:
            self.pool.shutdown()
            _SCAN.pop("part", None)


def _workers(n_items: int) -> int:
    return max(1, min(os.cpu_count() or 1, n_items))


def scan(cost, grid) -> list[float]:
    """``cost`` at every point of ``grid``, the points dealt over the cores."""
    n, grid = _workers(len(grid)), list(grid)
    with _Parts(lambda k, g: [cost(v) for v in g[k::n]], n) as run:
        parts = run(grid)
    out = [0.0] * len(grid)
    for k, part in enumerate(parts):
        out[k::n] = part
    return out


def _balanced(sizes: list, n: int) -> list[list[int]]:
    """The indices of ``sizes`` dealt into ``n`` ascending lists of about equal total
    size (the largest first, each to the lightest list)."""
    parts, load = [[] for _ in range(n)], [0] * n
    for i in sorted(range(len(sizes)), key=lambda i: -sizes[i]):
        k = load.index(min(load))
        parts[k].append(i)
        load[k] += sizes[i]
    return [sorted(part) for part in parts]


def fit_static_friction(preps, base: dict, cyl, geom, P_atm, L):
    """Stage 2: F_s by matching simulated starts to recorded ones."""
    all_starts = len(_windows(preps, L))
    wins = _windows(preps, L, base=base, cyl=cyl, P_atm=P_atm)
    if not wins:
        wins = _windows(preps, L)
    if not wins:
        return None, {"breakaways": 0}

    def cost(F_s):
        load = ph.Load(K_v=base["K_v"], F_s=F_s, F_d=base["F_d"], F_L=base["F_L"], M=base["M"])
        return sum(float(np.sum(((simulate_load(p, load, cyl, geom, P_atm, i0, i1, x0) - p.x_raw[i0:i1])[moved]) ** 2))
                   for p, i0, i1, x0, moved in wins)

    # F_s is not below F_d: a piston that broke away below the Coulomb level would stop
    # again at once (Eq. 9), so such an F_s could never be seen
    lo, hi = max(base["F_d"], 0.0), 3.0 * max(base["F_d"], 50.0)
    # the cost is rough (starts happen on a time grid), so scan first, then refine
    # around the best point of the scan
    grid = np.linspace(lo, hi, 41)
    costs = scan(cost, grid)
    j = int(np.argmin(costs))
    step = grid[1] - grid[0]
    res = minimize_scalar(cost, bounds=(max(lo, grid[j] - step), min(hi, grid[j] + step)),
                          method="bounded", options={"xatol": 0.01})
    if res.fun > costs[j]:
        res.x, res.fun = grid[j], costs[j]
    F_s = float(res.x)
    # interval: curvature of the cost with the residual variance and correlation
    h = max(0.5, 0.01 * F_s)
    c0, cp, cm = res.fun, cost(F_s + h), cost(F_s - h)
    n = sum(int(moved.sum()) for *_, moved in wins)
    curv = max((cp - 2 * c0 + cm) / h**2, 1e-30)
    sigma2 = c0 / max(n - 1, 1)
    half = 1.96 * math.sqrt(2.0 * sigma2 * correlation_samples(preps[0]) / curv)
    return Estimate(F_s, (F_s - half, F_s + half), "N"), {"breakaways": all_starts, "used": len(wins)}


def refine(preps, start: dict, cyl, geom, P_atm, L):
    """Stage 3: all five by output error on the whole trajectories (boom driven by the
    recorded pressures, restarted from the recorded position at each rest)."""
    segments = []
    for p in preps:
        idx = breakaways(p, L)
        bounds = idx + [len(p.t)]
        for j, i in enumerate(idx):
            i0 = max(0, i - int(0.2 * p.fs))
            i1 = min(bounds[j + 1], i + int(1.5 * p.fs), len(p.t))
            x0, reading = _rest(p, i0, L)
            segments.append((p, i0, i1, x0, np.abs(p.x_raw[i0:i1] - reading) > DEPARTED))
    names = ("K_v", "F_d", "F_L", "M")
    x0 = np.array([start[k] for k in names])
    n = _workers(len(segments))
    dealt = _balanced([i1 - i0 for _, i0, i1, _, _ in segments], n)
    parts = [[segments[i] for i in idx] for idx in dealt]
    order = np.argsort(np.concatenate(dealt))     # back to the segments' own order

    def part_residuals(k, theta):
        load = ph.Load(F_s=start["F_s"], **dict(zip(names, theta)))
        return [(simulate_load(p, load, cyl, geom, P_atm, i0, i1, xs) - p.x_raw[i0:i1])[moved]
                for p, i0, i1, xs, moved in parts[k]]

    with _Parts(part_residuals, n) as run:
        def residuals(theta):
            pieces = [r for part in run(theta) for r in part]
            return np.concatenate([pieces[i] for i in order])

        res = least_squares(residuals, x0, x_scale=np.abs(x0) + 1e-9, bounds=(1e-9, np.inf),
                            diff_step=1e-3, max_nfev=60)
    J = res.jac
    dof = max(len(res.fun) - len(names), 1)
    sigma2 = float(res.fun @ res.fun) / dof
    try:
        cov = np.linalg.inv(J.T @ J) * sigma2 * correlation_samples(preps[0])
    except np.linalg.LinAlgError:
        cov = np.full((len(names), len(names)), np.inf)
    est = {}
    for j, k in enumerate(names):
        half = 1.96 * math.sqrt(max(cov[j, j], 0.0))
        est[k] = Estimate(float(res.x[j]), (float(res.x[j] - half), float(res.x[j] + half)), UNITS[k])
    return est, {"segments": len(segments), "rms_x_m": float(np.sqrt(np.mean(res.fun ** 2))),
                 "evaluations": int(res.nfev)}


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


def identify(preps: list[Prepared], cyl: ph.Cylinder = ph.Cylinder(), geom: ph.Geometry = ph.Geometry(),
             P_atm: float = reference_rig.P_atm, refine_all: bool = True, with_A_max: bool = False,
             valve: ph.Valve = ph.Valve(), gas: ph.Gas = ph.Gas()) -> FitResult:
    """The sound method on prepared recordings; see the module's docstring."""
    L = cyl.L
    est, info = equation_error(preps, cyl, P_atm, L)
    base = {k: e.value for k, e in est.items()}
    F_s, info2 = fit_static_friction(preps, base, cyl, geom, P_atm, L)
    warnings = []
    if F_s is None:
        warnings.append("no start of motion from rest: F_s cannot be identified; F_d is used in its place")
        F_s = Estimate(base["F_d"], (math.nan, math.nan), "N")
    est["F_s"] = F_s
    details = {"equation_error": info, "static_friction": info2}
    if refine_all and info2.get("breakaways", 0) > 0 and all(v > 0 for v in base.values()):
        # stages 3 and 2 in turn: the trajectory fit with F_s held, then F_s again with
        # the refined dynamics (a start's timing depends on M and F_d as well)
        for _ in range(2):
            start = {k: est[k].value for k in PARAMS}
            refined, info3 = refine(preps, start, cyl, geom, P_atm, L)
            for k in refined:
                width = min(refined[k].ci95[1] - refined[k].ci95[0], est[k].ci95[1] - est[k].ci95[0])
                est[k] = Estimate(refined[k].value, (refined[k].value - width / 2, refined[k].value + width / 2),
                                  UNITS[k])
            F_s, info2 = fit_static_friction(preps, {k: e.value for k, e in est.items()}, cyl, geom, P_atm, L)
            est["F_s"] = F_s
        details["output_error"] = info3
        details["static_friction"] = info2
    if with_A_max:
        a_max = fit_A_max(preps, cyl, valve, gas)
        if a_max is None:
            warnings.append("the valve is hardly ever open: A_max cannot be identified")
        else:
            est["A_max"] = a_max
    for k, e in est.items():
        if not e.relative_halfwidth < 0.5:
            warnings.append(f"the data cannot identify {k}: its 95 % interval "
                            f"[{e.ci95[0]:.4g}, {e.ci95[1]:.4g}] {e.unit} is wider than half its value")
    ordered = {k: est[k] for k in (*PARAMS, "A_max") if k in est}
    return FitResult("fit", ordered, warnings, details)
