"""The whole excavator: swing, boom, arm and bucket as one rigid four-joint linkage.

Plain functions on floats and NumPy arrays, SI units, pressures absolute.  The values
are those of ``shared/spec/excavator.md`` (links, actuators) and, for the boom joint,
``shared/spec/reference-rig.md``; the choices this page leaves open are documented in
``docs/excavator.md``.

Coordinates
-----------
Two sets, one per joint each, in the order of :data:`JOINTS`:

* the piston positions ``x`` [m], each in its stroke [0, L] (0 = retracted);
* the recording's angles ``q = (theta_swing, alpha, theta_arm, theta_bucket)`` [rad].

Each joint's angle follows from its cylinder length ``l = l_min + x`` (Eq. 11) by the
law of cosines over its mounting triangle, ``l^2 = c1^2 + c2^2 - 2 c1 c2 cos(gamma)``
(for the boom this is the paper's Eq. 12 with c1 = a, c2 = b and gamma = alpha, computed
by :func:`physics.geometry.alpha_from_x`), and ``q = gamma + offset`` with the offset
chosen so that the retracted cylinder gives the joint's lower limit ``lower``.  So
every joint angle rises as its piston extends, and the generalised force of a cylinder
force F [N] (positive extending) on its joint is ``F dl/dgamma`` (:func:`lever_arms`).

World frame: z up, the swing axis through the origin, x straight ahead at
``theta_swing = 0``.  The boom, arm and bucket move in the vertical plane of the upper
structure, spanned by ``e_r = (cos theta_swing, sin theta_swing, 0)`` and ``e_z``.
In that plane a link's *pitch* is its centre line's angle above the horizontal (toward
e_r):

* boom pitch ``psi_b = alpha - arcsin(h/a)``: Eq. 10 to 12's triangle, with the rod eye
  on the boom's centre line ``b`` from the pivot and the cylinder's base eye ``a`` from
  the pivot, ``h`` below it (as :func:`physics.geometry.linkage_points` draws it);
* arm pitch ``psi_a = psi_b - theta_arm``, bucket pitch ``psi_k = psi_a - theta_bucket``:
  the arm's and the bucket's angles are measured *downward* (curling in), so that
  extending the arm cylinder crowds the arm in and extending the bucket cylinder curls
  the bucket, as on a real backhoe, while each angle still rises with its piston.

Dynamics
--------
Lagrange's equations in ``q`` (the paper's Eq. 8 generalised to four joints)::

    M(q) q'' + C(q, q') q' + G(q) = tau_cylinders + J(q)^T f_tip - tau_friction

with the mass matrix from the links' Jacobians (each link a slender rod along its centre
line, inertia ``m L^2 / 12`` about both axes across it), the Coriolis and centrifugal
vector from the mass matrix's exact analytic derivatives (Christoffel symbols), and
``G = dV/dq``.  Friction (Eq. 9) and the end stops act per cylinder, in the piston
coordinates ``x``, where :func:`advance_linkage` integrates the motion.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from . import _xp as xp
from . import reference_rig
from .geometry import alpha_from_x, phi_from_x, x_from_alpha
from .params import Cylinder, Geometry, Load, Valve
from .validation import ParameterError, require_finite, require_non_negative, require_positive

#: The joints, in the order of every 4-vector here.
JOINTS = ("swing", "boom", "arm", "bucket")
#: The planar links (the boom's, arm's and bucket's), in chain order.
LINKS = ("boom", "arm", "bucket")
#: Acceleration of gravity [m/s^2] (chosen).
G_EARTH = 9.81

_SWING, _BOOM, _ARM, _BUCKET = range(4)


def _gamma(l, c1, c2):
    """The triangle's angle at the pivot [rad] for cylinder length l (law of cosines)."""
    return np.arccos(np.clip((c1 * c1 + c2 * c2 - l * l) / (2.0 * c1 * c2), -1.0, 1.0))


def _rod_inertia(mass: float, length: float) -> float:
    return mass * length * length / 12.0


@dataclass(frozen=True)
class Link:
    """One rigid link of the planar chain (``excavator.md``, Links)."""
    length: float    #: pivot to the next pivot, or to the tip for the bucket [m]
    mass: float      #: [kg]
    com: float       #: centre of mass, from its pivot along its centre line [m]
    inertia: float   #: about its centre, across the centre line [kg m^2] (m L^2 / 12)


@dataclass(frozen=True)
class Actuator:
    """One joint's cylinder, mounting triangle, valve and friction (``excavator.md``,
    Actuators; the boom's from ``reference-rig.md``).

    ``c1``, ``c2``: pivot to base eye and pivot to rod eye [m] (the boom's a and b);
    ``lower``: the joint angle at x = 0 [rad] (``None``: gamma itself, as the boom's
    alpha of Eq. 12).  ``K_v``, ``F_s``, ``F_d``: Eq. 9 friction of this cylinder.
    """
    bore: float
    rod: float
    stroke: float
    c1: float
    c2: float
    l_min: float
    lower: float | None
    A_max: float
    V_a0: float
    V_b0: float
    K_v: float
    F_s: float
    F_d: float

    @property
    def A_a(self) -> float:
        """Cap-side piston area [m^2]."""
        return math.pi / 4.0 * self.bore ** 2

    @property
    def A_b(self) -> float:
        """Rod-side annulus area [m^2]."""
        return math.pi / 4.0 * (self.bore ** 2 - self.rod ** 2)

    @property
    def L(self) -> float:
        """Stroke [m]."""
        return self.stroke

    @property
    def cylinder(self) -> Cylinder:
        """The cylinder as the boom's parameter group (for the cylinder FMU)."""
        return Cylinder(A_a=self.A_a, A_b=self.A_b, L=self.L, V_a0=self.V_a0, V_b0=self.V_b0)

    @property
    def valve(self) -> Valve:
        """The valve, the reference rig's but for A_max (for the valve FMU)."""
        return Valve(A_max=self.A_max)

    @cached_property
    def offset(self) -> float:
        """Joint angle minus gamma [rad]: ``lower - gamma(l_min)`` (0 for the boom)."""
        if self.lower is None:
            return 0.0
        return self.lower - _gamma(self.l_min, self.c1, self.c2)

    @property
    def upper(self) -> float:
        """The joint angle at x = L [rad]."""
        return _gamma(self.l_min + self.stroke, self.c1, self.c2) + self.offset

    @property
    def lower_limit(self) -> float:
        """The joint angle at x = 0 [rad]."""
        return _gamma(self.l_min, self.c1, self.c2) + self.offset


def _scaled_friction(bore: float):
    """The boom's K_v, F_s, F_d (reference-rig.md) scaled by bore area relative to 32 mm."""
    s = (bore / reference_rig.bore) ** 2
    return dict(K_v=reference_rig.K_v * s, F_s=reference_rig.F_s * s, F_d=reference_rig.F_d * s)


def _actuator(bore, rod, stroke, c1, c2, l_min, lower, A_max, V0=1.0e-5):
    return Actuator(bore=bore, rod=rod, stroke=stroke, c1=c1, c2=c2, l_min=l_min, lower=lower,
                    A_max=A_max, V_a0=V0, V_b0=V0, **_scaled_friction(bore))


def _swing_lower() -> float:
    # symmetric about straight ahead: theta_swing(0) = -theta_swing(L)
    g0 = _gamma(0.17, 0.20, 0.06)
    g1 = _gamma(0.17 + 0.050, 0.20, 0.06)
    return -0.5 * (g1 - g0)


