"""Boom load, friction and end stops (the paper's Eq. 8 and 9).

Eq. 8, with absolute pressures::

    M x'' = P_a A_a - P_b A_b - P_atm (A_a - A_b) - K_v x' - F_c - F_L sin(phi) - f_ext

``f_ext`` is an external force along the cylinder axis, positive against extension
(the bucket meeting soil); the paper's model has none.  Eq. 9's friction F_c holds the
piston while it is at rest and the drive force stays within F_s cos(phi), and is the
Coulomb force F_d cos(phi) against the motion otherwise.

The paper's stick condition ``x' = 0`` is never met by a numerical integrator.  The
rule here is exact instead: over a short substep the forces are frozen, so Eq. 8 is
linear in the velocity and has a closed-form solution; the instant at which a sliding
piston's velocity reaches zero is solved for, the piston is stopped there (v = 0.0
exactly), and Eq. 9's stick test decides whether it stays or breaks away.  At the
stops x = 0 and x = L the piston is held (v = 0, no bounce) while it is pushed into
the stop.
"""
from __future__ import annotations

import math

import numpy as np

from . import _xp as xp
from .geometry import phi_from_x
from .params import Cylinder, Geometry, Load


def piston_force(p_a, p_b, cyl: Cylinder = Cylinder(), P_atm: float = 101_325.0):
    """Pneumatic force on the piston [N], positive extending:
    ``P_a A_a - P_b A_b - P_atm (A_a - A_b)`` with absolute pressures [Pa]."""
    return p_a * cyl.A_a - p_b * cyl.A_b - P_atm * (cyl.A_a - cyl.A_b)


def drive_force(p_a, p_b, phi, f_ext, cyl: Cylinder = Cylinder(), load: Load = Load(),
                P_atm: float = 101_325.0):
    """Everything but friction that pushes the piston [N]: the pneumatic force minus
    the load ``F_L sin(phi)`` and the external force ``f_ext``."""
    return piston_force(p_a, p_b, cyl, P_atm) - load.F_L * xp.sin(phi) - f_ext


def friction_force(v, F_drive, phi, load: Load = Load()):
    """Eq. 9: the friction force F_c [N] that opposes the motion.

    At rest (v = 0) and with ``|F_drive| <= F_s cos(phi)`` friction balances the drive
    exactly; at rest above that level, and while sliding, it is the Coulomb force
    ``F_d cos(phi)`` against the velocity (against the drive at breakaway).
    """
    c = xp.cos(phi)
    stuck = (v == 0) & (xp.abs_(F_drive) <= load.F_s * c)
    direction = xp.where(v == 0, xp.sign(F_drive), xp.sign(v))
    return xp.where(stuck, F_drive, load.F_d * c * direction)


def acceleration(v, F_drive, phi, load: Load = Load()):
    """Eq. 8: piston acceleration [m/s^2] given the drive force [N] and velocity [m/s]."""
    return (F_drive - load.K_v * v - friction_force(v, F_drive, phi, load)) / load.M


def sliding_acceleration(v, F_drive, phi, direction, load: Load = Load()):
    """Eq. 8 while sliding in ``direction`` (+1 extending, -1 retracting) [m/s^2]: the
    Coulomb friction ``F_d cos(phi)`` opposes the motion, also at the instant v = 0."""
    return (F_drive - load.K_v * v - direction * load.F_d * xp.cos(phi)) / load.M


def _phi1(z: float) -> float:
    """(e^z - 1) / z, equal to 1 at z = 0."""
    return math.expm1(z) / z if abs(z) > 1e-5 else 1.0 + z / 2.0 + z * z / 6.0


def _phi2(z: float) -> float:
    """(e^z - 1 - z) / z^2, equal to 1/2 at z = 0."""
    return (math.expm1(z) - z) / (z * z) if abs(z) > 1e-4 else 0.5 + z / 6.0 + z * z / 24.0


def _slide(v0: float, F_net: float, K_v: float, M: float, t: float):
    """Position change [m] and velocity [m/s] after sliding ``t`` [s] under the constant
    force ``F_net`` [N] (drive minus Coulomb friction) and viscous friction K_v."""
    z = -K_v * t / M
    e = math.exp(z)
    return v0 * t * _phi1(z) + F_net * t * t / M * _phi2(z), v0 * e + F_net * t / M * _phi1(z)


def _time_to_rest(v0: float, F_net: float, K_v: float, M: float) -> float:
    """Time [s] until a piston sliding at ``v0`` stops under a force ``F_net`` that
    opposes its motion."""
    q = -K_v * v0 / F_net
    if q > 1e-12:
        return M * math.log1p(q) / K_v
    return -M * v0 / F_net


