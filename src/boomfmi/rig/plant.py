"""The virtual rig's plant: the physical boom, simulated sample by sample at 1 kHz.

:class:`VirtualRig` stands in for the machine of the paper (DSNU 32-60 cylinder, MPYE-5
valve, SDE5-D10 pressure sensors, a 10 kOhm potentiometer, a 12-bit PCI-1711): give it
a valve command, it returns what the data acquisition would have recorded.  Its
configuration (:class:`RigConfig`, :func:`load_config`, JSON files in
``examples/rig/``) switches on the unmodelled effects of ``shared/spec/effects.md``,
sets the sensors' noise, and adds a contact with the ground or a disturbance.

Physics
-------
The baseline is the paper's model exactly as ``boomfmi.physics`` writes it: the
valve's ``chamber_flows`` and their slopes ``chamber_flow_slopes``, each chamber's
``chamber_pressure_step`` (exact for a closed chamber, exponential against the valve's
linearisation otherwise), ``advance_load`` with the paper's stick/slip rule and hard
end stops, and the geometry of Eq. 10 to 12.  Valve and chambers are coupled
Gauss-Seidel over internal substeps of at most ``SUBSTEP`` = 0.1 ms (shorter with a
stiff contact or a fast vibration): the load moves under the pressures predicted for
the middle of the substep (Eq. 7), then the chambers follow the volume change.  With every effect and the
noise off it reproduces ``boomfmi.reference.simulate_reference`` to about 0.01 %
NRMSE on the paper's experiment.

Effects (``RigConfig.effects``: name -> parameters; absent = off; ``{}`` or ``true`` =
the defaults).  Forms in ``boomfmi.physics.rig_truth``:

=================== ======== ============================== ========= ===============
effect              name     meaning [unit]                  default   realistic range
=================== ======== ============================== ========= ===============
valve_dynamics      f_n      spool natural frequency [Hz]    100       60 .. 150
                    zeta     spool damping ratio [1]         0.7       0.5 .. 0.9
valve_deadband      overlap  dead band half-width [V]        0.4       0.2 .. 0.6
                    edge     rounded-edge half-width [V]     0.15      0.05 .. 0.3
heat_transfer       h_w      wall coefficient [W/(m^2 K)]    40        10 .. 150
                    A_w0     dead-volume wall area [m^2]     0.01      0.003 .. 0.03
                    T_s      supply air temperature [K]      293.15    283 .. 313
piston_leakage      A_leak   seal leak orifice area [m^2]    2e-8      1e-8 .. 5e-8
stribeck_friction   v_s      Stribeck velocity [m/s]         0.01      0.002 .. 0.03
                    F_brk    breakaway force [N]             140       F_d .. 250
end_cushioning      l_c      cushion length [m]              0.012     0.005 .. 0.015
                    A_n      needle-valve area [m^2]         5e-8      2e-8 .. 3e-7
                    w        spigot entry chamfer [m]        0.001     0.0005 .. 0.003
sensor_lag          delay    transport delay [s]             0.003     0.001 .. 0.005
                    tau      first-order time constant [s]   0.005     0.002 .. 0.010
=================== ======== ============================== ========= ===============

What each does with its defaults (from rest at x = 0, noise off; the tests check each
direction):

* valve_dynamics: second-order spool ``y'' + 2 zeta w y' + w^2 y = w^2 u``
  (w = 2 pi f_n), exact over each substep; area and routing follow y.  The spool
  starts centred (5 V).  After a step to 1 V, p_a rises 3 kPa in the first ms
  instead of 42 kPa.
* valve_deadband: smooth overlap, zero opening for |y - 5| < overlap - edge, C1
  quadratic over the edge, linear (rescaled to reach A_max at full command) beyond.
  5.3 V or 4.7 V leave the piston where it is (the paper's valve moves it).
* heat_transfer: a temperature per chamber (m and T states, P = m R T / V), supply air
  entering at T_s, heat from the wall ``h_w A_wall(x) (T_wall - T)``, T_wall = params T.
  Chamber B filled in 80 ms at the stop reaches about 370 K; with the valve closed its
  pressure then falls from 6.0 to 4.5 bar gauge within a second as the air cools.
* piston_leakage: the paper's compressible orifice law (Eq. 1) across the piston,
  from the higher to the lower chamber pressure.  At the end of stroke with the valve
  centred, p_b rises by about 3 bar and the piston sinks 8 mm in 2.5 s.
* stribeck_friction: ``F_d + (F_brk - F_d) / (1 + (v/v_s)^2)`` times cos(phi), viscous
  K_v v kept, the stick test at F_brk cos(phi).  At 4 V the piston breaks away 4 ms
  later at 0.4 bar more; at speed, friction is back at F_d.
* end_cushioning: over the last l_c of stroke the exhausting chamber's outflow passes
  the needle A_n in series with the valve port (``1/A^2 = 1/A_v^2 + g/A_n^2``).  The
  exhaust pressure peaks at about 0.7 bar gauge (extending) or 1 bar (retracting) at
  the stroke end and the piston slows by 10 to 20 % in the last mm: the 15 cm^3 dead
  volume on the cylinder side of the restriction limits the cushion's air spring.
* sensor_lag: first-order filter (tau) then transport delay on p_a, p_b and alpha;
  a ramp is recorded delay + tau = 8 ms late.

Contact (``RigConfig.contact``), forces positive against extension:

* ``{"type": "spring", "x_contact": m, "stiffness": N/m, "damping": N s/m}``: below
  x_contact the ground pushes the piston out, ``f_ext = -(k (x_c - x) + c max(-v, 0))``;
  soft soil about 2e4 N/m, hard ground about 5e5 N/m (damping defaults to 0).
* ``{"type": "ramp", "start": s, "rate": N/s, "max": N, "sign": +1 | -1}``: a digging
  load ``sign min(rate (t - start), max)`` after ``start`` (start defaults to 0, sign to
  +1), independent of position.

Disturbance (``RigConfig.disturbance``), outside the effects' vocabulary, for blind
tests: ``{"type": "vibration", "amplitude": N, "frequency": Hz}``, a force
``amplitude sin(2 pi frequency t)`` on the piston, added to ``f_ext``.

Sensors (``RigConfig.noise``): Gaussian noise ``p_sigma`` [Pa] (default 500) on each
pressure and ``alpha_sigma`` [rad] (default 2e-4) on the angle, then, with ``quantise``
(default true), a 12-bit ADC: pressures over the SDE5-D10's 0 .. 10 bar gauge range
(LSB = 1e6 / 4096 = 244.14 Pa; readings saturate at 0 and 999 756 Pa gauge), the angle
over 0 .. pi rad (LSB = pi / 4096 = 7.67e-4 rad).  Noise comes from a NumPy Generator
seeded with ``RigConfig.seed``: the same config and commands give the same samples.

Model parameters (``RigConfig.params``) override the reference rig by the FMUs'
parameter names: ``A_max, P_s, P_e, k, R, T, A_a, A_b, L, V_a0, V_b0, a, b, h, l_min,
K_v, F_s, F_d, F_L, M, P_atm, p_a0, p_b0`` (pressures absolute [Pa]).
"""
from __future__ import annotations

