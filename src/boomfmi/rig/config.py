"""The virtual rig's configuration: :class:`RigConfig`, checked by :func:`load_config`.

A configuration (a JSON file in ``examples/rig/``, a dict, or a :class:`RigConfig`)
switches on the unmodelled effects of ``shared/spec/effects.md``, sets the sensors'
noise, overrides model parameters, and adds a contact with the ground or a
disturbance; :class:`boomfmi.rig.plant.VirtualRig` simulates it.

Effects (``RigConfig.effects``: name -> parameters; absent = off; ``{}`` or ``true`` =
the defaults; :data:`RIG_EFFECTS`, the rig's own configuration names, not the model
catalogue's).  Forms in :mod:`boomfmi.rig.truth`; an effect plug-in's own rig forms
(``rig_effects(truth)``: :class:`boomfmi.rig.truth.RigEffect`, in the command, port, seal
or friction stage) join them by their names and parameters (:func:`plugin_effects`):

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
pressure_friction   k_piston piston seal's rise [N/Pa]      2.5e-5    5e-6 .. 6e-5
                    k_rod    rod seal's rise [N/Pa]         1e-5      0 .. 3e-5
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
* pressure_friction: static and Coulomb levels both raised by ``k_piston`` times the
  higher chamber's gauge pressure plus ``k_rod`` times chamber B's (on F_brk too, with
  stribeck_friction).  At 6 bar in chamber B: 21 N more friction, a quarter of F_d.
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
from dataclasses import dataclass, field

from .. import physics as ph
from ..model.catalogue import PLUGINS, load_plugins
from ..physics import reference_rig
from . import truth
from .truth import RIG_FORMS, register_rig_effects

#: Model parameters that ``RigConfig.params`` may override, with the reference values.
PARAMETERS = {
    **{name: getattr(reference_rig, name)
       for name in ("A_max", "P_s", "P_e", "k", "R", "T", "A_a", "A_b", "L", "V_a0", "V_b0",
                    "a", "b", "h", "l_min", "K_v", "F_s", "F_d", "F_L", "M", "P_atm")},
    "p_a0": reference_rig.P_atm, "p_b0": reference_rig.P_atm,
}

#: Each of the rig's own effects' parameters and defaults (names exactly those of effects.md;
#: the rig's configuration names, not the model catalogue's); plug-ins add theirs
#: (:func:`plugin_effects`).
RIG_EFFECTS = {
    "valve_dynamics": {"f_n": 100.0, "zeta": 0.7},
    "valve_deadband": {"overlap": 0.4, "edge": 0.15},
    "heat_transfer": {"h_w": 40.0, "A_w0": 0.01, "T_s": reference_rig.T},
    "piston_leakage": {"A_leak": 2e-8},
    "stribeck_friction": {"v_s": 0.01, "F_brk": 140.0},
    "pressure_friction": {"k_piston": 2.5e-5, "k_rod": 1e-5},
    "end_cushioning": {"l_c": 0.012, "A_n": 5e-8, "w": 0.001},
    "sensor_lag": {"delay": 0.003, "tau": 0.005},
}
#: Realistic ranges of the effects' parameters (documentation; not enforced).
RIG_EFFECT_RANGES = {
    "valve_dynamics": {"f_n": (60.0, 150.0), "zeta": (0.5, 0.9)},
    "valve_deadband": {"overlap": (0.2, 0.6), "edge": (0.05, 0.3)},
    "heat_transfer": {"h_w": (10.0, 150.0), "A_w0": (0.003, 0.03), "T_s": (283.0, 313.0)},
    "piston_leakage": {"A_leak": (1e-8, 5e-8)},
    "stribeck_friction": {"v_s": (0.002, 0.03), "F_brk": (reference_rig.F_d, 250.0)},
    "pressure_friction": {"k_piston": (5e-6, 6e-5), "k_rod": (0.0, 3e-5)},
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


def model_parameters(params: dict):
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
    elif name == "pressure_friction":
        _require(f"{key}.k_piston", q["k_piston"] >= 0.0, "must be >= 0 N/Pa")
        _require(f"{key}.k_rod", q["k_rod"] >= 0.0, "must be >= 0 N/Pa")
    elif name == "end_cushioning":
        _require(f"{key}.l_c", 0.0 < q["l_c"] <= 0.5 * cyl.L, f"must lie in (0, {0.5 * cyl.L:g}] m")
        _require(f"{key}.A_n", q["A_n"] > 0.0, "must be > 0")
        _require(f"{key}.w", 0.0 < q["w"] <= q["l_c"], "must lie in (0, l_c] m")
    elif name == "sensor_lag":
        _require(f"{key}.delay", 0.0 <= q["delay"] <= 1.0, "must lie in [0, 1] s")
        _require(f"{key}.tau", q["tau"] >= 0.0, "must be >= 0 s")
    elif name in RIG_FORMS:
        check = RIG_FORMS[name].check
        problem = check(q) if check is not None else ""
        _require(key, not problem, problem)
    else:
        raise _err(key, f"no check of the rig's effect {name!r}")


def _check_together(key: str, effects: dict) -> None:
    """The rig's heat_transfer carries each flow's temperature, which a plug-in's port or
    seal form does not state: refused together."""
    if "heat_transfer" in effects:
        flows = [n for n in effects if n in RIG_FORMS and RIG_FORMS[n].stage in ("port", "seal")]
        _require(f"{key}.{flows[0]}" if flows else key, not flows,
                 "a plug-in's port or seal form cannot run with heat_transfer on the rig (its flows "
                 "carry no temperature)")


def plugin_effects() -> tuple:
    """Load the effect plug-ins' rig forms (``rig_effects(truth)`` of each plug-in the
    model's catalogue loaded, :func:`boomfmi.model.catalogue.load_plugins`) not loaded
    yet, their configurations' defaults into :data:`RIG_EFFECTS`; return their names."""
    for plugin in load_plugins():
        make = getattr(plugin.module, "rig_effects", None)
        if make is None or plugin.name in _RIG_PLUGINS:
            continue
        try:
            names = register_rig_effects(make(truth), plugin.name, taken=RIG_EFFECTS)
        except ValueError:
            raise
        except Exception as e:
            raise ValueError(f"effect plug-in {plugin.name}: rig_effects(truth) failed: {type(e).__name__}: {e}") from e
        _RIG_PLUGINS[plugin.name] = names
        for n in names:
            RIG_EFFECTS[n] = dict(RIG_FORMS[n].defaults)
    for name in [n for n in _RIG_PLUGINS if n not in PLUGINS]:      # a plug-in taken out again
        for n in _RIG_PLUGINS.pop(name):
            RIG_EFFECTS.pop(n, None)
            RIG_FORMS.pop(n, None)
    return tuple(n for names in _RIG_PLUGINS.values() for n in names)


