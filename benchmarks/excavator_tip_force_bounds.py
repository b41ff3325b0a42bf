"""What the excavator's recordings can tell of the tip force on the contact scenarios
(``experiments.TIP_FORCE_SCENARIOS``: the digging cycle's and the closed-loop ones): the
range of tip forces that exact measurements leave open, per
world axis, and the RMSE below which no estimator can be sure to come.

A joint that sticks feels the tip force only through its static friction, which takes
any force up to ``F_s scale`` without the joint moving (so without the pressures or the
angles changing); one pressed on an end stop does not feel a force towards the stop at
all.  Every tip force that keeps every joint's motion as recorded therefore gives the
very same recording.  At each contact sample the script runs the rig's exact states and
pressures (no noise, no ADC) through the linkage (``physics.linkage.piston_dynamics``)
and collects, per joint, what the tip force must satisfy::

    sliding:          lam_i (J^T f)_i = g0_i + K_v v_i + F_d scale_i sign(v_i)   (within --tol)
    sticking:         |lam_i (J^T f)_i - g0_i| <= F_s scale_i
    on a stop:        one side of that only (the stop takes any push into it)

with ``g0 = M_x x'' + bias - F_p``; then the smallest and largest force along each world
axis over that set (two linear programs).  Half that width is the least worst-case error
of any estimator at that sample: the recording cannot tell the ends apart.  Printed per
scenario and axis: the share of contact samples where the set is unbounded (a stop
takes the force), the RMS half-width over the bounded ones, and the share of samples
where the data pin the axis to within +-10 % of its peak, and the median width of
the set where bounded (what ``excavator_identification.py`` sets the estimator's
interval against).

Those sets are what *exact* sensors leave open; the estimator sees the standard
sensors' recording (the angles' and pressures' noise, the ADC).  Beside them the script
prints the *fair bound* (:func:`fair_bounds`): the set of tip forces consistent with the
standard-sensor recording within its own noise, computed offline with everything a
causal estimator cannot have (the angles and pressures filtered forwards and backwards,
the rig's true sliding / sticking / stop per joint, each joint's tolerance calibrated on
the true force so that the sets hold it at >= 95 % of the samples per axis).  Its median
width is how wide an interval with that coverage needs to be on the recording the
estimator actually sees (``--no-fair`` skips it).  Beside it the *causal fair bound*
(:func:`causal_fair_bounds`): the same construction with only what a causal estimator
has (the estimator's own causal filters and the sliding / sticking / stop it infers,
each joint's tolerance a quantile of its equation error over the recording's free-air
samples, where the tip force is zero and known; never the truth in contact).

    .venv/bin/python benchmarks/excavator_tip_force_bounds.py [--every 5] [--tol 2] [--no-fair]
"""
import argparse
import math

import numpy as np
from scipy.optimize import linprog

from boomfmi import experiments as E
from boomfmi.physics import linkage as exc
from boomfmi.rig import run_excavator_offline

EXACT = {"p_sigma": 0.0, "alpha_sigma": 0.0, "quantise": False}
SCENARIOS = tuple(E.TIP_FORCE_SCENARIOS)


def feasible_rows(x, v, a, p_a, p_b, ex: exc.Excavator, tol: float, x_stop: float = 1e-6):
    """``(A_ub, b_ub)`` of the tip forces [N] (world frame) that leave one sample's
    exact motion as it is (see the module's docstring); ``tol`` [N] on a sliding
    joint's equation."""
    Mx, bias, lam = exc.piston_dynamics(x, v, 0.0, ex)
    g0 = Mx @ a + bias - exc.cylinder_forces(p_a, p_b, ex)
    scale = exc.friction_scale(x, ex)
    JT = exc.tip_jacobian(exc.joint_angles(x, ex), ex).T * lam[:, None]     # piston force per N at the tip
    A, b = [], []
    for i, act in enumerate(ex.actuators):
        lower, upper = x[i] <= x_stop, x[i] >= act.stroke - x_stop
        if v[i] != 0.0 and not (lower or upper):
            e = g0[i] + act.K_v * v[i] + act.F_d * scale[i] * np.sign(v[i])
            lo, hi = e - tol, e + tol
        else:
            hold = act.F_s * scale[i]
            lo, hi = g0[i] - hold, g0[i] + hold
            if lower:
                lo = -np.inf          # the stop at x = 0 pushes outward: any force into it
            if upper:
                hi = np.inf
        if np.isfinite(hi):
            A.append(JT[i])
            b.append(hi)
        if np.isfinite(lo):
            A.append(-JT[i])
            b.append(-lo)
    return np.array(A), np.array(b)