@dataclass(frozen=True)
class Excavator:
    """Every constant of the whole excavator (``excavator.md``), SI units.

    ``boom_h`` is Eq. 10's h; the boom's triangle is ``Geometry(a=boom.c1, b=boom.c2,
    h=boom_h, l_min=boom.l_min)`` (:attr:`geometry`).  The drawing-only angles place
    the cylinders' base eyes (they do not enter the dynamics).
    """
    swing: Actuator = field(default_factory=lambda: _actuator(
        0.025, 0.010, 0.050, 0.20, 0.06, 0.17, _swing_lower(), 2.0e-6))
    boom: Actuator = field(default_factory=lambda: Actuator(
        bore=reference_rig.bore, rod=reference_rig.rod, stroke=reference_rig.L,
        c1=reference_rig.a, c2=reference_rig.b, l_min=reference_rig.l_min, lower=None,
        A_max=reference_rig.A_max, V_a0=reference_rig.V_a0, V_b0=reference_rig.V_b0,
        **_scaled_friction(reference_rig.bore)))
    arm: Actuator = field(default_factory=lambda: _actuator(
        0.025, 0.010, 0.080, 0.32, 0.07, 0.27, math.radians(50.0), 2.0e-6))
    bucket: Actuator = field(default_factory=lambda: _actuator(
        0.020, 0.008, 0.050, 0.20, 0.05, 0.17, math.radians(30.0), 2.0e-6))
    boom_h: float = reference_rig.h
    boom_link: Link = Link(0.60, 5.0, 0.30, _rod_inertia(5.0, 0.60))
    arm_link: Link = Link(0.35, 2.5, 0.15, _rod_inertia(2.5, 0.35))
    bucket_link: Link = Link(0.15, 1.5, 0.08, _rod_inertia(1.5, 0.15))
    upper_mass: float = 6.0            #: upper structure [kg], on the swing axis
    upper_inertia: float = 0.060       #: upper structure about z [kg m^2]
    pivot_forward: float = 0.05        #: boom pivot ahead of the swing axis [m]
    pivot_height: float = 0.20         #: boom pivot above the ground [m]
    g: float = G_EARTH                 #: [m/s^2]
    P_atm: float = reference_rig.P_atm
    # drawing only
    arm_base_angle: float = math.radians(10.0)     #: arm cylinder's base eye above the boom line, seen from the arm pivot
    bucket_base_angle: float = math.radians(10.0)  #: bucket cylinder's base eye above the arm line, seen from the bucket pivot
    swing_crank_angle: float = math.pi             #: swing crank's azimuth relative to the upper structure
    swing_eye_height: float = 0.10                 #: height of the swing cylinder's eyes [m]

    @property
    def actuators(self) -> tuple:
        return (self.swing, self.boom, self.arm, self.bucket)

    @property
    def links(self) -> tuple:
        return (self.boom_link, self.arm_link, self.bucket_link)

    @property
    def geometry(self) -> Geometry:
        """The boom's Eq. 10 to 12 geometry."""
        b = self.boom
        return Geometry(a=b.c1, b=b.c2, h=self.boom_h, l_min=b.l_min)

    def load(self, joint: str, F_L: float = 0.0, M: float = 1.0) -> Load:
        """Eq. 8, 9's friction of one cylinder as a :class:`Load` (F_L and M as given)."""
        a = getattr(self, joint)
        return Load(K_v=a.K_v, F_s=a.F_s, F_d=a.F_d, F_L=F_L, M=M)

    @property
    def strokes(self) -> np.ndarray:
        return np.array([a.stroke for a in self.actuators])


def excavator_parameters(**changes) -> Excavator:
    """The excavator of ``excavator.md`` (with ``changes`` to its fields), checked."""
    ex = replace(Excavator(), **changes) if changes else Excavator()
    check_excavator(ex)
    return ex


_DEFAULT = Excavator()


def check_excavator(ex: Excavator) -> None:
    """Raise :class:`ParameterError` naming the parameter (``<field>_<joint>`` for an
    actuator's, ``<field>_<link>`` for a link's, as the linkage FMU declares them)."""
    for joint, a in zip(JOINTS, ex.actuators):
        for name in ("bore", "stroke", "c1", "c2", "l_min", "A_max", "V_a0", "V_b0"):
            require_positive(f"{name}_{joint}", getattr(a, name))
        require_non_negative(f"rod_{joint}", a.rod)
        if a.rod >= a.bore:
            raise ParameterError(f"rod_{joint}", a.rod, f"must be smaller than the bore {a.bore:g} m")
        for name in ("K_v", "F_s", "F_d"):
            require_non_negative(f"{name}_{joint}", getattr(a, name))
        if a.F_s < a.F_d:
            raise ParameterError(f"F_s_{joint}", a.F_s,
                                 f"the static friction must be at least the Coulomb force F_d = {a.F_d:g} N (Eq. 9)")
        if a.lower is not None:
            require_finite(f"lower_{joint}", a.lower)
        lo, hi = abs(a.c1 - a.c2), a.c1 + a.c2
        if not a.l_min > lo:
            raise ParameterError(f"l_min_{joint}", a.l_min,
                                 f"the retracted cylinder must be longer than |c1 - c2| = {lo:g} m "
                                 "(a triangle with a non-zero lever arm)")
        if not a.l_min + a.stroke < hi:
            raise ParameterError(f"l_min_{joint}", a.l_min,
                                 f"the extended cylinder l_min + L must be shorter than c1 + c2 = {hi:g} m "
                                 "(a triangle with a non-zero lever arm)")
    require_non_negative("h", ex.boom_h)
    if ex.boom_h > ex.boom.c1:
        raise ParameterError("h", ex.boom_h, f"must not exceed a = {ex.boom.c1:g} m (arcsin(h/a) in Eq. 10)")
    for name, link in zip(LINKS, ex.links):
        require_positive(f"length_{name}", link.length)
        require_positive(f"mass_{name}", link.mass)
        require_non_negative(f"inertia_{name}", link.inertia)
        require_finite(f"com_{name}", link.com)
    require_non_negative("upper_mass", ex.upper_mass)
    require_positive("upper_inertia", ex.upper_inertia)
    require_finite("pivot_forward", ex.pivot_forward)
    require_finite("pivot_height", ex.pivot_height)
    require_non_negative("g", ex.g)
    require_positive("P_atm", ex.P_atm)


# --- joint kinematics: pistons <-> angles (Eq. 10 to 12 and their triangles) -------------

def _joint_gamma(j: int, x, ex: Excavator):
    a = ex.actuators[j]
    if j == _BOOM:
        return alpha_from_x(x, ex.geometry)                      # Eq. 12
    return _gamma(a.l_min + x, a.c1, a.c2)


def joint_angles(x, ex: Excavator = _DEFAULT) -> np.ndarray:
    """The recording's angles ``(theta_swing, alpha, theta_arm, theta_bucket)`` [rad] from
    the four piston positions ``x`` [m] (last axis of length 4).

    The boom's is Eq. 12's alpha; each other joint's ``gamma + offset`` by the law of
    cosines over its triangle (``excavator.md``), the offset making x = 0 its ``lower``
    limit."""
    x = np.asarray(x, dtype=float)
    return np.stack([_joint_gamma(j, x[..., j], ex) + ex.actuators[j].offset for j in range(4)], axis=-1)


