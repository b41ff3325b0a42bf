"""Chamber thermodynamics of the cylinder (the paper's Eq. 2 to 7).

Each chamber's air follows the isentropic energy balance of Eq. 4,
``k R T mdot = k P dV/dt + V dP/dt``, with the volumes of Eq. 6.
"""
from __future__ import annotations

import math

from .params import Cylinder, Gas


def chamber_volumes(x, cyl: Cylinder = Cylinder()):
    """Chamber volumes ``(V_a, V_b)`` [m^3] at piston position ``x`` [m] (Eq. 6)."""
    return cyl.A_a * x + cyl.V_a0, cyl.A_b * (cyl.L - x) + cyl.V_b0


def pressure_rates(p_a, p_b, mdot_a, mdot_b, x, v, cyl: Cylinder = Cylinder(),
                   gas: Gas = Gas(), cut=(0.0, 0.0)):
    """Chamber pressure rates ``(dp_a/dt, dp_b/dt)`` [Pa/s] (Eq. 7).

    ``p_a``, ``p_b`` absolute [Pa]; ``mdot_a``, ``mdot_b`` into each chamber [kg/s];
    piston position ``x`` [m] and velocity ``v`` [m/s], positive extending.  ``cut``:
    the volumes [m^3] cut off each chamber's dead volume (an end cushion's port,
    ``effects.cushion_port_cut``), whose change separates air and compresses none.
    """
    k, R, T = gas
    V_a, V_b = chamber_volumes(x, cyl)
    V_a, V_b = V_a - cut[0], V_b - cut[1]
    dp_a = (k * R * T * mdot_a - k * p_a * cyl.A_a * v) / V_a
    dp_b = (k * R * T * mdot_b + k * p_b * cyl.A_b * v) / V_b
    return dp_a, dp_b


def chamber_inflows(p_a, p_b, dp_a, dp_b, x, v, cyl: Cylinder = Cylinder(), gas: Gas = Gas()):
    """Eq. 7 solved for the flows: the mass flows into chambers A and B [kg/s] that the
    pressures ``p_a``, ``p_b`` [Pa], their rates ``dp_a``, ``dp_b`` [Pa/s] and the
    piston's ``x`` [m], ``v`` [m/s] imply."""
    k, R, T = gas
    V_a, V_b = chamber_volumes(x, cyl)
    return ((V_a * dp_a + k * p_a * cyl.A_a * v) / (k * R * T),
            (V_b * dp_b - k * p_b * cyl.A_b * v) / (k * R * T))


def _mean_power(V_0: float, V_1: float, exponent: float) -> float:
    """Mean of V^exponent over a linear ramp from V_0 to V_1, divided by V_0^exponent.

    Equals ((V_1/V_0)^(e+1) - 1) / ((e+1) (V_1/V_0 - 1)), evaluated without
    cancellation when V_1 is close to V_0.
    """
    d = V_1 / V_0 - 1.0
    n = exponent + 1.0
    if abs(d) < 1e-6:
        return 1.0 + 0.5 * exponent * d + exponent * (exponent - 1.0) / 6.0 * d * d
    return math.expm1(n * math.log1p(d)) / (n * d)


def chamber_pressure_step(P_0: float, V_0: float, V_1: float, mdot: float, dt: float,
                          gas: Gas = Gas(), dmdot_dP: float = 0.0) -> float:
    """Exact chamber pressure [Pa] after ``dt`` [s] of constant inflow ``mdot`` [kg/s]
    while the volume moves linearly from ``V_0`` to ``V_1`` [m^3].

    Integrating Eq. 4 gives ``d(P V^k)/dt = k R T mdot V^(k-1)``, so::

        P_1 V_1^k = P_0 V_0^k + k R T mdot * integral of V^(k-1) dt

    This is exact for held inputs, so it is stable for any step, and a closed chamber
    (``mdot = 0``) keeps ``P V^k`` constant to rounding.

    With ``dmdot_dP`` [kg/(s Pa)] (<= 0), the inflow is the valve's linearisation
    ``mdot + dmdot_dP (P - P_0)`` instead: Eq. 4 is then linear in ``y = P V^k``,
    ``dy/dt = k R T V^(k-1) (mdot - dmdot_dP P_0) + (k R T dmdot_dP / V) y``, and is
    solved by an exponential integrator over four substeps (volume frozen at each
    substep's midpoint).  It stays stable for any step however fast the chamber's own
    time constant, which explicit coupling of valve and cylinder does not.
    """
    k, R, T = gas
    if dmdot_dP == 0.0:
        integral = dt * V_0 ** (k - 1.0) * _mean_power(V_0, V_1, k - 1.0)
        return (P_0 * V_0**k + k * R * T * mdot * integral) / V_1**k
    h = dt / _SUBSTEPS
    kRT = k * R * T
    kRT_slope, dV, k1 = kRT * dmdot_dP, V_1 - V_0, k - 1.0
    source = mdot - dmdot_dP * P_0
    y = P_0 * V_0**k
    for middle in _MIDDLES:             # (the hot loop: what does not change is computed once)
        V = V_0 + dV * middle / _SUBSTEPS
        z = kRT_slope / V * h
        e = math.exp(z)
        phi1 = math.expm1(z) / z if abs(z) > 1e-8 else 1.0 + 0.5 * z
        y = e * y + h * phi1 * kRT * V ** k1 * source
    return y / V_1**k


#: chamber_pressure_step's substeps with a valve's slope, and their middles (in substeps)
_SUBSTEPS = 4
_MIDDLES = tuple(i + 0.5 for i in range(_SUBSTEPS))


__all__ = ["chamber_volumes", "pressure_rates", "chamber_inflows", "chamber_pressure_step"]
