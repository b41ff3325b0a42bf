"""Identification per joint of a machine on the linkage (the whole excavator) from its
recordings; ``identify.identify_recordings`` runs it on the excavator's recordings.

The linkage's rigid-body dynamics are known (``physics.linkage``: geometry, link
masses); the unknowns are each cylinder's Eq. 9 friction (K_v, F_s, F_d) and the mass
of the payload in the bucket.  In piston coordinates (``physics.linkage.
piston_dynamics``) every joint's equation of motion is::

    M_x(x, m) x'' + bias(x, x', m) = F_p - K_v x' - F_c + lam J^T f_tip

with F_p the pneumatic forces from the recorded pressures, ``lam = dq/dx`` and M_x and
the bias (Coriolis, centrifugal, gravity) affine in the payload m (a point mass at the
bucket's centre of mass: ``M_x(m) = M_x(0) + m (M_x(1) - M_x(0))``).  F_c is
``F_d scale dir`` while the cylinder slides (scale = cos(phi) for the boom,
``physics.linkage.friction_scale``) and whatever holds it while it rests.

Three stages, as the boom's (``identify.fit``):

Each recording's joints come from ``preprocess.prepare_machine``.

1. **Equation error over every sample** (:func:`equation_rows`): each joint's samples
   are classified as sliding or resting from its own position (``fit.motion_modes``);
   the equation, multiplied by the sliding indicator s (a resting row is 0 = 0, as
   the boom's), is linear in theta = (K_v, F_d per cylinder, m)::

       K_v G[s x'] + F_d G[s scale dir] + m G[s dD] = G[s (F_p - D0 + lam J^T f)]

   with D0 = M_x(0) x'' + bias(0) and dD = the payload's share per kg, evaluated from
   the position low-passed at the preparation's cut-off and every term then passed
   through the same zero-phase state-variable filter G; rows of every joint of every
   recording stacked, each joint weighted by the inverse of its residual's spread
   (two passes), samples near an impact on a stop left out, and those within
   ``TRANSITION_REACH`` periods of G of a start or a stop: D0 comes from motion
   filtered at the preparation's cut-off, whose inertia at a start or a stop spreads
   to both sides of it, and the sliding indicator cuts the resting side's share (the
   mask is needed: at rest the acceleration's noise times the joint's mass, 600 kg and
   more on the swing, would swamp its friction).  Intervals from a
   moving-block bootstrap, widened by ``fit.SYSTEMATIC``.
2. **Static friction from every start** per joint: each joint becomes an equivalent
   single cylinder (unit areas, the net force on it of everything but its own
   friction and inertia, its diagonal mass ``M_x[i, i]``) and the boom's stage 3
   (``fit.static_friction``) reads its starts.  Its interval is widened to every level
   within a 95 % likelihood ratio of the starts' combined evidence (:func:`honest_static`:
   a start bounds F_s sharply from above and only softly from below), and F_s counts as
   told only where that interval is within :data:`PROMISE` of it.
"""
from __future__ import annotations

import math

import numpy as np

from .. import physics as ph
from ..physics import linkage as exc
from .fit import (Estimate, FitResult, REACH, block_bootstrap, column_scale, motion, scaled_lstsq, static_friction,
                  _widened)
from .preprocess import CUTOFF, JointData, Prepared, lowpass, prepare_machine

JOINTS = exc.JOINTS
#: Cut-off [Hz] of the state-variable filter G of the equation error (the boom's EE_CUTOFF).
EE_CUTOFF = 10.0
#: Periods of EE_CUTOFF around each start and stop whose rows stage 1 leaves out.  G's
#: impulse response (zero-phase, second order) holds 94 % of its weight within half a
#: period and its step response is within 3 % of the step from a third of one on; a
#: whole period (99 %) leaves short slides too few rows (docs/excavator.md)
TRANSITION_REACH = 0.5
#: Parameters per joint, and the payload's name.
JOINT_PARAMS = ("K_v", "F_s", "F_d")
PARAMETER_UNITS = {"K_v": "N.s/m", "F_s": "N", "F_d": "N", "payload": "kg"}
SYSTEMATIC_PAYLOAD = 0.02
#: The accuracy a value reported as identified promises (a relative half-width of its
#: 95 % interval): F_s is reported as what the data cannot tell where its interval is
#: wider (``benchmarks/excavator_identification.py``'s target: within 5 % or flagged).
PROMISE = 0.05


