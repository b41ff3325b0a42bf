#!/usr/bin/env python3
"""A second, independent simulator of the reference rig for blind benchmark recordings.

Written from ``shared/spec/reference-rig.md``, ``effects.md`` and the paper (Eq. 2 to 12)
only: nothing here comes from ``boomfmi.physics``, ``boomfmi.model``, ``boomfmi.rig``,
``boomfmi.identify`` or ``boomfmi.diagnose``, so a diagnosis run on these recordings
never meets its own numerics.  ``boomfmi.recording`` is used only to write the CSV.

The plant
---------
Continuous states: piston position x [m], velocity v [m/s], chamber pressures p_a, p_b
[Pa absolute], plus what the switched-on effects need (spool position and velocity,
chamber temperatures, port-volume pressures, supply reservoir pressure, sensor lag
states).  The equations:

* orifice (reference-rig.md, the paper's Eq. 1 corrected), r = P_d / P_u::

      r >= P_cr: mdot = A P_u sqrt(2k / (R T (k-1))) sqrt(r^(2/k) - r^((k+1)/k))
      r <  P_cr: mdot = A P_u sqrt(k / (R T)) (2/(k+1))^((k+1)/(2(k-1)))

  with P_cr = (2/(k+1))^(k/(k-1)) = 0.5283; flow runs from the higher pressure to the
  lower one (T is the upstream gas's temperature where the chambers carry one).
* valve routing: u < 5 V: supply -> A and B -> exhaust; u > 5 V: supply -> B and
  A -> exhaust; A(u) = A_max min(|u - 5| / 5, 1) on both open ports.
* chambers (Eq. 4 to 7): V dP/dt + k P dV/dt = k R T mdot, V_a = A_a x + V_a0,
  V_b = A_b (L - x) + V_b0.
* load (Eq. 8, 9): M x'' = F_drive - K_v x' - F_c, with
  F_drive = P_a A_a - P_b A_b - P_atm (A_a - A_b) - F_L sin(phi) (+ disturbances), and
  F_c = F_d sign(x') cos(phi) while slipping, F_c = F_drive while sticking
  (x' = 0 and |F_drive| <= F_s cos(phi)).
* geometry (Eq. 10 to 12): l = x + l_min,
  phi = pi - asin(h/a) - acos((a^2 + l^2 - b^2) / (2 a l)),
  alpha = acos((a^2 + b^2 - l^2) / (2 a b)) (the inverse of Eq. 12).
* end stops at x = 0 and x = L: hard, no bounce, held while pushed into the stop.

The hybrid solve
----------------
Modes (the ``mode`` truth column): ``1`` slipping forwards (v > 0), ``-1`` slipping
backwards, ``0`` sticking (v = 0 held), ``2`` held at the stop x = L, ``-2`` held at
x = 0.  Mode changes are located by ``solve_ivp`` terminal events: v crossing 0 while
slipping, F_drive reaching +-(static level) cos(phi) while sticking, x reaching 0 or L,
F_drive turning away from the stop while held there (and, sticking at a stroke end,
F_drive turning back into the stop).  Command changes and disturbance switch times are
breakpoints: the integration restarts at each.  A chamber at rest that reaches its open
port's source pressure is *locked* there (event located; see ``_Model.lockable``): the
orifice law's flow ~ sqrt(P_u - P_d) makes that a finite-time, infinite-Jacobian
approach that integrators otherwise crawl across.  The command the valve sees is the
profile sampled at the DAQ instants k/fs and held (a DAQ card's zero-order hold); a
profile without ``breakpoints``, one with ``continuous = True``, or ``hold=False`` is
evaluated continuously instead.  The method is LSODA (switching to BDF when stiff); a
solve where it crawls (over a budget of RHS calls) or fails is redone with scipy's BDF.

API
---
``Plant`` (every constant, the load, ``effects``, ``disturbances``, ``sensors``),
``PLANT_DEFAULTS``, ``EFFECT_FORMS``, ``DISTURBANCE_FORMS``, ``SENSOR_DEFAULTS``,
``simulate(plant, profile, ...) -> DataFrame`` and ``write(path, frame, notes="")``.

    python benchmarks/hybrid_rig.py            # times a 12 s random-step recording
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

# --------------------------------------------------------------------------- modes
SLIP_POS, SLIP_NEG, STICK, STOP_HIGH, STOP_LOW = 1, -1, 0, 2, -2
MODE_NAMES = {SLIP_POS: "slip+", SLIP_NEG: "slip-", STICK: "stick", STOP_HIGH: "stop at L",
              STOP_LOW: "stop at 0"}
#: Velocity [m/s] a slip starts with when it leaves rest (stick or a stop).  It only
#: keeps the velocity event from firing at the instant the slip begins when the net
#: force there is zero to rounding (Stribeck friction starts at the static level); it
#: moves the piston by less than 1e-11 m over any recording.
V_START = 1e-12
#: A chamber at rest within this fraction of its source pressure is locked at it (set to
#: it exactly; see ``_Model.lockable``): 1e-9 of 7 bar is 0.7 mPa, crossed in microseconds.
LOCK_TOL = 1e-9


# --------------------------------------------------------------------------- plant
@dataclass
class Plant:
    """Every constant of the rig (SI units; pressures absolute), defaults from
    ``reference-rig.md``; the load (``K_v``, ``F_s``, ``F_d``, ``F_L``, ``M``) is the
    paper's identified set.  ``effects``, ``disturbances``: ``{name: {"form": ...,
    param: value}}`` (see :data:`EFFECT_FORMS`, :data:`DISTURBANCE_FORMS`; a missing
    form is the first listed, missing parameters take the form's defaults).
    ``sensors``: overrides of :data:`SENSOR_DEFAULTS`."""
    # gas
    k: float = 1.4                      #: ratio of specific heats
    R: float = 287.0                    #: gas constant [J/(kg K)]
    T: float = 293.15                   #: air (and supply, wall) temperature [K]
    P_atm: float = 101325.0             #: atmosphere [Pa]
    # valve and supply
    P_s: float = 701325.0               #: supply [Pa absolute] (0.6 MPa gauge)
    P_e: float | None = None            #: exhaust [Pa absolute]; None: P_atm
    A_max: float = 4.0e-6               #: full valve opening [m^2]
    # cylinder (DSNU 32-60: bore 32 mm, rod 12 mm)
    A_a: float = math.pi / 4 * 0.032 ** 2                     #: cap-side area [m^2]
    A_b: float = math.pi / 4 * (0.032 ** 2 - 0.012 ** 2)      #: rod-side annulus [m^2]
    L: float = 0.060                    #: stroke [m]
    V_a0: float = 1.5e-5                #: dead volume, chamber A [m^3]
    V_b0: float = 1.5e-5                #: dead volume, chamber B [m^3]
    # boom geometry (Eq. 10 to 12)
    a: float = 0.15
    b: float = 0.30
    h: float = 0.05
    l_min: float = 0.20
    # load and friction (Eq. 8, 9)
    K_v: float = 2829.0                 #: viscous friction [N s/m]
    F_s: float = 113.255                #: static friction [N]
    F_d: float = 85.727                 #: Coulomb friction [N]
    F_L: float = 261.177                #: gravity load [N]
    M: float = 22.7                     #: moving mass [kg]
    effects: dict = field(default_factory=dict)
    disturbances: dict = field(default_factory=dict)
    sensors: dict = field(default_factory=dict)

    @property
    def exhaust(self) -> float:
        return self.P_atm if self.P_e is None else float(self.P_e)


#: The reference rig's scalar constants (``Plant``'s defaults).
PLANT_DEFAULTS = {f.name: f.default for f in fields(Plant) if f.name not in ("effects", "disturbances", "sensors")}
#: Plant fields a recording's sidecar may carry (``boomfmi.recording.RIG_KEYS`` minus the
#: load, which stays hidden from the diagnosis).
SIDECAR_FIELDS = ("A_max", "P_s", "P_e", "k", "R", "T", "A_a", "A_b", "L", "V_a0", "V_b0",
                  "a", "b", "h", "l_min", "P_atm")
LOAD_FIELDS = ("K_v", "F_s", "F_d", "F_L", "M")

#: Sensor chain defaults: a 12-bit potentiometer over 300 degrees with noise sigma
#: 1e-4 rad; pressure sensors with noise sigma 500 Pa read by a 12-bit converter over
#: 0 to 1 MPa gauge, which saturates at the ends of its span (``p_saturate``).
#: ``*_bits = None`` switches quantisation off; ``fs`` [Hz], where given, is the sample
#: rate when ``simulate`` is not given one.
SENSOR_DEFAULTS = {"angle_bits": 12, "angle_span_deg": 300.0, "angle_noise": 1e-4,
                   "p_noise": 500.0, "p_bits": 12, "p_span": (0.0, 1.0e6), "p_saturate": True,
                   "fs": None}
#: Sensors without noise or quantisation: the physics as it is.
IDEAL_SENSORS = {"angle_bits": None, "angle_noise": 0.0, "p_noise": 0.0, "p_bits": None}

# --------------------------------------------------------------------------- effect forms
#: name -> form -> {param: (low, high)}: plausible magnitudes to draw from.  Each form's
#: docstring is in :data:`FORM_DOCS`; parameters not listed here take :data:`FORM_DEFAULTS`.
EFFECT_FORMS = {
    "valve_dynamics": {
        "first_order": {"tau": (0.002, 0.015)},
        "second_order": {"f_n": (30.0, 150.0), "zeta": (0.5, 1.2)},
        "rate_limited": {"tau": (0.002, 0.010), "rate": (100.0, 1000.0)},
    },
    "valve_deadband": {
        "overlap": {"d": (0.1, 0.6)},
        "rounded": {"d": (0.2, 0.6), "w": (0.05, 0.2)},
        "asymmetric": {"d_ext": (0.05, 0.6), "d_ret": (0.05, 0.6), "w": (0.0, 0.05)},
    },
    "heat_transfer": {
        "wall": {"h_c": (15.0, 150.0)},
        "polytropic": {"n": (1.0, 1.3)},
    },
    "piston_leakage": {
        "laminar": {"C": (5e-12, 5e-11)},
        "orifice": {"A": (3e-9, 3e-8)},
        "mixed": {"C": (2e-12, 2e-11), "A": (2e-9, 1.5e-8)},
    },
    "stribeck_friction": {
        "exponential": {"F_brk": (125.0, 200.0), "v_s": (0.002, 0.02)},
        "gaussian": {"F_brk": (125.0, 200.0), "v_s": (0.002, 0.02)},
        "power": {"F_brk": (125.0, 200.0), "v_s": (0.002, 0.02), "delta": (0.5, 2.5)},
    },
    "end_cushioning": {
        "needle": {"l_c": (0.005, 0.02), "A_n": (2e-7, 1.5e-6)},
        "sensed_port": {"l_c": (0.005, 0.02), "A_n": (2e-7, 1.5e-6), "V_p": (3e-6, 1e-5)},
        "no_check": {"l_c": (0.005, 0.02), "A_n": (2e-7, 1.5e-6)},
        "tapered": {"l_c": (0.005, 0.02), "A_n": (2e-7, 1.5e-6), "A_g": (1e-6, 6e-6)},
    },
    "sensor_lag": {
        "first_order": {"tau": (0.002, 0.02)},
        "delay_lag": {"delay": (0.001, 0.010), "tau": (0.001, 0.010)},
    },
    "pressure_friction": {
        "linear": {"c": (0.03, 0.25), "asym": (0.8, 1.25)},
        "seal_split": {"c_p": (0.03, 0.3), "c_r": (0.03, 0.3)},
        "saturating": {"g": (0.1, 2.0), "p_0": (1e5, 5e5)},
    },
}
#: Disturbances outside effects.md's vocabulary, same layout.
DISTURBANCE_FORMS = {
    "vibration": {"sinusoidal": {"amplitude": (10.0, 60.0), "frequency": (15.0, 60.0)}},
    "supply_sag": {"reservoir": {"V_r": (2e-4, 2e-3), "G": (5e-9, 5e-8)}},
    "payload_change": {"step": {"t_change": (2.0, 8.0), "dM": (2.0, 8.0), "dF_L": (20.0, 80.0)}},
    "external_force": {"ramp": {"rate": (10.0, 200.0), "t0": (0.0, 1.0), "F0": (0.0, 0.0)},
                       "function": {}},
}
#: Defaults of every form parameter (the ranges' middles, plus the fixed extras).
FORM_DEFAULTS = {
    ("valve_dynamics", "first_order"): {"tau": 0.005},
    ("valve_dynamics", "second_order"): {"f_n": 80.0, "zeta": 0.8},
    ("valve_dynamics", "rate_limited"): {"tau": 0.004, "rate": 300.0},
    ("valve_deadband", "overlap"): {"d": 0.3},
    ("valve_deadband", "rounded"): {"d": 0.4, "w": 0.1},
    ("valve_deadband", "asymmetric"): {"d_ext": 0.2, "d_ret": 0.4, "w": 0.02},
    ("heat_transfer", "wall"): {"h_c": 60.0, "A_dead": None},
    ("heat_transfer", "polytropic"): {"n": 1.2},
    ("piston_leakage", "laminar"): {"C": 2e-11},
    ("piston_leakage", "orifice"): {"A": 1e-8},
    ("piston_leakage", "mixed"): {"C": 1e-11, "A": 5e-9},
    ("stribeck_friction", "exponential"): {"F_brk": 160.0, "v_s": 0.008},
    ("stribeck_friction", "gaussian"): {"F_brk": 160.0, "v_s": 0.008},
    ("stribeck_friction", "power"): {"F_brk": 160.0, "v_s": 0.008, "delta": 1.5},
    ("end_cushioning", "needle"): {"l_c": 0.012, "A_n": 6e-7, "chamfer": 5e-4},
    ("end_cushioning", "sensed_port"): {"l_c": 0.012, "A_n": 6e-7, "V_p": 6e-6, "chamfer": 5e-4,
                                        "G_free": 1e-6},
    ("end_cushioning", "no_check"): {"l_c": 0.012, "A_n": 6e-7, "chamfer": 5e-4},
    ("end_cushioning", "tapered"): {"l_c": 0.012, "A_n": 6e-7, "A_g": 3e-6, "chamfer": 5e-4},
    ("sensor_lag", "first_order"): {"tau": 0.008},
    ("sensor_lag", "delay_lag"): {"delay": 0.004, "tau": 0.004},
    ("pressure_friction", "linear"): {"c": 0.12, "asym": 1.0},
    ("pressure_friction", "seal_split"): {"c_p": 0.12, "c_r": 0.12},
    ("pressure_friction", "saturating"): {"g": 0.8, "p_0": 2.5e5},
    ("vibration", "sinusoidal"): {"amplitude": 30.0, "frequency": 30.0, "phase": 0.0},
    ("supply_sag", "reservoir"): {"V_r": 5e-4, "G": 1.5e-8},
    ("payload_change", "step"): {"t_change": 3.0, "dM": 5.0, "dF_L": 50.0},
    ("external_force", "ramp"): {"rate": 50.0, "t0": 0.0, "F0": 0.0},
    ("external_force", "function"): {"f": None},
}
FORM_DOCS = {
    ("valve_dynamics", "first_order"):
        "The spool position s (in volts of command) lags the command: ds/dt = (u - s)/tau; the "
        "orifice area and the routing follow s.  tau [s], plausible 0.002 to 0.015 (the MPYE's "
        "~100 Hz bandwidth is tau ~ 1.6 ms; hoses and the amplifier add to it).",
    ("valve_dynamics", "second_order"):
        "The spool as a damped oscillator: s'' = w^2 (u - s) - 2 zeta w s', w = 2 pi f_n.  "
        "f_n [Hz] 30 to 150, zeta [-] 0.5 to 1.2.",
    ("valve_dynamics", "rate_limited"):
        "First order with a smooth slew-rate limit: ds/dt = rate tanh((u - s) / (tau rate)).  "
        "tau [s] 0.002 to 0.010, rate [V/s] 100 to 1000 (a full 5 V spool travel in 5 to 50 ms).",
    ("valve_deadband", "overlap"):
        "Spool overlap: no port opens while |s - 5| <= d; beyond, the opening grows linearly and "
        "is rescaled so that a full command still gives A_max: A = A_max min((|s-5| - d)/(5 - d), 1)."
        "  d [V] 0.1 to 0.6.",
    ("valve_deadband", "rounded"):
        "Overlap with a rounded (C1, quadratic) edge of half-width w around |s - 5| = d: the "
        "effective excess e = |s-5| - d becomes (e + w)^2 / (4 w) for |e| <= w.  d [V] 0.2 to 0.6, "
        "w [V] 0.05 to 0.2 (w <= d, so the centre stays closed).",
    ("valve_deadband", "asymmetric"):
        "A spool whose overlap differs between its two sides (ground or centred unevenly): no port "
        "opens while 5 - d_ext <= s <= 5 + d_ret; on each side the opening grows from that side's "
        "edge and is rescaled to reach A_max at full command: A = A_max min((|s-5| - d)/(5 - d), 1), "
        "d = d_ext for s < 5 (extending), d_ret for s > 5; a rounded edge of half-width w on both "
        "(as ``rounded``; 0: sharp).  d_ext, d_ret [V] 0.05 to 0.6, w [V] 0 to 0.05 (w <= both).",
    ("heat_transfer", "wall"):
        "Chamber temperature states and the energy equation V dP/dt + k P dV/dt = k R sum(mdot_i "
        "T_i) + (k-1) Q, Q = h_c A_wall(x) (T_wall - T_chamber); inflow at the supply (or "
        "atmosphere's) temperature T, outflow at the chamber's; T_wall = T.  A_wall = A_dead (the "
        "dead volume's wall: a 4 mm bore hose holding it, 4 V_0 / 0.004 = 0.015 m^2 by default) + "
        "both end faces + the swept barrel (and, in B, the rod).  h_c [W/(m^2 K)] 15 to 150 "
        "(thermal time constants of ~0.1 to 1 s).",
    ("heat_transfer", "polytropic"):
        "A polytropic exponent n in place of k in the chamber equation (both terms): "
        "V dP/dt + n P dV/dt = n R T mdot.  n [-] 1.0 (isothermal) to 1.3.",
    ("piston_leakage", "laminar"):
        "A laminar leak across the piston seal: mdot_AB = C (p_a - p_b).  C [kg/(s Pa)] 5e-12 to "
        "5e-11 (1e-6 to 3e-5 kg/s at 6 bar difference).",
    ("piston_leakage", "orifice"):
        "A leak gap obeying the orifice law between the chambers.  A [m^2] 3e-9 to 3e-8.",
    ("piston_leakage", "mixed"):
        "Both in parallel.  C [kg/(s Pa)] 2e-12 to 2e-11, A [m^2] 2e-9 to 1.5e-8.",
    ("stribeck_friction", "exponential"):
        "Friction at speed F_d + (F_brk - F_d) exp(-|v|/v_s) (times cos(phi), sign(v)); sticking "
        "and breakaway use F_brk as the static level.  F_brk [N] 125 to 200 (>= F_d), v_s [m/s] "
        "0.002 to 0.02.",
    ("stribeck_friction", "gaussian"):
        "As exponential with exp(-(v/v_s)^2).  F_brk [N] 125 to 200, v_s [m/s] 0.002 to 0.02.",
    ("stribeck_friction", "power"):
        "The generalised Stribeck curve: as exponential with exp(-(|v|/v_s)^delta), delta [-] 0.5 "
        "(a long tail) to 2.5 (a sharp drop); F_brk [N] 125 to 200, v_s [m/s] 0.002 to 0.02.",
    ("end_cushioning", "needle"):
        "Within l_c of each stroke end the chamber being exhausted vents through its cushioning "
        "needle A_n in series with the valve port (series areas combined as A A_n / sqrt(A^2 + "
        "A_n^2)); inflow passes freely through the check valve.  The cushion spigot engages over a "
        "0.5 mm chamfer (C1 blend).  l_c [m] 0.005 to 0.02, A_n [m^2] 2e-7 to 1.5e-6.",
    ("end_cushioning", "sensed_port"):
        "A port volume V_p (carved out of the dead volume, so the total stays V_0) between valve "
        "and chamber with its own pressure; the valve fills and empties the port.  Outside the "
        "cushion the chamber and port are joined by the free bore (a laminar conductance G_free "
        "= 1e-6 kg/(s Pa), ~0.07 bar drop at full valve flow); within l_c (up to L/3) of the end "
        "the chamber's outflow passes only the needle A_n, its inflow the check valve (free).  The "
        "pressure sensor reads the chamber.  l_c [m] 0.005 to 0.02, A_n [m^2] 2e-7 to 1.5e-6, "
        "V_p [m^3] 3e-6 to 1e-5 (< V_0).",
    ("end_cushioning", "no_check"):
        "As ``needle`` without the check valve (a cushion with a fixed bleed and no return "
        "function): within l_c of the end the chamber's flow passes the needle A_n in series with "
        "the valve port both ways, so the piston leaving the end draws its air through the needle "
        "too and starts slowly.  l_c [m] 0.005 to 0.02, A_n [m^2] 2e-7 to 1.5e-6.",
    ("end_cushioning", "tapered"):
        "A tapered (conical) cushion spear with a check valve: as the spear enters the cushion "
        "bore, the annular gap around it narrows linearly from A_n + A_g at the cushion's entry to "
        "the needle's A_n at the stroke end (a progressive cushion: the braking grows over the "
        "last l_c); outflow passes that gap in series with the valve port, inflow the check valve "
        "(free).  l_c [m] 0.005 to 0.02, A_n [m^2] 2e-7 to 1.5e-6, A_g [m^2] 1e-6 to 6e-6.",
    ("sensor_lag", "first_order"):
        "Every measured channel (alpha, p_a, p_b) passes a first-order lag tau [s] 0.002 to 0.02.",
    ("sensor_lag", "delay_lag"):
        "A dead time delay [s] 0.001 to 0.01 and a first-order lag tau [s] 0.001 to 0.01 on every "
        "measured channel.",
    ("pressure_friction", "linear"):
        "F_d(p) = F_d (1 + c (p_a + p_b - 2 P_atm) / 1e5), likewise F_s (and a Stribeck F_brk); "
        "c [1/bar] 0.03 to 0.25; asym [-] 0.8 to 1.25 multiplies the friction while moving (or "
        "pushed) in the retracting direction.",
    ("pressure_friction", "seal_split"):
        "The piston seal pressed by the pressure difference across it, the rod seal by the rod-side "
        "pressure: factor 1 + c_p |p_a - p_b| / 1e5 + c_r (p_b - P_atm) / 1e5 on F_d and F_s.  "
        "c_p, c_r [1/bar] 0.03 to 0.3.",
    ("pressure_friction", "saturating"):
        "Seal lips pressed by the chambers' pressure until fully in contact: factor "
        "1 + g (1 - exp(-max(p_a + p_b - 2 P_atm, 0) / p_0)) on F_d and F_s (and a Stribeck F_brk); "
        "linear at low pressure (g / p_0 per pascal), levelling off at 1 + g.  g [-] 0.1 to 2, "
        "p_0 [Pa] 1e5 to 5e5.",
    ("vibration", "sinusoidal"):
        "A sinusoidal force along the cylinder axis (positive extending): amplitude [N] 10 to 60, "
        "frequency [Hz] 15 to 60 (an engine's), phase [rad].",
    ("supply_sag", "reservoir"):
        "The valve draws from a reservoir V_r [m^3] 2e-4 to 2e-3 (isothermal) refilled from the "
        "compressor at P_s through a line of conductance G [kg/(s Pa)] 5e-9 to 5e-8: the supply "
        "sags while the valve draws air and recovers after (time constant V_r / (R T G)).",
    ("payload_change", "step"):
        "At t_change [s] the moving mass grows by dM [kg] and the gravity load by dF_L [N].",
    ("external_force", "ramp"):
        "A force along the axis (positive extending) F0 + rate (t - t0) from t0 on, 0 before: "
        "rate [N/s], t0 [s], F0 [N].",
    ("external_force", "function"):
        "A force along the axis (positive extending) f(t) [N]: f a Python callable.",
}


def _resolve_forms(spec: dict, table: dict, kind: str) -> dict:
    """``{name: (form, params)}`` from a plant's effects/disturbances dict."""
    out = {}
    for name, conf in (spec or {}).items():
        if conf is None or conf is False:
            continue
        if name not in table:
            raise ValueError(f"unknown {kind} {name!r}; known: {', '.join(table)}")
        conf = dict(conf) if isinstance(conf, dict) else {}
        if conf.pop("enabled", True) is False:
            continue
        form = conf.pop("form", next(iter(table[name])))
        if form not in table[name]:
            raise ValueError(f"{kind} {name!r} has no form {form!r}; forms: {', '.join(table[name])}")
        params = dict(FORM_DEFAULTS[(name, form)])
        for p, val in conf.items():
            if p not in params:
                raise ValueError(f"{kind} {name!r} form {form!r} has no parameter {p!r}; "
                                 f"parameters: {', '.join(params)}")
            params[p] = val
        out[name] = (form, params)
    return out


# --------------------------------------------------------------------------- geometry
def phi_of_x(x, plant: Plant = None):
    """Eq. 10, 11: the cylinder's angle to the horizontal [rad] at piston position x [m]."""
    p = plant or Plant()
    l = np.asarray(x, float) + p.l_min
    return math.pi - math.asin(p.h / p.a) - np.arccos((p.a ** 2 + l ** 2 - p.b ** 2) / (2 * p.a * l))


def alpha_of_x(x, plant: Plant = None):
    """The boom angle [rad] at piston position x (Eq. 12 solved for alpha)."""
    p = plant or Plant()
    l = np.asarray(x, float) + p.l_min
    return np.arccos((p.a ** 2 + p.b ** 2 - l ** 2) / (2 * p.a * p.b))


def x_of_alpha(alpha, plant: Plant = None):
    """Eq. 12: piston position [m] from the boom angle alpha [rad]."""
    p = plant or Plant()
    return np.sqrt(p.a ** 2 + p.b ** 2 - 2 * p.a * p.b * np.cos(np.asarray(alpha, float))) - p.l_min


def _smoothstep(s: float) -> float:
    if s <= 0.0:
        return 0.0
    if s >= 1.0:
        return 1.0
    return s * s * (3.0 - 2.0 * s)


# --------------------------------------------------------------------------- the model
class _Model:
    """The plant's equations on a flat state vector, for one set of effects."""

    def __init__(self, plant: Plant):
        p = self.plant = plant
        for name in PLANT_DEFAULTS:
            v = getattr(p, name)
            if name == "P_e" and v is None:
                continue
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"plant.{name} must be a finite number, not {v!r}")
        for name in ("k", "R", "T", "P_atm", "P_s", "A_max", "A_a", "A_b", "L", "V_a0", "V_b0", "a", "b",
                     "l_min", "M"):
            if getattr(p, name) <= 0:
                raise ValueError(f"plant.{name} must be positive, not {getattr(p, name)!r}")
        for name in ("K_v", "F_s", "F_d", "F_L"):
            if getattr(p, name) < 0:
                raise ValueError(f"plant.{name} must not be negative, not {getattr(p, name)!r}")
        self.eff = _resolve_forms(p.effects, EFFECT_FORMS, "effect")
        self.dist = _resolve_forms(p.disturbances, DISTURBANCE_FORMS, "disturbance")
        self.sens = dict(SENSOR_DEFAULTS)
        for key, val in (p.sensors or {}).items():
            if key not in SENSOR_DEFAULTS:
                raise ValueError(f"unknown sensor setting {key!r}; known: {', '.join(SENSOR_DEFAULTS)}")
            self.sens[key] = val

        k, R, T = p.k, p.R, p.T
        self.k, self.R, self.T = k, R, T
        self.P_cr = (2.0 / (k + 1.0)) ** (k / (k - 1.0))
        self.e1, self.e2 = 2.0 / k, (k + 1.0) / k
        self.c_sub = 2.0 * k / (R * (k - 1.0))                 # times 1/T under the sqrt
        self.c_ch = k / R * (2.0 / (k + 1.0)) ** ((k + 1.0) / (k - 1.0))   # sqrt(c_ch / T)
        self.Pe = p.exhaust
        self.asin_ha = math.asin(p.h / p.a)

        # ---- effects
        e = self.eff
        self.vd = e.get("valve_dynamics")
        self.db = e.get("valve_deadband")
        self.ht = e.get("heat_transfer")
        self.leak = e.get("piston_leakage")
        self.strib = e.get("stribeck_friction")
        self.cush = e.get("end_cushioning")
        self.lag = e.get("sensor_lag")
        self.pf = e.get("pressure_friction")
        self.vib = self.dist.get("vibration")
        self.sag = self.dist.get("supply_sag")
        self.payload = self.dist.get("payload_change")
        self.fext = self.dist.get("external_force")

        self.kappa = k                      # exponent of the chamber equation
        if self.ht and self.ht[0] == "polytropic":
            n = float(self.ht[1]["n"])
            if not 1.0 <= n <= k:
                raise ValueError(f"heat_transfer polytropic n must lie in [1, k = {k}], not {n}")
            self.kappa = n
        self.wall = bool(self.ht and self.ht[0] == "wall")
        if self.wall:
            hp = self.ht[1]
            self.h_c = float(hp["h_c"])
            D = math.sqrt(4.0 * p.A_a / math.pi)
            d_rod = math.sqrt(max(4.0 * (p.A_a - p.A_b) / math.pi, 0.0))
            self.Aw_a0 = (4.0 * p.V_a0 / 0.004 if hp["A_dead"] is None else float(hp["A_dead"])) + 2.0 * p.A_a
            self.Aw_b0 = (4.0 * p.V_b0 / 0.004 if hp["A_dead"] is None else float(hp["A_dead"])) + 2.0 * p.A_b
            self.Aw_a1 = math.pi * D                 # swept barrel per metre of x
            self.Aw_b1 = math.pi * (D + d_rod)       # barrel and rod per metre of L - x
        self.strib_F = None
        self.F_static = p.F_s
        if self.strib:
            sp = self.strib[1]
            self.strib_F = float(sp["F_brk"])
            self.strib_vs = float(sp["v_s"])
            self.strib_gauss = self.strib[0] == "gaussian"
            self.strib_delta = float(sp["delta"]) if self.strib[0] == "power" else None
            if self.strib_delta is not None and not self.strib_delta > 0:
                raise ValueError(f"stribeck power delta must be positive, not {self.strib_delta}")
            if self.strib_F < p.F_d:
                raise ValueError(f"stribeck F_brk = {self.strib_F} N lies below F_d = {p.F_d} N")
            if self.strib_vs <= 0:
                raise ValueError("stribeck v_s must be positive")
            self.F_static = self.strib_F
        elif p.F_s < p.F_d:
            raise ValueError(f"F_s = {p.F_s} N lies below F_d = {p.F_d} N: sticking would be inconsistent "
                             f"(the slip friction at rest would exceed the static level)")
        if self.db:
            dp = self.db[1]
            if self.db[0] == "asymmetric":
                self.db_sides = (float(dp["d_ext"]), float(dp["d_ret"]))
            else:
                self.db_sides = (float(dp["d"]),) * 2
            self.db_d = self.db_sides[0]
            self.db_w = float(dp.get("w", 0.0)) if self.db[0] in ("rounded", "asymmetric") else 0.0
            for d in self.db_sides:
                if not 0.0 <= d < 5.0 or self.db_w < 0 or self.db_w > d:
                    raise ValueError(f"valve_deadband needs 0 <= w <= d < 5 V, got d = {d}, w = {self.db_w}")
        if self.cush:
            cp = self.cush[1]
            self.l_c = float(cp["l_c"])
            self.A_n = float(cp["A_n"])
            self.chamfer = float(cp["chamfer"])
            self.cush_check = self.cush[0] != "no_check"        # inflow passes freely
            self.A_g = float(cp["A_g"]) if self.cush[0] == "tapered" else 0.0
            if self.A_n <= 0 or self.A_g < 0:
                raise ValueError(f"end_cushioning needs A_n > 0 and A_g >= 0, got {self.A_n}, {self.A_g}")
            if not 0.0 < self.l_c <= p.L / 3.0 + 1e-12:
                raise ValueError(f"end_cushioning l_c must lie in (0, L/3], not {self.l_c}")
            if self.cush[0] == "sensed_port":
                self.V_p = float(cp["V_p"])
                self.G_free = float(cp["G_free"])
                if not 0.0 < self.V_p < min(p.V_a0, p.V_b0):
                    raise ValueError(f"sensed_port V_p must lie in (0, V_0), not {self.V_p}")
        self.port = bool(self.cush and self.cush[0] == "sensed_port")
        if self.lag:
            lp = self.lag[1]
            self.lag_tau = float(lp["tau"])
            self.lag_delay = float(lp.get("delay", 0.0))
            if self.lag_tau <= 0 or self.lag_delay < 0:
                raise ValueError("sensor_lag needs tau > 0 and delay >= 0")
        if self.fext and self.fext[0] == "function" and not callable(self.fext[1]["f"]):
            raise ValueError("external_force 'function' needs a callable f(t) -> N")

        # ---- state layout
        names = ["x", "v", "p_a", "p_b"]
        if self.vd:
            names.append("s")
            if self.vd[0] == "second_order":
                names.append("s_dot")
        if self.wall:
            names += ["T_a", "T_b"]
        if self.port:
            names += ["pp_a", "pp_b"]
        if self.sag:
            names.append("p_r")
        if self.lag:
            names += ["alpha_m", "p_a_m", "p_b_m"]
        self.names = names
        self.idx = {n: i for i, n in enumerate(names)}
        scale = {"x": 1e-10, "v": 1e-9, "p_a": 1e-3, "p_b": 1e-3, "s": 1e-9, "s_dot": 1e-7, "T_a": 1e-7,
                 "T_b": 1e-7, "pp_a": 1e-3, "pp_b": 1e-3, "p_r": 1e-3, "alpha_m": 1e-10, "p_a_m": 1e-3,
                 "p_b_m": 1e-3}
        self.atol = np.array([scale[n] for n in names])
        #: Whether a chamber at rest may be *locked* at its port's source pressure.  The
        #: orifice law's flow ~ sqrt(P_u - P_d) near equal pressures: a closed chamber fed
        #: through an open port reaches the source pressure in finite time, with an
        #: infinite Jacobian there, and stays (the unique forward solution: the law is
        #: dissipative).  Integrators crawl across that point, so it is located as an event
        #: and the chamber held there exactly while nothing else moves its pressure: the
        #: piston at rest (stick or stop), no leakage, no heat exchange (h_c = 0 is fine)
        #: and a constant source (no supply sag).  With a port volume the chamber and its
        #: port are locked together once both are within LOCK_TOL of the source.  A lock
        #: ends when the piston moves or the routing changes.
        self.lockable = not (self.leak or (self.wall and self.h_c != 0.0) or self.sag)
        self.lock_nodes = ((2, self.idx["pp_a"]), (3, self.idx["pp_b"])) if self.port else ((2,), (3,))

    # ---------------------------------------------------------------- pieces
    def orifice(self, A, Pu, Pd, Tu):
        """Mass flow [kg/s] from Pu to Pd (Pu >= Pd) through area A (reference-rig.md's law).
        A non-positive upstream pressure only occurs in a solver's rejected trial step (every
        accepted state is checked): no flow there."""
        if A <= 0.0 or Pu <= 0.0:
            return 0.0
        r = Pd / Pu
        if r >= self.P_cr:
            d = r ** self.e1 - r ** self.e2
            return A * Pu * math.sqrt(self.c_sub / Tu * d) if d > 0.0 else 0.0
        return A * Pu * math.sqrt(self.c_ch / Tu)

    def flow(self, A, P1, P2, T1, T2):
        """Signed mass flow from node 1 to node 2."""
        if P1 >= P2:
            return self.orifice(A, P1, P2, T1)
        return -self.orifice(A, P2, P1, T2)

    def opening(self, s):
        """Valve area [m^2] at spool position s [V]: A_max min(|s - 5| / 5, 1), or with the
        deadband's overlap d (and rounded edge w) the excess over d, rescaled to 5 - d."""
        e = abs(s - 5.0)
        if not self.db:
            return self.plant.A_max * min(e / 5.0, 1.0)
        d, w = self.db_sides[0 if s < 5.0 else 1], self.db_w
        ex = e - d
        if w > 0.0 and -w < ex < w:
            ex = (ex + w) ** 2 / (4.0 * w)           # C1 quadratic edge
        if ex <= 0.0:
            return 0.0
        return self.plant.A_max * min(ex / (5.0 - d), 1.0)

    def geometry(self, x):
        p = self.plant
        l = x + p.l_min
        c = (p.a * p.a + l * l - p.b * p.b) / (2.0 * p.a * l)
        phi = math.pi - self.asin_ha - math.acos(c)
        return math.sin(phi), math.cos(phi)

    def alpha(self, x):
        p = self.plant
        l = x + p.l_min
        return math.acos((p.a * p.a + p.b * p.b - l * l) / (2.0 * p.a * p.b))

    def load(self, t):
        """(F_L, M) at time t (payload change)."""
        p = self.plant
        if self.payload and t >= self.payload[1]["t_change"]:
            return p.F_L + float(self.payload[1]["dF_L"]), p.M + float(self.payload[1]["dM"])
        return p.F_L, p.M

    def f_dist(self, t):
        """Disturbance force along the axis, positive extending [N]."""
        f = 0.0
        if self.vib:
            vp = self.vib[1]
            f += vp["amplitude"] * math.sin(2.0 * math.pi * vp["frequency"] * t + vp["phase"])
        if self.fext:
            fp = self.fext[1]
            if self.fext[0] == "ramp":
                if t >= fp["t0"]:
                    f += fp["F0"] + fp["rate"] * (t - fp["t0"])
            else:
                f += float(fp["f"](t))
        return f

    def drive(self, t, y):
        """(F_drive [N], cos(phi)): Eq. 8's force on the piston without friction."""
        p = self.plant
        sphi, cphi = self.geometry(y[0])
        F_L, _ = self.load(t)
        F = y[2] * p.A_a - y[3] * p.A_b - p.P_atm * (p.A_a - p.A_b) - F_L * sphi
        if self.vib or self.fext:
            F += self.f_dist(t)
        return F, cphi

    def fric_factor(self, y, direction):
        """Pressure-friction factor on F_d and F_s for motion (or push) in ``direction``."""
        if not self.pf:
            return 1.0
        form, pp = self.pf
        P_atm = self.plant.P_atm
        if form == "linear":
            f = 1.0 + pp["c"] * (y[2] + y[3] - 2.0 * P_atm) / 1e5
            if direction < 0:
                f *= pp["asym"]
            return f
        if form == "saturating":
            return 1.0 + pp["g"] * -math.expm1(-max(y[2] + y[3] - 2.0 * P_atm, 0.0) / pp["p_0"])
        return 1.0 + pp["c_p"] * abs(y[2] - y[3]) / 1e5 + pp["c_r"] * (y[3] - P_atm) / 1e5

    def static_level(self, y, direction, cphi):
        """The static friction level (times cos(phi)) for a push in ``direction``."""
        return self.F_static * self.fric_factor(y, direction) * cphi

    def slip_friction(self, y, v, cphi):
        s = 1.0 if v > 0.0 else -1.0
        if self.strib:
            z = abs(v) / self.strib_vs
            if self.strib_delta is not None:
                S = math.exp(-z ** self.strib_delta)
            else:
                S = math.exp(-z * z) if self.strib_gauss else math.exp(-z)
            Fc = self.plant.F_d + (self.strib_F - self.plant.F_d) * S
        else:
            Fc = self.plant.F_d
        return s * Fc * self.fric_factor(y, s) * cphi

    def cushion(self, x):
        """(f_a, f_b): how far chamber A's / B's cushion is engaged (0 free, 1 engaged)."""
        L = self.plant.L
        return (_smoothstep((self.l_c - x) / self.chamfer),
                _smoothstep((x - (L - self.l_c)) / self.chamfer))

    def cushion_area(self, gap):
        """The cushion's restriction [m^2] with the piston ``gap`` [m] from the stroke end:
        the needle A_n, plus a tapered spear's annulus narrowing linearly to it."""
        if not self.A_g:
            return self.A_n
        return self.A_n + self.A_g * min(max(gap / self.l_c, 0.0), 1.0)

    # ---------------------------------------------------------------- derivatives
    def derivs(self, t, y, mode, ucmd, locks=(False, False)):
        p = self.plant
        idx = self.idx
        k, R, T = self.k, self.R, self.T
        x, pa, pb = y[0], y[2], y[3]
        moving = mode == SLIP_POS or mode == SLIP_NEG
        v = y[1] if moving else 0.0
        dy = [0.0] * len(y)
        u = ucmd if not callable(ucmd) else ucmd(t)

        # valve spool
        if self.vd:
            form, vp = self.vd
            s = y[idx["s"]]
            if form == "first_order":
                dy[idx["s"]] = (u - s) / vp["tau"]
            elif form == "rate_limited":
                rate = vp["rate"]
                dy[idx["s"]] = rate * math.tanh((u - s) / (vp["tau"] * rate))
            else:
                w = 2.0 * math.pi * vp["f_n"]
                sd = y[idx["s_dot"]]
                dy[idx["s"]] = sd
                dy[idx["s_dot"]] = w * w * (u - s) - 2.0 * vp["zeta"] * w * sd
        else:
            s = u
        area = self.opening(s)

        # temperatures
        if self.wall:
            Ta, Tb = y[idx["T_a"]], y[idx["T_b"]]
        else:
            Ta = Tb = T
        Ps = y[idx["p_r"]] if self.sag else p.P_s
        Pe = self.Pe
        # the nodes the valve feeds: port volumes, else the chambers
        if self.port:
            na, nb = y[idx["pp_a"]], y[idx["pp_b"]]
            Tna = Tnb = T
        else:
            na, nb = pa, pb
            Tna, Tnb = Ta, Tb
        if self.cush:
            fa, fb = self.cushion(x)
        else:
            fa = fb = 0.0

        # valve flows into the A and B nodes (signed), and drawn from the supply
        m_va = m_vb = m_sup = 0.0
        if area > 0.0:
            # the pressure each node's open port leads to: supply or exhaust (routing)
            if s < 5.0:
                oa, ob = Ps, Pe
            else:
                oa, ob = Pe, Ps
            area_a = area_b = area
            if self.cush and not self.port:
                # a cushioned chamber's outflow passes its needle (a tapered spear's gap) in
                # series with the port; the check valve lets inflow through freely, where
                # there is one
                if fa > 0.0 and (na > oa or not self.cush_check):
                    A_c = self.cushion_area(x)
                    area_a = (1.0 - fa) * area + fa * area * A_c / math.hypot(area, A_c)
                if fb > 0.0 and (nb > ob or not self.cush_check):
                    A_c = self.cushion_area(p.L - x)
                    area_b = (1.0 - fb) * area + fb * area * A_c / math.hypot(area, A_c)
            # a locked chamber sits at its port's source pressure: no flow (see ``lockable``)
            m_va = 0.0 if locks[0] else self.flow(area_a, oa, na, T, Tna)
            m_vb = 0.0 if locks[1] else self.flow(area_b, ob, nb, T, Tnb)
            m_sup = m_va if s < 5.0 else m_vb

        # chamber mass flows: net mdot into each chamber, and sum(mdot_i T_i) (inflow at its
        # source's temperature, outflow at the chamber's) for the energy form
        ma_net = mb_net = 0.0
        Ha = Hb = 0.0
        if self.port:
            # chamber <-> port: free bore outside the cushion, needle/check valve inside
            m_ca = self._port_flow(pa, na, fa, Ta)          # port -> chamber A
            m_cb = self._port_flow(pb, nb, fb, Tb)
            # port volumes: rigid, their gas taken at T (the hose walls hold it there), with
            # the chamber equation's exponent
            kap = self.kappa
            dy[idx["pp_a"]] = kap * R * T * (m_va - m_ca) / self.V_p
            dy[idx["pp_b"]] = kap * R * T * (m_vb - m_cb) / self.V_p
            in_a, in_b = m_ca, m_cb
            Tin_a = Tin_b = T
        else:
            in_a, in_b = m_va, m_vb
            Tin_a = Tin_b = T            # supply and atmosphere at T
        ma_net += in_a
        mb_net += in_b
        Ha += in_a * (Tin_a if in_a > 0.0 else Ta)
        Hb += in_b * (Tin_b if in_b > 0.0 else Tb)
        if self.leak:
            lf, lp = self.leak
            m_ab = 0.0
            if lf in ("laminar", "mixed"):
                m_ab += lp["C"] * (pa - pb)
            if lf in ("orifice", "mixed"):
                m_ab += self.flow(lp["A"], pa, pb, Ta, Tb)
            ma_net -= m_ab
            mb_net += m_ab
            Tab = Ta if m_ab > 0.0 else Tb
            Ha -= m_ab * Tab
            Hb += m_ab * Tab

        # chambers
        V0a = p.V_a0 - (self.V_p if self.port else 0.0)
        V0b = p.V_b0 - (self.V_p if self.port else 0.0)
        Va = p.A_a * x + V0a
        Vb = p.A_b * (p.L - x) + V0b
        dVa = p.A_a * v
        dVb = -p.A_b * v
        if self.wall:
            Qa = self.h_c * (self.Aw_a0 + self.Aw_a1 * x) * (T - Ta)
            Qb = self.h_c * (self.Aw_b0 + self.Aw_b1 * (p.L - x)) * (T - Tb)
            dpa = (k * R * Ha - k * pa * dVa + (k - 1.0) * Qa) / Va
            dpb = (k * R * Hb - k * pb * dVb + (k - 1.0) * Qb) / Vb
            dy[idx["T_a"]] = Ta * (dpa / pa + dVa / Va - ma_net * R * Ta / (pa * Va))
            dy[idx["T_b"]] = Tb * (dpb / pb + dVb / Vb - mb_net * R * Tb / (pb * Vb))
        else:
            kap = self.kappa
            dpa = (kap * R * T * ma_net - kap * pa * dVa) / Va
            dpb = (kap * R * T * mb_net - kap * pb * dVb) / Vb
        dy[2] = dpa
        dy[3] = dpb

        if self.sag:
            sp = self.sag[1]
            dy[idx["p_r"]] = R * T * (sp["G"] * (p.P_s - Ps) - m_sup) / sp["V_r"]

        if self.lag:
            tau = self.lag_tau
            dy[idx["alpha_m"]] = (self.alpha(x) - y[idx["alpha_m"]]) / tau
            dy[idx["p_a_m"]] = (pa - y[idx["p_a_m"]]) / tau
            dy[idx["p_b_m"]] = (pb - y[idx["p_b_m"]]) / tau

        # motion
        if moving:
            F, cphi = self.drive(t, y)
            _, M = self.load(t)
            dy[0] = v
            dy[1] = (F - p.K_v * v - self.slip_friction(y, v, cphi)) / M
        return dy

    def _port_flow(self, pc, pp, f, Tc):
        """Mass flow port -> chamber [kg/s]: inflow through the free bore / check valve,
        outflow through the bore (1 - f) and the needle (f)."""
        if pp >= pc:
            return self.G_free * (pp - pc)
        out = (1.0 - f) * self.G_free * (pc - pp)
        if f > 0.0:
            out += f * self.orifice(self.A_n, pc, pp, Tc)
        return -out

    # ---------------------------------------------------------------- events
    def events(self, mode, y):
        """[(event function, kind)] for ``mode`` at the state ``y`` it starts from."""
        L = self.plant.L
        evs = []
        if mode in (SLIP_POS, SLIP_NEG):
            s = 1 if mode == SLIP_POS else -1

            def vzero(t, y):
                return y[1]
            vzero.terminal, vzero.direction = True, -s
            evs.append((vzero, "vzero"))
            if s > 0:
                def hit(t, y):
                    return y[0] - L
                hit.terminal, hit.direction = True, 1
                evs.append((hit, "stop_high"))
            else:
                def hit(t, y):
                    return y[0]
                hit.terminal, hit.direction = True, -1
                evs.append((hit, "stop_low"))
        elif mode == STICK:
            def brk_pos(t, y):
                F, c = self.drive(t, y)
                return F - self.static_level(y, 1, c)

            def brk_neg(t, y):
                F, c = self.drive(t, y)
                return F + self.static_level(y, -1, c)

            def push(t, y):
                return self.drive(t, y)[0]
            brk_pos.terminal, brk_pos.direction = True, 1
            brk_neg.terminal, brk_neg.direction = True, -1
            push.terminal = True
            if y[0] >= L:               # sticking at a stroke end: pushed back into the stop
                push.direction = 1
                evs = [(brk_neg, "break_neg"), (push, "push_high")]
            elif y[0] <= 0.0:
                push.direction = -1
                evs = [(brk_pos, "break_pos"), (push, "push_low")]
            else:
                evs = [(brk_pos, "break_pos"), (brk_neg, "break_neg")]
        else:
            def leave(t, y):
                return self.drive(t, y)[0]
            leave.terminal = True
            leave.direction = -1 if mode == STOP_HIGH else 1
            evs.append((leave, "leave"))
        return evs

    def route_side(self, t, y, ucmd):
        """+1 where the routing is u > 5 (supply -> B, A -> exhaust), -1 where u < 5, 0 at
        the centre; from the spool where the valve has dynamics."""
        u = ucmd(t) if callable(ucmd) else ucmd
        if self.vd:
            r = y[self.idx["s"]]
            if abs(r - 5.0) <= 1e-9:       # the spool at the centre: the way it moves
                sd = y[self.idx["s_dot"]] if self.vd[0] == "second_order" else 0.0
                r = 5.0 + sd if sd != 0.0 else u
        else:
            r = u
            if r == 5.0 and callable(ucmd):
                r = ucmd(t + 1e-9)          # where the command takes it
        return 0 if r == 5.0 else (1 if r > 5.0 else -1)

    def sources(self, side):
        """(source of A, source of B) [Pa] for a routing side (None: closed)."""
        if side == 0:
            return None, None
        return (self.plant.P_s, self.Pe) if side < 0 else (self.Pe, self.plant.P_s)

    def check_locks(self, mode, y, side):
        """The locks valid at (mode, y, side): a chamber is locked where it sits at its
        source pressure (to 2 LOCK_TOL relative, then set to it exactly) with the piston at
        rest."""
        if not self.lockable or mode in (SLIP_POS, SLIP_NEG) or side == 0:
            return (False, False)
        src = self.sources(side)
        out = []
        for j in (0, 1):
            nodes = self.lock_nodes[j]
            hit = all(abs(y[i] - src[j]) <= 2.0 * LOCK_TOL * src[j] for i in nodes)
            if hit:
                for i in nodes:
                    y[i] = src[j]
            out.append(hit)
        return tuple(out)

    def lock_events(self, y, side, locks):
        """A chamber reaching its source pressure (within LOCK_TOL, from the side it is on)."""
        evs = []
        src = self.sources(side)
        for j, key in ((0, "lock_a"), (1, "lock_b")):
            if locks[j]:
                continue
            if self.port:
                # chamber and port converge on the source together (the chamber through the
                # free bore or the needle, the port through the valve): both within LOCK_TOL
                def g(t, y, ic=2 + j, ip=self.lock_nodes[j][1], ps=src[j]):
                    return max(abs(y[ic] - ps), abs(y[ip] - ps)) - LOCK_TOL * ps
                g.terminal, g.direction = True, -1
                evs.append((g, key))
                continue
            below = y[2 + j] < src[j]
            level = src[j] * (1.0 - LOCK_TOL if below else 1.0 + LOCK_TOL)

            def g(t, y, i=2 + j, level=level):
                return y[i] - level
            g.terminal, g.direction = True, (1 if below else -1)
            evs.append((g, key))
        return evs

    def route_event(self, ucmd, side):
        """The routing's flip (the spool or a continuous command crossing 5 V)."""
        if self.vd:
            i = self.idx["s"]

            def g(t, y):
                return y[i] - 5.0
        else:
            def g(t, y):
                return ucmd(t) - 5.0
        g.terminal, g.direction = True, -side
        return (g, "route")

    # ---------------------------------------------------------------- transitions
    def at_rest(self, t, y):
        """The mode of a piston at rest (v = 0): at a stop, sticking, or starting to slip."""
        F, c = self.drive(t, y)
        L = self.plant.L
        if y[0] >= L and F > 0.0:
            return STOP_HIGH
        if y[0] <= 0.0 and F < 0.0:
            return STOP_LOW
        d = 1 if F > 0.0 else -1
        if abs(F) <= self.static_level(y, d, c):
            return STICK
        return SLIP_POS if d > 0 else SLIP_NEG

    def transition(self, kind, mode, t, y):
        """The new (mode, state) after event ``kind`` fired in ``mode`` at (t, y)."""
        y = np.array(y, dtype=float)
        L = self.plant.L
        if -1e-12 < y[0] < 0.0:           # an event's rounding past a stroke end
            y[0] = 0.0
        elif L < y[0] < L + 1e-12:
            y[0] = L
        if kind == "vzero":
            y[1] = 0.0
            F, c = self.drive(t, y)
            d = 1 if F > 0.0 else -1
            if (y[0] >= L and F > 0.0) or (y[0] <= 0.0 and F < 0.0):
                new = STOP_HIGH if F > 0.0 else STOP_LOW     # came to rest right at the stop
            elif d == (1 if mode == SLIP_POS else -1) or abs(F) <= self.static_level(y, d, c):
                new = STICK
            else:
                new = SLIP_POS if d > 0 else SLIP_NEG
        elif kind in ("stop_high", "stop_low"):
            y[0] = L if kind == "stop_high" else 0.0
            y[1] = 0.0
            new = self.at_rest(t, y)
        elif kind == "break_pos":
            new = STOP_HIGH if y[0] >= L else SLIP_POS
        elif kind == "break_neg":
            new = STOP_LOW if y[0] <= 0.0 else SLIP_NEG
        elif kind == "push_high":
            new = STOP_HIGH
        elif kind == "push_low":
            new = STOP_LOW
        elif kind == "leave":
            new = self.at_rest(t, y)
            if new == mode:              # rounding at the root: the force has turned away
                new = STICK
        else:
            raise AssertionError(kind)
        if new == SLIP_POS and y[1] <= 0.0:
            y[1] = V_START
        elif new == SLIP_NEG and y[1] >= 0.0:
            y[1] = -V_START
        elif new in (STICK, STOP_HIGH, STOP_LOW):
            y[1] = 0.0
        return new, y

    # ---------------------------------------------------------------- initial state
    def initial(self, x0):
        """(y0, mode0) at t = 0 from x0: a position [m] (chambers at atmosphere, at rest), or
        a dict with x and optionally v [m/s], p_a, p_b [Pa gauge]."""
        p = self.plant
        if x0 is None:
            x0 = 0.0
        if isinstance(x0, dict):
            unknown = set(x0) - {"x", "v", "p_a", "p_b"}
            if unknown:
                raise ValueError(f"x0 keys are x, v, p_a, p_b (gauge); not {sorted(unknown)}")
            x, v = float(x0.get("x", 0.0)), float(x0.get("v", 0.0))
            pa, pb = p.P_atm + float(x0.get("p_a", 0.0)), p.P_atm + float(x0.get("p_b", 0.0))
        else:
            x, v, pa, pb = float(x0), 0.0, p.P_atm, p.P_atm
        if not 0.0 <= x <= p.L:
            raise ValueError(f"x0 = {x} m lies outside the stroke [0, {p.L}]")
        if pa <= 0 or pb <= 0:
            raise ValueError("initial chamber pressures must be above vacuum")
        y = np.zeros(len(self.names))
        y[0], y[1], y[2], y[3] = x, v, pa, pb
        i = self.idx
        if self.vd:
            y[i["s"]] = 5.0          # overwritten by simulate with the first command
        if self.wall:
            y[i["T_a"]] = y[i["T_b"]] = p.T
        if self.port:
            y[i["pp_a"]], y[i["pp_b"]] = pa, pb
        if self.sag:
            y[i["p_r"]] = p.P_s
        if self.lag:
            y[i["alpha_m"]], y[i["p_a_m"]], y[i["p_b_m"]] = self.alpha(x), pa, pb
        if v > 0:
            mode = SLIP_POS
        elif v < 0:
            mode = SLIP_NEG
        else:
            mode = self.at_rest(0.0, y)
        return y, mode


