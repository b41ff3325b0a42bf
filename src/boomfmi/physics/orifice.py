"""Compressible mass flow through an orifice (the paper's Eq. 1, standard form).

The paper prints Eq. 1 with 2/(k-1) outside the square root and the choked exponent
(k+1)/(k-1); both are errata (``docs/paper-errata.md``).  The standard form is::

    r = P_d / P_u
    r >= P_cr:  mdot = A P_u sqrt(2k / (R T (k-1))) sqrt(r^(2/k) - r^((k+1)/k))
    r <  P_cr:  mdot = A P_u sqrt(k / (R T)) (2/(k+1))^((k+1)/(2(k-1)))

which is continuous at r = P_cr = (2/(k+1))^(k/(k-1)).
"""
from __future__ import annotations

from . import _xp as xp
from .params import Gas


def critical_pressure_ratio(k: float) -> float:
    """P_cr = (2/(k+1))^(k/(k-1)) [1]; 0.5283 for k = 1.4 (the paper prints 0.582)."""
    return (2.0 / (k + 1.0)) ** (k / (k - 1.0))


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
    k, R, T = gas
    P_cr = critical_pressure_ratio(k)
    r = xp.clip(P_d / P_u, 0.0, 1.0)
    subsonic = (2.0 * k / (R * T * (k - 1.0))) ** 0.5 * xp.sqrt(
        xp.maximum(r ** (2.0 / k) - r ** ((k + 1.0) / k), 0.0))
    choked = (k / (R * T)) ** 0.5 * (2.0 / (k + 1.0)) ** ((k + 1.0) / (2.0 * (k - 1.0)))
    return A * P_u * xp.where(r >= P_cr, subsonic, choked)


def signed_mass_flow(A, P_1, P_2, gas: Gas = Gas()):
    """Mass flow [kg/s] from side 1 to side 2, negative where it runs from 2 to 1.

    ``P_1``, ``P_2`` are absolute pressures [Pa]; the upstream side is whichever is
    higher.
    """
    forward = P_1 >= P_2
    P_u = xp.where(forward, P_1, P_2)
    P_d = xp.where(forward, P_2, P_1)
    return xp.where(forward, 1.0, -1.0) * mass_flow(A, P_u, P_d, gas)
