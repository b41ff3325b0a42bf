#!/usr/bin/env python3
"""A second, independent simulator of the whole excavator (four joints) for blind benchmarks.

Written from ``shared/spec/excavator.md``, ``reference-rig.md`` and ``effects.md`` (and the
values ``docs/excavator.md`` documents where the spec leaves a choice open: the joint
angles' offsets, Eq. 9's cos(phi) on the boom only, the start at the holding pressures)
only: nothing here comes from ``boomfmi.physics``, ``boomfmi.model``, ``boomfmi.rig``,
``boomfmi.identify`` or ``boomfmi.diagnose``, so that a diagnosis run on these
recordings never meets its own numerics or its own effect laws.  ``boomfmi.recording``
is used only to write the CSV and its sidecar (:func:`write`).

The machine
-----------
* **Linkage.**  Swing angle theta (about z), and in the vertical plane of the upper
  structure the links' pitches (absolute angles above the horizontal)
  ``psi_b = alpha - asin(h/a)``, ``psi_a = psi_b - theta_arm``,
  ``psi_k = psi_a - theta_bucket``.  The planar chain is written in the absolute pitches:
  ``M_jk = A_jk cos(psi_j - psi_k)`` (``A_jk = sum_i m_i l_ij l_ik + I_j delta_jk``, ``l_ij``
  link j's length for a later link i, its centre of mass for i = j), Coriolis and
  centrifugal ``A_jk sin(psi_j - psi_k) psi_k'^2``, gravity ``g cos(psi_j) sum_i m_i l_ij``;
  the swing's inertia ``J_z = I_us + sum m_i r_i^2 + sum I_i cos^2 psi_i`` (a slender rod
  has no inertia about its own axis) with its coupling ``J_z' theta'`` and the planar
  joints' centrifugal ``-1/2 dJ_z/dpsi theta'^2``.  Mapped to the joint angles (a linear
  map) and from there to the piston coordinates by each mounting triangle
  (``l^2 = c1^2 + c2^2 - 2 c1 c2 cos(gamma)``, ``q = gamma + offset``), with the second
  derivative of that map in the bias.
* **Valve** per joint: reference-rig.md's routing (u < 5 V: supply -> A, B -> exhaust) and
  orifice law (choked below P_cr), flow from the higher pressure to the lower.
* **Chambers**: ``V dP/dt + k P dV/dt = k R T mdot``; a step takes the compression
  exactly (``P (V0/V1)^k``) and adds the flows; a chamber that the flow would carry past
  its source's pressure in one step is set to it.
* **Friction per cylinder**: Eq. 9 with the boom's K_v, F_s, F_d scaled by bore area;
  cos(phi) on the boom, 1 on the others.
* **Hard end stops**, no bounce: a plastic impact, the joint held at its stop from the
  substep it reaches it in, the stop's reaction reaching the other joints through the
  mass matrix (until 2026-11-27 the velocity was zeroed alone, as if the stop's impulse
  acted on no other joint; a boom hitting its stop then left the arm and bucket
  unmoved where the linkage's inertia moves them).

The integrator
--------------
A fixed-step semi-implicit scheme of its own (``SUBSTEP``, 0.25 ms): the viscous friction
implicit; the set of joints at rest is solved with their accelerations held at zero and
the force each needs compared with its static friction (or its stop's one side), the
joint that breaks away the furthest released and the set solved again; a moving joint
whose velocity would change sign sticks; positions from the new velocities; then the
chambers.  The commands are held between the 1 ms samples.

Effects (every one of effects.md, on any joint, several forms per mechanism; the first
form of each is the catalogue's kind of law where effects.md leaves no choice, the
others differ from it on purpose): see :data:`EFFECT_FORMS` and :data:`FORM_DOCS`.
Disturbances outside the vocabulary: :data:`DISTURBANCE_FORMS`.  Sensors:
:data:`SENSOR_DEFAULTS` (angle resolution, pressure noise).

API
---
``Machine`` (payload, ``effects``: ``{joint: {name: {"form": ..., param: value}}}``,
``disturbances``: ``{name: {...}}``, ``sensors``), ``simulate(machine, profile, duration,
seed) -> DataFrame`` (the recording's columns, plus ``x_<joint>``, ``v_<joint>`` and the
noise-free sensed signals ``<column>_sensed``) and ``write(path, frame)``.

    python benchmarks/hybrid_excavator.py       # times the digging cycle
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

JOINTS = ("swing", "boom", "arm", "bucket")
SUBSTEP = 2.5e-4
G = 9.81
# gas, supply (reference-rig.md)
K, R, T0 = 1.4, 287.0, 293.15
P_ATM = 101325.0
P_S = 701325.0
CP = K * R / (K - 1.0)
P_CR = (2.0 / (K + 1.0)) ** (K / (K - 1.0))
_C_SUB = math.sqrt(2.0 * K / (R * (K - 1.0)))
_C_CHOKED = math.sqrt(K / R) * (2.0 / (K + 1.0)) ** ((K + 1.0) / (2.0 * (K - 1.0)))


@dataclass(frozen=True)
class Actuator:
    """One joint's cylinder, valve and mounting triangle (excavator.md's table)."""
    bore: float
    rod: float
    L: float
    c1: float
    c2: float
    l_min: float
    A_max: float
    V0: float
    lower_deg: float | None     #: the joint's angle at x = 0 (None: see offset rule)

    @property
    def A_a(self) -> float:
        return math.pi / 4 * self.bore ** 2

    @property
    def A_b(self) -> float:
        return math.pi / 4 * (self.bore ** 2 - self.rod ** 2)

    def gamma(self, x: float) -> float:
        l = self.l_min + x
        return math.acos((self.c1 ** 2 + self.c2 ** 2 - l * l) / (2 * self.c1 * self.c2))


BOOM_A, BOOM_B, BOOM_H = 0.15, 0.30, 0.05
ACTUATORS = {
    "swing": Actuator(0.025, 0.010, 0.050, 0.20, 0.06, 0.17, 2.0e-6, 1.0e-5, None),
    "boom": Actuator(0.032, 0.012, 0.060, BOOM_A, BOOM_B, 0.20, 4.0e-6, 1.5e-5, None),
    "arm": Actuator(0.025, 0.010, 0.080, 0.32, 0.07, 0.27, 2.0e-6, 1.0e-5, 50.0),
    "bucket": Actuator(0.020, 0.008, 0.050, 0.20, 0.05, 0.17, 2.0e-6, 1.0e-5, 30.0),
}


def _offset(j: str) -> float:
    a = ACTUATORS[j]
    if j == "boom":
        return 0.0                                     # alpha of Eq. 12 is gamma itself
    if j == "swing":                                   # the range symmetric about straight ahead
        return -0.5 * (a.gamma(0.0) + a.gamma(a.L))
    return math.radians(a.lower_deg) - a.gamma(0.0)


OFFSETS = {j: _offset(j) for j in JOINTS}
#: the boom's friction and loads at reference-rig.md's values, per cylinder by bore area
BOOM_FRICTION = {"K_v": 2829.0, "F_s": 113.255, "F_d": 85.727}
FRICTION = {j: {k: v * (ACTUATORS[j].bore / 0.032) ** 2 for k, v in BOOM_FRICTION.items()} for j in JOINTS}
# links: (length, mass, centre of mass from the pivot); upper structure's inertia about z
LINKS = ((0.60, 5.0, 0.30), (0.35, 2.5, 0.15), (0.15, 1.5, 0.08))
I_UPPER = 0.060
PIVOT_R, PIVOT_Z = 0.05, 0.20
PSI_B0 = math.asin(BOOM_H / BOOM_A)
# angle ADC ranges [rad] and the pressure converter's span [Pa gauge]
ANGLE_RANGES = {"swing": (-0.5 * math.pi, 0.5 * math.pi), "boom": (0.0, math.pi),
                "arm": (0.0, math.pi), "bucket": (0.0, math.pi)}

# ----------------------------------------------------------------------------- effects
EFFECT_FORMS = {
    "valve_dynamics": ("first_order", "second_order"),
    "valve_deadband": ("overlap", "rounded"),
    "heat_transfer": ("polytropic", "wall"),
    "piston_leakage": ("laminar", "mixed"),
    "stribeck_friction": ("exponential", "gaussian"),
    "end_cushioning": ("needle", "progressive"),
    "pressure_friction": ("linear", "seal_max"),
    "sensor_lag": ("first_order", "second_order", "dead_time"),
}
FORM_DEFAULTS = {
    ("valve_dynamics", "first_order"): {"tau": 0.005},
    ("valve_dynamics", "second_order"): {"f_n": 80.0, "zeta": 0.8},
    ("valve_deadband", "overlap"): {"d": 0.3},
    ("valve_deadband", "rounded"): {"d": 0.3, "w": 0.1},
    ("heat_transfer", "polytropic"): {"n": 1.2},
    ("heat_transfer", "wall"): {"h_c": 60.0},
    ("piston_leakage", "laminar"): {"C": 1e-11},
    ("piston_leakage", "mixed"): {"C": 5e-12, "A": 5e-9},
    ("stribeck_friction", "exponential"): {"F_brk": None, "v_s": 0.008},
    ("stribeck_friction", "gaussian"): {"F_brk": None, "v_s": 0.008},
    ("end_cushioning", "needle"): {"l_c": 0.010, "A_n": 5e-7},
    ("end_cushioning", "progressive"): {"l_c": 0.010, "A_n": 5e-7},
    ("pressure_friction", "linear"): {"c": 0.1},
    ("pressure_friction", "seal_max"): {"c": 0.1},
    ("sensor_lag", "first_order"): {"tau": 0.005},
    ("sensor_lag", "second_order"): {"f_n": 40.0, "zeta": 0.7},
    ("sensor_lag", "dead_time"): {"delay": 0.004},
}
FORM_DOCS = {
    ("valve_dynamics", "first_order"): "spool s (volts) lags the command: ds/dt = (u - s)/tau [s].",
    ("valve_dynamics", "second_order"): "spool as a damped oscillator s'' = w^2 (u - s) - 2 zeta w s', "
                                        "w = 2 pi f_n [Hz].",
    ("valve_deadband", "overlap"): "no port opens while |s - 5| <= d [V]; beyond, "
                                   "A = A_max min((|s-5| - d)/(5 - d), 1).",
    ("valve_deadband", "rounded"): "overlap with a smooth edge: the excess e = |s-5| - d becomes "
                                   "w log(1 + exp(e / w)) (softplus, w [V]), rescaled as overlap.",
    ("heat_transfer", "polytropic"): "a polytropic exponent n in place of k in the chamber equation (both terms).",
    ("heat_transfer", "wall"): "the chamber's mass as a state and the energy equation V dP/dt + k P dV/dt = "
                               "k R (T_in mdot_in - T mdot_out) + (k-1) h_c A_wall (T_wall - T), T = P V/(m R), "
                               "A_wall the barrel swept plus both ends plus a 4 mm hose holding the dead volume.",
    ("piston_leakage", "laminar"): "a laminar compressible leak mdot = C (P_hi^2 - P_lo^2) / (2 R T), C [m^3/(s Pa)].",
    ("piston_leakage", "mixed"): "the laminar leak in parallel with a turbulent gap of area A [m^2] (orifice law).",
    ("stribeck_friction", "exponential"): "F_d + (F_brk - F_d) exp(-|v|/v_s), static level F_brk (times the "
                                          "joint's cos(phi) factor).",
    ("stribeck_friction", "gaussian"): "F_d + (F_brk - F_d) exp(-(v/v_s)^2), static level F_brk.",
    ("end_cushioning", "needle"): "within l_c [m] of a stroke end the chamber being emptied vents through the "
                                  "needle only: its outflow area min(valve, A_n [m^2]).",
    ("end_cushioning", "progressive"): "the spigot closes progressively: the outflow area falls linearly from the "
                                       "valve's at l_c to A_n at the end.",
    ("pressure_friction", "linear"): "F_s and F_d grow by c [-] times the mean chamber gauge pressure times A_a.",
    ("pressure_friction", "seal_max"): "the piston seal is pressed by the higher chamber: F_s and F_d grow by c "
                                       "max(p_a, p_b, 0) (gauge) times A_a.",
    ("sensor_lag", "first_order"): "the joint's angle and pressures pass a first-order lag tau [s].",
    ("sensor_lag", "second_order"): "a second-order low-pass f_n [Hz], zeta on the joint's angle and pressures.",
    ("sensor_lag", "dead_time"): "a pure dead time delay [s] on the joint's angle and pressures.",
}
DISTURBANCE_FORMS = {
    "supply_sag": {"V_r": 1e-3, "G": 1.5e-8},
    "vibration": {"joint": "boom", "amplitude": 30.0, "frequency": 30.0},
}
DISTURBANCE_DOCS = {
    "supply_sag": "all valves draw from a reservoir V_r [m^3] (isothermal) refilled from the compressor at P_s "
                  "through a line of conductance G [kg/(s Pa)]: the supply sags while the valves draw air.",
    "vibration": "an engine's vibration: a force amplitude [N] sin(2 pi frequency t) along one joint's cylinder.",
}
#: angle converter bits, angle noise [rad], pressure noise [Pa], pressure converter bits
#: (over 0 .. 1 MPa gauge, saturating)
SENSOR_DEFAULTS = {"angle_bits": 12, "angle_noise": 2e-4, "p_noise": 500.0, "p_bits": 12}
IDEAL_SENSORS = {"angle_bits": None, "angle_noise": 0.0, "p_noise": 0.0, "p_bits": None}


@dataclass
class Machine:
    """The whole excavator: ``payload`` [kg] at the bucket's centre of mass, per-joint
    friction overrides (``friction``: ``{joint: {"K_v", "F_s", "F_d"}}``), ``effects``
    ``{joint: {name: {"form": ..., param: value}}}``, ``disturbances`` ``{name: {...}}``,
    ``sensors`` overriding :data:`SENSOR_DEFAULTS`, ``x0`` [m] per joint (mid-stroke)."""
    payload: float = 0.0
    friction: dict = field(default_factory=dict)
    effects: dict = field(default_factory=dict)
    disturbances: dict = field(default_factory=dict)
    sensors: dict = field(default_factory=dict)
    x0: dict = field(default_factory=dict)

    def effect(self, joint: str, name: str):
        """``(form, params)`` of effect ``name`` on ``joint``, or None."""
        conf = (self.effects.get(joint) or {}).get(name)
        if not conf:
            return None
        conf = dict(conf)
        form = conf.pop("form", EFFECT_FORMS[name][0])
        if form not in EFFECT_FORMS[name]:
            raise ValueError(f"effect {name!r} on {joint} has no form {form!r}; forms: {', '.join(EFFECT_FORMS[name])}")
        params = dict(FORM_DEFAULTS[(name, form)])
        unknown = set(conf) - set(params)
        if unknown:
            raise ValueError(f"effect {name!r} ({form}) on {joint}: unknown parameter(s) {sorted(unknown)}")
        params.update(conf)
        return form, params

    def check(self) -> None:
        for j, effs in self.effects.items():
            if j not in JOINTS:
                raise ValueError(f"unknown joint {j!r}; the joints are {', '.join(JOINTS)}")
            for n in effs:
                if n not in EFFECT_FORMS:
                    raise ValueError(f"unknown effect {n!r} on {j}; known: {', '.join(EFFECT_FORMS)}")
                self.effect(j, n)
        for n in self.disturbances:
            if n not in DISTURBANCE_FORMS:
                raise ValueError(f"unknown disturbance {n!r}; known: {', '.join(DISTURBANCE_FORMS)}")


# ----------------------------------------------------------------------------- kinematics
def piston_map(x):
    """Joint angles q, dq/dx and d2q/dx2 (each a 4-array) at piston positions x."""
    q, d1, d2 = np.empty(4), np.empty(4), np.empty(4)
    for i, j in enumerate(JOINTS):
        a = ACTUATORS[j]
        l = a.l_min + x[i]
        c = (a.c1 ** 2 + a.c2 ** 2 - l * l) / (2 * a.c1 * a.c2)
        g = math.acos(min(max(c, -1.0), 1.0))
        s = math.sin(g)
        dg = l / (a.c1 * a.c2 * s)                       # dgamma/dl
        q[i] = g + OFFSETS[j]
        d1[i] = dg
        d2[i] = (s - l * math.cos(g) * dg) / (a.c1 * a.c2 * s * s)
    return q, d1, d2


_S = np.array([[1.0, 0.0, 0.0], [1.0, -1.0, 0.0], [1.0, -1.0, -1.0]])   # pitches from (alpha, th_a, th_k)


def _chain(payload: float):
    """A_jk with and without the rods' own inertia, and each link's sum_i m_i l_ij."""
    masses = [LINKS[0][1], LINKS[1][1], LINKS[2][1] + payload]
    lij = np.zeros((3, 3))
    for i in range(3):
        for j in range(i + 1):
            lij[i, j] = LINKS[j][0] if j < i else LINKS[i][2]
    m = np.array(masses)
    A = np.einsum("i,ij,ik->jk", m, lij, lij)
    inertia = np.array([LINKS[i][1] * LINKS[i][0] ** 2 / 12.0 for i in range(3)])
    return A, inertia, lij, m


def dynamics(x, v, payload: float, cache=None):
    """Piston coordinates: ``(M_x, bias_x)`` with ``M_x x'' + bias_x = F`` (the
    cylinders' forces, positive extending)."""
    A, inertia, lij, m = cache if cache is not None else _chain(payload)
    q, d1, d2 = piston_map(x)
    qd = d1 * v
    theta_d = qd[0]
    psi = _S @ q[1:] - np.array([PSI_B0, PSI_B0, PSI_B0])
    psid = _S @ qd[1:]
    cp, sp = np.cos(psi), np.sin(psi)
    diff = psi[:, None] - psi[None, :]
    Mp = A * np.cos(diff) + np.diag(inertia)
    hp = (A * np.sin(diff)) @ (psid ** 2)
    Gp = G * cp * (m @ lij)
    r = PIVOT_R + lij @ cp                              # each centre of mass's distance from the axis
    Jz = I_UPPER + float(m @ r ** 2) + float(inertia @ cp ** 2)
    dJz = -2.0 * (m * r) @ lij * sp - inertia * np.sin(2 * psi)
    Mq = np.zeros((4, 4))
    Mq[0, 0] = Jz
    Mq[1:, 1:] = _S.T @ Mp @ _S
    hq = np.empty(4)
    hq[0] = float(dJz @ psid) * theta_d
    hq[1:] = _S.T @ (hp - 0.5 * dJz * theta_d ** 2 + Gp)
    Mx = d1[:, None] * Mq * d1[None, :]
    bias = d1 * (Mq @ (d2 * v * v) + hq)
    return Mx, bias


def boom_cos_phi(x_boom: float) -> float:
    """cos(phi) of Eq. 10 at the boom's piston position."""
    l = ACTUATORS["boom"].l_min + x_boom
    phi = math.pi - math.asin(BOOM_H / BOOM_A) - math.acos((BOOM_A ** 2 + l * l - BOOM_B ** 2) / (2 * BOOM_A * l))
    return math.cos(phi)


def tip_position(q) -> np.ndarray:
    """The bucket tip in the world frame [m] at joint angles q."""
    psi = _S @ np.asarray(q)[1:] - PSI_B0
    rr = PIVOT_R + sum(LINKS[i][0] * math.cos(psi[i]) for i in range(3))
    z = PIVOT_Z + sum(LINKS[i][0] * math.sin(psi[i]) for i in range(3))
    return np.array([rr * math.cos(q[0]), rr * math.sin(q[0]), z])


def holding_pressures(x, payload: float = 0.0):
    """Absolute chamber pressures that hold the pistons at x at rest against gravity (the
    holding force on the side that pushes, the other chamber at P_atm)."""
    _, bias = dynamics(np.asarray(x, float), np.zeros(4), payload)
    pa = [P_ATM + max(F, 0.0) / ACTUATORS[j].A_a for F, j in zip(bias, JOINTS)]
    pb = [P_ATM + max(-F, 0.0) / ACTUATORS[j].A_b for F, j in zip(bias, JOINTS)]
    return pa, pb


# ----------------------------------------------------------------------------- pneumatics
def orifice(A: float, p_u: float, p_d: float, T: float = T0) -> float:
    """Mass flow [kg/s] from p_u to p_d (p_u >= p_d) through area A (reference-rig.md)."""
    if A <= 0.0 or p_u <= p_d:
        return 0.0
    r = p_d / p_u
    if r < P_CR:
        return A * p_u * _C_CHOKED / math.sqrt(T)
    return A * p_u * _C_SUB / math.sqrt(T) * math.sqrt(max(r ** (2.0 / K) - r ** ((K + 1.0) / K), 0.0))


def flow(A: float, p_src: float, p_ch: float, T_src: float = T0, T_ch: float = T0) -> float:
    """Signed mass flow [kg/s] into a chamber at p_ch from a source at p_src."""
    if p_src >= p_ch:
        return orifice(A, p_src, p_ch, T_src)
    return -orifice(A, p_ch, p_src, T_ch)


def _opening(s: float, deadband) -> float:
    """Fraction of A_max open at spool position s [V] (with the deadband's form)."""
    e = abs(s - 5.0)
    if deadband is None:
        return min(e / 5.0, 1.0)
    form, p = deadband
    d = p["d"]
    if form == "overlap":
        ex = e - d
    else:
        w = p["w"]
        z = (e - d) / w
        ex = w * (z + math.log1p(math.exp(-z))) if z > 0 else w * math.log1p(math.exp(z))
    return min(max(ex, 0.0) / (5.0 - d), 1.0)


# ----------------------------------------------------------------------------- the solve
class _Joint:
    """A joint's switched-on effects, resolved once."""

    def __init__(self, machine: Machine, j: str):
        self.name = j
        self.act = ACTUATORS[j]
        fr = dict(FRICTION[j], **(machine.friction.get(j) or {}))
        self.K_v, self.F_s, self.F_d = fr["K_v"], fr["F_s"], fr["F_d"]
        e = lambda n: machine.effect(j, n)
        self.spool = e("valve_dynamics")
        self.deadband = e("valve_deadband")
        self.heat = e("heat_transfer")
        self.leak = e("piston_leakage")
        self.stribeck = e("stribeck_friction")
        if self.stribeck and self.stribeck[1]["F_brk"] is None:
            self.stribeck[1]["F_brk"] = 1.6 * self.F_d
        self.cushion = e("end_cushioning")
        self.pfric = e("pressure_friction")
        self.lag = e("sensor_lag")
        self.n = self.heat[1]["n"] if self.heat and self.heat[0] == "polytropic" else K
        self.wall = self.heat[1]["h_c"] if self.heat and self.heat[0] == "wall" else None
        a = self.act
        self.hose = 4.0 * a.V0 / 0.004          # wall of a 4 mm bore hose holding the dead volume [m^2]

    def levels(self, v: float, x: float, pa: float, pb: float) -> tuple[float, float]:
        """(static level, kinetic level at speed v) [N], both >= 0."""
        fac = boom_cos_phi(x) if self.name == "boom" else 1.0
        Fs, Fd = self.F_s, self.F_d
        if self.stribeck:
            form, p = self.stribeck
            Fs = p["F_brk"]
            w = math.exp(-abs(v) / p["v_s"]) if form == "exponential" else math.exp(-(v / p["v_s"]) ** 2)
            Fk = Fd + (Fs - Fd) * w
        else:
            Fk = Fd
        if self.pfric:
            form, p = self.pfric
            ga, gb = pa - P_ATM, pb - P_ATM
            press = 0.5 * (ga + gb) if form == "linear" else max(ga, gb, 0.0)
            extra = p["c"] * max(press, 0.0) * self.act.A_a
            Fs, Fk = Fs + extra, Fk + extra
        return Fs * fac, Fk * fac


def _sources(u_eff: float, p_sup: float):
    """(source of A, source of B) pressures and which is the supply (reference-rig.md)."""
    if u_eff < 5.0:
        return p_sup, P_ATM, True, False
    return P_ATM, p_sup, False, True


def simulate(machine: Machine, profile, duration: float | None = None, seed: int = 0, fs: float = 1000.0,
             substep: float = SUBSTEP) -> pd.DataFrame:
    """Run ``machine`` under ``profile(t) -> {"u_<joint>": V}`` for ``duration`` s (the
    profile's ``.duration`` where not given); one row per sample (t = k / fs): the
    recording's columns (noise and converters per ``machine.sensors``, the command
    applied from t on), the truth ``x_<joint>``, ``v_<joint>`` and the noise-free sensed
    signals ``angle_<joint>_sensed``, ``p_a_<joint>_sensed``, ``p_b_<joint>_sensed``."""
    machine.check()
    duration = float(duration if duration is not None else profile.duration)
    joints = [_Joint(machine, j) for j in JOINTS]
    acts = [jt.act for jt in joints]
    cache = _chain(machine.payload)
    n_sub = max(1, int(round(1.0 / (fs * substep))))
    h = 1.0 / (fs * n_sub)
    n = int(round(duration * fs))
    x = np.array([machine.x0.get(j, 0.5 * a.L) for j, a in zip(JOINTS, acts)], float)
    v = np.zeros(4)
    pa, pb = (np.array(p) for p in holding_pressures(x, machine.payload))
    # chamber masses (the wall form's state)
    Va = np.array([a.A_a * x[i] + a.V0 for i, a in enumerate(acts)])
    Vb = np.array([a.A_b * (a.L - x[i]) + a.V0 for i, a in enumerate(acts)])
    ma, mb = pa * Va / (R * T0), pb * Vb / (R * T0)
    spool = np.full(4, 5.0)
    spool_d = np.zeros(4)
    sag = machine.disturbances.get("supply_sag")
    if sag:
        sag = dict(DISTURBANCE_FORMS["supply_sag"], **sag)
    vib = machine.disturbances.get("vibration")
    if vib:
        vib = dict(DISTURBANCE_FORMS["vibration"], **vib)
        if vib["joint"] not in JOINTS:
            raise ValueError(f"vibration on unknown joint {vib['joint']!r}")
        vib_i = JOINTS.index(vib["joint"])
    p_sup = P_S
    Kv = np.array([jt.K_v for jt in joints])
    out_t = np.empty(n + 1)
    out_u = np.empty((n + 1, 4))
    out_x, out_v = np.empty((n + 1, 4)), np.empty((n + 1, 4))
    out_pa, out_pb = np.empty((n + 1, 4)), np.empty((n + 1, 4))
    for k in range(n + 1):
        t = k / fs
        cmd = profile(t)
        u = np.array([min(max(float(cmd[f"u_{j}"]), 0.0), 10.0) for j in JOINTS])
        out_t[k], out_u[k] = t, u
        out_x[k], out_v[k], out_pa[k], out_pb[k] = x, v, pa, pb
        if k == n:
            break
        for s in range(n_sub):
            ts = t + s * h
            # ---- spools
            for i, jt in enumerate(joints):
                if jt.spool is None:
                    spool[i] = u[i]
                elif jt.spool[0] == "first_order":
                    spool[i] = u[i] + (spool[i] - u[i]) * math.exp(-h / jt.spool[1]["tau"])
                else:
                    w = 2 * math.pi * jt.spool[1]["f_n"]
                    zeta = jt.spool[1]["zeta"]
                    # semi-implicit (the damping implicit): stable for w h < 2
                    spool_d[i] = (spool_d[i] + h * w * w * (u[i] - spool[i])) / (1.0 + 2 * zeta * w * h)
                    spool[i] += h * spool_d[i]
            # ---- mechanics
            F = np.array([pa[i] * a.A_a - pb[i] * a.A_b - P_ATM * (a.A_a - a.A_b) for i, a in enumerate(acts)])
            if vib:
                F[vib_i] += vib["amplitude"] * math.sin(2 * math.pi * vib["frequency"] * ts)
            Mx, bias = dynamics(x, v, machine.payload, cache)
            Meff = Mx + np.diag(h * Kv)
            rhs = F - bias - Kv * v
            levels = [jt.levels(v[i], x[i], pa[i], pb[i]) for i, jt in enumerate(joints)]
            fric = np.zeros(4)
            rest = [i for i in range(4) if v[i] == 0.0]
            for i in range(4):
                if v[i] != 0.0:
                    fric[i] = -math.copysign(levels[i][1], v[i])
            released = {}
            held_at = {}       # joint -> the stop (0 or L) it reaches within this substep: held there
            while True:
                while True:
                    free = [i for i in range(4) if i not in rest]
                    a = np.zeros(4)
                    held = list(held_at)
                    for i in held:                   # brought to rest within the substep by its stop
                        a[i] = -v[i] / h
                    b = rhs + fric
                    if free:
                        a[free] = np.linalg.solve(Meff[np.ix_(free, free)],
                                                  b[free] - Meff[np.ix_(free, held)] @ a[held] if held else b[free])
                    if not rest:
                        break
                    need = Meff[rest] @ a - b[rest]            # the force each resting joint needs to stay
                    worst, wi = 0.0, None
                    for r_i, f_need in zip(rest, need):
                        if r_i in held_at:
                            continue                             # on its stop in this substep: the stop holds it
                        Fs = levels[r_i][0]
                        lo, hi = -Fs, Fs
                        if x[r_i] <= 0.0:
                            hi = math.inf                    # the stop pushes outwards without limit
                        if x[r_i] >= acts[r_i].L:
                            lo = -math.inf
                        over = max(lo - f_need, f_need - hi, 0.0)
                        if over > worst:
                            worst, wi = over, r_i
                    if wi is None:
                        break
                    f_need = need[rest.index(wi)]
                    d = -math.copysign(1.0, f_need)           # the way it breaks away
                    released[wi] = d
                    fric[wi] = -d * levels[wi][1]
                    rest.remove(wi)
                v_new = v + h * a
                for i in range(4):
                    if i in rest:
                        v_new[i] = 0.0
                    elif i in released:
                        if v_new[i] * released[i] <= 0.0:
                            v_new[i] = 0.0
                    elif v[i] != 0.0 and v_new[i] * v[i] <= 0.0:
                        v_new[i] = 0.0                         # the velocity's sign change: it sticks
                # a joint that reaches its stop within the substep is held there, and the
                # substep solved again with it held: its stop's reaction (a plastic impact)
                # reaches the other joints through the mass matrix, as the stop's force would
                hits = {}
                for i, ac in enumerate(acts):
                    if i not in rest:
                        xn = x[i] + h * v_new[i]
                        if xn < 0.0 or xn > ac.L:
                            hits[i] = 0.0 if xn < 0.0 else ac.L
                if not hits:
                    break
                for i, target in hits.items():
                    held_at[i] = target
                    rest.append(i)
                    fric[i] = 0.0
                    released.pop(i, None)
            x_new = x + h * v_new
            for i, target in held_at.items():
                x_new[i] = target
            for i, ac in enumerate(acts):
                if x_new[i] <= 0.0:
                    x_new[i] = 0.0
                    if v_new[i] < 0.0:
                        v_new[i] = 0.0
                elif x_new[i] >= ac.L:
                    x_new[i] = ac.L
                    if v_new[i] > 0.0:
                        v_new[i] = 0.0
            # ---- chambers
            supply_draw = 0.0
            for i, (jt, ac) in enumerate(zip(joints, acts)):
                src_a, src_b, a_sup, b_sup = _sources(spool[i], p_sup)
                area = ac.A_max * _opening(spool[i], jt.deadband)
                area_a_out = area_b_out = area
                if jt.cushion:
                    form, p = jt.cushion
                    for side, dist in (("a", x_new[i]), ("b", ac.L - x_new[i])):
                        if dist < p["l_c"]:
                            if form == "needle":
                                lim = p["A_n"]
                            else:
                                lim = p["A_n"] + (area - p["A_n"]) * dist / p["l_c"]
                            if side == "a":
                                area_a_out = min(area, lim)
                            else:
                                area_b_out = min(area, lim)
                Ta = pa[i] * (ac.A_a * x[i] + ac.V0) / (ma[i] * R) if jt.wall else T0
                Tb = pb[i] * (ac.A_b * (ac.L - x[i]) + ac.V0) / (mb[i] * R) if jt.wall else T0
                qa = flow(area if src_a >= pa[i] else area_a_out, src_a, pa[i], T0, Ta)
                qb = flow(area if src_b >= pb[i] else area_b_out, src_b, pb[i], T0, Tb)
                if a_sup:
                    supply_draw += qa
                if b_sup:
                    supply_draw += qb
                ql = 0.0                                  # leak from A to B
                if jt.leak:
                    form, p = jt.leak
                    hi_, lo_ = max(pa[i], pb[i]), min(pa[i], pb[i])
                    m_l = p["C"] * (hi_ * hi_ - lo_ * lo_) / (2 * R * T0)
                    if form == "mixed":
                        m_l += orifice(p["A"], hi_, lo_, T0)
                    ql = m_l if pa[i] > pb[i] else -m_l
                Va0, Va1 = ac.A_a * x[i] + ac.V0, ac.A_a * x_new[i] + ac.V0
                Vb0, Vb1 = ac.A_b * (ac.L - x[i]) + ac.V0, ac.A_b * (ac.L - x_new[i]) + ac.V0
                na = nb = jt.n
                for side in ("a", "b"):
                    if side == "a":
                        p0, V0_, V1_, q_in, src, m0, Tc = pa[i], Va0, Va1, qa - ql, src_a, ma[i], Ta
                    else:
                        p0, V0_, V1_, q_in, src, m0, Tc = pb[i], Vb0, Vb1, qb + ql, src_b, mb[i], Tb
                    if jt.wall:
                        # energy equation with the chamber's own temperature and the wall's heat
                        A_w = jt.hose + 2 * ac.A_a + math.pi * ac.bore * (V1_ - ac.V0) / ac.A_a
                        T_in_flow = T0 if q_in > 0 else Tc
                        Q = jt.wall * A_w * (T0 - Tc)
                        dp = h * (K * R * T_in_flow * q_in + (K - 1.0) * Q) / V1_
                        p1 = p0 * (V0_ / V1_) ** K + dp
                        m1 = m0 + h * q_in
                    else:
                        nn = na if side == "a" else nb
                        p1 = p0 * (V0_ / V1_) ** nn + h * nn * R * T0 * q_in / V1_
                        m1 = m0
                    # the valve's flow may not carry the chamber past its source's pressure in a step
                    comp = p0 * (V0_ / V1_) ** (K if jt.wall else (na if side == "a" else nb))
                    if (comp - src) * (p1 - src) < 0.0 and abs(q_in) > 0.0:
                        p1 = src
                    p1 = max(p1, 1.0)
                    if side == "a":
                        pa[i], ma[i] = p1, max(m1, 1e-12)
                    else:
                        pb[i], mb[i] = p1, max(m1, 1e-12)
            if sag:
                # isothermal reservoir: refilled through G from the compressor at P_S
                p_sup += h * R * T0 / sag["V_r"] * (sag["G"] * (P_S - p_sup) - supply_draw)
                p_sup = min(max(p_sup, P_ATM), P_S)
            x, v = x_new, v_new
    return _measure(machine, joints, out_t, out_u, out_x, out_v, out_pa, out_pb, seed, fs)


def _lagged(y: np.ndarray, fs: float, lag) -> np.ndarray:
    if lag is None:
        return y
    from scipy.signal import bilinear, lfilter, lfilter_zi
    form, p = lag
    if form == "dead_time":
        t = np.arange(len(y)) / fs
        return np.interp(t - p["delay"], t, y, left=y[0])
    if form == "first_order":
        b, a = bilinear([1.0], [p["tau"], 1.0], fs)
    else:
        w = 2 * math.pi * p["f_n"]
        b, a = bilinear([w * w], [1.0, 2 * p["zeta"] * w, w * w], fs)
    out, _ = lfilter(b, a, y, zi=lfilter_zi(b, a) * y[0])
    return out


def _quantise(y: np.ndarray, lo: float, hi: float, bits) -> np.ndarray:
    if bits is None:
        return y
    lsb = (hi - lo) / 2 ** bits
    return lo + np.clip(np.floor((y - lo) / lsb), 0, 2 ** bits - 1) * lsb


def _measure(machine, joints, t, u, x, v, pa, pb, seed, fs) -> pd.DataFrame:
    sens = dict(SENSOR_DEFAULTS, **machine.sensors)
    rng = np.random.default_rng(seed)
    cols = {"t": np.round(t, 9)}
    for i, j in enumerate(JOINTS):
        cols[f"u_{j}"] = u[:, i]
    q = np.array([piston_map(xx)[0] for xx in x])
    sensed = {}
    for i, (j, jt) in enumerate(zip(JOINTS, joints)):
        sensed[f"p_a_{j}"] = _lagged(pa[:, i] - P_ATM, fs, jt.lag)
        sensed[f"p_b_{j}"] = _lagged(pb[:, i] - P_ATM, fs, jt.lag)
        sensed[f"angle_{j}"] = _lagged(q[:, i], fs, jt.lag)
    for key in ("p_a", "p_b"):
        for j in JOINTS:
            y = sensed[f"{key}_{j}"] + sens["p_noise"] * rng.standard_normal(len(t))
            cols[f"{key}_{j}"] = _quantise(y, 0.0, 1.0e6, sens["p_bits"])
    for j in JOINTS:
        y = sensed[f"angle_{j}"] + sens["angle_noise"] * rng.standard_normal(len(t))
        cols[f"angle_{j}"] = _quantise(y, *ANGLE_RANGES[j], sens["angle_bits"])
    for i, j in enumerate(JOINTS):
        cols[f"x_{j}"] = x[:, i]
        cols[f"v_{j}"] = v[:, i]
    for name, y in sensed.items():
        cols[f"{name}_sensed"] = y
    df = pd.DataFrame(cols)
    df.attrs.update(fs=fs, seed=seed)
    return df


RECORDING_COLUMNS = ("t",) + tuple(f"{q}_{j}" for q in ("u", "p_a", "p_b", "angle") for j in JOINTS)


def write(path, frame: pd.DataFrame, machine: Machine | None = None, notes: str = "") -> Path:
    """Write ``frame`` as an excavator recording: ``path`` (CSV, the recording's required
    columns only) with a sidecar holding ``notes`` only (the reference machine applies),
    and, with ``machine``, ``<name>.truth.json`` beside it (the hidden payload, friction,
    effects, disturbances and sensors; never read by the diagnosis)."""
    from boomfmi.recording import write_recording
    path = Path(path)
    sidecar = {"notes": notes or "benchmarks/hybrid_excavator.py (an independent simulator)"}
    write_recording(path, frame[list(RECORDING_COLUMNS)], sidecar=sidecar)
    if machine is not None:
        truth = {"payload": machine.payload, "friction": machine.friction, "effects": machine.effects,
                 "disturbances": machine.disturbances, "sensors": machine.sensors,
                 "simulator": "benchmarks/hybrid_excavator.py"}
        path.with_suffix(".truth.json").write_text(json.dumps(truth, indent=1, default=str))
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=None)
    args = ap.parse_args(argv)
    from boomfmi.experiments import digging_cycle
    prof = digging_cycle()
    t0 = time.perf_counter()
    df = simulate(Machine(), prof, args.duration)
    wall = time.perf_counter() - t0
    sim_t = float(df["t"].iloc[-1])
    print(f"{sim_t:.1f} s of the digging cycle in {wall:.1f} s ({wall / sim_t:.2f} s per simulated s)")
    for j in JOINTS:
        print(f"{j:7s} x {1e3 * df[f'x_{j}'].min():6.1f} .. {1e3 * df[f'x_{j}'].max():6.1f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