def axis_ranges(A, b):
    """``(lo, hi)`` 3-vectors: the smallest and largest force along each world axis over
    ``A f <= b`` (``-inf`` / ``inf`` where unbounded), or None where no force fits."""
    free = [(None, None)] * 3
    if linprog(np.zeros(3), A_ub=A, b_ub=b, bounds=free, method="highs").status != 0:
        return None
    ends = np.empty((2, 3))
    for k in range(3):
        for row, sign in ((0, 1.0), (1, -1.0)):
            c = np.zeros(3)
            c[k] = sign
            r = linprog(c, A_ub=A, b_ub=b, bounds=free, method="highs")
            # the set is not empty: any status but optimal is an unbounded direction
            ends[row, k] = r.fun * sign if r.status == 0 else -sign * np.inf
    return ends[0], ends[1]


def best_bounds(name: str, every: int = 5, tol: float = 2.0, ex: exc.Excavator | None = None):
    """The scenario ``name`` run with exact sensors; at every ``every``-th contact sample
    the set of tip forces consistent with it.  Returns ``(samples, half, inside, none,
    peak)``: the samples' indices, the half-widths per axis (m, 3) [N] (``inf`` where
    unbounded) of those with a set, how many held the true force, how many had no
    force within ``tol`` [N], and each axis's peak [N]."""
    ex = exc.Excavator() if ex is None else ex
    c, cmd = E.tip_force_scenario(name)
    d = run_excavator_offline({"machine": "excavator", "noise": EXACT, "contact": c.config()}, cmd, cmd.duration)
    return _sets(d, every, tol, ex)