def pistons_from_angles(q, ex: Excavator = _DEFAULT) -> np.ndarray:
    """The inverse of :func:`joint_angles`: piston positions ``x`` [m] from ``q`` [rad]
    (the boom's by Eq. 12, :func:`physics.geometry.x_from_alpha`)."""
    q = np.asarray(q, dtype=float)
    out = []
    for j, a in enumerate(ex.actuators):
        if j == _BOOM:
            out.append(x_from_alpha(q[..., j], ex.geometry))
        else:
            g = q[..., j] - a.offset
            out.append(np.sqrt(a.c1 ** 2 + a.c2 ** 2 - 2.0 * a.c1 * a.c2 * np.cos(g)) - a.l_min)
    return np.stack(out, axis=-1)


def joint_limits(ex: Excavator = _DEFAULT) -> np.ndarray:
    """(4, 2) array of each joint angle's [lower, upper] limits [rad] (x = 0 and x = L)."""
    return np.array([[a.lower_limit, a.upper] for a in ex.actuators])


def lever_arms(x, ex: Excavator = _DEFAULT) -> np.ndarray:
    """``dl/dgamma`` per joint [m/rad]: joint torque = cylinder force x lever arm.

    From the law of cosines, ``l dl = c1 c2 sin(gamma) dgamma``, so
    ``dl/dgamma = c1 c2 sin(gamma) / l``; for the boom (Eq. 12 differentiated)
    ``dl/dalpha = a b sin(alpha) / l``.  Positive over every stroke: extending a
    cylinder raises its joint angle."""
    x = np.asarray(x, dtype=float)
    out = []
    for j, a in enumerate(ex.actuators):
        l = a.l_min + x[..., j]
        out.append(a.c1 * a.c2 * np.sin(_joint_gamma(j, x[..., j], ex)) / l)
    return np.stack(out, axis=-1)


def _posture(x, ex: Excavator):
    """At one posture (``x`` 4 piston positions [m]), with plain floats, or at many
    (``x`` of shape (n, 4): each entry an array over the n postures): the joint angles
    q, lam = dq/dx [rad/m], dlam = d^2 q / dx^2 and the boom's cos(phi) (Eq. 10)."""
    x = np.asarray(x, dtype=float) if not isinstance(x, (list, tuple)) else x
    cols = [x[..., j] for j in range(4)] if getattr(x, "ndim", 1) > 1 else [float(x[j]) for j in range(4)]
    q = [0.0] * 4
    lam = [0.0] * 4
    dlam = [0.0] * 4
    for j, a in enumerate(ex.actuators):
        xj = cols[j]
        l = a.l_min + xj
        g = alpha_from_x(xj, ex.geometry) if j == _BOOM else \
            xp.arccos(xp.clip((a.c1 * a.c1 + a.c2 * a.c2 - l * l) / (2.0 * a.c1 * a.c2), -1.0, 1.0))
        q[j] = g + a.offset
        s, c = xp.sin(g), xp.cos(g)
        lj = l / (a.c1 * a.c2 * s)
        lam[j] = lj
        dlam[j] = lj / l - lj * lj * c / s
    cos_phi = xp.cos(phi_from_x(cols[_BOOM], ex.geometry))
    return q, lam, dlam, cos_phi


def friction_scale(x, ex: Excavator = _DEFAULT) -> np.ndarray:
    """Eq. 9's factor on each cylinder's F_s and F_d: ``cos(phi)`` (Eq. 10) for the boom,
    exactly as the boom-only model; 1 for the other three, whose cylinders have no
    such angle in the paper (see ``docs/excavator.md``)."""
    x = np.asarray(x, dtype=float)
    one = np.ones_like(x[..., 0])
    return np.stack([one, np.cos(phi_from_x(x[..., 1], ex.geometry)), one, one], axis=-1)


# --- forward kinematics ------------------------------------------------------------------

def _pitches(q, ex: Excavator):
    beta = math.asin(ex.boom_h / ex.boom.c1)
    psi_b = q[..., 1] - beta
    psi_a = psi_b - q[..., 2]
    psi_k = psi_a - q[..., 3]
    return psi_b, psi_a, psi_k


#: d psi / d q for the boom, arm and bucket pitches (rows) over q (columns).
_DPSI = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 1.0, -1.0, 0.0], [0.0, 1.0, -1.0, -1.0]])
_DPSI_P = ((1.0, 0.0, 0.0), (1.0, -1.0, 0.0), (1.0, -1.0, -1.0))


def _planar_points(ex: Excavator, payload_at_com: bool = True):
    """Coefficients of the points' positions along (u_boom, u_arm, u_bucket)."""
    b, a, k = ex.links
    return {
        "boom_com": (b.com, 0.0, 0.0),
        "arm_pivot": (b.length, 0.0, 0.0),
        "arm_com": (b.length, a.com, 0.0),
        "bucket_pivot": (b.length, a.length, 0.0),
        "bucket_com": (b.length, a.length, k.com),
        "tip": (b.length, a.length, k.length),
    }


def _to_world(r, z, ts):
    return np.stack([r * np.cos(ts), r * np.sin(ts), z + 0.0 * ts], axis=-1)


def forward_kinematics(q, ex: Excavator = _DEFAULT) -> dict:
    """World-frame positions [m] (last axis 3) of the machine's points at ``q``.

    Keys: ``swing_axis`` (on the ground), ``boom_pivot``, ``arm_pivot``,
    ``bucket_pivot``, ``tip``, the links' centres of mass ``<link>_com``, and each
    cylinder's eyes ``cyl_<joint>_base`` and ``cyl_<joint>_rod`` (|rod - base| is the
    cylinder length l = l_min + x).  ``q`` may carry leading axes (a time series)."""
    q = np.asarray(q, dtype=float)
    ts = q[..., 0]
    psi = _pitches(q, ex)
    r0, z0 = ex.pivot_forward, ex.pivot_height
    out = {"swing_axis": _to_world(0.0 * ts, 0.0 * ts, ts), "boom_pivot": _to_world(r0 + 0.0 * ts, z0 + 0.0 * ts, ts)}
    cs = [np.cos(p) for p in psi]
    sn = [np.sin(p) for p in psi]
    planar = {}
    for name, c in _planar_points(ex).items():
        r = r0 + c[0] * cs[0] + c[1] * cs[1] + c[2] * cs[2]
        z = z0 + c[0] * sn[0] + c[1] * sn[1] + c[2] * sn[2]
        planar[name] = (r, z)
        out[name] = _to_world(r, z, ts)
    # boom cylinder: Eq. 10 to 12's triangle (linkage_points)
    a, b_, h = ex.boom.c1, ex.boom.c2, ex.boom_h
    beta = math.asin(h / a)
    out["cyl_boom_base"] = _to_world(r0 + a * math.cos(beta) + 0.0 * ts, z0 - h + 0.0 * ts, ts)
    out["cyl_boom_rod"] = _to_world(r0 + b_ * cs[0], z0 + b_ * sn[0], ts)
    # arm and bucket: base eye c1 from the pivot, back along the proximal link and
    # lifted by the base angle; rod eye c2 from the pivot, gamma clockwise of it
    for joint, pivot, prox, delta, j in (("arm", "arm_pivot", psi[0], ex.arm_base_angle, _ARM),
                                         ("bucket", "bucket_pivot", psi[1], ex.bucket_base_angle, _BUCKET)):
        act = ex.actuators[j]
        pr, pz = planar[pivot]
        base_ang = prox + math.pi - delta
        gam = q[..., j] - act.offset
        rod_ang = base_ang - gam
        out[f"cyl_{joint}_base"] = _to_world(pr + act.c1 * np.cos(base_ang), pz + act.c1 * np.sin(base_ang), ts)
        out[f"cyl_{joint}_rod"] = _to_world(pr + act.c2 * np.cos(rod_ang), pz + act.c2 * np.sin(rod_ang), ts)
    # swing: base eye fixed on the undercarriage, crank eye on the upper structure
    sw = ex.swing
    crank = ts + ex.swing_crank_angle
    base_az = ex.swing_crank_angle + sw.offset
    zc = ex.swing_eye_height
    out["cyl_swing_rod"] = np.stack([sw.c2 * np.cos(crank), sw.c2 * np.sin(crank), zc + 0.0 * ts], axis=-1)
    out["cyl_swing_base"] = np.stack([sw.c1 * math.cos(base_az) + 0.0 * ts, sw.c1 * math.sin(base_az) + 0.0 * ts,
                                      zc + 0.0 * ts], axis=-1)
    return out


