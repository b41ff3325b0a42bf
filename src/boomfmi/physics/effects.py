"""Candidate forms of the unmodelled effects (``shared/spec/effects.md``), for diagnosis.

Each is the simplest physical form of its mechanism with one or two parameters, meant
to be fitted to recordings and switched on as an option of the FMU it belongs to.
Which effect each function serves, its parameters, their units and bounds, and the FMU
option that switches it on are listed once, in the catalogue
(``boomfmi/model/catalogue.py``); the assembled model (``boomfmi/model/boom.py``) calls
these functions.  They differ on purpose from the virtual rig's forms
(``boomfmi/rig/truth.py``): a diagnosis that only recognised its own simulator would be
worth nothing on a real machine.
"""
from __future__ import annotations

import math

import numpy as np

from . import _xp as xp
from .lag import first_order_step
from .orifice import signed_mass_flow, signed_mass_flow_and_slope, signed_mass_flow_slope
from .params import Cylinder, Gas, Load
from .validation import ParameterError


def spool_lag_step(y: float, u: float, dt: float, tau: float, rate: float = 0.0) -> float:
    """The spool's position [V] after ``dt`` [s] of command ``u`` [V], first-order with
    time constant ``tau`` [s]; where ``rate`` [V/s] > 0 its speed is limited to it
    (the pilot stage's flow limits how fast the spool can travel: a slew-rate limit),
    ``dy/dt = clip((u - y) / tau, -rate, rate)`` (:func:`spool_rate`).  Exact for a held
    command: the spool travels at ``rate`` until it is within ``rate tau`` of ``u``, then
    approaches it exponentially.  ``tau <= 0`` follows u."""
    e = u - y
    knee = rate * tau
    if rate <= 0.0 or tau <= 0.0 or abs(e) <= knee:
        return first_order_step(y, u, dt, tau)
    sign = math.copysign(1.0, e)
    t_slew = (abs(e) - knee) / rate            # [s] until the lag takes over
    if dt <= t_slew:
        return y + sign * rate * dt
    return first_order_step(u - sign * knee, u, dt - t_slew, tau)


def spool_rate(y: float, u: float, tau: float, rate: float = 0.0) -> float:
    """The spool's speed [V/s] at position ``y`` [V] under command ``u`` [V]:
    ``(u - y) / tau``, limited to +-``rate`` where ``rate`` > 0 (see :func:`spool_lag_step`)."""
    r = (u - y) / tau
    return min(max(r, -rate), rate) if rate > 0.0 else r


def deadband_command(u: float, width: float, u_centre: float = 5.0, u_span: float = 5.0,
                     width_ext: float | None = None, width_ret: float | None = None,
                     edge: float = 0.0) -> float:
    """The command the orifice sees with a dead band of half-width ``width`` [V] around
    the centre: nothing opens within it, and beyond it the opening is linear again,
    reaching full opening at the ends of the range.  A valve's band is often not
    centred (the spool's overlap differs on its two lands, or the valve's zero has
    drifted): ``width_ext`` [V] is the band's width below the centre (commands that
    extend), ``width_ret`` above it (that retract), each in place of ``width`` where
    given and > 0.  Worn or rounded lands open gradually: with ``edge`` [V] > 0 the
    excess over the band, ``z = |u - centre| - w``, opens as the hyperbola
    ``(z + sqrt(z^2 + edge^2)) / 2`` (closed far inside, linear far outside), less its
    value at the centre and rescaled to full opening at the range's end."""
    d = u - u_centre
    side = width_ext if d < 0.0 else width_ret
    w = side if side is not None and side > 0.0 else width
    if w <= 0.0:
        return u
    if edge <= 0.0:
        mag = max(abs(d) - w, 0.0) * u_span / (u_span - w)
    else:
        ramp = lambda z: 0.5 * (z + math.sqrt(z * z + edge * edge))
        closed = ramp(-w)
        mag = (ramp(abs(d) - w) - closed) * u_span / (ramp(u_span - w) - closed)
    return u_centre + math.copysign(mag, d)


