"""Compressible mass flow through an orifice (the paper's Eq. 1, standard form).

The paper prints Eq. 1 with 2/(k-1) outside the square root and the choked exponent
(k+1)/(k-1); both are errata (``docs/paper-errata.md``).  The standard form is::

    r = P_d / P_u
    r >= P_cr:  mdot = A P_u sqrt(2k / (R T (k-1))) sqrt(r^(2/k) - r^((k+1)/k))
    r <  P_cr:  mdot = A P_u sqrt(k / (R T)) (2/(k+1))^((k+1)/(2(k-1)))

which is continuous at r = P_cr = (2/(k+1))^(k/(k-1)).

Near r = 1 the subsonic branch behaves like sqrt(1 - r): its slope with respect to the
pressures is infinite at equal pressures, so a chamber approaching the supply pressure
reaches it in finite time and no implicit integrator can converge there (the Jacobian
is unbounded).  Above ``R_LAMINAR`` = 0.999 (a pressure difference under 0.1 % of the
upstream pressure, 700 Pa at the supply) the flow is therefore taken linear in the
pressure difference, through the formula's value at ``R_LAMINAR`` and zero at r = 1: a
laminar region, as in ISO 6358 style valve models.  It is continuous, and changes
nothing outside that band.
"""
from __future__ import annotations

from functools import lru_cache

from . import _xp as xp
from .params import Gas


def critical_pressure_ratio(k: float) -> float:
    """P_cr = (2/(k+1))^(k/(k-1)) [1]; 0.5283 for k = 1.4 (the paper prints 0.582)."""
    return (2.0 / (k + 1.0)) ** (k / (k - 1.0))


#: Pressure ratio above which the flow is taken linear in the pressure difference.
R_LAMINAR = 0.999


def _subsonic_root(r, k):
    """sqrt(r^(2/k) - r^((k+1)/k)), the pressure-ratio factor of the subsonic branch."""
    return xp.sqrt(xp.maximum(r ** (2.0 / k) - r ** ((k + 1.0) / k), 0.0))


def _subsonic_slope(r, k, C, root):
    """d/dr of the subsonic branch's flow per area and upstream pressure, ``C`` times
    :func:`_subsonic_root` (its value ``root`` at ``r``): d/dr sqrt(g(r)) = g'(r) /
    (2 sqrt(g)), g = r^(2/k) - r^((k+1)/k)."""
    g_prime = (2.0 / k) * r ** (2.0 / k - 1.0) - ((k + 1.0) / k) * r ** (1.0 / k)
    return C * g_prime / (2.0 * xp.maximum(root, 1e-300))


@lru_cache(maxsize=64)
def _constants(k: float, R: float, T: float):
    """(P_cr, subsonic coefficient, choked flow per area and pressure, laminar slope) for
    a gas: computed once per gas, not on every call."""
    C = (2.0 * k / (R * T * (k - 1.0))) ** 0.5
    choked = (k / (R * T)) ** 0.5 * (2.0 / (k + 1.0)) ** ((k + 1.0) / (2.0 * (k - 1.0)))
    laminar = C * _subsonic_root(R_LAMINAR, k) / (1.0 - R_LAMINAR)
    return critical_pressure_ratio(k), C, choked, laminar


def mass_flow(A, P_u, P_d, gas: Gas = Gas()):
    """Mass flow [kg/s] from upstream to downstream through an orifice.

    Parameters
    ----------
    A : float or array
        Orifice area [m^2].
    P_u, P_d : float or array
        Absolute upstream and downstream pressures [Pa], with ``P_d <= P_u``
        (a ratio above 1 is treated as 1: no flow).
    gas : Gas
        k [1], R [J/(kg K)], T [K].
    """
    k = gas.k
    P_cr, C, choked, laminar_slope = _constants(*gas)
    if type(A) in xp.SCALARS and type(P_u) in xp.SCALARS and type(P_d) in xp.SCALARS:
        # one state's step (the reference solver calls this millions of times): only
        # the branch taken is evaluated, with the same operations as below
        r = xp.clip(P_d / P_u, 0.0, 1.0)
        if not r >= P_cr:
            return A * P_u * choked
        if r > R_LAMINAR:
            return A * P_u * (laminar_slope * (1.0 - r))
        return A * P_u * (C * _subsonic_root(r, k))
    r = xp.clip(P_d / P_u, 0.0, 1.0)
    subsonic = C * _subsonic_root(xp.minimum(r, R_LAMINAR), k)
    laminar = laminar_slope * (1.0 - r)
    return A * P_u * xp.where(r >= P_cr, xp.where(r > R_LAMINAR, laminar, subsonic), choked)