# --------------------------------------------------------------------------- simulate
#: Work a solve may take before it is redone with the other method: RHS calls, fixed
#: plus per simulated second (LSODA needs ~1e3 per second here; where it crawls, near
#: the orifice law's singular point with heat exchange or a port volume, BDF does not).
BUDGET = (20000, 20000)


class _OverBudget(Exception):
    pass


def _budgeted(fun, budget):
    if budget is None:
        return fun
    count = [0]

    def wrapped(t, y):
        count[0] += 1
        if count[0] > budget:
            raise _OverBudget
        return fun(t, y)
    return wrapped


def _command_plan(profile, duration, ts, hold):
    """(u at the samples, segments [(t_start, t_end, command)]) where command is a
    float (held) or a callable of t."""
    u_s = np.array([float(profile(float(t))["u"]) for t in ts])
    continuous = (not hold) or not hasattr(profile, "breakpoints") or bool(getattr(profile, "continuous", False))
    if continuous:
        bps = sorted(float(b) for b in getattr(profile, "breakpoints", ()) or () if 0.0 < float(b) < duration)
        edges = [0.0] + bps + [duration]
        ufun = lambda t: float(profile(t)["u"])   # noqa: E731
        segs = [(edges[i], edges[i + 1], ufun) for i in range(len(edges) - 1) if edges[i + 1] > edges[i]]
        return u_s, segs
    change = np.flatnonzero(np.diff(u_s) != 0.0) + 1
    starts = np.concatenate(([0], change))
    segs = []
    for j, i0 in enumerate(starts):
        t0 = float(ts[i0])
        t1 = float(ts[starts[j + 1]]) if j + 1 < len(starts) else duration
        if t1 > t0:
            segs.append((t0, t1, float(u_s[i0])))
    return u_s, segs


