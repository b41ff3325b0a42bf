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

    .venv/bin/python benchmarks/excavator_tip_force_bounds.py [--every 5] [--tol 2]
"""
import argparse

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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=5, help="every n-th contact sample")
    ap.add_argument("--tol", type=float, default=2.0, help="[N] on a sliding joint's equation")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS), help=f"of {', '.join(SCENARIOS)}")
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


if __name__ == "__main__":
    main()