import json
import math
import os
from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .. import physics as ph
from ..physics import reference_rig as rig
from ..physics.chamber import chamber_pressure_step, chamber_volumes, pressure_rates
from ..physics.geometry import alpha_from_x
from ..physics.load import advance_load
from ..physics.orifice import signed_mass_flow, signed_mass_flow_slope
from ..physics.params import Gas
from ..physics.rig_truth import (chamber_temperature, chamber_wall_areas, cushion_engagement,
                                 cushion_exhaust_area, first_order_coefficient, overlap_command,
                                 piston_leak_flows, quantise, ramp_force, spool_step,
                                 spool_transition, spring_contact_force, stribeck_load,
                                 thermal_equivalent_flow, vibration_force, wall_heat_flow)
from ..physics.valve import chamber_flow_slopes, chamber_flows, orifice_area

#: Longest internal substep [s].  0.1 ms: the load moves under the pressures at the
#: start of a substep and a start of motion is tested at substep boundaries, so a
#: coarser substep delays every start by a fraction of it (0.25 ms biased starts from a
#: stop, where the drive force sweeps through the static band in about a millisecond).
SUBSTEP = 1.0e-4
#: Command range of the valve [V].
U_MIN, U_MAX = rig.u_min, rig.u_max
#: ADC resolution [bit] and the measured ranges: pressure gauge [Pa], angle [rad].
ADC_BITS = 12
P_RANGE = (0.0, 1.0e6)
ALPHA_RANGE = (0.0, math.pi)
P_LSB = (P_RANGE[1] - P_RANGE[0]) / 2**ADC_BITS
ALPHA_LSB = (ALPHA_RANGE[1] - ALPHA_RANGE[0]) / 2**ADC_BITS