def _split(segs, times):
    """Segments cut at extra breakpoint ``times``."""
    for tc in times:
        out = []
        for a, b, c in segs:
            if a < tc < b:
                out += [(a, tc, c), (tc, b, c)]
            else:
                out.append((a, b, c))
        segs = out
    return segs


def simulate(plant: Plant | None, profile, duration=None, fs=None, seed=0, x0=None, hold=True,
             rtol: float = 1e-7, method: str = "auto", atol_scale: float = 1.0) -> pd.DataFrame:
    """Run the rig on ``profile`` (t -> {"u": V}; ``.duration``, ``.breakpoints``) and
    return a recording as a DataFrame: ``t`` (from 0, every 1/fs), ``u``, ``p_a``, ``p_b``
    (gauge, measured), ``alpha`` (rad, measured), and the truth ``x_true``, ``v_true``,
    ``p_a_true``, ``p_b_true`` (gauge), ``alpha_true``, ``mode`` (1/-1 slipping, 0 sticking,
    2/-2 held at x = L / x = 0), and ``p_a_sensed``, ``p_b_sensed``, ``alpha_sensed``: what
    reaches the converters (through the sensor path's lag, before noise and rounding).

    ``fs`` [Hz]: None is ``plant.sensors["fs"]`` or 1000.  ``seed``: the sensor noise's
    numpy Generator.  ``x0``: None (x = 0, chambers at atmosphere), a position [m], or a
    dict {x, v, p_a, p_b (gauge)}.  ``hold``: sample and hold the command at the DAQ
    instants (False: evaluate it continuously).  ``rtol``, ``method``, ``atol_scale``:
    the solver's (the absolute tolerances are per state, scaled by ``atol_scale``).
    ``frame.attrs`` carries the plant, the solver statistics and wall time
    (``solver``) and every located event (``events``: (t, kind, mode before, mode
    after); kinds vzero, stop_high, stop_low, break_pos, break_neg, push_high,
    push_low, leave, lock_a, lock_b, route)."""
    wall0 = time.perf_counter()
    plant = plant if plant is not None else Plant()
    m = _Model(plant)
    if fs is None:
        fs = m.sens.get("fs") or 1000.0
    fs = float(fs)
    if duration is None:
        duration = getattr(profile, "duration", None)
        if duration is None:
            raise ValueError("the profile has no duration: give one")
    duration = float(duration)
    n = int(math.floor(duration * fs + 1e-9)) + 1
    ts = np.arange(n) / fs
    u_s, segs = _command_plan(profile, duration, ts, hold)
    jumps = []                            # where the load on the piston may jump
    if m.payload:
        jumps.append(float(m.payload[1]["t_change"]))
    if m.fext and m.fext[0] == "ramp":
        jumps.append(float(m.fext[1]["t0"]))
    segs = _split(segs, jumps)

    # where the states are wanted: the samples, and the samples minus a sensor dead time
    delay = m.lag_delay if m.lag else 0.0
    want = ts if delay <= 0.0 else np.unique(np.concatenate((ts, ts[ts >= delay] - delay)))
    Y = np.empty((len(m.names), len(want)))
    modes = np.empty(len(want), dtype=int)

    y, mode = m.initial(x0)
    if m.vd:
        u0 = segs[0][2] if not callable(segs[0][2]) else segs[0][2](0.0)
        y[m.idx["s"]] = u0                # the spool rests where the first command puts it
    atol = m.atol * atol_scale
    max_step = np.inf
    if m.vib:
        max_step = 0.1 / m.vib[1]["frequency"]
    stats = {"segments": 0, "transitions": 0, "nfev": 0, "fallbacks": 0}
    events = []                           # (t, event kind, mode before, mode after)
    if method == "auto":
        # LSODA (Adams, switching to BDF where stiff) is ten times faster than scipy's BDF
        # here, but crawls near the orifice law's singular point where something keeps a
        # small flow going (heat exchange, a port volume): a solve that overruns BUDGET,
        # or fails, is redone with BDF
        methods = ("LSODA", "BDF")
    else:
        methods = (method,)
    ie = 0
    t = 0.0
    stuck = 0
    for (ta, tb, ucmd) in segs:
        if ta in jumps and mode in (STICK, STOP_HIGH, STOP_LOW):
            mode = m.at_rest(ta, y)          # the load jumped: is the rest still one?
            if mode == SLIP_POS:
                y[1] = V_START
            elif mode == SLIP_NEG:
                y[1] = -V_START
        t = ta
        route_flips = 0
        while t < tb:
            j = int(np.searchsorted(want, tb, side="left"))
            if tb - t <= 1e-13 * max(1.0, tb):      # an event right at the segment's end
                Y[:, ie:j] = y[:, None]
                modes[ie:j] = mode
                ie = j
                break
            evs = m.events(mode, y)
            # no locks while the command sits at the centre (the spool settles there, perhaps
            # crossing it again and again) nor after a few routing flips in one segment
            lock_ok = m.lockable and route_flips <= 4 and (callable(ucmd) or ucmd != 5.0)
            side = m.route_side(t, y, ucmd) if lock_ok else 0
            locks = m.check_locks(mode, y, side)
            if lock_ok and side != 0 and mode not in (SLIP_POS, SLIP_NEG):
                lev = m.lock_events(y, side, locks)
                evs += lev
                if (lev or any(locks)) and (m.vd or callable(ucmd)):
                    evs.append(m.route_event(ucmd, side))
            fun = (lambda mo, uc, lk: (lambda tt, yy: m.derivs(tt, yy, mo, uc, lk)))(mode, ucmd, locks)
            t_eval = np.append(want[ie:j], tb)
            sol, why = None, ""
            for k_meth, meth in enumerate(methods):
                last = k_meth == len(methods) - 1
                budget = None if last else BUDGET[0] + BUDGET[1] * (tb - t)
                try:
                    sol = solve_ivp(_budgeted(fun, budget), (t, tb), y, method=meth, t_eval=t_eval,
                                    events=[e for e, _ in evs], rtol=rtol, atol=atol, max_step=max_step)
                except _OverBudget:
                    sol, why = None, f"{meth} needed more than {budget:.0f} RHS calls"
                    stats["nfev"] += int(budget)
                    stats["fallbacks"] += 1
                    continue
                except ValueError as exc:        # an event root bracketed only to rounding
                    sol, why = None, str(exc)
                    stats["fallbacks"] += 1
                    continue
                stats["nfev"] += sol.nfev
                if sol.status >= 0:
                    break
                why, sol = sol.message, None
                stats["fallbacks"] += 1
            if sol is None:
                raise RuntimeError(f"the solver failed at t = {t:.6f} s in mode {MODE_NAMES[mode]}: {why}")
            stats["segments"] += 1
            held = mode not in (SLIP_POS, SLIP_NEG)
            x_held = y[0]
            got = min(len(sol.t), j - ie)
            if got:
                Y[:, ie:ie + got] = np.asarray(sol.y)[:, :got]
                if held:        # x held exactly (the solver's algebra leaves ~1e-17 m of dust)
                    Y[0, ie:ie + got] = x_held
                    Y[1, ie:ie + got] = 0.0
            modes[ie:ie + got] = mode
            ie += got
            if sol.status == 1:
                hits = [(sol.t_events[i][0], i) for i in range(len(evs)) if len(sol.t_events[i])]
                te, i = min(hits)
                ye = np.array(sol.y_events[i][0], dtype=float)
                if held:
                    ye[0], ye[1] = x_held, 0.0
                kind = evs[i][1]
                if kind in ("lock_a", "lock_b", "route"):
                    new, y = mode, np.array(ye, dtype=float)
                    if kind != "route":      # the chamber reached its source: hold it there
                        c = 0 if kind == "lock_a" else 1
                        for node in m.lock_nodes[c]:
                            y[node] = m.sources(side)[c]
                    else:
                        route_flips += 1
                        if m.vd:             # the spool at the centre, exactly
                            y[m.idx["s"]] = 5.0
                else:
                    new, y = m.transition(kind, mode, te, ye)
                events.append((float(te), kind, mode, new))
                stats["transitions"] += 1
                stuck = stuck + 1 if te - t < 1e-12 else 0
                if stuck > 50:
                    raise RuntimeError(f"mode changes do not advance time at t = {te:.9f} s "
                                       f"({MODE_NAMES[mode]} -> {MODE_NAMES[new]} on {kind})")
                mode, t = new, float(te)
            else:
                y = sol.y[:, -1].copy()
                if held:
                    y[0], y[1] = x_held, 0.0
                t = tb
            pmin = min(y[2], y[3])
            if not pmin > 0.0:
                raise RuntimeError(f"a chamber pressure fell to {pmin} Pa absolute at t = {t}: the "
                                   f"solve is broken")
    if ie < len(want):                    # the last sample sits exactly on the end
        Y[:, ie:] = y[:, None]
        modes[ie:] = mode

    i_s = np.searchsorted(want, ts)
    P_atm = plant.P_atm
    x = Y[0, i_s]
    frame = pd.DataFrame({"t": ts, "u": u_s})
    alpha_true = alpha_of_x(x, plant)
    if m.lag:
        i_d = np.searchsorted(want, np.maximum(ts - delay, 0.0))
        idx = m.idx
        a_m, pa_m, pb_m = Y[idx["alpha_m"], i_d], Y[idx["p_a_m"], i_d], Y[idx["p_b_m"], i_d]
    else:
        a_m, pa_m, pb_m = alpha_true, Y[2, i_s], Y[3, i_s]
    rng = np.random.default_rng(seed)
    a_meas, pa_meas, pb_meas = _sensors(m.sens, a_m, pa_m - P_atm, pb_m - P_atm, rng)
    frame["p_a"], frame["p_b"], frame["alpha"] = pa_meas, pb_meas, a_meas
    # what reaches the converters: the sensor path (its lag) without noise or rounding
    frame["p_a_sensed"], frame["p_b_sensed"], frame["alpha_sensed"] = pa_m - P_atm, pb_m - P_atm, a_m
    frame["x_true"] = x
    frame["v_true"] = Y[1, i_s]
    frame["p_a_true"] = Y[2, i_s] - P_atm
    frame["p_b_true"] = Y[3, i_s] - P_atm
    frame["alpha_true"] = alpha_true
    frame["mode"] = modes[i_s]
    for name in m.names[4:]:
        if name in ("alpha_m", "p_a_m", "p_b_m"):
            continue
        col = Y[m.idx[name], i_s]
        frame[f"{name}_true"] = col - P_atm if name in ("pp_a", "pp_b", "p_r") else col
    stats["wall_s"] = time.perf_counter() - wall0
    frame.attrs["plant"] = copy.deepcopy(plant)
    frame.attrs["solver"] = stats
    frame.attrs["events"] = events
    frame.attrs["fs"] = fs
    frame.attrs["seed"] = seed
    return frame