#: plug-in -> the names of its rig forms, loaded by :func:`plugin_effects`
_RIG_PLUGINS: dict = {}


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
    _, _, cyl, _, load, _ = model_parameters(params)

    effects = {}
    for name, value in _table("effects", data.get("effects") or {}).items():
        if name not in RIG_EFFECTS and name not in plugin_effects():
            raise _err(f"effects.{name}", f"unknown effect (known: {', '.join(RIG_EFFECTS)})")
        if value is None or value is False:
            continue
        if value is True:
            value = {}
        q = _fill(f"effects.{name}", _table(f"effects.{name}", value), RIG_EFFECTS[name])
        _check_effect(name, q, load, cyl)
        effects[name] = q
    _check_together("effects", effects)

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



# -- the whole excavator (shared/spec/excavator.md) -------------------------------------------
#: Joints of the excavator's rig (``physics.linkage.JOINTS``).
JOINTS = ("swing", "boom", "arm", "bucket")
#: Supply and gas parameters an excavator configuration's ``params`` may override
#: (shared by the four valves and cylinders).
EXCAVATOR_PARAMETERS = {name: PARAMETERS[name] for name in ("P_s", "P_e", "k", "R", "T", "P_atm")}
#: Parameters a joint's ``params`` may override (the defaults: its actuator in
#: ``physics.linkage``); the bore, rod, stroke and mounting stay the machine's.
JOINT_PARAMETERS = ("A_max", "V_a0", "V_b0", "K_v", "F_s", "F_d")
#: Tip contacts: ``experiments.TipContact``'s two kinds and their keys (None: required).
TIP_CONTACTS = {
    "ground": {"ground_z": 0.0, "stiffness": None, "damping": 0.0, "friction": 0.0, "v_slip": 0.01},
    "prescribed": {"force": None, "start": 0.0, "stop": None, "ramp": 0.0},
}
_EXCAVATOR_TOP = ("machine", "params", "joints", "noise", "contact", "payload", "seed")
_JOINT_KEYS = ("params", "effects", "noise", "x0")


@dataclass
class ExcavatorConfig:
    """What the excavator's virtual rig is: built by :func:`load_excavator_config`.

    ``joints[j]`` holds, for each joint of :data:`JOINTS`: ``params`` (the joint's
    parameter groups as the boom's config would give them, its actuator's values with the
    overrides applied), ``effects`` (filled with their defaults), ``noise`` and ``x0``."""
    params: dict = field(default_factory=dict)     #: supply and gas overrides
    joints: dict = field(default_factory=dict)     #: joint -> {"params", "effects", "noise", "x0", "overrides"}
    contact: dict | None = None                    #: tip contact (ground or prescribed)
    payload: float = 0.0                           #: mass in the bucket [kg]
    seed: int = 0                                  #: seed of the sensor noise