def _sets(d, every, tol, ex):
    """best_bounds' sets over the exact recording ``d``."""
    t = d["t"].to_numpy(float)
    X = d[[f"x_{j}" for j in exc.JOINTS]].to_numpy(float)
    V = d[[f"v_{j}" for j in exc.JOINTS]].to_numpy(float)
    Acc = np.gradient(V, t, axis=0)
    PA = d[[f"p_a_{j}" for j in exc.JOINTS]].to_numpy(float) + ex.P_atm
    PB = d[[f"p_b_{j}" for j in exc.JOINTS]].to_numpy(float) + ex.P_atm
    F = d[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy(float)
    peak = np.abs(F).max(axis=0)
    samples = np.flatnonzero(np.linalg.norm(F, axis=1) > 0.0)[::every]
    half, none, inside = [], 0, 0
    for k in samples:
        A, b = feasible_rows(X[k], V[k], Acc[k], PA[k], PB[k], ex, tol)
        inside += bool(np.all(A @ F[k] <= b + 1e-9))
        ranges = axis_ranges(A, b)
        if ranges is None:
            none += 1                 # no force fits within --tol (a derivative's error at a start or stop)
            continue
        half.append(0.5 * (ranges[1] - ranges[0]))
    return samples, np.array(half).reshape(-1, 3), inside, none, peak


#: [Hz] The zero-phase filters the fair bound tries on the angles and pressures (the
#: corner that gives the narrowest set is kept; an offline filter, no delay).
FAIR_CORNERS = (5.0, 10.0, 20.0)
#: The tolerances the fair bound tries, as quantiles of each joint's residual (its
#: magnitude) of its sliding law on the true force over the sliding samples (the
#: smallest whose sets hold the truth at >= 95 % of the samples per axis is kept; quantiles, not
#: multiples of the RMS, since a start's or a stop's residuals are far in the tail).
FAIR_SCALES = (0.0, 0.25, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 0.98, 0.99, 1.0)


def _zero_phase(y, t, corner: float):
    """``y`` (n, m) through a 2nd-order Butterworth low-pass at ``corner`` [Hz], forwards
    and backwards (no delay)."""
    from scipy.signal import butter, filtfilt
    b, a = butter(2, corner / (0.5 / float(np.median(np.diff(t)))))
    return filtfilt(b, a, y, axis=0)


def fair_bounds(d, every: int = 5, ex: exc.Excavator | None = None, x_stop: float = 1e-6):
    """The set of tip forces consistent with the *measured* recording ``d`` (standard
    sensors: the angles' and pressures' noise and ADC) within its own noise, computed
    offline with what no causal estimator has: the angles and pressures filtered forwards
    and backwards (:data:`FAIR_CORNERS`, the narrowest kept), each joint's sliding,
    sticking or stop from the rig's true x and v, and each joint's tolerance on its
    sliding law from its residual on the true force (a quantile, :data:`FAIR_SCALES`, of
    its magnitude over the sliding samples, the smallest whose sets hold the true force
    at >= 95 % of the samples per axis, as the estimator's interval must), within the
    estimator's own box ``|f_k| <= F_BOUND`` (a side on it is open).  What an interval
    with that coverage needs at the least on this recording, with more information than
    any causal estimator has (not a proof: one tolerance per joint for all samples).
    Returns ``(width, covered, inside, n, corner, scale)``: the widths (m, 3) [N] per
    axis (``inf`` where a side is open), the share of the samples whose set holds the
    true force per axis (3,), at how many of the ``n`` samples (every
    ``every``-th contact sample) the truth lies in the set (on every joint's row at
    once), and the corner [Hz] and quantile used."""
    from boomfmi.physics.force_estimation import F_BOUND, tip_force_interval
    ex = exc.Excavator() if ex is None else ex
    t = d["t"].to_numpy(float)
    Q = d[[f"angle_{j}" for j in exc.JOINTS]].to_numpy(float)
    P = d[[f"p_{s}_{j}" for s in "ab" for j in exc.JOINTS]].to_numpy(float) + ex.P_atm
    Xt = d[[f"x_{j}" for j in exc.JOINTS]].to_numpy(float)
    Vt = d[[f"v_{j}" for j in exc.JOINTS]].to_numpy(float)
    F = d[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy(float)
    samples = np.flatnonzero(np.linalg.norm(F, axis=1) > 0.0)[::every]
    strokes = np.array([a.stroke for a in ex.actuators])
    lower, upper = Xt[samples] <= x_stop, Xt[samples] >= strokes - x_stop
    sliding = (Vt[samples] != 0.0) & ~lower & ~upper
    Xm = exc.pistons_from_angles(Q, ex)
    best = None
    for corner in FAIR_CORNERS:
        X = _zero_phase(Xm, t, corner)
        V = np.gradient(X, t, axis=0)
        Acc = np.gradient(V, t, axis=0)
        Pf = _zero_phase(P, t, corner)
        rows = []                    # per sample: (q, lam, the sliding law's or the net's value, the hold) per joint
        for k in samples:
            x = np.clip(X[k], 0.0, strokes)
            Mx, bias, lam = exc.piston_dynamics(x, V[k], 0.0, ex)
            g0 = Mx @ Acc[k] + bias - exc.cylinder_forces(Pf[k, :4], Pf[k, 4:], ex)
            scale = exc.friction_scale(x, ex)
            slide = np.array([g0[i] + a.K_v * Vt[k, i] + a.F_d * scale[i] * np.sign(Vt[k, i])
                              for i, a in enumerate(ex.actuators)])
            hold = np.array([a.F_s for a in ex.actuators]) * scale
            rows.append((exc.joint_angles(x, ex), lam, g0, slide, hold))
        m = len(samples)
        res = np.array([lam * (exc.tip_jacobian(q, ex).T @ F[k]) - slide
                        for k, (q, lam, _, slide, _) in zip(samples, rows)])

        def sets(s):
            """The sets' widths (m, 3), per-axis coverage of the truth and how many sets
            hold it whole, with each joint's tolerance its residual's ``s`` quantile."""
            tol = np.array([np.quantile(np.abs(res[sliding[:, i], i]), s) if sliding[:, i].any() else 0.0
                            for i in range(4)]) + 1e-3
            width, covered, whole = np.empty((m, 3)), np.zeros(3), 0
            for r, (q, lam, g0, slide, hold) in enumerate(rows):
                lo = np.where(sliding[r], slide - tol, g0 - hold - tol)
                hi = np.where(sliding[r], slide + tol, g0 + hold + tol)
                lo[lower[r]], hi[upper[r]] = -np.inf, np.inf
                v = lam * (exc.tip_jacobian(q, ex).T @ F[samples[r]])
                whole += bool(np.all((v >= lo - 1e-9) & (v <= hi + 1e-9)))
                t_lo, t_hi = lo / lam, hi / lam
                # within the estimator's own box |f_k| <= F_BOUND (the same prior: an axis coupled
                # to an open one is bounded by the box's corner in both); a side on the box is open
                f_lo, f_hi, ok = tip_force_interval(q, np.minimum(t_lo, t_hi), np.maximum(t_lo, t_hi), ex, F_BOUND)
                covered += (F[samples[r]] >= f_lo - 1e-9) & (F[samples[r]] <= f_hi + 1e-9)
                open_ = (f_lo <= -F_BOUND + 1e-6) | (f_hi >= F_BOUND - 1e-6) | (not ok)
                width[r] = np.where(open_, np.inf, f_hi - f_lo)
            return width, covered / m, whole

        # the smallest quantile whose sets hold the truth at >= 95 % per axis (as the
        # estimator's interval must): bisection, the coverage grows with the tolerance
        a, b = 0, len(FAIR_SCALES) - 1
        found = sets(FAIR_SCALES[b])
        while a < b:
            mid = (a + b) // 2
            trial = sets(FAIR_SCALES[mid])
            if np.all(trial[1] >= 0.95):
                b, found = mid, trial
            else:
                a = mid + 1
        width, covered, inside = found
        s = FAIR_SCALES[b]
        score = np.sum(np.median(np.where(np.isfinite(width), width, 1e9), axis=0))
        if best is None or score < best[-1]:
            best = (width, covered, inside, m, corner, s, score)
    return best[:6]


#: The quantile of each joint's free-air equation error (its magnitude) the causal fair bound
#: takes as that joint's tolerance.
CAUSAL_QUANTILE = 0.95


def free_air_tolerances(d, ex: exc.Excavator | None = None, quantile: float = CAUSAL_QUANTILE, equations=None):
    """Each joint's tolerance on its sliding law [N on the piston] from the recording ``d``
    alone where the tip force is known: the ``quantile`` of the magnitude of its
    equation's error over the free-air samples (true tip force 0) where the estimator
    takes it as sliding (there the sliding law's value, ``estimate_tip_force(...,
    equations=True)``'s fifth array, is the error; ``equations`` (n, 4) those values if
    already computed).  A joint with fewer than 20 such samples keeps the estimator's own
    tolerance (``BAND_SLIDE`` times its ``F_s``)."""
    from boomfmi.physics.force_estimation import BAND_SLIDE, estimate_tip_force
    ex = exc.Excavator() if ex is None else ex
    if equations is None:
        *_, equations, _ = estimate_tip_force(d, ex, bounds=True, equations=True)
    free = np.linalg.norm(d[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy(float), axis=1) == 0.0
    F_s = np.array([a.F_s for a in ex.actuators])
    tol = np.broadcast_to(np.asarray(BAND_SLIDE, float), (4,)) * F_s
    for i in range(4):
        e = np.abs(np.asarray(equations, float)[free, i])
        e = e[np.isfinite(e)]
        if len(e) >= 20:
            tol[i] = np.quantile(e, quantile)
    return tol


def causal_fair_bounds(d, every: int = 5, ex: exc.Excavator | None = None, quantile: float = CAUSAL_QUANTILE,
                       tol=None):
    """Beside :func:`fair_bounds`, the same construction with only what a causal estimator
    has: the estimator's own causal filters and its own inferred sliding / sticking /
    stop per joint (``physics.force_estimation.observer_step``), and each joint's
    tolerance [N on the piston] its free-air equation error's ``quantile``
    (:func:`free_air_tolerances`, or ``tol`` (4,) if given; never the truth in contact),
    one per joint for all samples, no union over a window and no share of the force's
    change (``band_rate`` 0, ``t_hold`` 0); a sticking joint keeps its friction band
    (widened by its tolerance), a joint on a stop its one side, within the box
    ``|f_k| <= F_BOUND``.  Returns ``(width, covered, tol)``: the widths (m, 3) [N] at
    every ``every``-th contact sample (``inf`` where a side is open), the share of them
    whose interval holds the true force per axis (3,), and the tolerances (4,) [N]."""
    from boomfmi.physics.force_estimation import F_BOUND, estimate_tip_force
    ex = exc.Excavator() if ex is None else ex
    tol = free_air_tolerances(d, ex, quantile) if tol is None else np.asarray(tol, float)
    F_s = np.array([a.F_s for a in ex.actuators])
    _, _, lo, hi = estimate_tip_force(d, ex, bounds=True, band_slide=tol / F_s, band_rate=0.0, t_hold=0.0)
    F = d[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy(float)
    samples = np.flatnonzero(np.linalg.norm(F, axis=1) > 0.0)[::every]
    lo, hi, f = lo[samples], hi[samples], F[samples]
    open_ = (lo <= -F_BOUND + 1e-6) | (hi >= F_BOUND - 1e-6)
    return np.where(open_, np.inf, hi - lo), ((f >= lo) & (f <= hi)).mean(axis=0), tol


#: the tolerances' scales :func:`causal_bounds_at_coverage` tries, in turn
COVERAGE_SCALES = (1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0)


def causal_bounds_at_coverage(d, every: int = 5, ex: exc.Excavator | None = None, target: float = 0.95,
                              scales=COVERAGE_SCALES, tol=None, at_tol=None):
    """The causal fair bound (:func:`causal_fair_bounds`) at the coverage the estimator
    must reach: per world axis, the free-air tolerances scaled by the smallest of
    ``scales`` at which the truth lies in the bound at ``target`` of the contact samples
    or more.  Against it the estimator's interval is judged at equal coverage (the
    causal bound at its free-air tolerances covers less than 95 % on some scenarios, so
    a narrower width there is not a width the estimator could have had).  Returns per
    axis ``(widths, coverage, scale)``: the widths (m,) [N] at that scale (``inf`` where
    open), its coverage and the scale (``nan`` and the last scale's figures where none
    reaches ``target``).  ``tol`` (4,) [N]: the free-air tolerances if already known;
    ``at_tol``: :func:`causal_fair_bounds`' ``(width, covered)`` at them, if already run
    (the scale 1 is then not run again)."""
    ex = exc.Excavator() if ex is None else ex
    tol = free_air_tolerances(d, ex) if tol is None else np.asarray(tol, float)
    out = [None, None, None]
    for scale in scales:
        if scale == 1.0 and at_tol is not None:
            width, covered = at_tol
        else:
            width, covered, _ = causal_fair_bounds(d, every, ex, tol=scale * tol)
        for k in range(3):
            if out[k] is None and covered[k] >= target:
                out[k] = (width[:, k], float(covered[k]), scale)
        if all(o is not None for o in out):
            break
    return [o if o is not None else (width[:, k], float(covered[k]), math.nan) for k, o in enumerate(out)]


def median_width(w) -> str:
    """The median of the widths ``w`` [N] (``inf`` where a side is open) as printed:
    "open" where the set is open at more than half the samples."""
    w = np.asarray(w, float)
    return "open" if not len(w) or np.mean(np.isfinite(w)) <= 0.5 else f"{float(np.median(w)):.3g} N"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=5, help="every n-th contact sample")
    ap.add_argument("--tol", type=float, default=2.0, help="[N] on a sliding joint's equation")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS), help=f"of {', '.join(SCENARIOS)}")
    ap.add_argument("--no-fair", dest="fair", action="store_false",
                    help="skip the fair bound (the standard-sensor recording's set, see fair_bounds)")
    args = ap.parse_args(argv)
    ex = exc.Excavator()
    for name in args.scenarios.split(","):
        samples, half, inside, none, peak = best_bounds(name, args.every, args.tol, ex)
        print(f"{name}: {len(samples)} contact samples (every {args.every}-th), the true force in the set at "
              f"{inside}, {none} with no force within {args.tol:g} N")
        for k, c in enumerate("xyz"):
            h = half[:, k]
            bounded = np.isfinite(h)
            rms = float(np.sqrt(np.mean(h[bounded] ** 2))) if bounded.any() else float("nan")
            pinned = float(np.mean(h <= 0.1 * peak[k]))
            med = float(np.median(2.0 * h[bounded])) if bounded.any() else float("nan")
            print(f"  {c}: peak {peak[k]:6.1f} N; unbounded {100 * (1 - bounded.mean()):5.1f} % of the samples; "
                  f"RMS half-width where bounded {rms:7.2f} N = {100 * rms / peak[k]:6.1f} % of the peak; "
                  f"pinned within +-10 % of the peak at {100 * pinned:5.1f} %; median width where bounded "
                  f"{med:7.2f} N")
        if args.fair:
            c, cmd = E.tip_force_scenario(name)
            d = run_excavator_offline({"machine": "excavator", "contact": c.config()}, cmd, cmd.duration)
            width, covered, inside, n, corner, scale = fair_bounds(d, args.every, ex)
            print(f"  fair bound (standard sensors, filtered at {corner:g} Hz forwards and backwards, the rig's "
                  f"sliding and sticking, tolerance each joint's residual's {scale:g} quantile): the true force in the set "
                  f"at {inside} of {n} (per axis " + " / ".join(f"{100 * v:.1f}" for v in covered) + " %); median width x / y / z "
                  + " / ".join(median_width(width[:, k]) for k in range(3)) + f" (exact sensors "
                  + " / ".join(median_width(2.0 * half[:, k]) for k in range(3)) + ")")
            width, covered, tol = causal_fair_bounds(d, args.every, ex)
            print(f"  causal fair bound (the estimator's causal filters and inferred states, each joint's tolerance "
                  f"its free-air equation error's {CAUSAL_QUANTILE:g} quantile, " + " / ".join(f"{v:.1f}" for v in tol)
                  + " N): per axis " + " / ".join(f"{100 * v:.1f}" for v in covered) + " %; median width x / y / z "
                  + " / ".join(median_width(width[:, k]) for k in range(3)))


if __name__ == "__main__":
    main()
