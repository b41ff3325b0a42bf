"""The virtual rig's unmodelled effects: what the "real" machine does beyond the paper.

The virtual rig (``boomfmi.rig``) simulates the paper's model (Eq. 1 to 12, through
``boomfmi.physics``) plus the effects named in ``shared/spec/effects.md``, each
switchable.  The forms here are deliberately *not* the simple candidate forms a
diagnosis would try first (first-order spool lag, a sharp deadband, a polytropic
exponent, a laminar leak conductance, an exponential Stribeck curve, a first-order
sensor lag): the rig must not be a perfect-model test for the diagnosis.  Every form
is physically plausible, has one to three parameters, and is written here once as
plain functions on Python floats (``math`` only), SI units throughout, pressures
absolute unless said otherwise.

``valve_dynamics``: the spool is a second-order system between the command u [V] and
the spool position y [V-equivalent: the command that would give the same opening]::

    y'' + 2 zeta w y' + w^2 y = w^2 u,   w = 2 pi f_n

    f_n   natural frequency [Hz]   default 100   range 60 to 150
    zeta  damping ratio [1]        default 0.7   range 0.5 to 0.9

integrated exactly over each substep with u held (:func:`spool_transition`,
:func:`spool_step`).  The orifice area *and* the port routing follow y, not u: a step
across 5 V passes through the closed centre.

``valve_deadband``: spool overlap with a smooth edge.  With e = |y - 5 V| the
effective opening e' [V] is zero below d - w, the linear e - d above d + w, and the
C1 quadratic (e - d + w)^2 / (4 w) between; it is rescaled so that the full command
still gives A_max, ``u_eq = 5 +- 5 min(e' / (5 - d), 1)``, which then goes through the
paper's ``orifice_area`` (:func:`overlap_command`)::

    overlap  d, half-width of the dead band [V]   default 0.4    range 0.2 to 0.6
    edge     w, half-width of the rounded edge [V] default 0.15  range 0.05 to 0.3

``heat_transfer``: each chamber has its own gas temperature T (a state) besides the
pressure; the mass m = P V / (R T) is tracked, and the energy balance is::

    V dP/dt + k P dV/dt = k R sum(mdot_i T_i) + (k - 1) Q,
    Q = h_w A_wall(x) (T_wall - T)

where ``T_i`` is the temperature of the air that a flow carries (the supply air at
T_s entering, the chamber's own T leaving, the upstream chamber's for the leak), and
the orifice flows use the upstream temperature (mdot ~ 1/sqrt(T_u)).  T_wall is the
reference T (293.15 K).  The wall area is the dead volume's (port, hose) A_w0 plus the
two end faces plus the swept barrel (and the rod in chamber B)
(:func:`chamber_wall_areas`)::

    h_w   wall heat-transfer coefficient [W/(m^2 K)]  default 40      range 10 to 150
    A_w0  wall area of each dead volume [m^2]          default 0.01    range 0.003 to 0.03
    T_s   supply air temperature [K]                   default 293.15  range 283 to 313

The plant feeds this to the paper's ``chamber_pressure_step`` as an equivalent flow at
the reference temperature (:func:`thermal_equivalent_flow`), so the pressure update
stays the exact/exponential one; T then follows from P = m R T / V.  With the defaults
the thermal time constant m c_v / (h_w A_wall) is 0.03 to 0.5 s: after filling stops,
the hot compressed air cools and the pressure drifts down by several percent.

``piston_leakage``: a small compressible orifice across the piston seal, from the
higher to the lower chamber pressure, through the paper's own orifice law (Eq. 1,
choked and subsonic branches: a turbulent, sqrt-like leak, not a laminar conductance)
(:func:`piston_leak_flows`)::

    A_leak  effective leak area [m^2]   default 2e-8   range 1e-8 to 5e-8

``stribeck_friction``: the friction level falls from the breakaway force to the
Coulomb force F_d (the model's) along a rational curve, viscous K_v v kept::

    F_f(v) = [F_d + (F_brk - F_d) / (1 + (v / v_s)^2)] cos(phi) sign(v) + K_v v

    v_s    Stribeck velocity [m/s]          default 0.01   range 0.002 to 0.03
    F_brk  breakaway (static) force [N]     default 140    range F_d to 250

Sticking is the paper's exact rule (``physics.load.slide_or_stick``) with F_s replaced
by F_brk and the Coulomb level F_d replaced by F_f(|v|) frozen over each short substep
(:func:`breakaway_stribeck_load`).

``pressure_friction``: each seal pressed by the pressure that loads it: the piston
seal by the higher chamber's gauge pressure, the rod seal by chamber B's; the static
(or breakaway) and the Coulomb levels both rise by the seals' share
(:func:`seal_friction_load`)::

    dF = k_piston max(p_a, p_b, P_atm)_gauge + k_rod max(p_b - P_atm, 0)
    k_piston  piston seal [N/Pa]   default 2.5e-5  range 5e-6 to 6e-5
    k_rod     rod seal [N/Pa]      default 1e-5    range 0 to 3e-5

``end_cushioning``: over the last l_c of stroke at each end the exhausting chamber's
outflow must pass the cushion needle valve (area A_n) in series with the valve port
(area A_v).  Two orifices in series are combined as ``1/A^2 = 1/A_v^2 + g/A_n^2``, with
g the cushion's engagement (0 outside, 1 inside, a smoothstep over the spigot's entry
chamfer w) (:func:`cushion_engagement`, :func:`cushion_exhaust_area`); inflow passes
the cushion's check valve freely::

    l_c  cushion length [m]              default 0.012  range 0.005 to 0.015
    A_n  needle-valve area [m^2]         default 5e-8   range 2e-8 to 3e-7
    w    spigot entry chamfer [m]        default 0.001  range 0.0005 to 0.003

``sensor_lag``: the measurement path of every measured channel (p_a, p_b, alpha) is a
first-order filter and a transport delay, in series, apart from the physics
(:func:`first_order_coefficient`)::

    y(t) = z(t - delay),   tau z' + z = signal

    delay  transport delay [s]       default 0.003  range 0.001 to 0.005
    tau    filter time constant [s]  default 0.005  range 0.002 to 0.010

Contact and disturbance forces (``f_ext`` [N], positive against extension, as in
``physics.load``): :func:`spring_contact_force`, :func:`ramp_force`,
:func:`vibration_force`.  Sensors: :func:`quantise` (12-bit ADC).
"""
from __future__ import annotations