def config_machine(source) -> str:
    """``"excavator"`` or ``"boom"``: which rig a configuration (path, dict, RigConfig,
    ExcavatorConfig or None) describes.  An excavator's says ``"machine": "excavator"``."""
    if isinstance(source, ExcavatorConfig):
        return "excavator"
    if source is None or isinstance(source, RigConfig):
        return "boom"
    if isinstance(source, (str, os.PathLike)):
        try:
            with open(source, encoding="utf-8") as f:
                source = json.load(f)
        except (OSError, json.JSONDecodeError):
            return "boom"           # load_config says what is wrong with it
    if isinstance(source, dict) and source.get("machine") == "excavator":
        return "excavator"
    return "boom"


def _noise(key: str, given: dict, base: dict) -> dict:
    for name in given:
        if name not in NOISE:
            raise _err(f"{key}.{name}", f"unknown key (known: {', '.join(NOISE)})")
    out = {}
    for name in ("p_sigma", "alpha_sigma"):
        out[name] = _number(f"{key}.{name}", given.get(name, base[name]))
        _require(f"{key}.{name}", out[name] >= 0.0, "must be >= 0")
    quant = given.get("quantise", base["quantise"])
    _require(f"{key}.quantise", isinstance(quant, bool), f"must be true or false, got {quant!r}")
    out["quantise"] = quant
    return out


def _tip_contact(data) -> dict:
    contact = dict(_table("contact", data))
    kind = contact.pop("type", None)
    _require("contact.type", kind in TIP_CONTACTS,
             f"an excavator's contact is at the bucket tip: one of {', '.join(TIP_CONTACTS)}, got {kind!r}")
    keys = TIP_CONTACTS[kind]
    for name in contact:
        if name not in keys:
            raise _err(f"contact.{name}", f"unknown key (known: {', '.join(keys)})")
    out = {"type": kind}
    if kind == "ground":
        out.update(_fill("contact", contact, keys))
        _require("contact.stiffness", out["stiffness"] > 0.0, "must be > 0 N/m")
        for name in ("damping", "friction"):
            _require(f"contact.{name}", out[name] >= 0.0, "must be >= 0")
        _require("contact.v_slip", out["v_slip"] > 0.0, "must be > 0 m/s")
    else:
        force = contact.get("force")
        _require("contact.force", isinstance(force, list) and len(force) == 3,
                 f"must be three numbers [N] (x, y, z, world frame), got {force!r}")
        out["force"] = [_number(f"contact.force[{i}]", f) for i, f in enumerate(force)]
        out["start"] = _number("contact.start", contact.get("start", 0.0))
        stop = contact.get("stop")
        out["stop"] = None if stop is None else _number("contact.stop", stop)
        _require("contact.stop", out["stop"] is None or out["stop"] > out["start"], "must come after start")
        out["ramp"] = _number("contact.ramp", contact.get("ramp", 0.0))
        _require("contact.ramp", out["ramp"] >= 0.0, "must be >= 0 s")
    return out