def tip_position(q, ex: Excavator = _DEFAULT) -> np.ndarray:
    """The bucket tip in the world frame [m]."""
    return forward_kinematics(q, ex)["tip"]


# --- the rigid-body terms, at one posture ----------------------------------------------

def _bodies(ex: Excavator, payload: float):
    """Point masses (name, coefficient triple, mass) and link rods (pitch index, inertia)."""
    pts = _planar_points(ex)
    b, a, k = ex.links
    masses = [(pts["boom_com"], b.mass), (pts["arm_com"], a.mass), (pts["bucket_com"], k.mass + payload)]
    return masses, ((0, b.inertia), (1, a.inertia), (2, k.inertia))


def _terms(q, ex: Excavator, payload: float, derivatives: bool):
    """M (4x4), dM/dq (4x4x4, last index the coordinate) and G (4) at one posture."""
    q = np.asarray(q, dtype=float)
    psi = _pitches(q, ex)
    cs = np.array([math.cos(p) for p in psi])
    sn = np.array([math.sin(p) for p in psi])
    r0, z0 = ex.pivot_forward, ex.pivot_height
    masses, rods = _bodies(ex, payload)
    M = np.zeros((4, 4))
    dM = np.zeros((4, 4, 4)) if derivatives else None
    G = np.zeros(4)
    M[0, 0] = ex.upper_inertia
    for coef, m in masses:
        c = np.asarray(coef)
        r = r0 + c @ cs
        Jr = -(c * sn) @ _DPSI          # dr/dq, (4,)
        Jz = (c * cs) @ _DPSI           # dz/dq
        M[0, 0] += m * r * r
        M += m * (np.outer(Jr, Jr) + np.outer(Jz, Jz))
        G += m * ex.g * Jz
        if derivatives:
            # second derivatives: d2r/dq2 = -sum c_k cos(psi_k) d_k d_k^T, d2z = -sum c_k sin ...
            Hr = -np.einsum("k,ka,kb->ab", c * cs, _DPSI, _DPSI)
            Hz = -np.einsum("k,ka,kb->ab", c * sn, _DPSI, _DPSI)
            dM[0, 0, :] += 2.0 * m * r * Jr
            # d/dq_c (Jr_a Jr_b) = Hr[a, c] Jr_b + Jr_a Hr[b, c]
            dM += m * (np.einsum("ac,b->abc", Hr, Jr) + np.einsum("a,bc->abc", Jr, Hr)
                       + np.einsum("ac,b->abc", Hz, Jz) + np.einsum("a,bc->abc", Jz, Hz))
    for i, I0 in rods:
        d = _DPSI[i]
        M += I0 * np.outer(d, d)
        M[0, 0] += I0 * cs[i] * cs[i]
        if derivatives:
            dM[0, 0, :] += -2.0 * I0 * cs[i] * sn[i] * d
    # the swing row and column stay decoupled: velocities along e_t are orthogonal to
    # the plane's, and a rod's spin is theta_swing' e_z - psi' e_t
    M[0, 1:] = 0.0
    M[1:, 0] = 0.0
    return M, dM, G


class _Prepared:
    """One excavator's (and payload's) constants as plain floats, for the stepping's hot
    path (:func:`_prepared` keeps the last few).

    With the point masses' coefficients ``c_bk`` along the three pitches' unit vectors
    (:func:`_planar_points`), ``S_kl = sum_b m_b c_bk c_bl`` and ``s_k = sum_b m_b c_bk``
    are all that the rigid-body terms need of the masses: the planar mass matrix is
    ``D^T K D`` with ``K_kl = S_kl cos(psi_k - psi_l) + I_k delta_kl`` and ``D = d psi / d q``
    (:data:`_DPSI_P`), so it depends on the relative angles only (:func:`_rigid_terms`)."""

    def __init__(self, ex: Excavator, payload: float):
        self.ex, self.payload = ex, payload
        acts = ex.actuators
        #: per joint: l_min, c1^2 + c2^2, 2 c1 c2, c1 c2, offset
        self.tri = tuple((a.l_min, a.c1 * a.c1 + a.c2 * a.c2, 2.0 * a.c1 * a.c2, a.c1 * a.c2, a.offset)
                         for a in acts)
        self.L = [a.stroke for a in acts]
        self.Kv = [a.K_v for a in acts]
        self.Fs = [a.F_s for a in acts]
        self.Fd = [a.F_d for a in acts]
        self.A_a = [a.A_a for a in acts]
        self.A_b = [a.A_b for a in acts]
        self.P_atm = ex.P_atm
        self.beta = math.asin(ex.boom_h / ex.boom.c1)
        self.boom_ab = (ex.boom.c1, ex.boom.c2, ex.boom.l_min)
        b, a, k = ex.links
        bodies = (((b.com, 0.0, 0.0), b.mass), ((b.length, a.com, 0.0), a.mass),
                  ((b.length, a.length, k.com), k.mass + payload))
        self.S = [[sum(m * c[i] * c[j] for c, m in bodies) for j in range(3)] for i in range(3)]
        self.s = [sum(m * c[i] for c, m in bodies) for i in range(3)]
        self.m = sum(m for _, m in bodies)
        self.I = (b.inertia, a.inertia, k.inertia)
        self.tip = (b.length, a.length, k.length)
        self.r0, self.g, self.Iz = ex.pivot_forward, ex.g, ex.upper_inertia
        self.z0 = ex.pivot_height


_PREPARED: dict = {}


def _prepared(ex: Excavator, payload: float) -> _Prepared:
    key = (id(ex), payload)
    p = _PREPARED.get(key)
    if p is None or p.ex is not ex:
        if len(_PREPARED) > 16:
            _PREPARED.clear()
        p = _PREPARED[key] = _Prepared(ex, payload)
    return p


def _fast_posture(x, P: _Prepared):
    """:func:`_posture` on prepared constants (the stepping's path)."""
    q = [0.0] * 4
    lam = [0.0] * 4
    dlam = [0.0] * 4
    for j in range(4):
        l_min, cc, two, c1c2, off = P.tri[j]
        l = l_min + x[j]
        cg = (cc - l * l) / two
        cg = 1.0 if cg > 1.0 else (-1.0 if cg < -1.0 else cg)
        g = math.acos(cg)
        s = math.sin(g)
        q[j] = g + off
        lj = l / (c1c2 * s)
        lam[j] = lj
        dlam[j] = lj / l - lj * lj * cg / s
    a, b, l_min = P.boom_ab
    l = l_min + x[1]
    # Eq. 10: phi = pi - arcsin(h/a) - arccos((a^2 + l^2 - b^2) / (2 a l)); cos(phi) = -cos(beta + that)
    cos_phi = -math.cos(P.beta + math.acos((a * a + l * l - b * b) / (2.0 * a * l)))
    return q, lam, dlam, cos_phi