import math
from typing import Callable, NamedTuple, Optional

from ..physics import reference_rig
from ..physics.orifice import signed_mass_flow, signed_mass_flow_slope
from ..physics.params import Cylinder, Gas, Load, Valve


# --------------------------------------------------------------------------- valve
def spool_transition(f_n: float, zeta: float, h: float):
    """Transition matrix ``(a, b, c, d)`` of the spool's free response over ``h`` [s].

    For the deviation e = y - u (u held) and its rate e', the second-order spool
    ``e'' + 2 zeta w e' + w^2 e = 0`` (w = 2 pi f_n [rad/s]) gives exactly
    ``e(h) = a e + b e'`` and ``e'(h) = c e + d e'``.  Valid for any zeta > 0
    (under-, critically and over-damped).
    """
    w = 2.0 * math.pi * f_n
    s = zeta * w
    E = math.exp(-s * h)
    if abs(zeta - 1.0) < 1e-9:
        return E * (1.0 + w * h), E * h, -E * w * w * h, E * (1.0 - w * h)
    if zeta < 1.0:
        wd = w * math.sqrt(1.0 - zeta * zeta)
        C, S = math.cos(wd * h), math.sin(wd * h)
    else:
        wd = w * math.sqrt(zeta * zeta - 1.0)
        C, S = math.cosh(wd * h), math.sinh(wd * h)
    return (E * (C + s / wd * S), E * S / wd, -E * w * w / wd * S, E * (C - s / wd * S))


def spool_step(y: float, y_dot: float, u: float, transition):
    """Spool position [V] and rate [V/s] after one substep with the command ``u`` [V]
    held; ``transition`` from :func:`spool_transition` for that substep."""
    a, b, c, d = transition
    e = y - u
    return u + a * e + b * y_dot, c * e + d * y_dot