def mass_flow_slope(A, P_u, P_d, gas: Gas = Gas()):
    """d mdot / d P_d [kg/(s Pa)] of :func:`mass_flow` at fixed P_u (<= 0: a higher
    downstream pressure lets less air through)."""
    k = gas.k
    P_cr, C, _, laminar_slope = _constants(*gas)
    r = xp.clip(P_d / P_u, 0.0, 1.0)
    rs = xp.minimum(r, R_LAMINAR)
    d_subsonic = _subsonic_slope(rs, k, C, _subsonic_root(rs, k))
    d_laminar = -laminar_slope
    d_dr = xp.where(r >= P_cr, xp.where(r > R_LAMINAR, d_laminar, d_subsonic), 0.0)
    return A * d_dr        # A P_u d/dr * dr/dP_d, with dr/dP_d = 1 / P_u


def flow_at(mdot, slope, p, p_eval):
    """A mass flow [kg/s] evaluated at chamber pressure ``p_eval`` [Pa], with its slope
    ``slope`` [kg/(s.Pa)] there (:func:`signed_mass_flow_slope`), carried to the
    chamber's pressure ``p`` [Pa] along that slope: ``mdot + slope (p - p_eval)``, the
    first-order Taylor form of Eq. 1 about ``p_eval``.  A co-simulation stepped Jacobi
    hands the chambers flows evaluated at the previous communication point's pressures;
    carried to the present ones they no longer lag a step behind (which, at an end stop,
    makes the exhausting chamber's pressure chatter about the exhaust's)."""
    return mdot + slope * (p - p_eval)


def signed_mass_flow(A, P_1, P_2, gas: Gas = Gas()):
    """Mass flow [kg/s] from side 1 to side 2, negative where it runs from 2 to 1.

    ``P_1``, ``P_2`` are absolute pressures [Pa]; the upstream side is whichever is
    higher.
    """
    forward = P_1 >= P_2
    P_u = xp.where(forward, P_1, P_2)
    P_d = xp.where(forward, P_2, P_1)
    return xp.where(forward, 1.0, -1.0) * mass_flow(A, P_u, P_d, gas)


def signed_mass_flow_slope(A, P_1, P_2, gas: Gas = Gas()):
    """d/dP_2 of :func:`signed_mass_flow` [kg/(s Pa)] at fixed ``P_1``: how the flow
    from side 1 into side 2 changes with side 2's pressure (always <= 0)."""
    forward = P_1 >= P_2
    # forward: mdot = m(P_1, P_2), d/dP_2 = slope wrt the downstream pressure.
    # reverse: mdot = -m(P_2, P_1);  m(P_u, P_d) = A P_u f(P_d / P_u), so
    #   dm/dP_u = A f(r) - A r f'(r) = m / P_u - P_d * slope_d / P_u ... evaluated below.
    P_u = xp.where(forward, P_1, P_2)
    P_d = xp.where(forward, P_2, P_1)
    m = mass_flow(A, P_u, P_d, gas)
    slope_d = mass_flow_slope(A, P_u, P_d, gas)          # d m / d P_d
    slope_u = m / P_u - slope_d * P_d / P_u               # d m / d P_u (m is homogeneous of degree 1)
    return xp.where(forward, slope_d, -slope_u)


def signed_mass_flow_and_slope(A, P_1, P_2, gas: Gas = Gas()):
    """``(signed_mass_flow, signed_mass_flow_slope)`` at once [kg/s, kg/(s Pa)]: the flow
    from side 1 into side 2 and its slope in ``P_2`` (the valve's local linearisation
    that a chamber integrates against).  On one state (floats) the flow by
    :func:`mass_flow`'s own one-branch path and the slope of only the branch taken, with
    the same operations as the two functions (the same values to the bit); on arrays,
    the two functions."""
    if not (type(A) in xp.SCALARS and type(P_1) in xp.SCALARS and type(P_2) in xp.SCALARS):
        return signed_mass_flow(A, P_1, P_2, gas), signed_mass_flow_slope(A, P_1, P_2, gas)
    forward = P_1 >= P_2
    P_u, P_d = (P_1, P_2) if forward else (P_2, P_1)
    m = mass_flow(A, P_u, P_d, gas)
    P_cr, C, _, laminar_slope = _constants(*gas)
    r = xp.clip(P_d / P_u, 0.0, 1.0)
    if not r >= P_cr:
        slope_d = A * 0.0
    elif r > R_LAMINAR:
        slope_d = A * -laminar_slope
    else:
        slope_d = A * _subsonic_slope(r, gas.k, C, _subsonic_root(r, gas.k))
    if forward:
        return m, slope_d
    return -m, -(m / P_u - slope_d * P_d / P_u)


__all__ = ["critical_pressure_ratio", "R_LAMINAR", "mass_flow", "mass_flow_slope", "flow_at", "signed_mass_flow",
           "signed_mass_flow_slope", "signed_mass_flow_and_slope"]