def _rigid_terms(q, qd, P: _Prepared):
    """M (nested lists), C(q, q') q' and G at one posture, in closed form on plain floats
    (or at many: ``q``, ``qd`` lists of arrays over the postures, entries arrays or 0.0).

    Planar part: ``M = D^T K D`` (see :class:`_Prepared`); ``(C q')_i = sum_k D_ki h_k``
    with ``h_k = sum_l S_kl sin(psi_k - psi_l) psi_l'^2`` (the point masses' centripetal
    accelerations projected on their Jacobians; the rods spin about a fixed axis in the
    plane and add none); ``G_i = g sum_k D_ki s_k cos(psi_k)``.  Swing: ``M_00 = I_z +
    sum_b m_b r_b^2 + sum_k I_k cos^2(psi_k)``, ``dM_00/dpsi_k = -2 sin(psi_k) (rho_k +
    I_k cos(psi_k))`` with ``rho_k = sum_b m_b r_b c_bk``; it adds ``q0' (dM00/dq . q')``
    to its own row and ``-1/2 dM00/dq q0'^2`` to the planar rows."""
    p0 = q[1] - P.beta
    p1 = p0 - q[2]
    p2 = p1 - q[3]
    c0, c1, c2 = xp.cos(p0), xp.cos(p1), xp.cos(p2)
    s0, s1, s2 = xp.sin(p0), xp.sin(p1), xp.sin(p2)
    c01, s01 = c0 * c1 + s0 * s1, s0 * c1 - c0 * s1
    c02, s02 = c0 * c2 + s0 * s2, s0 * c2 - c0 * s2
    c12, s12 = c1 * c2 + s1 * s2, s1 * c2 - c1 * s2
    (S00, S01, S02), (_, S11, S12), (_, _, S22) = P.S
    I0, I1, I2 = P.I
    K00, K11, K22 = S00 + I0, S11 + I1, S22 + I2
    K01, K02, K12 = S01 * c01, S02 * c02, S12 * c12
    M22 = K11 + 2.0 * K12 + K22
    M23 = K12 + K22
    M13 = -(K02 + M23)
    M12 = -(K01 + K02 + M22)
    M11 = K00 + K11 + K22 + 2.0 * (K01 + K02 + K12)
    w0 = qd[1]
    w1 = w0 - qd[2]
    w2 = w1 - qd[3]
    ww0, ww1, ww2 = w0 * w0, w1 * w1, w2 * w2
    a01, a02, a12 = S01 * s01, S02 * s02, S12 * s12
    h0 = a01 * ww1 + a02 * ww2
    h1 = a12 * ww2 - a01 * ww0
    h2 = -a02 * ww0 - a12 * ww1
    sk0, sk1, sk2 = P.s
    g = P.g
    g0, g1, g2 = g * sk0 * c0, g * sk1 * c1, g * sk2 * c2
    r0 = P.r0
    rho0 = r0 * sk0 + S00 * c0 + S01 * c1 + S02 * c2
    rho1 = r0 * sk1 + S01 * c0 + S11 * c1 + S12 * c2
    rho2 = r0 * sk2 + S02 * c0 + S12 * c1 + S22 * c2
    M00 = (P.Iz + r0 * r0 * P.m + r0 * (sk0 * c0 + sk1 * c1 + sk2 * c2)
           + c0 * rho0 + c1 * rho1 + c2 * rho2 + I0 * c0 * c0 + I1 * c1 * c1 + I2 * c2 * c2)
    d0 = -2.0 * s0 * (rho0 + I0 * c0)
    d1 = -2.0 * s1 * (rho1 + I1 * c1)
    d2 = -2.0 * s2 * (rho2 + I2 * c2)
    e1, e2, e3 = d0 + d1 + d2, -(d1 + d2), -d2
    qd0 = qd[0]
    hh = 0.5 * qd0 * qd0
    M = [[M00, 0.0, 0.0, 0.0], [0.0, M11, M12, M13], [0.0, M12, M22, M23], [0.0, M13, M23, K22]]
    C = [qd0 * (e1 * qd[1] + e2 * qd[2] + e3 * qd[3]),
         h0 + h1 + h2 - hh * e1, -(h1 + h2) - hh * e2, -h2 - hh * e3]
    G = [0.0, g0 + g1 + g2, -(g1 + g2), -g2]
    return M, C, G


def _fast_tip_torques(q, f, P: _Prepared):
    """``J(q)^T f`` [N m] on plain floats (:func:`tip_jacobian`'s closed form)."""
    p0 = q[1] - P.beta
    p1 = p0 - q[2]
    p2 = p1 - q[3]
    a, b, c = P.tip
    t0, t1, t2 = a * math.sin(p0), b * math.sin(p1), c * math.sin(p2)
    u0, u1, u2 = a * math.cos(p0), b * math.cos(p1), c * math.cos(p2)
    r = P.r0 + u0 + u1 + u2
    ct, st = math.cos(q[0]), math.sin(q[0])
    fr = ct * f[0] + st * f[1]
    fz = f[2]
    return [r * (ct * f[1] - st * f[0]),
            -fr * (t0 + t1 + t2) + fz * (u0 + u1 + u2),
            fr * (t1 + t2) - fz * (u1 + u2),
            fr * t2 - fz * u2]


def angles_and_tip(x, ex: Excavator = _DEFAULT):
    """The joint angles (as :func:`joint_angles`) and the bucket tip's world position (as
    :func:`tip_position`) at piston positions ``x`` [m], as plain floats for one posture:
    ``([theta_swing, alpha, theta_arm, theta_bucket], (x, y, z))`` [rad], [m].  The
    linkage FMU's outputs, at a fraction of the array functions' cost."""
    P = _prepared(ex, 0.0)
    q = _fast_posture([float(t) for t in x], P)[0]
    p0 = q[1] - P.beta
    p1 = p0 - q[2]
    p2 = p1 - q[3]
    a, b, c = P.tip
    r = P.r0 + a * math.cos(p0) + b * math.cos(p1) + c * math.cos(p2)
    z = P.z0 + a * math.sin(p0) + b * math.sin(p1) + c * math.sin(p2)
    return q, (r * math.cos(q[0]), r * math.sin(q[0]), z)


def holding_forces(x, payload: float = 0.0, ex: Excavator = _DEFAULT) -> list:
    """The gravity load reflected to each piston at piston positions ``x`` [m] and rest,
    ``lam G`` [N] (4 plain floats, positive: the cylinder must extend to hold): the force
    each cylinder exerts to hold its joint still, on the stepping's prepared constants."""
    P = _prepared(ex, float(payload))
    q, lam, _, _ = _fast_posture([float(t) for t in x], P)
    G = _rigid_terms(q, [0.0] * 4, P)[2]
    return [lam[j] * G[j] for j in range(4)]


def _fast_terms(q, qd, ex: Excavator, payload: float):
    """M (4x4), C(q, q') q' and G at one posture, with plain floats (the stepping's path,
    :func:`_rigid_terms`).  Returns nested lists (M) and lists (C q', G)."""
    return _rigid_terms([float(t) for t in q], [float(t) for t in qd], _prepared(ex, payload))


