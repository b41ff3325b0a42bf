"""Parameter groups of the boom model, with the reference rig's values as defaults.

Plain named tuples: cheap to pass into the per-step physics, easy to build from an
FMU's parameters once at initialisation, and each with a ``check_*`` function that
names the offending field.  Units are SI throughout; pressures are absolute.
"""
from __future__ import annotations

from typing import NamedTuple

from . import reference_rig
from .validation import (ParameterError, require_finite, require_non_negative,
                         require_positive)


#: The longest stroke the model accepts [m]: its scope, DSNU-class cylinders of a
#: mini-scale machine (the reference rig's 0.060 m, the whole excavator's 0.050 to
#: 0.080 m in ``excavator.md``) with room to spare.  Every piston position is bounded by
#: it, since x <= L <= L_MAX, and a stroke-end cushion by half of it.
L_MAX = 0.5


class Gas(NamedTuple):
    """Thermodynamic constants of the air (Eq. 1, 4 to 7)."""
    k: float = reference_rig.k      #: ratio of specific heats [1]
    R: float = reference_rig.R      #: specific gas constant [J/(kg K)]
    T: float = reference_rig.T      #: temperature [K]


class Valve(NamedTuple):
    """The proportional valve (Eq. 1 and the reference rig's A(u) and routing)."""
    A_max: float = reference_rig.A_max        #: orifice area at full opening [m^2]
    P_s: float = reference_rig.P_s            #: supply pressure, absolute [Pa]
    P_e: float = reference_rig.P_e            #: exhaust pressure, absolute [Pa]
    u_centre: float = reference_rig.u_centre  #: command that closes every port [V]
    u_span: float = 5.0             #: command offset from centre for full opening [V]


class Cylinder(NamedTuple):
    """The double-acting cylinder (Eq. 6, 7)."""
    A_a: float = reference_rig.A_a    #: cap-side piston area [m^2]
    A_b: float = reference_rig.A_b    #: rod-side annulus area [m^2]
    L: float = reference_rig.L        #: stroke [m]
    V_a0: float = reference_rig.V_a0  #: dead volume of chamber A [m^3]
    V_b0: float = reference_rig.V_b0  #: dead volume of chamber B [m^3]


class Geometry(NamedTuple):
    """Boom linkage of Eq. 10 to 12 [m]."""
    a: float = reference_rig.a
    b: float = reference_rig.b
    h: float = reference_rig.h
    l_min: float = reference_rig.l_min


class Load(NamedTuple):
    """Boom load and friction of Eq. 8, 9."""
    K_v: float = reference_rig.K_v  #: viscous friction coefficient [N s/m]
    F_s: float = reference_rig.F_s  #: static friction force [N]
    F_d: float = reference_rig.F_d  #: Coulomb friction force [N]
    F_L: float = reference_rig.F_L  #: load force from the backhoe's weight [N]
    M: float = reference_rig.M      #: moving mass reduced to the piston [kg]


def check_gas(gas: Gas) -> None:
    """Raise :class:`ParameterError` unless k > 1, R > 0 and T > 0."""
    require_finite("k", gas.k)
    if gas.k <= 1.0:
        raise ParameterError("k", gas.k, "the ratio of specific heats must be > 1")
    require_positive("R", gas.R)
    require_positive("T", gas.T)


def check_valve(valve: Valve) -> None:
    """Raise unless A_max >= 0, P_s > P_e > 0 and u_span > 0."""
    require_non_negative("A_max", valve.A_max)
    require_positive("P_s", valve.P_s)
    require_positive("P_e", valve.P_e)
    if not valve.P_s > valve.P_e:
        raise ParameterError("P_s", valve.P_s, f"the supply must be above the exhaust pressure P_e = {valve.P_e:g} Pa")
    require_finite("u_centre", valve.u_centre)
    require_positive("u_span", valve.u_span)


def check_cylinder(cyl: Cylinder) -> None:
    """Raise unless every area, the stroke and both dead volumes are > 0."""
    for name in Cylinder._fields:
        require_positive(name, getattr(cyl, name))


def check_load(load: Load) -> None:
    """Raise unless M > 0 and the friction and load forces are >= 0."""
    require_positive("M", load.M)
    require_non_negative("K_v", load.K_v)
    require_non_negative("F_s", load.F_s)
    require_non_negative("F_d", load.F_d)
    require_finite("F_L", load.F_L)


def channel(quantity: str, joint: str, n: int) -> str:
    """The name of joint ``joint``'s ``quantity`` (``p_a``, ``x``, ``u``, ``angle``,
    ``K_v`` ...) in a machine of ``n`` joints, the one naming rule of recordings, FMU
    variables and parameters: one joint (the boom rig) carries no suffix and calls its
    angle ``alpha`` (Eq. 12); more joints suffix ``_<joint>`` (``p_a_arm``,
    ``angle_arm``, ``K_v_arm``)."""
    if n == 1:
        return "alpha" if quantity == "angle" else quantity
    return f"{quantity}_{joint}"


__all__ = ["L_MAX", "Gas", "Valve", "Cylinder", "Geometry", "Load", "check_gas", "check_valve", "check_cylinder",
           "check_load", "channel"]