def thermal_relaxation_step(p: float, m: float, V: float, dt: float, tau: float,
                            R: float, T_wall: float) -> float:
    """The chamber pressure [Pa] after ``dt`` [s] of relaxation towards the isothermal
    pressure ``m R T_wall / V`` of its air mass ``m`` [kg] in volume ``V`` [m^3], with
    time constant ``tau`` [s]: the wall takes back the heat of compression (and gives
    it to expanding air).  ``tau <= 0`` leaves p alone."""
    if not 0.0 < tau < math.inf:
        return p
    p_iso = m * R * T_wall / V
    return p_iso + (p - p_iso) * math.exp(-dt / tau)


def thermal_relaxation_rate(p: float, m: float, V: float, tau: float, R: float, T_wall: float) -> float:
    """d/dt of a chamber's pressure [Pa/s] from its heat exchange with the wall: the
    pressure ``p`` [Pa] relaxes towards the isothermal ``m R T_wall / V`` of its air mass
    ``m`` [kg] in volume ``V`` [m^3] with time constant ``tau`` [s] (the rate form of
    :func:`thermal_relaxation_step`, for an ODE solver)."""
    return (m * R * T_wall / V - p) / tau


def outflow_temperature_rate(p: float, m: float, V: float, mdot: float, k: float, R: float, T: float) -> float:
    """The correction to d/dt of a chamber's pressure [Pa/s] where its air, tracked as
    mass ``m`` [kg] at pressure ``p`` [Pa] in volume ``V`` [m^3] (so at temperature
    ``T_c = p V / (m R)``), leaves at its own temperature rather than at the reference
    ``T`` [K] Eq. 4 assumes: ``k R mdot (T_c - T) / V`` for an outflow (``mdot`` < 0
    [kg/s]), 0 for an inflow (air enters at the supply's T).  With it the chamber's
    energy balance is the full one (Richer and Hurmuzlu 2000, Eq. 10), heat exchange
    with the wall included."""
    if mdot >= 0.0 or m <= 0.0:
        return 0.0
    return k * R * mdot * (p * V / (m * R) - T) / V


def chamber_wall_area(V: float, A_piston: float, bore: float) -> float:
    """The wall [m^2] a chamber's air of volume ``V`` [m^3] touches: the two end faces
    ``2 A_piston`` and the barrel over the chamber's equivalent length ``V / A_piston``
    (dead volume included)."""
    return 2.0 * A_piston + math.pi * bore * V / A_piston


def thermal_time_constant(m: float, wall_area: float, h: float, k: float, R: float) -> float:
    """Time constant [s] of a chamber's heat exchange with its wall: ``m c_v / (h A)``,
    air mass ``m`` [kg], wall ``A`` [m^2], coefficient ``h`` [W/(m^2 K)],
    ``c_v = R / (k - 1)``; infinite for h = 0."""
    if h <= 0.0:
        return math.inf
    return m * R / (k - 1.0) / (h * wall_area)


def leakage_flow(p_a: float, p_b: float, C: float) -> float:
    """Laminar leakage across the piston seal [kg/s], from A to B (negative B to A):
    ``C (p_a - p_b)`` with conductance ``C`` [kg/(s Pa)]."""
    return C * (p_a - p_b)


def leakage_orifice_flow(p_a: float, p_b: float, A: float, gas: Gas = Gas()) -> float:
    """Turbulent leakage across the piston seal [kg/s], from A to B (negative B to A):
    a gap of effective area ``A`` [m^2] passing the orifice law (Eq. 1, choked or not)
    from the higher chamber pressure to the lower; ``A <= 0``: none."""
    if A <= 0.0:
        return 0.0
    return float(signed_mass_flow(A, p_a, p_b, gas))