def overlap_opening(e: float, overlap: float, edge: float) -> float:
    """Effective opening [V] of a spool displaced ``e`` >= 0 [V] from centre with an
    overlap of half-width ``overlap`` [V] and a rounded edge of half-width ``edge`` [V]:
    0 below overlap - edge, e - overlap above overlap + edge, and the C1 quadratic
    (e - overlap + edge)^2 / (4 edge) between (a sharp deadband for edge = 0)."""
    lo = overlap - edge
    if e <= lo:
        return 0.0
    if e >= overlap + edge:
        return e - overlap
    r = e - lo
    return r * r / (4.0 * edge)


def overlap_command(y: float, overlap: float, edge: float, u_centre: float = 5.0,
                    u_span: float = 5.0) -> float:
    """The command [V] that gives the paper's ``orifice_area`` and routing the same
    opening as an overlapped spool at ``y`` [V]: ``u_centre +- u_span * min(e' /
    (u_span - overlap), 1)`` with e' = :func:`overlap_opening` of |y - u_centre|, the
    sign of y - u_centre (full command still opens A_max)."""
    e = y - u_centre
    if e == 0.0:
        return u_centre
    o = overlap_opening(abs(e), overlap, edge) / (u_span - overlap)
    if o > 1.0:
        o = 1.0
    return u_centre + u_span * o if e > 0.0 else u_centre - u_span * o


# ------------------------------------------------------------------- cushioning
def cushion_engagement(distance: float, l_c: float, w: float) -> float:
    """Engagement g [1] of an end cushion when the piston is ``distance`` [m] from its
    stroke end: 1 within l_c - w, 0 beyond l_c, a smoothstep s^2 (3 - 2 s) with
    s = (l_c - distance) / w over the spigot's entry chamfer ``w`` [m]."""
    if distance >= l_c:
        return 0.0
    if distance <= l_c - w:
        return 1.0
    s = (l_c - distance) / w
    return s * s * (3.0 - 2.0 * s)


def cushion_exhaust_area(A_valve: float, A_n: float, g: float) -> float:
    """Effective exhaust area [m^2] of the valve port ``A_valve`` [m^2] in series with
    the cushion needle ``A_n`` [m^2] at engagement ``g``: ``1/A^2 = 1/A_v^2 + g/A_n^2``."""
    if g <= 0.0 or A_valve <= 0.0:
        return A_valve
    q = A_valve / A_n
    return A_valve / math.sqrt(1.0 + g * q * q)


# ----------------------------------------------------------------------- leakage
def piston_leak_flows(A_leak: float, p_a: float, p_b: float, gas: Gas = Gas()):
    """Leak across the piston seal through an orifice of area ``A_leak`` [m^2]
    (the paper's Eq. 1, upstream temperature ``gas.T``).

    Returns ``(mdot_ab, dmdot_a_dp_a, dmdot_b_dp_b)``: the flow [kg/s] from chamber A
    to chamber B (negative from B to A), and the slopes [kg/(s Pa)] (<= 0) of the flow
    *into* each chamber with respect to that chamber's own pressure.
    """
    return (signed_mass_flow(A_leak, p_a, p_b, gas),
            signed_mass_flow_slope(A_leak, p_b, p_a, gas),
            signed_mass_flow_slope(A_leak, p_a, p_b, gas))


# ---------------------------------------------------------------------- friction
def stribeck_level(v: float, F_brk: float, F_c: float, v_s: float) -> float:
    """Friction level [N] at speed ``v`` [m/s] (before the cos(phi) of Eq. 9):
    ``F_c + (F_brk - F_c) / (1 + (v / v_s)^2)``, F_brk at rest, F_c fast."""
    q = v / v_s
    return F_c + (F_brk - F_c) / (1.0 + q * q)


def breakaway_stribeck_load(load: Load, v: float, F_brk: float, v_s: float) -> Load:
    """The paper's load parameters with the stick limit F_s replaced by ``F_brk`` [N]
    and the Coulomb level F_d by :func:`stribeck_level` at ``v`` [m/s] (F_d being the
    curve's fast limit): frozen over a short substep of ``advance_load``."""
    return Load(load.K_v, F_brk, stribeck_level(v, F_brk, load.F_d, v_s), load.F_L, load.M)


