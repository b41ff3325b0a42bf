"""The paper's identification method, as written (Sec. 4.2, Eq. 13 to 17).

1. **Starts of motion.**  "As soon as the force acting on the piston ... was greater
   than the static friction force, the piston started to move": at the first sample
   where the piston has visibly left its rest, the gauge pressures give (Eq. 14)
   ``F_Start = P_ar A_a - P_br A_b``, positive direction (extension, StartP) and
   negative (retraction, StartN), with phi from Eq. 10.  The start is the last sample
   before the departure where the filtered position was within 0.05 mm of its rest.
2. **Eq. 13** gives F_L and F_s from one start of each kind::

       F_L = (F_StartP cos(phi_N) - F_StartN cos(phi_P)) / sin(phi_P + phi_N)
       F_s = (F_StartP - F_L sin(phi_P)) / cos(phi_P)

   ``eq13="printed"`` uses this as printed, with F_StartN as Eq. 14 defines it;
   ``eq13="derived"`` uses the form the two force balances give (a plus sign, see
   docs/paper-errata.md, section 8.1).
3. **Three states of roughly constant acceleration**, one per step U_1, U_2, U_3, give
   Eq. 15 and 16, ``A_i - B_i K_v - C_i F_d - D_i M = 0``, a 3 x 3 system solved for K_v,
   F_d and M.  Its condition number is reported: the paper's own Eq. 17 has 335.

Where several starts of a kind are found, their forces and angles are averaged.
"""
from __future__ import annotations

import math

import numpy as np

from .. import physics as ph
from ..physics import reference_rig
from .fit import PARAMETER_UNITS, Estimate, FitResult, breakaways
from .preprocess import Prepared

NAN = (math.nan, math.nan)


def onset(p: Prepared, i: int, tolerance: float = 5e-5) -> int:
    """Walk back from the departure at sample i to the last sample where the filtered
    position was still within ``tolerance`` [m] of its rest."""
    rest = float(np.median(p.x[max(0, i - int(0.12 * p.fs)):max(1, i - int(0.07 * p.fs))]))
    j = i
    while j > 0 and abs(p.x[j] - rest) > tolerance:
        j -= 1
    return j


def _starts(preps: list[Prepared], cyl: ph.Cylinder, P_atm: float, L: float):
    pos, neg = [], []
    for p in preps:
        for k in breakaways(p, L):
            i = onset(p, k)
            F = float(ph.piston_force(p.p_a[i], p.p_b[i], cyl, P_atm))   # Eq. 14, gauge form
            extending = p.x[k] > p.x[i]
            (pos if extending else neg).append((F, float(p.phi[i]), float(p.t[i])))
    return pos, neg


def _constant_acceleration_states(preps, F_L, cyl, P_atm, L, window=0.03, margin=0.003):
    """One state per extension phase: the window of ``window`` s, while the piston
    moves out well clear of the stops, where the acceleration varies least."""
    states = []
    for p in preps:
        n = int(window * p.fs)
        moving_out = (p.v > 0.2 * max(p.v.max(), 1e-9)) & (p.x > margin) & (p.x < L - margin)
        # contiguous runs of outward motion: one phase each
        edges = np.flatnonzero(np.diff(moving_out.astype(int)))
        bounds = np.concatenate([[0], edges + 1, [len(p.t)]])
        for a, b in zip(bounds[:-1], bounds[1:]):
            if not moving_out[a] or b - a < 2 * n:
                continue
            best, best_std = None, math.inf
            for s in range(a, b - n, max(1, n // 4)):
                sd = float(np.std(p.a[s:s + n]))
                if sd < best_std:
                    best, best_std = s, sd
            sl = slice(best, best + n)
            phi = p.phi[sl]
            A = float(np.mean(ph.drive_force(p.p_a[sl], p.p_b[sl], phi, 0.0, cyl, ph.Load(F_L=F_L), P_atm)))
            states.append(dict(t=float(p.t[best]), A=A, B=float(np.mean(p.v[sl])),
                               C=float(np.mean(np.cos(phi))), D=float(np.mean(p.a[sl]))))
    return states


def identify_paper(preps: list[Prepared], cyl: ph.Cylinder = ph.Cylinder(), P_atm: float = reference_rig.P_atm,
                   eq13: str = "printed") -> FitResult:
    """The paper's method on prepared recordings of its multistep experiment."""
    if eq13 not in ("printed", "derived"):
        raise ValueError("eq13 must be 'printed' or 'derived'")
    L = cyl.L
    warnings: list[str] = []
    pos, neg = _starts(preps, cyl, P_atm, L)
    if not pos or not neg:
        raise ValueError(f"the paper's method needs a start of motion in each direction; found "
                         f"{len(pos)} extending and {len(neg)} retracting (record its multistep experiment)")
    F_P, phi_P = np.mean([e[0] for e in pos]), np.mean([e[1] for e in pos])
    F_N, phi_N = np.mean([e[0] for e in neg]), np.mean([e[1] for e in neg])
    sign = -1.0 if eq13 == "printed" else 1.0
    F_L = (F_P * math.cos(phi_N) + sign * F_N * math.cos(phi_P)) / math.sin(phi_P + phi_N)     # Eq. 13
    F_s = (F_P - F_L * math.sin(phi_P)) / math.cos(phi_P)
    states = _constant_acceleration_states(preps, F_L, cyl, P_atm, L)
    details = {"starts_positive": [dict(F=e[0], phi=e[1], t=e[2]) for e in pos],
               "starts_negative": [dict(F=e[0], phi=e[1], t=e[2]) for e in neg],
               "eq13": eq13, "states": states}
    if len(states) < 3:
        warnings.append(f"only {len(states)} phases of constant acceleration found; the paper's "
                        f"Eq. 16 needs three (U_1, U_2, U_3): K_v, F_d and M are not identified")
        K_v = F_d = M = math.nan
        cond = math.nan
    else:
        use = states[:3]
        Mx = np.array([[s["B"], s["C"], s["D"]] for s in use])
        rhs = np.array([s["A"] for s in use])
        cond = float(np.linalg.cond(Mx))
        try:
            K_v, F_d, M = (float(v) for v in np.linalg.solve(Mx, rhs))
        except np.linalg.LinAlgError:
            K_v = F_d = M = math.nan
        details["matrix"] = Mx.tolist()
        details["rhs"] = rhs.tolist()
        if cond > 100:
            warnings.append(f"the 3 x 3 system of Eq. 16 has condition number {cond:.0f}: "
                            f"K_v, F_d and M are fragile")
        if M <= 0:
            warnings.append(f"Eq. 16 gives a non-physical mass M = {M:.3g} kg")
    details["condition_number"] = cond
    values = {"K_v": K_v, "F_s": F_s, "F_d": F_d, "F_L": F_L, "M": M}
    params = {k: Estimate(float(v), NAN, PARAMETER_UNITS[k]) for k, v in values.items()}
    return FitResult("paper", params, warnings, details)


def solve_printed_eq17():
    """The paper's printed Eq. 17: (K_v, F_d, M) solving it, and the matrix's 2-norm
    condition number."""
    A = np.array([[0.0784, 0.6169, 0.0517], [0.0783, 0.5853, 0.0269], [0.0739, 0.5846, 0.0250]])
    b = np.array([297.2217, 290.3454, 289.2136])
    return np.linalg.solve(A, b), float(np.linalg.cond(A)), A, b


__all__ = ["NAN", "onset", "identify_paper", "solve_printed_eq17"]