def leakage_orifice_flow_and_slopes(p_a: float, p_b: float, A: float, gas: Gas = Gas()) -> tuple[float, float, float]:
    """:func:`leakage_orifice_flow` and its slopes: ``(leak A to B [kg/s], d/dp_a of A's
    inflow, d/dp_b of B's [kg/(s Pa)])``, both slopes <= 0 (what the exponential
    integrator needs), each orifice evaluated once (``orifice.signed_mass_flow_and_slope``)."""
    if A <= 0.0:
        return 0.0, 0.0, 0.0
    leak, g_b = signed_mass_flow_and_slope(A, p_a, p_b, gas)
    _, g_a = signed_mass_flow_and_slope(A, p_b, p_a, gas)
    return float(leak), float(g_a), float(g_b)


def stribeck_weight(v, v_s: float):
    """The static level's share w of the Stribeck friction at speed ``v`` [m/s] (float
    or array): the Coulomb level is ``F_d (1 - w) + F_s w``, ``w = exp(-|v| / v_s)``."""
    return xp.exp(-xp.abs_(v) / v_s)


def stribeck_level(v, F_d, F_s, v_s: float):
    """The sliding level [N] at speed ``v`` [m/s] on the Stribeck curve from the static
    level ``F_s`` at rest to the Coulomb level ``F_d`` [N]: ``F_d + (F_s - F_d)
    exp(-|v| / v_s)`` (:func:`stribeck_weight`), ``v_s`` [m/s] > 0; floats or arrays."""
    return F_d + (F_s - F_d) * stribeck_weight(v, v_s)


def stribeck_load(load: Load, v: float, v_s: float) -> Load:
    """The load with its Coulomb level at speed ``v`` [m/s] on the Stribeck curve
    (:func:`stribeck_level`); ``v_s <= 0`` leaves the paper's step."""
    if v_s <= 0.0:
        return load
    K_v, F_s, F_d, F_L, M = load            # (built directly: namedtuple._replace costs 3 times as much)
    return Load(K_v, F_s, stribeck_level(v, F_d, F_s, v_s), F_L, M)


def seal_pressure(p_a, p_b, P_atm: float, form: str = "sum"):
    """The pressure [Pa] that presses the seals against barrel and rod
    (pressure_friction; floats or arrays of absolute pressures [Pa]):

    * ``"sum"``: the chambers' summed gauge pressure ``(p_a - P_atm) + (p_b - P_atm)``
      (a chamber below the atmosphere counting 0), each seal lip pressed by the
      chamber it holds (the law the real friction tests
      chose, ``docs/real-data.md``: one chamber charged, the Coulomb and static levels
      growing linearly with its gauge pressure, alike in both directions);
    * ``"max"``: the higher chamber's gauge pressure ``max(p_a, p_b) - P_atm``, one
      double-acting seal pressed by the side that loads it;
    * ``"diff"``: the pressure difference across the piston ``|p_a - p_b|``, a seal
      pressed by the net force on it.

    With one chamber at the atmosphere the three agree, which is all a single-chamber
    friction test can show; recordings of the boom, where both chambers are charged,
    tell them apart."""
    if form == "sum":
        return xp.maximum(p_a - P_atm, 0.0) + xp.maximum(p_b - P_atm, 0.0)
    if form == "max":
        return xp.maximum(xp.maximum(p_a, p_b) - P_atm, 0.0)
    if form == "diff":
        return xp.abs_(p_a - p_b)
    raise ValueError(f"seal_pressure: unknown form {form!r} (sum, max or diff)")