def mass_matrix(q, payload: float = 0.0, ex: Excavator = _DEFAULT) -> np.ndarray:
    """The joint-space mass matrix M(q) [kg m^2] (4x4, symmetric positive definite).

    ``M = sum_i m_i Jv_i^T Jv_i + sum_i Jw_i^T I_i Jw_i`` over the links (and the payload,
    a point mass [kg] at the bucket's centre of mass) plus the upper structure's
    inertia about z.  It depends on alpha, theta_arm and theta_bucket only; the swing's
    entry is ``I_z + sum m r^2 + sum I_i cos^2(psi_i)`` (r: distance from the swing
    axis) and is decoupled from the planar joints."""
    return _terms(q, ex, payload, False)[0]


def mass_matrix_derivative(q, payload: float = 0.0, ex: Excavator = _DEFAULT) -> np.ndarray:
    """dM/dq [kg m^2/rad], shape (4, 4, 4), last index the coordinate (analytic)."""
    return _terms(q, ex, payload, True)[1]


def coriolis(q, qdot, payload: float = 0.0, ex: Excavator = _DEFAULT) -> np.ndarray:
    """The Coriolis and centrifugal vector ``C(q, q') q'`` [N m], from the Christoffel
    symbols of M (exact analytic derivatives)::

        (C q')_i = sum_jk (dM_ij/dq_k - 1/2 dM_jk/dq_i) q'_j q'_k

    evaluated in closed form (the point masses' centripetal accelerations projected on
    their Jacobians, plus the swing's terms from dM_00/dq; see ``_fast_terms``); the
    tests check it against this sum with :func:`mass_matrix_derivative`."""
    q = [float(v) for v in np.asarray(q, dtype=float)]
    qd = [float(v) for v in np.asarray(qdot, dtype=float)]
    return np.array(_fast_terms(q, qd, ex, payload)[1])


def gravity(q, payload: float = 0.0, ex: Excavator = _DEFAULT) -> np.ndarray:
    """The generalised gravity torques ``G(q) = dV/dq`` [N m] of ``M q'' + C q' + G = tau``:
    the joint torques that hold the machine still.  V = g sum m_i z_i; the swing's is 0."""
    return _terms(q, ex, payload, False)[2]


def potential_energy(q, payload: float = 0.0, ex: Excavator = _DEFAULT) -> float:
    """Gravitational potential energy [J], zero at the ground plane."""
    pts = forward_kinematics(q, ex)
    b, a, k = ex.links
    return ex.g * (b.mass * pts["boom_com"][..., 2] + a.mass * pts["arm_com"][..., 2]
                   + (k.mass + payload) * pts["bucket_com"][..., 2])


def kinetic_energy(q, qdot, payload: float = 0.0, ex: Excavator = _DEFAULT) -> float:
    """Kinetic energy ``1/2 q'^T M(q) q'`` [J]."""
    qdot = np.asarray(qdot, dtype=float)
    return 0.5 * float(qdot @ mass_matrix(q, payload, ex) @ qdot)


def tip_jacobian(q, ex: Excavator = _DEFAULT) -> np.ndarray:
    """d tip / d q, shape (3, 4) [m/rad], world frame (analytic)."""
    q = np.asarray(q, dtype=float)
    psi = _pitches(q, ex)
    cs = np.array([math.cos(p) for p in psi])
    sn = np.array([math.sin(p) for p in psi])
    c = np.asarray(_planar_points(ex)["tip"])
    r = ex.pivot_forward + c @ cs
    Jr = -(c * sn) @ _DPSI
    Jz = (c * cs) @ _DPSI
    ct, st = math.cos(q[0]), math.sin(q[0])
    J = np.vstack([ct * Jr, st * Jr, Jz])
    J[0, 0] = -r * st
    J[1, 0] = r * ct
    return J


# --- actuation ------------------------------------------------------------------------

def cylinder_forces(p_a, p_b, ex: Excavator = _DEFAULT) -> np.ndarray:
    """Each piston's pneumatic force [N], positive extending (Eq. 8's first terms):
    ``P_a A_a - P_b A_b - P_atm (A_a - A_b)``, absolute pressures [Pa]."""
    p_a = np.asarray(p_a, dtype=float)
    p_b = np.asarray(p_b, dtype=float)
    A_a = np.array([a.A_a for a in ex.actuators])
    A_b = np.array([a.A_b for a in ex.actuators])
    return p_a * A_a - p_b * A_b - ex.P_atm * (A_a - A_b)


def cylinder_torques(forces, x, ex: Excavator = _DEFAULT) -> np.ndarray:
    """Joint torques [N m] of the cylinder forces [N]: force x lever arm dl/dgamma."""
    return np.asarray(forces, dtype=float) * lever_arms(x, ex)


def tip_torques(q, f_tip, ex: Excavator = _DEFAULT) -> np.ndarray:
    """Joint torques [N m] of a force [N] (world frame, exerted by the environment on
    the bucket at its tip): ``J(q)^T f``."""
    return tip_jacobian(q, ex).T @ np.asarray(f_tip, dtype=float)


def piston_dynamics(x, v, payload: float = 0.0, ex: Excavator = _DEFAULT):
    """The equations of motion in piston coordinates at one state: ``(M_x, bias, lam)``
    with ``M_x x'' = F - bias - friction``, F the cylinder forces plus the tip force's
    share [N]:

        M_x  = diag(lam) M(q) diag(lam),   lam = dq/dx = 1 / lever arm
        bias = diag(lam) (M(q) lam' v^2 + C(q, q') q' + G(q)),   q' = lam v

    ``x``, ``v`` [m, m/s]: 4-vectors (one state), or arrays of shape (n, 4) (one state
    per row, e.g. every sample of a recording: ``M_x`` (n, 4, 4), ``bias`` and ``lam``
    (n, 4), the same closed forms on arrays)."""
    v = np.asarray(v, dtype=float)
    if np.ndim(x) > 1:
        return _piston_dynamics_rows(np.asarray(x, dtype=float), v, payload, ex)
    q, lam, dlam, _ = _posture(x, ex)
    lam, dlam = np.array(lam), np.array(dlam)
    M, Cq, G = (np.array(t) for t in _fast_terms(q, lam * v, ex, payload))
    Mx = lam[:, None] * M * lam[None, :]
    bias = lam * (M @ (dlam * v * v) + Cq + G)
    return Mx, bias, lam


def _piston_dynamics_rows(x: np.ndarray, v: np.ndarray, payload: float, ex: Excavator):
    """:func:`piston_dynamics` at every row of ``x``, ``v`` (n, 4)."""
    n = len(x)
    v = np.broadcast_to(v, x.shape)
    q, lam, dlam, _ = _posture(x, ex)
    lam, dlam = np.stack(lam, axis=-1), np.stack(dlam, axis=-1)
    qd = lam * v
    M, Cq, G = _rigid_terms(q, [qd[:, j] for j in range(4)], _prepared(ex, float(payload)))
    col = lambda e: np.broadcast_to(np.asarray(e, dtype=float), (n,))
    M = np.stack([np.stack([col(e) for e in row], axis=-1) for row in M], axis=-2)
    Cq, G = np.stack([col(e) for e in Cq], axis=-1), np.stack([col(e) for e in G], axis=-1)
    Mx = lam[:, :, None] * M * lam[:, None, :]
    bias = lam * (np.einsum("nij,nj->ni", M, dlam * v * v) + Cq + G)
    return Mx, bias, lam