def equation_rows(joints: list[JointData], cutoff: float = EE_CUTOFF):
    """Stage 1's rows of one recording: ``(X, y, use, joint)`` with theta =
    (K_v x4, F_d x4, payload) (see the module's docstring)."""
    Xs, ys, uses, which = [], [], [], []
    for i, jd in enumerate(joints):
        p, modes = jd.p, jd.modes
        G = lambda y: lowpass(y, p.fs, cutoff)
        s = modes.sliding.astype(float)
        n = len(p.t)
        X = np.zeros((n, 9))
        # the viscous term multiplied by s as every other term: a slow slide below the
        # speed that counts as motion (which rises with the sensor's quantum and noise) is
        # classified as rest, and a row with its velocity but without its drive force
        # pulled K_v_boom 1 to 2 % low and F_d_boom 3 to 5 % high over noise draws, their
        # intervals missing the truth
        X[:, i] = G(s * p.v)
        X[:, 4 + i] = G(s * jd.scale * modes.direction)
        X[:, 8] = G(s * jd.dD)
        y = G(s * (jd.F_p - jd.D0))
        reach = int(REACH * p.fs / cutoff)
        use = np.ones(n, bool)
        use[:reach] = use[-reach:] = False
        for k in modes.impacts:
            use[max(0, k - reach):k + reach] = False
        # a start or a stop: D0 comes from filtered motion, whose spread across the change
        # (the inertia of a start or a stop, half of it on the resting side) the sliding
        # indicator cuts; G carries that cut to the rows within its reach, which are left out
        near = int(TRANSITION_REACH * p.fs / cutoff)
        for k in np.flatnonzero(np.diff(modes.sliding.astype(np.int8)) != 0) + 1:
            use[max(0, k - near):k + near] = False
        Xs.append(X)
        ys.append(y)
        uses.append(use)
        which.append(np.full(n, i))
    return np.vstack(Xs), np.concatenate(ys), np.concatenate(uses), np.concatenate(which)


def equation_error(data: list[list[JointData]], n_boot: int = 200, block: float = 0.1, seed: int = 0,
                   cutoff: float = EE_CUTOFF):
    """Stage 1 over every recording: estimates ``{"K_v_<joint>", "F_d_<joint>",
    "payload"}`` and details."""
    rows = [equation_rows(r, cutoff) for r in data]
    X = np.vstack([r[0][r[2]] for r in rows])
    y = np.concatenate([r[1][r[2]] for r in rows])
    joint = np.concatenate([r[3][r[2]] for r in rows])
    # the recordings' blocks: a block never spans two joints' rows
    w = np.ones(len(y))
    theta = scaled_lstsq(X, y)
    for _ in range(2):                       # each joint weighted by its residual's spread
        res = y - X @ theta
        for i in range(4):
            sel = joint == i
            sd = float(np.std(res[sel])) if sel.any() else 1.0
            w[sel] = 1.0 / max(sd, 1e-9)
        theta = scaled_lstsq(X * w[:, None], y * w)
    Xw, yw = X * w[:, None], y * w
    boots = block_bootstrap(Xw, yw, data[0][0].p.fs, n_boot, block, seed)
    lo, hi = np.percentile(boots, [2.5, 97.5], axis=0)
    est = {}
    for i, j in enumerate(JOINTS):
        for k, name in ((i, "K_v"), (4 + i, "F_d")):
            est[f"{name}_{j}"] = _widened(name, theta[k], min(lo[k], theta[k]), max(hi[k], theta[k]))
    floor = SYSTEMATIC_PAYLOAD * abs(theta[8])
    est["payload"] = Estimate(float(theta[8]), (float(min(lo[8], theta[8]) - floor),
                                                float(max(hi[8], theta[8]) + floor)), "kg")
    res = y - X @ theta
    return est, {"samples": len(y), "condition_number": float(np.linalg.cond(Xw / column_scale(Xw))),
                 "rms_residual_N": {j: float(np.sqrt(np.mean(res[joint == i] ** 2))) for i, j in enumerate(JOINTS)}}


def equivalent(jd: JointData, payload: float) -> Prepared:
    """The joint as a single cylinder with the payload's share in its net force."""
    p = jd.p
    extra = payload * (jd.dD - jd.down)
    fs = p.fs
    return Prepared(t=p.t, u=p.u, p_a=p.p_a - lowpass(extra, fs, p.cutoff), p_b=p.p_b, x=p.x, v=p.v, a=p.a,
                    phi=p.phi, x_raw=p.x_raw, p_a_raw=p.p_a_raw - extra, p_b_raw=p.p_b_raw, fs=fs,
                    cutoff=p.cutoff, source=p.source)