def _sensors(sens, alpha, pa, pb, rng):
    """Noise and quantisation of the measured channels (pressures gauge)."""
    n = len(alpha)
    a_noise = rng.standard_normal(n)
    pa_noise = rng.standard_normal(n)
    pb_noise = rng.standard_normal(n)
    a = alpha + float(sens["angle_noise"]) * a_noise
    if sens["angle_bits"]:
        span = math.radians(float(sens["angle_span_deg"]))
        q = span / 2 ** int(sens["angle_bits"])
        a = np.clip(np.round(a / q), 0, 2 ** int(sens["angle_bits"]) - 1) * q
    out = [a]
    for p, noise in ((pa, pa_noise), (pb, pb_noise)):
        p = p + float(sens["p_noise"]) * noise
        lo, hi = (float(v) for v in sens["p_span"])
        if sens["p_bits"]:
            levels = 2 ** int(sens["p_bits"])
            q = (hi - lo) / levels
            c = np.round((p - lo) / q)
            if sens["p_saturate"]:
                c = np.clip(c, 0, levels - 1)
            p = lo + c * q
        elif sens["p_saturate"] and float(sens["p_noise"]) > 0:
            p = np.clip(p, lo, hi)
        out.append(p)
    return out


# --------------------------------------------------------------------------- write
def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (bool, int, float, str)) or obj is None:
        return obj
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return repr(obj)