def load_excavator_config(source=None) -> ExcavatorConfig:
    """A validated :class:`ExcavatorConfig` from a JSON file's path, a dict, an
    ExcavatorConfig or None (effect-free, realistic noise, every piston at mid-stroke).

    Keys: ``machine`` ("excavator"), ``params`` (supply and gas:
    :data:`EXCAVATOR_PARAMETERS`), ``joints`` (joint -> ``params`` of
    :data:`JOINT_PARAMETERS`, ``effects`` as the boom's, ``noise`` overriding the
    machine's, ``x0`` [m]), ``noise`` (as the boom's), ``contact`` (at the bucket tip,
    :data:`TIP_CONTACTS`), ``payload`` [kg] and ``seed``.  Every key is checked; an
    unknown or invalid one raises ``ValueError`` naming it (``joints.arm.effects.
    piston_leakage.A_leak``).  stribeck_friction's default breakaway force F_brk is
    scaled by the joint's bore area relative to 32 mm, as its F_s is."""
    from ..physics.linkage import Excavator
    if source is None:
        data = {"machine": "excavator"}
    elif isinstance(source, ExcavatorConfig):
        return source
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
        raise TypeError(f"load_excavator_config takes a path, a dict or None, not {type(source).__name__}")
    for key in data:
        if key not in _EXCAVATOR_TOP:
            raise _err(key, f"unknown key (known: {', '.join(_EXCAVATOR_TOP)})")
    _require("machine", data.get("machine", "excavator") == "excavator",
             f"must be \"excavator\", got {data.get('machine')!r}")
    params = {}
    for name, value in _table("params", data.get("params") or {}).items():
        if name not in EXCAVATOR_PARAMETERS:
            raise _err(f"params.{name}", f"unknown parameter (known: {', '.join(EXCAVATOR_PARAMETERS)})")
        params[name] = _number(f"params.{name}", value)
    noise = _noise("noise", _table("noise", data.get("noise") or {}), NOISE)
    given = _table("joints", data.get("joints") or {})
    for name in given:
        if name not in JOINTS:
            raise _err(f"joints.{name}", f"unknown joint (known: {', '.join(JOINTS)})")
    ex = Excavator()
    joints = {}
    for j in JOINTS:
        key = f"joints.{j}"
        jd = _table(key, given.get(j) or {})
        for name in jd:
            if name not in _JOINT_KEYS:
                raise _err(f"{key}.{name}", f"unknown key (known: {', '.join(_JOINT_KEYS)})")
        act = getattr(ex, j)
        overrides = {}
        for name, value in _table(f"{key}.params", jd.get("params") or {}).items():
            if name not in JOINT_PARAMETERS:
                raise _err(f"{key}.params.{name}", f"unknown parameter (known: {', '.join(JOINT_PARAMETERS)})")
            overrides[name] = _number(f"{key}.params.{name}", value)
        # the joint as the boom's configuration: its actuator's values, the supply's and
        # gas's overrides; the triangle (c1, c2, l_min) as Eq. 12's a, b, l_min (h only
        # matters for the boom's phi)
        jp = dict(params, A_max=act.A_max, A_a=act.A_a, A_b=act.A_b, L=act.stroke, V_a0=act.V_a0,
                  V_b0=act.V_b0, K_v=act.K_v, F_s=act.F_s, F_d=act.F_d, a=act.c1, b=act.c2,
                  h=ex.boom_h if j == "boom" else 0.0, l_min=act.l_min)
        jp.update(overrides)
        try:
            cfg = load_config({"params": jp})
        except ValueError as e:
            raise ValueError(str(e).replace("rig config: params.", f"rig config: {key}.params.")) from None
        _, _, cyl, _, load, _ = model_parameters(cfg.params)
        effects = {}
        scale = (act.bore / reference_rig.bore) ** 2
        for name, value in _table(f"{key}.effects", jd.get("effects") or {}).items():
            if name not in RIG_EFFECTS and name not in plugin_effects():
                raise _err(f"{key}.effects.{name}", f"unknown effect (known: {', '.join(RIG_EFFECTS)})")
            if value is None or value is False:
                continue
            if value is True:
                value = {}
            defaults = dict(RIG_EFFECTS[name])
            if name == "stribeck_friction":
                defaults["F_brk"] = defaults["F_brk"] * scale
            q = _fill(f"{key}.effects.{name}", _table(f"{key}.effects.{name}", value), defaults)
            try:
                _check_effect(name, q, load, cyl)
            except ValueError as e:
                raise ValueError(str(e).replace("rig config: effects.", f"rig config: {key}.effects.")) from None
            effects[name] = q
        _check_together(f"{key}.effects", effects)
        jn = _noise(f"{key}.noise", _table(f"{key}.noise", jd.get("noise") or {}), noise)
        x0 = _number(f"{key}.x0", jd.get("x0", 0.5 * act.stroke))
        _require(f"{key}.x0", 0.0 <= x0 <= act.stroke, f"must lie within the stroke [0, {act.stroke:g}] m")
        joints[j] = {"params": cfg.params, "overrides": overrides, "effects": effects, "noise": jn, "x0": x0}
    contact = data.get("contact")
    if contact is not None:
        contact = _tip_contact(contact)
    payload = _number("payload", data.get("payload", 0.0))
    _require("payload", payload >= 0.0, "must be >= 0 kg")
    seed = data.get("seed", 0)
    _require("seed", isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0,
             f"must be an integer >= 0, got {seed!r}")
    return ExcavatorConfig(params=params, joints=joints, contact=contact, payload=payload, seed=seed)

__all__ = [
    "PARAMETERS", "RIG_EFFECTS", "RIG_EFFECT_RANGES", "NOISE", "CONTACTS", "DISTURBANCES", "RigConfig",
    "model_parameters", "plugin_effects", "load_config", "JOINTS", "EXCAVATOR_PARAMETERS",
    "JOINT_PARAMETERS", "TIP_CONTACTS", "ExcavatorConfig", "config_machine", "load_excavator_config",
]
