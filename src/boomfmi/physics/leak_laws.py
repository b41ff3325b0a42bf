"""Leak-down of a closed chamber (SI units, pressures absolute).

A leak-down test charges a chamber of volume ``V``, closes it, and records how its
pressure ``p`` falls.  The air's mass ``m`` leaves through the leak, and its temperature
``T`` is not the ambient ``T_amb`` at first: charging heats the air (compression), and
it cools back with a time constant ``tau``, so the first seconds' pressure drop is
cooling, not leaking.  With the full energy balance of a rigid chamber whose air leaves
at its own temperature (as ``effects.outflow_temperature_rate``)::

    dm/dt = -mdot(p, T)
    dT/dt = (k - 1) T (dm/dt) / m + (T_amb - T) / tau
    p     = m R T / V

the first term being the remaining air's isentropic expansion.  ``tau -> 0`` is the
isothermal leak-down.  Two leak laws:

- laminar (a long narrow gap): ``mdot = C (p - P_atm)`` with conductance ``C``
  [kg/(s Pa)] (``effects.leakage_flow``, the model's ``piston_leakage``);
- orifice (a short hole): the compressible orifice flow of Eq. 1
  (``orifice.mass_flow``, the model's valve and ``leakage_orifice_flow``) through an
  effective area ``A`` [m^2], choked above about 0.9 bar gauge.
"""
from __future__ import annotations

from .effects import leakage_flow
from .orifice import mass_flow
from .params import Gas


def leak_flow(law: str, size: float, p: float, T: float, P_atm: float, gas: Gas = Gas()):
    """Mass flow [kg/s] out of a chamber at absolute pressure ``p`` [Pa] and temperature
    ``T`` [K] through a leak of ``size`` (a conductance C [kg/(s Pa)] for ``law =
    "laminar"``, an effective area A [m^2] for ``"orifice"``) into ``P_atm`` [Pa]; none
    where ``p <= P_atm`` for the orifice (the chamber does not refill)."""
    if law == "laminar":
        return leakage_flow(p, P_atm, size)
    if law == "orifice":
        if p <= P_atm:
            return 0.0
        return float(mass_flow(size, p, P_atm, Gas(gas.k, gas.R, T)))
    raise ValueError(f"unknown leak law {law!r}: laminar or orifice")


def leakdown_rates(m: float, T: float, mdot: float, tau: float, T_amb: float, k: float):
    """``(dm/dt, dT/dt)`` of a closed chamber's air, mass ``m`` [kg] at ``T`` [K],
    losing ``mdot`` [kg/s]: isentropic expansion of the air left and heat exchange with
    the wall at ``T_amb`` [K] with time constant ``tau`` [s] (``tau <= 0``: isothermal,
    dT/dt = 0 with T held at T_amb by the caller)."""
    dm = -mdot
    if tau <= 0.0:
        return dm, 0.0
    return dm, (k - 1.0) * T * dm / m + (T_amb - T) / tau


def chamber_pressure(m, T, V: float, R: float):
    """Absolute pressure [Pa] of air mass ``m`` [kg] at ``T`` [K] in ``V`` [m^3]."""
    return m * R * T / V


def air_mass(p, T, V: float, R: float):
    """Air mass [kg] at absolute pressure ``p`` [Pa] and ``T`` [K] in ``V`` [m^3]."""
    return p * V / (R * T)


__all__ = ["leak_flow", "leakdown_rates", "chamber_pressure", "air_mass"]