def write(path, frame: pd.DataFrame, notes: str = "", truth: bool = True) -> Path:
    """Write ``frame`` as a recording: ``path`` (CSV: t, u, p_a, p_b, alpha only), a sidecar
    ``<name>.json`` only where the plant's geometry, cylinder, valve, gas or supply differ
    from the reference rig (``{"rig": {...}}`` by boomfmi's key names, pressures absolute;
    never the load or the effects), and, with ``truth``, ``<name>.truth.json`` holding
    the hidden load, effects, disturbances and sensors."""
    from boomfmi.recording import write_recording
    path = Path(path)
    plant = frame.attrs.get("plant") or Plant()
    rig = {}
    for name in SIDECAR_FIELDS:
        ref = PLANT_DEFAULTS[name] if name != "P_e" else PLANT_DEFAULTS["P_atm"]
        val = plant.exhaust if name == "P_e" else float(getattr(plant, name))
        if not math.isclose(val, ref, rel_tol=1e-12, abs_tol=0.0):
            rig[name] = float(val)
    sidecar = {}
    if rig:
        sidecar["rig"] = rig
        if notes:
            sidecar["notes"] = str(notes)
    side = path.with_suffix(".json")
    if side.exists() and not sidecar:
        side.unlink()                    # a stale sidecar would override the reference rig
    write_recording(path, frame[["t", "u", "p_a", "p_b", "alpha"]], sidecar=sidecar or None)
    if truth:
        info = {"load": {k: float(getattr(plant, k)) for k in LOAD_FIELDS},
                "effects": _jsonable(plant.effects), "disturbances": _jsonable(plant.disturbances),
                "sensors": _jsonable(plant.sensors),
                "plant": {k: _jsonable(getattr(plant, k)) for k in PLANT_DEFAULTS},
                "fs": frame.attrs.get("fs"), "seed": frame.attrs.get("seed"), "notes": str(notes),
                "simulator": "benchmarks/hybrid_rig.py"}
        path.with_name(path.stem + ".truth.json").write_text(json.dumps(info, indent=2))
    return path


# --------------------------------------------------------------------------- timing
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="write the recording here")
    args = ap.parse_args(argv)
    from boomfmi.experiments import random_steps
    prof = random_steps(args.seed, duration=args.duration)
    t0 = time.perf_counter()
    frame = simulate(Plant(), prof)
    wall = time.perf_counter() - t0
    st = frame.attrs["solver"]
    print(f"{args.duration:g} s of random steps (seed {args.seed}) in {wall:.2f} s wall: "
          f"{st['segments']} solver segments, {st['transitions']} mode changes, {st['nfev']} RHS calls")
    if args.out:
        write(args.out, frame, notes=f"hybrid_rig random_steps({args.seed})")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