def piston_accelerations(x, v, forces, f_tip=(0.0, 0.0, 0.0), payload: float = 0.0,
                         ex: Excavator = _DEFAULT) -> np.ndarray:
    """x'' [m/s^2] without friction and end stops, given the cylinder forces [N] and the
    tip force [N] (world frame)."""
    x = np.asarray(x, dtype=float)
    Mx, bias, lam = piston_dynamics(x, v, payload, ex)
    q = joint_angles(x, ex)
    F = np.asarray(forces, dtype=float) + lam * (tip_jacobian(q, ex).T @ np.asarray(f_tip, dtype=float))
    return np.linalg.solve(Mx, F - bias)


def lumped_boom_load(q, payload: float = 0.0, ex: Excavator = _DEFAULT):
    """The boom-only model's equivalents (Eq. 8) at posture ``q``, the other joints
    locked and the swing at rest: ``(M, F_L)`` with

        M   = M_q[alpha, alpha] / (dl/dalpha)^2              [kg]
        F_L = G_alpha / ((dl/dalpha) sin(phi))               [N]

    so that ``M x'' = F - F_L sin(phi) - friction`` is the linkage's boom row."""
    q = np.asarray(q, dtype=float)
    x = pistons_from_angles(q, ex)
    M, _, G = _terms(q, ex, payload, False)
    lever = float(lever_arms(x, ex)[_BOOM])
    phi = float(phi_from_x(float(x[_BOOM]), ex.geometry))
    return M[1, 1] / lever ** 2, G[1] / (lever * math.sin(phi))


# --- stepping -----------------------------------------------------------------------

def _solve3(a00, a01, a02, a11, a12, a22, b0, b1, b2):
    """Solve a symmetric 3x3 system in closed form (Cramer's rule on plain floats)."""
    m00 = a11 * a22 - a12 * a12
    m01 = a02 * a12 - a01 * a22
    m02 = a01 * a12 - a02 * a11
    det = a00 * m00 + a01 * m01 + a02 * m02
    m11 = a00 * a22 - a02 * a02
    m12 = a01 * a02 - a00 * a12
    m22 = a00 * a11 - a01 * a01
    return ((m00 * b0 + m01 * b1 + m02 * b2) / det, (m01 * b0 + m11 * b1 + m12 * b2) / det,
            (m02 * b0 + m12 * b1 + m22 * b2) / det)


def _solve_step(Mx, f, v, Kv, h, S, fric):
    """Semi-implicit step of ``M (v' - v) = h (f - K v' - Fc)`` with v'_S = 0 for the
    joints in S (Fc_S whatever holds them) and Fc = fric on the others.  Returns v' and
    the force friction must supply on each joint (``need``; for the free joints, fric).

    M is block diagonal (the swing is decoupled from the plane): the swing's row is
    solved on its own, the planar free joints in closed form."""
    vn = [0.0] * 4
    if 0 not in S:
        vn[0] = (Mx[0][0] * v[0] + h * (f[0] - fric[0])) / (Mx[0][0] + h * Kv[0])
    free = [j for j in (1, 2, 3) if j not in S]
    if free:
        rhs = [Mx[i][1] * v[1] + Mx[i][2] * v[2] + Mx[i][3] * v[3] + h * (f[i] - fric[i]) for i in free]
        if len(free) == 3:
            vn[1], vn[2], vn[3] = _solve3(Mx[1][1] + h * Kv[1], Mx[1][2], Mx[1][3], Mx[2][2] + h * Kv[2],
                                          Mx[2][3], Mx[3][3] + h * Kv[3], *rhs)
        elif len(free) == 2:
            i, j = free
            a00, a01, a11 = Mx[i][i] + h * Kv[i], Mx[i][j], Mx[j][j] + h * Kv[j]
            det = a00 * a11 - a01 * a01
            vn[i] = (a11 * rhs[0] - a01 * rhs[1]) / det
            vn[j] = (a00 * rhs[1] - a01 * rhs[0]) / det
        else:
            i = free[0]
            vn[i] = rhs[0] / (Mx[i][i] + h * Kv[i])
    dv0, dv1, dv2, dv3 = vn[0] - v[0], vn[1] - v[1], vn[2] - v[2], vn[3] - v[3]
    need = [f[0] - Kv[0] * vn[0] - Mx[0][0] * dv0 / h]
    for i in (1, 2, 3):
        Mi = Mx[i]
        need.append(f[i] - Kv[i] * vn[i] - (Mi[1] * dv1 + Mi[2] * dv2 + Mi[3] * dv3) / h)
    return vn, need