#: Model parameters that ``RigConfig.params`` may override, with the reference values.
PARAMETERS = {
    "A_max": rig.A_max, "P_s": rig.P_s, "P_e": rig.P_e,
    "k": rig.k, "R": rig.R, "T": rig.T,
    "A_a": rig.A_a, "A_b": rig.A_b, "L": rig.L, "V_a0": rig.V_a0, "V_b0": rig.V_b0,
    "a": rig.a, "b": rig.b, "h": rig.h, "l_min": rig.l_min,
    "K_v": rig.K_v, "F_s": rig.F_s, "F_d": rig.F_d, "F_L": rig.F_L, "M": rig.M,
    "P_atm": rig.P_atm, "p_a0": rig.P_atm, "p_b0": rig.P_atm,
}

#: Each effect's parameters and defaults (names exactly those of effects.md).
EFFECTS = {
    "valve_dynamics": {"f_n": 100.0, "zeta": 0.7},
    "valve_deadband": {"overlap": 0.4, "edge": 0.15},
    "heat_transfer": {"h_w": 40.0, "A_w0": 0.01, "T_s": rig.T},
    "piston_leakage": {"A_leak": 2e-8},
    "stribeck_friction": {"v_s": 0.01, "F_brk": 140.0},
    "end_cushioning": {"l_c": 0.012, "A_n": 5e-8, "w": 0.001},
    "sensor_lag": {"delay": 0.003, "tau": 0.005},
}
#: Realistic ranges of the effects' parameters (documentation; not enforced).
EFFECT_RANGES = {
    "valve_dynamics": {"f_n": (60.0, 150.0), "zeta": (0.5, 0.9)},
    "valve_deadband": {"overlap": (0.2, 0.6), "edge": (0.05, 0.3)},
    "heat_transfer": {"h_w": (10.0, 150.0), "A_w0": (0.003, 0.03), "T_s": (283.0, 313.0)},
    "piston_leakage": {"A_leak": (1e-8, 5e-8)},
    "stribeck_friction": {"v_s": (0.002, 0.03), "F_brk": (rig.F_d, 250.0)},
    "end_cushioning": {"l_c": (0.005, 0.015), "A_n": (2e-8, 3e-7), "w": (0.0005, 0.003)},
    "sensor_lag": {"delay": (0.001, 0.005), "tau": (0.002, 0.010)},
}
NOISE = {"p_sigma": 500.0, "alpha_sigma": 2e-4, "quantise": True}
CONTACTS = {
    "spring": {"x_contact": None, "stiffness": None, "damping": 0.0},
    "ramp": {"start": 0.0, "rate": None, "max": None, "sign": 1.0},
}
DISTURBANCES = {"vibration": {"amplitude": None, "frequency": None}}
_TOP = ("params", "effects", "noise", "contact", "disturbance", "seed", "x0")


# ------------------------------------------------------------------ configuration
@dataclass
class RigConfig:
    """What the virtual rig is: built by :func:`load_config` (which validates it)."""
    params: dict = field(default_factory=dict)       #: model parameter overrides
    effects: dict = field(default_factory=dict)      #: effect name -> its parameters
    noise: dict = field(default_factory=lambda: dict(NOISE))
    contact: dict | None = None                      #: spring or ramp, see the module doc
    disturbance: dict | None = None                  #: vibration, see the module doc
    seed: int = 0                                    #: seed of the sensor noise
    x0: float = 0.0                                  #: initial piston position [m]


def _err(key: str, reason: str) -> ValueError:
    return ValueError(f"rig config: {key}: {reason}")