def pressure_friction_load(load: Load, p_a: float, p_b: float, P_atm: float, c_sum: float = 0.0,
                           c_max: float = 0.0, c_diff: float = 0.0) -> Load:
    """The load with its static and Coulomb levels raised by the seals' pressure
    (pressure_friction, the real data's law, ``docs/real-data.md``)::

        F_s(p) = F_s + c_sum p_sum + c_max p_max + c_diff |p_a - p_b|
        F_d(p) = F_d + c_sum p_sum + c_max p_max + c_diff |p_a - p_b|
        p_sum = (p_a - P_atm)+ + (p_b - P_atm)+,   p_max = (max(p_a, p_b) - P_atm)+

    ``c_sum``, ``c_max``, ``c_diff`` [N/Pa] >= 0 (an effective contact area times a friction
    coefficient; the real seals of 25 mm bore: 0.2 to 1.7 N/bar, 2e-6 to 1.7e-5 N/Pa);
    the paper's Eq. 9 otherwise unchanged (the levels times cos(phi)); see
    :func:`seal_pressure`."""
    dF = 0.0
    if c_sum > 0.0:
        dF += c_sum * seal_pressure(p_a, p_b, P_atm, "sum")
    if c_max > 0.0:
        dF += c_max * seal_pressure(p_a, p_b, P_atm, "max")
    if c_diff > 0.0:
        dF += c_diff * seal_pressure(p_a, p_b, P_atm, "diff")
    if dF == 0.0:
        return load
    K_v, F_s, F_d, F_L, M = load
    return Load(K_v, F_s + dF, F_d + dF, F_L, M)


def _cushion(mdot: float, p: float, distance: float, length: float, A_n: float, P_e: float,
             gas: Gas, P_s: float = 0.0, A_c: float = 0.0):
    """The spear's engagement g [1] and the restriction's flow into the chamber [kg/s] and
    its slope in ``p`` [kg/(s Pa)], where the cushion acts on ``mdot``; else None.  An
    outflow passes the needle ``A_n`` to the exhaust ``P_e``; an inflow passes freely, or
    (``A_c`` > 0) the needle and the check valve's ``A_c`` side by side from the supply
    ``P_s``."""
    if mdot < 0.0:
        A, P_up = A_n, P_e
    elif mdot > 0.0 and A_c > 0.0:
        A, P_up = A_n + A_c, P_s
    else:
        return None
    engaged = cushion_engagement(distance, length)
    if engaged <= 0.0:
        return None
    return engaged, signed_mass_flow(A, P_up, p, gas), signed_mass_flow_slope(A, P_up, p, gas)


def cushion_engagement(distance, length: float):
    """How far the cushion spear has entered its bore [1]: 0 at ``distance`` [m] from
    the chamber's end of stroke at or beyond ``length`` [m], rising linearly to 1 over
    the first fifth of ``length`` (the spear's chamfer), 1 closer to the end.
    ``length <= 0``: 0 (no cushion).  ``distance`` may be an array."""
    if length <= 0.0:
        return np.zeros_like(distance) if isinstance(distance, np.ndarray) else 0.0
    return np.clip((length - np.maximum(distance, 0.0)) / (0.2 * length), 0.0, 1.0) \
        if isinstance(distance, np.ndarray) else min(1.0, max(0.0, (length - max(distance, 0.0)) / (0.2 * length)))


def cushion_engagement_slope(distance: float, length: float) -> float:
    """d(:func:`cushion_engagement`)/d(distance) [1/m]: ``-1 / (0.2 length)`` on the
    spear's chamfer, else 0."""
    if length <= 0.0 or not 0.8 * length < distance < length:
        return 0.0
    return -1.0 / (0.2 * length)


def check_cushion_port(V_p: float, cyl: Cylinder, name: str = "V_p") -> None:
    """Raise :class:`ParameterError` (naming ``name``) unless the cushion's port volume
    ``V_p`` [m^3], part of each chamber's dead volume, is smaller than both."""
    if V_p >= min(cyl.V_a0, cyl.V_b0):
        raise ParameterError(name, V_p, f"the cushion's port is part of the dead volume: it must be smaller "
                                        f"than V_a0 and V_b0 ({cyl.V_a0:g}, {cyl.V_b0:g} m^3)")