def sliding_velocity(v0, F_net, K_v: float, M: float, dt: float):
    """Eq. 8 while sliding one way, along a sampled force: the velocity [m/s] at every
    sample of ``F_net`` [N] (the drive force minus the Coulomb friction F_d cos(phi)
    against the motion; sample k held over [t_k, t_k+1]), from ``v0`` [m/s] at the
    first sample, with viscous friction ``K_v`` [N s/m] and mass ``M`` [kg].  Exact for
    a held force (``_slide``'s velocity, run as one linear recursive filter)::

        v[k+1] = e v[k] + (1 - e) F_net[k] / K_v,   e = exp(-K_v dt / M)

    ``F_net`` may be 2-D: one force history per row (``v0`` a scalar or one per row)."""
    from scipy.signal import lfilter      # here, not at the top: the FMUs bundle this module without scipy
    e = math.exp(-K_v * dt / M)
    F_net = np.asarray(F_net, dtype=float)
    zi = np.broadcast_to(np.asarray(v0, dtype=float), F_net.shape[:-1])[..., None].copy()
    v, _ = lfilter([0.0, (1.0 - e) / K_v], [1.0, -e], F_net, axis=-1, zi=zi)
    return v


def slide_or_stick(v: float, F_drive: float, cos_phi: float, dt: float,
                   load: Load = Load()):
    """Advance the piston ``dt`` [s] with a frozen drive force; returns ``(dx, v)``.

    Exact for constant ``F_drive`` [N] and ``cos_phi``: velocity zero crossings are
    solved for, and Eq. 9's stick test is applied at each.
    """
    K_v, F_s, F_d, _, M = load
    dx = 0.0
    t_left = dt
    for _ in range(3):   # slide -> rest -> break away the other way, at most
        if v == 0.0:
            if abs(F_drive) <= F_s * cos_phi:
                return dx, 0.0
            s = 1.0 if F_drive > 0.0 else -1.0
        else:
            s = 1.0 if v > 0.0 else -1.0
        F_net = F_drive - s * F_d * cos_phi
        if s * F_net <= 0.0:       # decelerating (or, at rest, not enough to move)
            if v == 0.0:
                return dx, 0.0
            t_rest = _time_to_rest(v, F_net, K_v, M)
            if t_rest < t_left:
                ddx, _ = _slide(v, F_net, K_v, M, t_rest)
                dx += ddx
                v = 0.0
                t_left -= t_rest
                continue
        ddx, v = _slide(v, F_net, K_v, M, t_left)
        if s * v < 0.0:            # rounding at the very instant of rest
            v = 0.0
        return dx + ddx, v
    return dx, v


def advance_load(x: float, v: float, dt: float, p_a: float, p_b: float, f_ext: float,
                 cyl: Cylinder = Cylinder(), geom: Geometry = Geometry(),
                 load: Load = Load(), P_atm: float = 101_325.0,
                 max_substep: float = 2e-4, load_at=None):
    """Advance the boom ``dt`` [s] with held pressures and external force.

    Parameters
    ----------
    x, v : float
        Piston position [m] in [0, L] and velocity [m/s].
    p_a, p_b : float
        Absolute chamber pressures [Pa], held over ``dt``.
    f_ext : float
        External force [N] along the cylinder axis, positive against extension.
    max_substep : float
        Longest substep [s] over which phi (and so the load and friction) is frozen.
    load_at : callable, optional
        For a friction level that varies with speed (stribeck_friction): ``load_at(load,
        v) -> Load``, evaluated at each substep's start and frozen over it.

    Returns
    -------
    (x, v) : the state after ``dt``; x never leaves [0, L].
    """
    L = cyl.L
    F_p = piston_force(p_a, p_b, cyl, P_atm) - f_ext
    n = max(1, math.ceil(dt / max_substep - 1e-9))
    h = dt / n
    for _ in range(n):
        phi = phi_from_x(x, geom)
        ld = load if load_at is None else load_at(load, v)
        F = F_p - ld.F_L * math.sin(phi)
        dx, v = slide_or_stick(v, F, math.cos(phi), h, ld)
        x, v = end_stops(x + dx, v, L)
    return x, v


def end_stops(x: float, v: float, L: float):
    """The hard end stops (Eq. 8's stroke, no bounce): ``(x, v)`` with the position [m]
    held within [0, L] and a velocity [m/s] into a stop it has reached set to 0."""
    if x <= 0.0:
        return 0.0, (0.0 if v < 0.0 else v)
    if x >= L:
        return L, (0.0 if v > 0.0 else v)
    return x, v


__all__ = ["piston_force", "drive_force", "friction_force", "acceleration", "sliding_acceleration", "sliding_velocity",
           "slide_or_stick", "advance_load", "end_stops"]