def _number(key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _err(key, f"must be a finite number, got {value!r}")
    return float(value)


def _table(key: str, value) -> dict:
    if not isinstance(value, dict):
        raise _err(key, f"must be an object, got {value!r}")
    return value


def _fill(key: str, given: dict, defaults: dict) -> dict:
    """Known keys of ``given`` as floats over ``defaults``; None in defaults = required."""
    for name in given:
        if name not in defaults:
            raise _err(f"{key}.{name}", f"unknown key (known: {', '.join(defaults)})")
    out = {}
    for name, default in defaults.items():
        if name in given:
            out[name] = _number(f"{key}.{name}", given[name])
        elif default is None:
            raise _err(f"{key}.{name}", "missing")
        else:
            out[name] = default
    return out


def _require(key: str, ok: bool, reason: str) -> None:
    if not ok:
        raise _err(key, reason)


def _model(params: dict):
    """The physics parameter tuples of ``params`` (overrides) with the checks applied."""
    p = dict(PARAMETERS)
    p.update(params)
    if "P_atm" in params and "P_e" not in params:
        p["P_e"] = p["P_atm"]
    valve = ph.Valve(A_max=p["A_max"], P_s=p["P_s"], P_e=p["P_e"])
    gas = ph.Gas(k=p["k"], R=p["R"], T=p["T"])
    cyl = ph.Cylinder(A_a=p["A_a"], A_b=p["A_b"], L=p["L"], V_a0=p["V_a0"], V_b0=p["V_b0"])
    geom = ph.Geometry(a=p["a"], b=p["b"], h=p["h"], l_min=p["l_min"])
    load = ph.Load(K_v=p["K_v"], F_s=p["F_s"], F_d=p["F_d"], F_L=p["F_L"], M=p["M"])
    try:
        ph.check_valve(valve)
        ph.check_gas(gas)
        ph.check_cylinder(cyl)
        ph.check_geometry(geom, cyl.L)
        ph.check_load(load)
        for name in ("P_atm", "p_a0", "p_b0"):
            ph.validation.require_positive(name, p[name])
    except ph.ParameterError as e:
        raise _err(f"params.{e.name}", str(e)) from None
    return valve, gas, cyl, geom, load, p


def _check_effect(name: str, q: dict, load, cyl) -> None:
    key = f"effects.{name}"
    if name == "valve_dynamics":
        _require(f"{key}.f_n", q["f_n"] > 0.0, "must be > 0 Hz")
        _require(f"{key}.zeta", q["zeta"] > 0.0, "must be > 0")
    elif name == "valve_deadband":
        _require(f"{key}.overlap", 0.0 <= q["overlap"] < 4.0, "must lie in [0, 4) V")
        _require(f"{key}.edge", 0.0 <= q["edge"] <= q["overlap"], "must lie in [0, overlap] V")
    elif name == "heat_transfer":
        _require(f"{key}.h_w", q["h_w"] >= 0.0, "must be >= 0")
        _require(f"{key}.A_w0", q["A_w0"] >= 0.0, "must be >= 0")
        _require(f"{key}.T_s", q["T_s"] > 0.0, "must be > 0 K")
    elif name == "piston_leakage":
        _require(f"{key}.A_leak", q["A_leak"] >= 0.0, "must be >= 0")
    elif name == "stribeck_friction":
        _require(f"{key}.v_s", q["v_s"] > 0.0, "must be > 0 m/s")
        _require(f"{key}.F_brk", q["F_brk"] >= load.F_d,
                 f"must be >= the Coulomb force F_d = {load.F_d:g} N")
    elif name == "end_cushioning":
        _require(f"{key}.l_c", 0.0 < q["l_c"] <= 0.5 * cyl.L, f"must lie in (0, {0.5 * cyl.L:g}] m")
        _require(f"{key}.A_n", q["A_n"] > 0.0, "must be > 0")
        _require(f"{key}.w", 0.0 < q["w"] <= q["l_c"], "must lie in (0, l_c] m")
    elif name == "sensor_lag":
        _require(f"{key}.delay", 0.0 <= q["delay"] <= 1.0, "must lie in [0, 1] s")
        _require(f"{key}.tau", q["tau"] >= 0.0, "must be >= 0 s")


def load_config(source=None) -> RigConfig:
    """A validated :class:`RigConfig` from a JSON file's path, a dict, a RigConfig or
    None (the reference rig: no effects, no contact, realistic noise).

    Every key is checked; an unknown or invalid one raises ``ValueError`` whose
    message names it (``effects.valve_dynamics.f_n``).  Effects are filled with their
    defaults, so the result says exactly what the rig simulates.
    """
    if source is None:
        data = {}
    elif isinstance(source, RigConfig):
        data = {"params": source.params, "effects": source.effects, "noise": source.noise,
                "contact": source.contact, "disturbance": source.disturbance,
                "seed": source.seed, "x0": source.x0}
    elif isinstance(source, dict):
        data = source
    elif isinstance(source, (str, os.PathLike)):
        try:
            with open(source, encoding="utf-8") as f:
                data = json.load(f)
        except json.JSONDecodeError as e:
            raise ValueError(f"rig config {os.fspath(source)}: not valid JSON: {e}") from None
        if not isinstance(data, dict):
            raise ValueError(f"rig config {os.fspath(source)}: must hold a JSON object")
    else:
        raise TypeError(f"load_config takes a path, a dict or None, not {type(source).__name__}")
    for key in data:
        if key not in _TOP:
            raise _err(key, f"unknown key (known: {', '.join(_TOP)})")

    params = {}
    for name, value in _table("params", data.get("params") or {}).items():
        if name not in PARAMETERS:
            raise _err(f"params.{name}", f"unknown parameter (known: {', '.join(PARAMETERS)})")
        params[name] = _number(f"params.{name}", value)
    _, _, cyl, _, load, _ = _model(params)

    effects = {}
    for name, value in _table("effects", data.get("effects") or {}).items():
        if name not in EFFECTS:
            raise _err(f"effects.{name}", f"unknown effect (known: {', '.join(EFFECTS)})")
        if value is None or value is False:
            continue
        if value is True:
            value = {}
        q = _fill(f"effects.{name}", _table(f"effects.{name}", value), EFFECTS[name])
        _check_effect(name, q, load, cyl)
        effects[name] = q

    noise_in = _table("noise", data.get("noise") or {})
    noise = {}
    for name in noise_in:
        if name not in NOISE:
            raise _err(f"noise.{name}", f"unknown key (known: {', '.join(NOISE)})")
    for name in ("p_sigma", "alpha_sigma"):
        noise[name] = _number(f"noise.{name}", noise_in.get(name, NOISE[name]))
        _require(f"noise.{name}", noise[name] >= 0.0, "must be >= 0")
    quant = noise_in.get("quantise", NOISE["quantise"])
    _require("noise.quantise", isinstance(quant, bool), f"must be true or false, got {quant!r}")
    noise["quantise"] = quant

    contact = data.get("contact")
    if contact is not None:
        contact = dict(_table("contact", contact))
        kind = contact.pop("type", None)
        _require("contact.type", kind in CONTACTS, f"must be one of {', '.join(CONTACTS)}, got {kind!r}")
        contact = {"type": kind, **_fill("contact", contact, CONTACTS[kind])}
        if kind == "spring":
            _require("contact.stiffness", contact["stiffness"] >= 0.0, "must be >= 0 N/m")
            _require("contact.damping", contact["damping"] >= 0.0, "must be >= 0 N s/m")
        else:
            _require("contact.rate", contact["rate"] >= 0.0, "must be >= 0 N/s")
            _require("contact.max", contact["max"] >= 0.0, "must be >= 0 N")
            _require("contact.sign", contact["sign"] in (1.0, -1.0), "must be +1 or -1")

    disturbance = data.get("disturbance")
    if disturbance is not None:
        disturbance = dict(_table("disturbance", disturbance))
        kind = disturbance.pop("type", None)
        _require("disturbance.type", kind in DISTURBANCES,
                 f"must be one of {', '.join(DISTURBANCES)}, got {kind!r}")
        disturbance = {"type": kind, **_fill("disturbance", disturbance, DISTURBANCES[kind])}
        _require("disturbance.frequency", disturbance["frequency"] >= 0.0, "must be >= 0 Hz")

    seed = data.get("seed", 0)
    _require("seed", isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0,
             f"must be an integer >= 0, got {seed!r}")
    x0 = _number("x0", data.get("x0", 0.0))
    _require("x0", 0.0 <= x0 <= cyl.L, f"must lie within the stroke [0, {cyl.L:g}] m")
    return RigConfig(params=params, effects=effects, noise=noise, contact=contact,
                     disturbance=disturbance, seed=seed, x0=x0)


# --------------------------------------------------------------------------- plant
class Sample(NamedTuple):
    """One sample of the data acquisition (plus the truth a real rig would not give)."""
    t: float          #: time of the sample [s]
    u_applied: float  #: command the valve got [V], 0 .. 10
    p_a: float        #: chamber A pressure, measured, gauge [Pa]
    p_b: float        #: chamber B pressure, measured, gauge [Pa]
    alpha: float      #: boom angle, measured [rad]
    f_ext: float      #: true external force on the piston [N], positive against extension
    x: float          #: true piston position [m]


def _port_flow(A: float, P_port: float, p: float, T_port: float, T_ch: float, gas: Gas):
    """Flow into a chamber at ``p`` [Pa] and temperature ``T_ch`` [K] through an
    orifice ``A`` [m^2] from a port at ``P_port`` [Pa] holding air at ``T_port`` [K]:
    ``(mdot, d mdot / d p, T of the air that flows)``, the orifice law at the upstream
    temperature."""
    T_up = T_port if P_port >= p else T_ch
    g = gas if T_up == gas.T else Gas(gas.k, gas.R, T_up)
    return signed_mass_flow(A, P_port, p, g), signed_mass_flow_slope(A, P_port, p, g), T_up


class VirtualRig:
    """The boom as a machine: :meth:`step` it with valve commands, read samples.

    ``t`` is the current time [s]; :attr:`truth` the true state.  See the module
    docstring for the physics, the effects and the sensors.
    """

    def __init__(self, config: RigConfig | None = None):
        self.config = cfg = load_config(config)
        self._valve, self._gas, self._cyl, self._geom, self._load, p = _model(cfg.params)
        self._P_atm, self._p_a0, self._p_b0 = p["P_atm"], p["p_a0"], p["p_b0"]
        fx = cfg.effects
        self._spool = fx.get("valve_dynamics")
        self._deadband = fx.get("valve_deadband")
        self._heat = fx.get("heat_transfer")
        self._leak = fx.get("piston_leakage")
        self._stribeck = fx.get("stribeck_friction")
        self._cushion = fx.get("end_cushioning")
        self._lag = fx.get("sensor_lag")
        c = cfg.contact or {}
        self._spring = c if c.get("type") == "spring" else None
        self._ramp = c if c.get("type") == "ramp" else None
        self._vib = cfg.disturbance
        # substep: short enough for a stiff contact and a fast vibration
        h = SUBSTEP
        M = self._load.M
        if self._spring:
            if self._spring["stiffness"] > 0.0:
                h = min(h, 0.1 / math.sqrt(self._spring["stiffness"] / M))
            if self._spring["damping"] > 0.0:
                h = min(h, 0.1 * M / self._spring["damping"])
        if self._vib and self._vib["frequency"] > 0.0:
            h = min(h, 1.0 / (40.0 * self._vib["frequency"]))
        self.substep = h   #: longest internal substep [s]
        n = cfg.noise
        self._p_sigma, self._alpha_sigma, self._quantise = n["p_sigma"], n["alpha_sigma"], n["quantise"]
        self.reset()

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to t = 0 and the initial state; the noise restarts from the seed."""
        self.t = 0.0
        self._u = self._valve.u_centre
        self._p_a, self._p_b = self._p_a0, self._p_b0
        self._x, self._v = self.config.x0, 0.0
        self._y, self._y_dot = self._valve.u_centre, 0.0          # spool [V], [V/s]
        T = self._gas.T
        V_a, V_b = chamber_volumes(self._x, self._cyl)
        self._T_a = self._T_b = T
        self._m_a = self._p_a * V_a / (self._gas.R * T)
        self._m_b = self._p_b * V_b / (self._gas.R * T)
        self._z = (self._p_a - self._P_atm, self._p_b - self._P_atm, alpha_from_x(self._x, self._geom))
        self._history = deque([(0.0, *self._z)])
        self._rng = np.random.default_rng(self.config.seed)
        self._normals, self._k_normal = [], 0
        self._h = None
        self._dt = None

    def _prepare(self, h: float) -> None:
        """Constants that depend on the substep ``h`` [s]."""
        self._h = h
        if self._spool:
            self._transition = spool_transition(self._spool["f_n"], self._spool["zeta"], h)
        if self._lag:
            self._c_lag = first_order_coefficient(h, self._lag["tau"])

    def _normal(self) -> float:
        if self._k_normal >= len(self._normals):
            self._normals = self._rng.standard_normal(3000).tolist()
            self._k_normal = 0
        z = self._normals[self._k_normal]
        self._k_normal += 1
        return z

    def _force(self, t: float, x: float, v: float) -> float:
        """External force on the piston [N] at time ``t`` and state ``x``, ``v``."""
        f = 0.0
        s = self._spring
        if s is not None:
            f = spring_contact_force(x, v, s["x_contact"], s["stiffness"], s["damping"])
        elif self._ramp is not None:
            r = self._ramp
            f = ramp_force(t, r["start"], r["rate"], r["max"], r["sign"])
        if self._vib is not None:
            f += vibration_force(t, self._vib["amplitude"], self._vib["frequency"])
        return f

    @property
    def truth(self) -> dict:
        """The true state: ``p_a``, ``p_b`` absolute [Pa], ``x`` [m], ``v`` [m/s],
        ``alpha`` [rad], ``f_ext`` [N]."""
        return {"p_a": self._p_a, "p_b": self._p_b, "x": self._x, "v": self._v,
                "alpha": alpha_from_x(self._x, self._geom),
                "f_ext": self._force(self.t, self._x, self._v)}

    # ----------------------------------------------------------------- step
    def step(self, u: float, dt: float = 1e-3) -> Sample:
        """Apply the command ``u`` [V] (clipped to 0 .. 10) for ``dt`` [s]; return the
        sample measured at the end."""
        u = float(u)
        if not u >= U_MIN:
            if u != u:
                raise ValueError("valve command u must be a number, got nan")
            u = U_MIN
        elif u > U_MAX:
            u = U_MAX
        if dt != self._dt:
            dt = float(dt)
            if not (dt > 0.0 and math.isfinite(dt)):
                raise ValueError(f"dt must be a finite number > 0 s, got {dt!r}")
            self._dt = dt
            self._n = max(1, math.ceil(dt / self.substep - 1e-9))
        n = self._n
        h = dt / n
        if h != self._h:
            self._prepare(h)

        valve, gas, cyl, geom, load, P_atm = (self._valve, self._gas, self._cyl, self._geom,
                                              self._load, self._P_atm)
        u_c, P_s, P_e = valve.u_centre, valve.P_s, valve.P_e
        p_a, p_b, x, v, t0 = self._p_a, self._p_b, self._x, self._v, self.t
        V_a, V_b = chamber_volumes(x, cyl)
        spool, deadband, heat, leak = self._spool, self._deadband, self._heat, self._leak
        stribeck, cushion, lag = self._stribeck, self._cushion, self._lag
        forced = self._spring is not None or self._ramp is not None or self._vib is not None
        per_port = heat is not None or cushion is not None
        if spool:
            y, y_dot, transition = self._y, self._y_dot, self._transition
        if heat:
            m_a, m_b, T_a, T_b = self._m_a, self._m_b, self._T_a, self._T_b
            T_ref, T_s, h_w, A_w0, R = gas.T, heat["T_s"], heat["h_w"], heat["A_w0"], gas.R
        else:
            T_a = T_b = T_s = gas.T
        if lag:
            z_a, z_b, z_al = self._z
            c_lag, history = self._c_lag, self._history
        half = 0.5 * h

        for i in range(n):
            # the opening the valve's spool gives
            if spool:
                y, y_dot = spool_step(y, y_dot, u, transition)
                uv = y
            else:
                uv = u
            if deadband:
                uv = overlap_command(uv, deadband["overlap"], deadband["edge"], u_c, valve.u_span)
            f = self._force(t0 + i * h + half, x, v) if forced else 0.0

            # valve flows into each chamber, and their slopes
            if uv == u_c:
                m_in_a = m_in_b = s_a = s_b = 0.0
                mT_a = mT_b = sT_a = sT_b = 0.0
            elif not per_port:
                m_in_a, m_in_b = chamber_flows(uv, p_a, p_b, valve, gas)
                s_a, s_b = chamber_flow_slopes(uv, p_a, p_b, valve, gas)
            else:
                A_v = orifice_area(uv, valve)
                extend = uv < u_c
                A_a = A_b = A_v
                if cushion:
                    if not extend and p_a > P_e:      # A exhausts near x = 0
                        A_a = cushion_exhaust_area(A_v, cushion["A_n"],
                                                   cushion_engagement(x, cushion["l_c"], cushion["w"]))
                    elif extend and p_b > P_e:        # B exhausts near x = L
                        A_b = cushion_exhaust_area(A_v, cushion["A_n"],
                                                   cushion_engagement(cyl.L - x, cushion["l_c"], cushion["w"]))
                if extend:
                    m_in_a, s_a, Tf_a = _port_flow(A_a, P_s, p_a, T_s, T_a, gas)
                    m_in_b, s_b, Tf_b = _port_flow(A_b, P_e, p_b, gas.T, T_b, gas)
                else:
                    m_in_a, s_a, Tf_a = _port_flow(A_a, P_e, p_a, gas.T, T_a, gas)
                    m_in_b, s_b, Tf_b = _port_flow(A_b, P_s, p_b, T_s, T_b, gas)
                if heat:
                    mT_a, mT_b, sT_a, sT_b = m_in_a * Tf_a, m_in_b * Tf_b, s_a * Tf_a, s_b * Tf_b
            if leak:
                if heat:
                    T_up = T_a if p_a >= p_b else T_b
                    q, l_a, l_b = piston_leak_flows(leak["A_leak"], p_a, p_b,
                                                    Gas(gas.k, gas.R, T_up))
                    mT_a -= q * T_up
                    mT_b += q * T_up
                    sT_a += l_a * T_up
                    sT_b += l_b * T_up
                else:
                    q, l_a, l_b = piston_leak_flows(leak["A_leak"], p_a, p_b, gas)
                m_in_a -= q
                m_in_b += q
                s_a += l_a
                s_b += l_b

            # the boom moves under the pressures predicted for the middle of the substep
            # (a second-order coupling: pressures from the substep's start would delay
            # every start of motion by half a substep)
            dpa, dpb = pressure_rates(p_a, p_b, m_in_a, m_in_b, x, v, cyl, gas)
            p_am = max(p_a + half * dpa, 0.5 * p_a)
            p_bm = max(p_b + half * dpb, 0.5 * p_b)
            ld = stribeck_load(load, abs(v), stribeck["F_brk"], stribeck["v_s"]) if stribeck else load
            x1, v = advance_load(x, v, h, p_am, p_bm, f, cyl, geom, ld, P_atm, h)
            V_a1, V_b1 = chamber_volumes(x1, cyl)

            # the chambers follow
            if heat:
                W_a, W_b = chamber_wall_areas(x, A_w0, cyl)
                p_a1 = chamber_pressure_step(
                    p_a, V_a, V_a1, thermal_equivalent_flow(mT_a, wall_heat_flow(h_w, W_a, T_ref, T_a), gas),
                    h, gas, sT_a / T_ref)
                p_b1 = chamber_pressure_step(
                    p_b, V_b, V_b1, thermal_equivalent_flow(mT_b, wall_heat_flow(h_w, W_b, T_ref, T_b), gas),
                    h, gas, sT_b / T_ref)
                m_a += h * (m_in_a + 0.5 * s_a * (p_a1 - p_a))
                m_b += h * (m_in_b + 0.5 * s_b * (p_b1 - p_b))
                if not (m_a > 0.0 and m_b > 0.0):
                    raise RuntimeError(f"a chamber emptied at t = {t0 + i * h:g} s")
                T_a = chamber_temperature(p_a1, V_a1, m_a, R)
                T_b = chamber_temperature(p_b1, V_b1, m_b, R)
            else:
                p_a1 = chamber_pressure_step(p_a, V_a, V_a1, m_in_a, h, gas, s_a)
                p_b1 = chamber_pressure_step(p_b, V_b, V_b1, m_in_b, h, gas, s_b)
            if not (p_a1 > 0.0 and p_b1 > 0.0):
                raise RuntimeError(f"a chamber emptied at t = {t0 + i * h:g} s "
                                   f"(p_a = {p_a1:g} Pa, p_b = {p_b1:g} Pa)")
            p_a, p_b, x, V_a, V_b = p_a1, p_b1, x1, V_a1, V_b1

            if lag:   # the sensors' first-order filter, at the substep rate
                z_a += c_lag * (p_a - P_atm - z_a)
                z_b += c_lag * (p_b - P_atm - z_b)
                z_al += c_lag * (alpha_from_x(x, geom) - z_al)
                history.append((t0 + (i + 1) * h, z_a, z_b, z_al))

        self._p_a, self._p_b, self._x, self._v = p_a, p_b, x, v
        self.t = t0 + dt
        self._u = u
        if spool:
            self._y, self._y_dot = y, y_dot
        if heat:
            self._m_a, self._m_b, self._T_a, self._T_b = m_a, m_b, T_a, T_b
        if lag:
            self._z = (z_a, z_b, z_al)
        return self.measure()

    # -------------------------------------------------------------- sensors
    def _sensed(self):
        """What reaches the ADC: (p_a gauge, p_b gauge, alpha), through the sensor lag."""
        if not self._lag:
            return self._p_a - self._P_atm, self._p_b - self._P_atm, alpha_from_x(self._x, self._geom)
        history = self._history
        target = self.t - self._lag["delay"]
        while len(history) > 1 and history[1][0] <= target:
            history.popleft()
        e0 = history[0]
        if len(history) == 1 or target <= e0[0]:
            return e0[1], e0[2], e0[3]
        e1 = history[1]
        w = (target - e0[0]) / (e1[0] - e0[0])
        return (e0[1] + w * (e1[1] - e0[1]), e0[2] + w * (e1[2] - e0[2]),
                e0[3] + w * (e1[3] - e0[3]))

    def measure(self) -> Sample:
        """The sample at the current time (a fresh noise draw)."""
        p_a, p_b, alpha = self._sensed()
        if self._p_sigma > 0.0:
            p_a += self._p_sigma * self._normal()
            p_b += self._p_sigma * self._normal()
        if self._alpha_sigma > 0.0:
            alpha += self._alpha_sigma * self._normal()
        if self._quantise:
            p_a = quantise(p_a - P_RANGE[0], P_LSB, ADC_BITS) + P_RANGE[0]
            p_b = quantise(p_b - P_RANGE[0], P_LSB, ADC_BITS) + P_RANGE[0]
            alpha = quantise(alpha - ALPHA_RANGE[0], ALPHA_LSB, ADC_BITS) + ALPHA_RANGE[0]
        return Sample(self.t, self._u, p_a, p_b, alpha,
                      self._force(self.t, self._x, self._v), self._x)