def seal_friction_load(load: Load, p_a: float, p_b: float, P_atm: float, k_piston: float,
                       k_rod: float) -> Load:
    """The load with its static and Coulomb levels raised by the seals' contact force:
    ``k_piston`` [N/Pa] times the higher chamber's gauge pressure (the piston seal is
    pressed by the side that loads it) plus ``k_rod`` [N/Pa] times chamber B's (the
    rod seal)."""
    hi = p_a if p_a > p_b else p_b
    dF = k_piston * max(hi - P_atm, 0.0) + k_rod * max(p_b - P_atm, 0.0)
    return Load(load.K_v, load.F_s + dF, load.F_d + dF, load.F_L, load.M)


# ------------------------------------------------------------------ heat transfer
def chamber_wall_areas(x: float, A_w0: float, cyl: Cylinder = Cylinder(),
                       bore: float = reference_rig.bore, rod: float = reference_rig.rod):
    """Wall areas [m^2] of chambers A and B at piston position ``x`` [m]: the dead
    volume's ``A_w0`` [m^2] plus both end faces plus the swept barrel (and, in B, the
    rod): ``A_w0 + 2 A_a + pi bore x`` and ``A_w0 + 2 A_b + pi (bore + rod) (L - x)``."""
    return (A_w0 + 2.0 * cyl.A_a + math.pi * bore * x,
            A_w0 + 2.0 * cyl.A_b + math.pi * (bore + rod) * (cyl.L - x))


def wall_heat_flow(h_w: float, A_wall: float, T_wall: float, T: float) -> float:
    """Heat flow [W] from the wall into the air: ``h_w A_wall (T_wall - T)``."""
    return h_w * A_wall * (T_wall - T)


def thermal_equivalent_flow(mdot_T: float, Q: float, gas: Gas = Gas()) -> float:
    """The inflow [kg/s] at the reference temperature ``gas.T`` that has the same effect
    on the chamber pressure as flows carrying ``mdot_T = sum(mdot_i T_i)`` [kg K/s] plus
    the wall heat ``Q`` [W]: ``(mdot_T + (k - 1) Q / (k R)) / T``.  Passed to
    ``chamber_pressure_step``, it integrates the non-adiabatic energy balance."""
    k, R, T = gas
    return (mdot_T + (k - 1.0) * Q / (k * R)) / T


def chamber_temperature(P: float, V: float, m: float, R: float = 287.0) -> float:
    """Gas temperature [K] of a chamber holding ``m`` [kg] at ``P`` [Pa] in ``V`` [m^3]."""
    return P * V / (m * R)


# ------------------------------------------------------------------------ sensors
def first_order_coefficient(h: float, tau: float) -> float:
    """Exact update weight of ``tau z' + z = s`` over ``h`` [s] with s held:
    ``z += c (s - z)``, c = 1 - exp(-h / tau) (1 for tau = 0: no filter)."""
    return 1.0 if tau <= 0.0 else -math.expm1(-h / tau)


def quantise(value: float, lsb: float, bits: int = 12) -> float:
    """A reading of ``value`` by an ADC whose codes 0 .. 2^bits - 1 stand for
    ``code * lsb``: rounded to the nearest code and saturated at both ends."""
    code = math.floor(value / lsb + 0.5)
    top = (1 << bits) - 1
    if code < 0:
        code = 0
    elif code > top:
        code = top
    return code * lsb


# -------------------------------------------------------------- external forces
def spring_contact_force(x: float, v: float, x_contact: float, stiffness: float,
                         damping: float) -> float:
    """Ground contact [N] (positive against extension): while the piston is retracted
    below ``x_contact`` [m] the ground pushes it out, ``-(k (x_c - x) + c max(-v, 0))``
    with ``stiffness`` k [N/m] and ``damping`` c [N s/m]; 0 otherwise."""
    if x >= x_contact:
        return 0.0
    return -(stiffness * (x_contact - x) + (damping * -v if v < 0.0 else 0.0))


def ramp_force(t: float, start: float, rate: float, f_max: float, sign: float) -> float:
    """A digging load [N]: 0 before ``start`` [s], then ``sign * min(rate (t - start),
    f_max)`` (``rate`` [N/s], ``f_max`` [N], sign +1 resists extension)."""
    if t <= start:
        return 0.0
    f = rate * (t - start)
    return sign * (f if f < f_max else f_max)