def cushion_port_cut(distance, length: float, V_p: float):
    """The volume [m^3] a cushion cuts off a chamber's dead volume at ``distance`` [m]
    from its end of stroke: its port ``V_p`` [m^3] (the bore between the spear and the
    valve, part of the dead volume V_0 of Eq. 6) times the spear's engagement
    (:func:`cushion_engagement`).  Within the cushion the chamber, which the pressure
    sensor reads, is left with ``A x + V_0 - V_p``: it is stiffer, and the port's air
    reaches the valve without passing the needle (its pressure follows the valve's
    quasi-statically: the series restriction of :func:`cushion_flow`).  The cut
    separates air, it does not compress it: the chamber's pressure is continuous as the
    spear enters, and only its air's volume and mass are smaller.  ``V_p <= 0``: 0."""
    if V_p <= 0.0:
        return 0.0 * distance
    return V_p * cushion_engagement(distance, length)


def cushion_flow(mdot: float, p: float, distance: float, length: float, A_n: float,
                 P_e: float, gas: Gas = Gas(), P_s: float = 0.0, A_c: float = 0.0) -> float:
    """End-of-stroke cushioning: a chamber's mass flow [kg/s] once the cushion acts on
    the flow ``mdot`` [kg/s] the valve alone passes, the chamber at pressure ``p`` [Pa,
    absolute] and the piston ``distance`` [m] from that chamber's end of stroke.

    Within ``length`` [m] of the end the cushion spear closes the main exhaust and an
    outflow (``mdot < 0``) must also pass the cushion needle, an orifice of area ``A_n``
    [m^2] to the exhaust pressure ``P_e`` [Pa]; two restrictions in series pass
    ``1/mdot^2 = 1/mdot_v^2 + g/mdot_n^2``, the spear's engagement ``g`` rising from 0
    to 1 over the first fifth of ``length`` (so the flow is continuous in the position).
    Inflow passes the cushion's check valve freely; or, with ``A_c`` [m^2] > 0, a check
    valve of that area beside the needle (a small one, or none at all: the needle alone,
    and leaving the end is slowed too), the two in series with the valve from the supply
    ``P_s`` [Pa] alike.  ``length <= 0``: off."""
    c = _cushion(mdot, p, distance, length, A_n, P_e, gas, P_s, A_c)
    if c is None:
        return mdot
    g, n, _ = c
    if n * mdot <= 0.0:                 # no pressure left to push air through the restriction
        return 0.0
    return mdot / math.sqrt(1.0 + g * (mdot / n) ** 2)


def cushion_flow_slope(mdot: float, slope: float, p: float, distance: float, length: float,
                       A_n: float, P_e: float, gas: Gas = Gas(), P_s: float = 0.0, A_c: float = 0.0) -> float:
    """The slope [kg/(s Pa)] of :func:`cushion_flow` with respect to ``p``, given the
    valve's flow ``mdot`` and its slope ``slope``: with ``r = mdot / mdot_n`` and
    ``D = 1 + g r^2``, ``(slope + g r^3 dmdot_n/dp) / D^(3/2)``."""
    c = _cushion(mdot, p, distance, length, A_n, P_e, gas, P_s, A_c)
    if c is None:
        return slope
    g, n, s_n = c
    if n * mdot <= 0.0:
        return 0.0
    r = mdot / n
    return (slope + g * r ** 3 * s_n) / (1.0 + g * r * r) ** 1.5


def sensor_lag_step(measured: float, true: float, dt: float, tau: float) -> float:
    """A sensor channel after ``dt`` [s]: first-order towards the true value with time
    constant ``tau`` [s]; ``tau <= 0`` reads the true value."""
    return first_order_step(measured, true, dt, tau)

__all__ = [
    "spool_lag_step", "spool_rate", "deadband_command", "thermal_relaxation_step", "thermal_relaxation_rate",
    "outflow_temperature_rate", "chamber_wall_area", "thermal_time_constant", "leakage_flow",
    "leakage_orifice_flow", "leakage_orifice_flow_and_slopes", "stribeck_weight", "stribeck_level",
    "stribeck_load", "seal_pressure", "pressure_friction_load", "cushion_engagement",
    "cushion_engagement_slope", "check_cushion_port", "cushion_port_cut", "cushion_flow",
    "cushion_flow_slope", "sensor_lag_step",
]