def honest_static(F_s: Estimate, info: dict) -> tuple[Estimate, bool]:
    """F_s's interval widened to every level its starts' combined evidence allows
    (``fit.static_friction``'s ``likelihood_range_N``: a start bounds F_s sharply from
    above and only softly from below, so the posterior is flat-topped with the truth
    near its upper edge, which its 2.5 and 97.5 percentiles cut off: on the excavator's
    rig, F_s_boom's interval missed the truth on some noise draws).  The data identify
    F_s where that interval is narrower than :data:`PROMISE` of it on either side and
    its top is below the grid's (a start not bounded above)."""
    lo_L, hi_L = info.get("likelihood_range_N", (F_s.ci95[0], F_s.ci95[1]))
    ratio = _widened("F_s", F_s.value, min(lo_L, F_s.value), max(hi_L, F_s.value))   # its floor once
    est = Estimate(F_s.value, (min(F_s.ci95[0], ratio.ci95[0]), max(F_s.ci95[1], ratio.ci95[1])), F_s.unit)
    top = info.get("grid_N", (math.nan, math.inf))[1]
    return est, bool(hi_L < top and est.relative_halfwidth < PROMISE)


def identify_joints(recordings, ex: exc.Excavator = exc.Excavator(), cutoff: float = CUTOFF) -> FitResult:
    """Each cylinder's K_v, F_s, F_d and the payload [kg] from excavator recordings
    (``Recording`` objects or DataFrames with the excavator's columns), the linkage's
    geometry and link masses ``ex`` known.  Parameters are named ``<name>_<joint>``
    (``K_v_arm``, ``physics.params.channel``) and ``payload``; see the module's docstring."""
    data = [prepare_machine(r, ex, cutoff) for r in recordings]
    est, info = equation_error(data)
    details = {"equation_error": info, "static_friction": {}}
    warnings = []
    payload = est["payload"].value
    for i, j in enumerate(JOINTS):
        act = ex.actuators[i]
        cyl = ph.Cylinder(A_a=1.0, A_b=1.0, L=act.stroke, V_a0=act.V_a0, V_b0=act.V_b0)
        P_atm = ex.P_atm
        motions = [motion(equivalent(r[i], payload), cyl, P_atm) for r in data]
        # the joint's own mass where each start happens (it moves with the posture)
        M = [r[i].Mii0 + payload * r[i].dMii for r in data]
        # the other joints' motion's share of the net force is known only as well as
        # their filtered motion: a rest's force bounds F_s only beyond its whole size,
        # and a start tells F_s only to within its error's scale
        base = {"M": M, "K_v": est[f"K_v_{j}"].value, "F_d": est[f"F_d_{j}"].value, "F_L": 0.0,
                "F_unsure": [r[i].unsure for r in data], "F_error": [r[i].coupling_error for r in data]}
        F_s, identified, info3 = static_friction(motions, base, cyl, P_atm)
        if F_s is not None:
            F_s, identified = honest_static(F_s, info3)
        details["static_friction"][j] = dict(info3, identified=bool(identified))
        if F_s is None:
            warnings.append(f"{j}: no start of motion from rest: F_s_{j} cannot be identified; F_d is used")
            F_s = Estimate(base["F_d"], (math.nan, math.nan), "N")
        elif not identified:
            warnings.append(f"{j}: the data cannot tell F_s_{j} within {100 * PROMISE:.0f} %: the starts put it "
                            f"anywhere in [{F_s.ci95[0]:.4g}, {F_s.ci95[1]:.4g}] N")
        est[f"F_s_{j}"] = F_s
    for k, e in est.items():
        if not k.startswith("F_s") and not e.tells and k != "payload":
            warnings.append(f"the data cannot identify {k}: its 95 % interval "
                            f"[{e.ci95[0]:.4g}, {e.ci95[1]:.4g}] {e.unit} is wider than half its value")
    ordered = {f"{n}_{j}": est[f"{n}_{j}"] for j in JOINTS for n in JOINT_PARAMS}
    ordered["payload"] = est["payload"]
    return FitResult("fit-excavator", ordered, warnings, details)


def true_values(ex: exc.Excavator = exc.Excavator(), payload: float = 0.0) -> dict:
    """The machine's own values under this module's names (for tests and benchmarks)."""
    out = {f"{n}_{j}": getattr(a, n) for j, a in zip(JOINTS, ex.actuators) for n in JOINT_PARAMS}
    out["payload"] = payload
    return out


__all__ = ["identify_joints", "equation_rows", "equation_error", "equivalent", "honest_static", "true_values",
           "JOINTS", "JOINT_PARAMS", "PARAMETER_UNITS", "EE_CUTOFF", "PROMISE"]