def vibration_force(t: float, amplitude: float, frequency: float) -> float:
    """Engine vibration on the piston [N]: ``amplitude sin(2 pi frequency t)``."""
    return amplitude * math.sin(2.0 * math.pi * frequency * t)


# ------------------------------------------------------------ plug-ins' rig forms
class RigSite(NamedTuple):
    """What a plug-in's rig form reads of the joint it acts on: the valve's, the gas's
    and the cylinder's parameters and the atmosphere's pressure [Pa]."""
    valve: Valve
    gas: Gas
    cylinder: Cylinder
    P_atm: float


class RigEffect(NamedTuple):
    """A plug-in's effect as the virtual rig simulates it: its own form of the mechanism
    (not the model's candidate form), its configuration's parameters with their defaults
    (``RigConfig.effects[name]``, as the rig's own effects) and the stage it acts in.

    ``apply``'s signature per stage (``q`` the configured parameters, ``site`` a
    :class:`RigSite`):

    * ``command``: ``(y, q, site) -> y``, the spool's position [V] to the command the
      orifices see;
    * ``port``, ``seal``: ``(m_a, m_b, s_a, s_b, p_a, p_b, x, q, site) -> (m_a, m_b,
      s_a, s_b)``, the chambers' inflows [kg/s] and their slopes [kg/(s Pa)] at the
      chambers' absolute pressures [Pa] and the piston's position [m];
    * ``friction``: ``(load, v, p_a, p_b, q, site) -> load``, the load parameters
      (:class:`~boomfmi.physics.params.Load`) at the piston's speed [m/s] and pressures.

    ``check(q)``, if given, says why a configuration's values are not physical ('' if
    they are)."""
    name: str
    stage: str
    defaults: dict
    apply: Callable
    check: Optional[Callable] = None
    summary: str = ""


#: the rig's stages a plug-in's form may act in, in the order the rig applies them
RIG_STAGES = ("command", "port", "seal", "friction")
#: name -> :class:`RigEffect`: the plug-ins' rig forms (the rig's own effects are the functions above)
RIG_FORMS: dict = {}


def register_rig_effects(entries, owner: str, taken=()) -> tuple:
    """Add plug-in ``owner``'s rig forms (:class:`RigEffect`), all or none; ``taken``:
    the names the rig's own effects use.  Raises ``ValueError`` naming the plug-in and
    the entry at fault."""
    entries = tuple(entries)
    for e in entries:
        if not isinstance(e, RigEffect):
            raise ValueError(f"effect plug-in {owner}: rig_effects(truth) must return RigEffect entries, "
                             f"got {type(e).__name__}")
        if e.name in taken or e.name in RIG_FORMS:
            raise ValueError(f"effect plug-in {owner}: rig effect {e.name!r}: the name is taken")
        if e.stage not in RIG_STAGES:
            raise ValueError(f"effect plug-in {owner}: rig effect {e.name!r}: stage {e.stage!r} is not one of "
                             f"{', '.join(RIG_STAGES)}")
        if not callable(e.apply) or not isinstance(e.defaults, dict) or not e.defaults:
            raise ValueError(f"effect plug-in {owner}: rig effect {e.name!r}: needs apply (its form) and "
                             f"defaults (its parameters)")
        bad = [k for k, v in e.defaults.items() if not (isinstance(k, str) and isinstance(v, (int, float))
                                                         and not isinstance(v, bool) and math.isfinite(v))]
        if bad:
            raise ValueError(f"effect plug-in {owner}: rig effect {e.name!r}: default of {bad[0]!r} must be "
                             f"a finite number")
    RIG_FORMS.update({e.name: e for e in entries})
    return tuple(e.name for e in entries)

__all__ = [
    "spool_transition", "spool_step", "overlap_opening", "overlap_command", "cushion_engagement",
    "cushion_exhaust_area", "piston_leak_flows", "stribeck_level", "breakaway_stribeck_load",
    "seal_friction_load", "chamber_wall_areas", "wall_heat_flow", "thermal_equivalent_flow",
    "chamber_temperature", "first_order_coefficient", "quantise", "spring_contact_force", "ramp_force",
    "vibration_force", "RigSite", "RigEffect", "RIG_STAGES", "RIG_FORMS", "register_rig_effects",
]