def advance_linkage(state, p_a, p_b, f_tip, dt: float, ex: Excavator = _DEFAULT,
                    payload: float = 0.0, max_substep: float = 2.5e-4, locked=(), forces=None,
                    refresh: int = 1, friction=None):
    """Advance the four-joint linkage ``dt`` [s] with held pressures and tip force.

    Parameters
    ----------
    state : (x, v)
        Piston positions [m] (each in [0, L]) and velocities [m/s], 4-vectors.
    p_a, p_b : 4-vectors
        Absolute chamber pressures [Pa], held over ``dt``.
    f_tip : 3-vector
        Force [N] of the environment on the bucket tip, world frame, held.
    locked : iterable of joint indices or names
        Joints held at rest whatever the forces (for the boom-only reduction).
    forces : 4-vector, optional
        Cylinder forces [N] to use instead of those of the pressures.
    refresh : int
        The posture's terms (M_x, the bias, the lever arms, the tip force's torques) are
        evaluated at the first of every ``refresh`` substeps and kept over the others
        (1: every substep).
    friction : 4-sequence of callables or None, optional
        Per joint, the friction of its cylinder where an effect changes it (the
        ``friction`` stage of the catalogue of effects: a Stribeck curve, the seals'
        pressure): ``friction[j](v, p_a, p_b) -> (K_v, F_s, F_d)`` at the joint's piston
        speed [m/s] and absolute chamber pressures [Pa], evaluated at each substep's
        start and frozen over it (as ``physics.advance_load``'s ``load_at``); ``None``
        (or a ``None`` entry): the excavator's constant K_v, F_s, F_d.

    Each substep (at most ``max_substep`` long) freezes M_x, the bias, the lever arms
    and the forces at its start and solves ``M_x (v' - v) = h (F - bias - K_v v' - F_c)``
    for v' (implicit in the viscous friction), then ``x' = x + h v'``.  Eq. 9 per
    cylinder: a joint at rest, or one whose velocity would reverse within the substep,
    is tried stuck (v' = 0); it stays stuck while the force that holds it, given the
    others' motion, is within ``F_s cos(phi)`` (boom) or ``F_s``; the worst violator
    breaks away (Coulomb ``F_d`` against the force) and the remaining combination is
    solved again, so at most a few of the sixteen stick/slip combinations are tried.  At
    the stops x = 0 and x = L a piston pushed into the stop is held (v = 0, no bounce),
    and x never leaves [0, L].

    The arithmetic is on plain floats with the excavator's constants prepared once
    (:class:`_Prepared`), the rigid-body terms in closed form (:func:`_rigid_terms`)
    and the planar 3x3 solve by Cramer's rule: NumPy's call overhead is larger than
    these small systems' work.

    Returns ``(x, v)`` as new arrays.
    """
    P = _prepared(ex, float(payload))
    x = [float(t) for t in state[0]]
    v = [float(t) for t in state[1]]
    L, Kv, Fs, Fd = P.L, P.Kv, P.Fs, P.Fd
    lockset = {JOINTS.index(j) if isinstance(j, str) else int(j) for j in locked}
    hooks = [(j, fn) for j, fn in enumerate(friction or ()) if fn is not None]
    if hooks:                                       # per-substep levels: copies, P's are shared
        Kv, Fs, Fd = list(Kv), list(Fs), list(Fd)
    if forces is None:
        A_a, A_b, P_atm = P.A_a, P.A_b, P.P_atm
        Fp = [float(p_a[j]) * A_a[j] - float(p_b[j]) * A_b[j] - P_atm * (A_a[j] - A_b[j]) for j in range(4)]
    else:
        Fp = [float(t) for t in forces]
    f_tip = [float(t) for t in f_tip]
    has_tip = f_tip[0] != 0.0 or f_tip[1] != 0.0 or f_tip[2] != 0.0
    n = max(1, math.ceil(dt / max_substep - 1e-9))
    h = dt / n
    refresh = max(1, int(refresh))
    for k in range(n):
        for j in lockset:
            v[j] = 0.0
        if k % refresh == 0:
            q, lam, dlam, cos_phi = _fast_posture(x, P)
            M, Cq, G = _rigid_terms(q, [lam[j] * v[j] for j in range(4)], P)
            Mx = [[lam[i] * M[i][j] * lam[j] for j in range(4)] for i in range(4)]
            acc = [dlam[j] * v[j] * v[j] for j in range(4)]
            f = [Fp[i] - lam[i] * (M[i][0] * acc[0] + M[i][1] * acc[1] + M[i][2] * acc[2] + M[i][3] * acc[3]
                                   + Cq[i] + G[i]) for i in range(4)]
            if has_tip:
                tau = _fast_tip_torques(q, f_tip, P)
                f = [f[i] + lam[i] * tau[i] for i in range(4)]
            scale = (1.0, cos_phi, 1.0, 1.0)
            cap = [Fs[j] * scale[j] for j in range(4)]
        for j, fn in hooks:
            Kv[j], Fs[j], Fd[j] = fn(v[j], float(p_a[j]), float(p_b[j]))
            cap[j] = Fs[j] * scale[j]
        S = set(lockset)
        direction = [0.0] * 4
        for j in range(4):
            if v[j] == 0.0:
                S.add(j)
            else:
                direction[j] = 1.0 if v[j] > 0.0 else -1.0
        released = set()
        stops = {}                                  # joint -> the stop it reaches in this substep
        vn = v
        for _it in range(12):
            fric = [Fd[j] * scale[j] * direction[j] for j in range(4)]
            vn, need = _solve_step(Mx, f, v, Kv, h, S, fric)
            # stuck joints whose holding force exceeds static friction (or the stop)
            worst, excess = None, 0.0
            for j in S:
                if j in lockset or j in stops:
                    continue
                hi = math.inf if x[j] >= L[j] else cap[j]   # at x = L the stop takes any push outward
                lo = math.inf if x[j] <= 0.0 else cap[j]    # at x = 0 any push inward
                e = max(need[j] - hi, -need[j] - lo)
                if e > excess:
                    worst, excess = j, e
            if worst is not None:
                S.discard(worst)
                released.add(worst)
                direction[worst] = 1.0 if need[worst] > 0.0 else -1.0
                continue
            changed = False
            for j in range(4):
                if j in S:
                    continue
                xn = x[j] + h * vn[j]
                if xn < 0.0 or xn > L[j]:          # reaches a stop within the substep: held there
                    S.add(j)
                    stops[j] = 0.0 if xn < 0.0 else L[j]
                    changed = True
                elif direction[j] * vn[j] < 0.0 and j not in released:   # would reverse: try it stuck
                    S.add(j)
                    changed = True
            if not changed:
                break
        for j in released:
            if direction[j] * vn[j] < 0.0:
                vn[j] = 0.0
        xn = [x[j] + h * vn[j] for j in range(4)]
        for j, target in stops.items():
            xn[j] = target
        for j in range(4):
            if xn[j] <= 0.0:
                xn[j] = 0.0
                if vn[j] < 0.0:
                    vn[j] = 0.0
            elif xn[j] >= L[j]:
                xn[j] = L[j]
                if vn[j] > 0.0:
                    vn[j] = 0.0
        x, v = xn, vn
    return np.array(x), np.array(v)


# --- the machine from named values (a machine file, a sidecar, the linkage FMU) ------------

#: An actuator's values by name, per joint as ``<field>_<joint>`` (the linkage FMU's names).
ACTUATOR_FIELDS = ("bore", "rod", "stroke", "c1", "c2", "l_min", "lower", "A_max", "V_a0", "V_b0", "K_v", "F_s", "F_d")
#: A link's values by name, as ``<field>_<link>`` (its inertia follows: a slender rod, m L^2 / 12).
LINK_FIELDS = ("length", "mass", "com")
#: The machine's own values by name.
MACHINE_FIELDS = {"h": "boom_h", "pivot_forward": "pivot_forward", "pivot_height": "pivot_height", "P_atm": "P_atm"}


def excavator_value_names() -> tuple:
    """Every name :func:`excavator_from_values` takes (``lower_boom`` is not one: the
    boom's angle is Eq. 12's own)."""
    return (*(f"{f}_{j}" for j in JOINTS for f in ACTUATOR_FIELDS if not (f == "lower" and j == "boom")),
            *(f"{f}_{n}" for n in LINKS for f in LINK_FIELDS), *MACHINE_FIELDS)


def excavator_from_values(values: dict, base: Excavator = _DEFAULT) -> Excavator:
    """``base`` with the named ``values`` [SI] in place (names of
    :func:`excavator_value_names`), checked (:func:`check_excavator`, naming the value).
    ``ParameterError`` for a name it does not know."""
    known = set(excavator_value_names())
    for k in values:
        if k not in known:
            raise ParameterError(k, values[k], "is not a value of the excavator (excavator.md): "
                                               "<field>_<joint>, <field>_<link>, h, pivot_forward, pivot_height, P_atm")
    acts = {}
    for j in JOINTS:
        mine = {f: float(values[f"{f}_{j}"]) for f in ACTUATOR_FIELDS if f"{f}_{j}" in values}
        if mine:
            acts[j] = replace(getattr(base, j), **mine)
    links = {}
    for n, link in zip(LINKS, base.links):
        mine = {f: float(values[f"{f}_{n}"]) for f in LINK_FIELDS if f"{f}_{n}" in values}
        if mine:
            new = replace(link, **mine)
            links[f"{n}_link"] = replace(new, inertia=_rod_inertia(new.mass, new.length))
    own = {field_: float(values[k]) for k, field_ in MACHINE_FIELDS.items() if k in values}
    ex = replace(base, **acts, **links, **own)
    check_excavator(ex)
    return ex


__all__ = ["JOINTS", "LINKS", "G_EARTH", "Link", "Actuator", "Excavator", "excavator_parameters", "check_excavator",
           "joint_angles", "pistons_from_angles", "joint_limits", "lever_arms", "friction_scale", "forward_kinematics",
           "tip_position", "angles_and_tip", "holding_forces", "mass_matrix", "mass_matrix_derivative", "coriolis",
           "gravity", "potential_energy", "kinetic_energy", "tip_jacobian", "cylinder_forces", "cylinder_torques",
           "tip_torques", "piston_dynamics", "piston_accelerations", "lumped_boom_load", "advance_linkage",
           "ACTUATOR_FIELDS", "LINK_FIELDS", "MACHINE_FIELDS", "excavator_value_names", "excavator_from_values"]
