"""The catalogue of unmodelled effects: one entry per name of ``shared/spec/effects.md``.

Each entry says what the effect is in the model: the FMU whose option it is, the stage
of the boom model it acts on, its laws (``forms``: a mechanism with two laws, such as a
seal that leaks laminar or turbulent, has two, and diagnosis fits both) and for every
parameter its unit, fitting bounds and scale, the FMU variable it maps to, its start
value there and a description.  The assembled model (:mod:`.boom`), the FMUs'
variable tables (``fmislave.effect_options``), diagnosis's candidates and its
confirmation through the FMUs all read this table; nothing else lists the effects.

Stages (where in the model an effect acts; :mod:`.boom` applies them in this order):

=============== ============================================================== =========
stage           what the effect's function maps                                stateful
=============== ============================================================== =========
``spool``       the command to the spool's position (a lag)                    yes
``command``     the spool's position to the command the orifices see            no
``port``        a chamber's flow through its valve port (and its slope)          no
``seal``        the chambers' inflows, with flows between them                 no
``heat``        the chambers' pressures, exchanging heat with the wall          yes
``friction``    the load parameters at the piston's speed and pressures          no
``measurement`` what the sensors report of the physics                          yes
=============== ============================================================== =========

A stateless stage's ``apply`` is called by the model with every effect of that stage
that is on, so a new effect there is its physics function, its entry here and its FMU
option.  A stateful stage (a new state of the model) needs the model's integrators
too (``Effect.integrator``, one of ``INTEGRATORS``; an entry the model cannot step is
refused by name, :func:`check_entry`).  Every stage function takes a
:class:`StageContext`.  How an entry is fitted is its own too: the generic output-error
fit (a friction-stage effect's with the baseline load re-identified with it), or a
faster fit it names (``Effect.fit``); a friction effect whose parameters enter the
load's own identification says how (``Effect.load_law``).  Nothing outside this table,
the effects' forms and the virtual rig's own forms reads an effect's name.
"""
from __future__ import annotations

import importlib
from typing import Callable, NamedTuple, Optional, Protocol, Tuple

from ..physics import effects as fx
from ..physics.params import L_MAX, Cylinder, Gas, Geometry, Load, Valve

#: the stages of the boom model, in the order it applies them
STAGES = ("spool", "command", "port", "seal", "heat", "friction", "measurement")
#: the stages whose effects hold a state of the model: each needs an integrator of
#: ``model/boom.py`` (``Effect.integrator``); the others are ``Effect.apply`` alone
STATEFUL = ("spool", "heat", "measurement")
#: the model's integrators of the states effects hold (``Effect.integrator``, stepped by
#: :class:`.boom.Boom`) -> the stage each serves: the spool's lag, the chambers' heat
#: exchange with the wall, the sensors' lag and dead time, and an end cushion's port
#: volume cut off its chamber (a state of the stateless ``port`` stage's effect)
INTEGRATORS = {"spool_lag": "spool", "wall_heat": "heat", "sensor_path": "measurement", "cushion_port": "port"}
#: how a friction-stage effect's parameters enter the load's own identification
#: (``Effect.load_law``): the Stribeck velocity of ``identify.fit``'s ``v_s``, or a
#: coefficient of a seal-pressure law (``identify.fit.PRESSURE_COEFFICIENT``)
LOAD_LAWS = ("stribeck", "seal_pressure")
#: the upper bounds a parameter may take from the joint it is fitted on (``Parameter.cap``)
CAPS = ("dead_volume",)


class StageContext(Protocol):
    """What every stage function (``Effect.apply``) reads of the model it acts in: the
    parameter groups and the atmosphere.  :class:`.boom.Boom` passes itself in every
    stage."""
    valve: Valve
    gas: Gas
    cylinder: Cylinder
    geometry: Geometry
    load: Load
    P_atm: float


class Parameter(NamedTuple):
    """One parameter of an effect."""
    name: str           #: the key in ``Model.effects[effect]``
    unit: str           #: SI unit (``fmubuild``'s unit names)
    lower: float        #: fitting bounds
    upper: float
    log: bool           #: fitted on a log scale
    option: str         #: the FMU variable (of the effect's FMU) that sets it
    description: str    #: what it is, for the FMU's variable and the docs
    start: float = 0.0  #: the FMU variable's start value
    switch: bool = True  #: a value > 0 switches the effect on (False: a setting only)
    max: Optional[float] = None  #: the FMU variable's declared maximum
    on_min: Optional[float] = None  #: the least value that is on (0 < value < on_min is refused)
    no_max: str = ""    #: why the FMU variable declares no maximum (required where ``max`` is None)
    #: an upper bound it takes from the joint (one of ``CAPS``): ``"dead_volume"``, kept
    #: below the cylinder's dead volumes (``Model.check``; diagnosis's fitting bound)
    cap: str = ""


class Effect(NamedTuple):
    """One unmodelled effect of ``effects.md``."""
    name: str
    fmu: str                                #: the FMU whose option it is
    stage: str                              #: see the module's table
    forms: Tuple[Tuple[Parameter, ...], ...]  #: the laws, each with its parameters
    summary: str
    apply: Optional[Callable] = None        #: a stateless stage's function, see :mod:`.boom`
    advice: str = ""                        #: what a technician can check or do where it is found
    #: a faster fit the entry supplies, ``"package.module:function"`` (resolved when
    #: used, :func:`fit_hook`), called ``fn(effect, fit_recs, hold_recs)`` by diagnosis
    #: and returning ``(name, {name: params}, fit cost, holdout NRMSE, load or None)``;
    #: "": the generic output-error fit (a friction-stage effect's with the baseline
    #: load re-identified with it, ``diagnose.attribute``)
    fit: str = ""
    #: how a friction-stage effect enters the load's own identification (one of
    #: ``LOAD_LAWS``); "": it does not (the generic path)
    load_law: str = ""
    #: the model's integrator that steps the state it holds (``model.boom.INTEGRATORS``);
    #: required in a ``STATEFUL`` stage
    integrator: str = ""

    @property
    def parameters(self) -> Tuple[Parameter, ...]:
        """Every parameter over all forms, each once, in order."""
        seen = {}
        for form in self.forms:
            for p in form:
                seen.setdefault(p.name, p)
        return tuple(seen.values())

    def is_on(self, params: dict) -> bool:
        """Whether ``params`` switch the effect on (a switching parameter > 0)."""
        return any(params.get(p.name, 0.0) > 0.0 for p in self.parameters if p.switch)


# ------------------------------------------------------------ stateless stages' functions
# every one is called with a StageContext as ``model`` (the Boom)
# command: (command [V], params, model) -> command [V]
def _deadband(u, q, model):
    return fx.deadband_command(u, q.get("width", 0.0), model.valve.u_centre, model.valve.u_span,
                               q.get("width_ext"), q.get("width_ret"), q.get("edge", 0.0))


# port, seal: (mdot_a, mdot_b, s_a, s_b, p_a, p_b, x, params, model) -> (mdot_a, mdot_b, s_a, s_b);
# s_a, s_b (the flows' slopes in their chamber's pressure) may be None: not wanted
def _cushion(m_a, m_b, s_a, s_b, p_a, p_b, x, q, model):
    l_c, A_n, P_e, gas, L = q["length"], q["A_n"], model.valve.P_e, model.gas, model.cylinder.L
    more = (model.valve.P_s, q.get("A_c", 0.0))
    if s_a is not None:
        s_a = fx.cushion_flow_slope(m_a, s_a, p_a, x, l_c, A_n, P_e, gas, *more)
        s_b = fx.cushion_flow_slope(m_b, s_b, p_b, L - x, l_c, A_n, P_e, gas, *more)
    return (fx.cushion_flow(m_a, p_a, x, l_c, A_n, P_e, gas, *more),
            fx.cushion_flow(m_b, p_b, L - x, l_c, A_n, P_e, gas, *more), s_a, s_b)


def _leak(m_a, m_b, s_a, s_b, p_a, p_b, x, q, model):
    C, A = q.get("C", 0.0), q.get("A", 0.0)
    if s_a is None:
        leak = fx.leakage_flow(p_a, p_b, C) + fx.leakage_orifice_flow(p_a, p_b, A, model.gas)
        return m_a - leak, m_b + leak, s_a, s_b
    orifice, g_a, g_b = fx.leakage_orifice_flow_and_slopes(p_a, p_b, A, model.gas)
    leak = fx.leakage_flow(p_a, p_b, C) + orifice
    return m_a - leak, m_b + leak, s_a - C + g_a, s_b - C + g_b


# friction: (load, v, p_a, p_b, params, model) -> load, v, p_a, p_b floats or arrays alike
# (the generic identification calls it on whole recordings); the effects of this stage
# commute (the Stribeck curve runs between levels that the seals' pressure raises alike)
def _stribeck(load, v, p_a, p_b, q, model):
    return fx.stribeck_load(load, v, q["v_s"])


def _pressure_friction(load, v, p_a, p_b, q, model):
    return fx.pressure_friction_load(load, p_a, p_b, model.P_atm, q.get("c_sum", 0.0), q.get("c_max", 0.0),
                                     q.get("c_diff", 0.0))


def _p(name, unit, lower, upper, log, option, description, **kw):
    return Parameter(name, unit, lower, upper, log, option, description, **kw)


#: the reason most effect options declare no maximum (``Parameter.no_max``)
SIZE_UNBOUNDED = "an unmodelled effect's size: no physical bound (the catalogue's fitting range is not one)"


_TAU_SENSOR = _p("tau", "s", 2e-4, 0.03, True, "tau_sensor",
                 "sensor_lag: time constant of a first-order lag on every measured channel; 0: off",
                 no_max=SIZE_UNBOUNDED)
_DEADBAND = _p("width", "V", 0.01, 1.5, True, "deadband",
               "valve_deadband: half-width of the closed band around 5 V; 0: off", max=4.9)
_DEADBAND_EDGE = _p("edge", "V", 0.005, 0.5, True, "deadband_edge",
                    "valve_deadband: the width over which the band's edge opens gradually (rounded or worn "
                    "lands: a hyperbola blends closed and linear); 0: a sharp edge", switch=False, max=4.9)
_DEADBAND_EXT = _p("width_ext", "V", 0.01, 1.5, True, "deadband_ext",
                   "valve_deadband: width of the closed band below 5 V (commands that extend), in place of "
                   "deadband on that side; 0: deadband's", max=4.9)
_DEADBAND_RET = _p("width_ret", "V", 0.01, 1.5, True, "deadband_ret",
                   "valve_deadband: width of the closed band above 5 V (commands that retract), in place of "
                   "deadband on that side; 0: deadband's", max=4.9)
_TAU_SPOOL = _p("tau", "s", 2e-4, 0.05, True, "tau_spool",
                "valve_dynamics: time constant of the spool's first-order lag; 0: off", no_max=SIZE_UNBOUNDED)
_C_LEAK = _p("C", "kg/(s.Pa)", 1e-13, 5e-10, True, "C_leak",
             "piston_leakage: laminar conductance of the piston seal, A to B; 0: off", no_max=SIZE_UNBOUNDED)
_A_LEAK = _p("A", "m2", 1e-10, 2e-7, True, "A_leak",
             "piston_leakage: area of a turbulent leak gap across the piston seal (orifice law); 0: off",
             no_max=SIZE_UNBOUNDED)

_CUSHION_LENGTH = _p("length", "m", 2e-3, 0.02, False, "l_cushion",
                     "end_cushioning: cushion length at each end of stroke (at most L/2); 0: off", max=L_MAX / 2)
_CUSHION_AREA = _p("A_n", "m2", 1e-8, 4e-6, True, "A_cushion",
                   "end_cushioning: cushion needle's orifice area", start=1e-7, switch=False,
                   no_max=SIZE_UNBOUNDED)

#: name -> :class:`Effect`, in the order of ``effects.md``
EFFECTS = {e.name: e for e in (
    Effect("valve_dynamics", "valve", "spool",
           ((_TAU_SPOOL,),
            (_TAU_SPOOL, _p("rate", "V/s", 10.0, 5000.0, True, "rate_spool",
                            "valve_dynamics: the spool's greatest speed, in volts of command per second "
                            "(a slew-rate limit: the pilot stage's flow); 0: unlimited",
                            switch=False, no_max=SIZE_UNBOUNDED))),
           "first-order lag of the spool, dy/dt = (u - y) / tau; or that lag with the spool's "
           "speed limited to rate (a slew-rate limit), whichever fits",
           advice="the valve's spool follows the command late: check the valve's driver and pilot supply, and give the controller and the model the spool's lag",
           integrator="spool_lag"),
    Effect("valve_deadband", "valve", "command",
           ((_DEADBAND,), (_DEADBAND, _DEADBAND_EDGE), (_DEADBAND_EXT, _DEADBAND_RET),
            (_DEADBAND_EXT, _DEADBAND_RET, _DEADBAND_EDGE)),
           "no opening for |u - 5| < width; linear beyond, full opening still at 0 and 10 V; or a band "
           "of its own width on each side of 5 V (lands of unequal overlap, a drifted zero); either with "
           "its edge rounded over edge (worn lands open gradually), whichever fits",
           _deadband, advice="the valve stays shut around its centre: re-zero the valve, or compensate the "
                             "deadband in the controller"),
    Effect("heat_transfer", "cylinder", "heat",
           ((_p("h", "W/(m2.K)", 1.0, 2000.0, True, "h_wall",
                "heat_transfer: heat-transfer coefficient between the air and the chamber wall; 0: off",
                no_max=SIZE_UNBOUNDED),),
            (_p("n", "1", 1.0, 1.4, False, "n_poly",
                "heat_transfer: polytropic exponent of the chambers' process, in place of k in Eq. 4 to 7 "
                "(1: isothermal, 1.4: isentropic); 0: off", max=1.4, on_min=1.0),)),
           "the pressure relaxes towards the isothermal m R T_w / V with time constant "
           "m c_v / (h A_wall), A_wall the wall the air touches (end faces and barrel, growing with "
           "the chamber's length); or the chambers follow a polytropic process of exponent n "
           "between isothermal and isentropic, whichever fits",
           advice="the air exchanges heat with the chamber walls: a held pressure drifts as the air cools; "
                  "no repair, but slow tests and the model need it", integrator="wall_heat"),
    Effect("piston_leakage", "cylinder", "seal",
           ((_C_LEAK,), (_A_LEAK,), (_C_LEAK, _A_LEAK)),
           "a leak A -> B across the seal: laminar C (p_a - p_b), turbulent through a gap "
           "of area A (the orifice law, Eq. 1), or both at once (a worn seal), whichever fits", _leak,
           advice="air leaks across the piston seal: inspect and replace the piston seal"),
    Effect("stribeck_friction", "boom_load", "friction",
           ((_p("v_s", "m/s", 2e-4, 0.1, True, "v_s",
                "stribeck_friction: Stribeck velocity of exp(-|v|/v_s); 0: off (the paper's step)",
                no_max=SIZE_UNBOUNDED),),),
           "Coulomb level F_d + (F_s - F_d) exp(-|v| / v_s)", _stribeck,
           advice="the friction falls off with speed (stick-slip at low speed): check the rod's and the "
                  "joint's lubrication, and avoid slow moves in fine positioning",
           fit="boomfmi.diagnose.attribute:fit_stribeck", load_law="stribeck"),
    Effect("end_cushioning", "cylinder", "port",
           ((_CUSHION_LENGTH, _CUSHION_AREA),
            (_CUSHION_LENGTH, _CUSHION_AREA,
             _p("A_c", "m2", 1e-9, 1e-4, True, "A_cushion_check",
                "end_cushioning: the check valve's area beside the needle, through which the air returns "
                "into the chamber within the cushion (small: a cushion without a check valve, leaving "
                "the end slowed too); 0: a free return", switch=False, no_max=SIZE_UNBOUNDED)),
            (_CUSHION_LENGTH, _CUSHION_AREA,
             _p("V_p", "m3", 3e-7, 1.2e-5, True, "V_cushion_port",
                "end_cushioning: the port's volume (part of the dead volume, between the cushion's "
                "spear and the valve), cut off the chamber within the cushion; 0: none",
                switch=False, no_max="part of the dead volumes V_a0, V_b0, which have none: refused at "
                                     "initialisation where it is not smaller", cap="dead_volume"))),
           "within length of a chamber's end, its outflow also passes the cushion needle "
           "(area A_n, to the exhaust) in series with the valve; inflow passes freely (the check "
           "valve), or with a check valve of area A_c the needle and it in series with the valve (a "
           "small A_c: no check valve); where the port's volume V_p is given, the chamber the sensor reads is left "
           "without it within the cushion, whichever fits",
           _cushion, advice="the cylinder's end cushions brake the last part of the stroke: check the cushion "
                            "needles' setting, or keep the work away from the stroke's ends",
           integrator="cushion_port"),
    Effect("pressure_friction", "boom_load", "friction",
           ((_p("c_sum", "N/Pa", 1e-7, 2e-4, True, "c_friction_sum",
                "pressure_friction: rise of the static and Coulomb friction per pascal of the chambers' "
                "summed gauge pressure; 0: off", no_max=SIZE_UNBOUNDED),),
            (_p("c_max", "N/Pa", 1e-7, 2e-4, True, "c_friction_max",
                "pressure_friction: rise of the static and Coulomb friction per pascal of the higher "
                "chamber's gauge pressure; 0: off", no_max=SIZE_UNBOUNDED),),
            (_p("c_diff", "N/Pa", 1e-7, 2e-4, True, "c_friction_diff",
                "pressure_friction: rise of the static and Coulomb friction per pascal of pressure "
                "difference across the piston; 0: off", no_max=SIZE_UNBOUNDED),)),
           "the seals pressed by the pressure they hold: F_s and F_d both grow by c_sum times the "
           "chambers' summed gauge pressure (the real friction tests' law), by c_max times the higher "
           "chamber's, or by c_diff times the pressure difference across the piston, whichever fits", _pressure_friction,
           advice="the seals' friction grows with the pressure they hold: check the seals for wear or "
                  "swelling and the rod's lubrication",
           fit="boomfmi.diagnose.attribute:fit_seal_laws", load_law="seal_pressure"),
    Effect("sensor_lag", "hardware_bridge", "measurement",
           ((_TAU_SENSOR,),
            (_TAU_SENSOR, _p("delay", "s", 2e-4, 0.02, True, "delay_sensor",
                             "sensor_lag: dead time of every measured channel (before its lag); 0: none",
                             no_max=SIZE_UNBOUNDED))),
           "a first-order lag of every measured channel, or a dead time then the lag, whichever fits",
           advice="the sensors report late: check the DAQ's filters, sampling and the transducers' response",
           integrator="sensor_path"),
)}

#: the effects.md names that have no entry yet, with why (checked by the tests)
PENDING: dict = {}


def check_entry(effect: Effect) -> None:
    """Raise ValueError naming ``effect`` where the model could not use its entry: a
    stage not of ``STAGES``, a stateless stage's effect without ``apply``, a stateful
    stage's without ``integrator`` (which of them the model has, ``Model.check`` says),
    a ``load_law`` not of ``LOAD_LAWS``, a parameter's ``cap`` not of ``CAPS``."""
    where = f"effect {effect.name!r}"
    if effect.stage not in STAGES:
        raise ValueError(f"{where} acts in the stage {effect.stage!r}, not one of the model's "
                         f"({', '.join(STAGES)})")
    if effect.stage in STATEFUL and not effect.integrator:
        raise ValueError(f"{where} acts in the stateful {effect.stage!r} stage but names no integrator of the "
                         f"model (Effect.integrator): a new state needs its integration in model/boom.py")
    if effect.integrator and INTEGRATORS.get(effect.integrator) != effect.stage:
        raise ValueError(f"{where}: {effect.integrator!r} is not an integrator of the model's {effect.stage!r} "
                         f"stage ({', '.join(k for k, s in INTEGRATORS.items() if s == effect.stage) or 'none'})")
    if effect.stage not in STATEFUL and effect.apply is None:
        raise ValueError(f"{where} acts in the {effect.stage!r} stage but has no function to apply there "
                         f"(Effect.apply)")
    if effect.load_law and effect.load_law not in LOAD_LAWS:
        raise ValueError(f"{where}: load_law {effect.load_law!r} is not one of {', '.join(LOAD_LAWS)}")
    if effect.load_law and effect.stage != "friction":
        raise ValueError(f"{where}: a load_law is for the friction stage's effects, not the {effect.stage!r} stage's")
    for p in effect.parameters:
        if p.cap and p.cap not in CAPS:
            raise ValueError(f"{where}: parameter {p.name!r}'s cap {p.cap!r} is not one of {', '.join(CAPS)}")


def fit_hook(effect: Effect) -> Optional[Callable]:
    """The faster fit ``effect`` supplies (``Effect.fit``, imported now), or None: the
    generic fit.  ValueError naming the effect where the name does not resolve."""
    if not effect.fit:
        return None
    module, _, attr = effect.fit.partition(":")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError, ValueError) as e:
        raise ValueError(f"effect {effect.name!r}: its fit {effect.fit!r} does not resolve "
                         f"(\"package.module:function\"): {e}") from None


def capped(effect: Effect, parameter: str, cylinder: Cylinder, upper: float) -> float:
    """The fitting bound ``upper`` of ``effect``'s ``parameter`` on a joint of ``cylinder``
    (its ``Parameter.cap``: a share of the dead volumes kept below 0.9 of the smaller)."""
    q = next(p for p in effect.parameters if p.name == parameter)
    if not q.cap:
        return upper
    if q.cap == "dead_volume":
        return min(upper, 0.9 * min(cylinder.V_a0, cylinder.V_b0))
    raise ValueError(f"effects.{effect.name}.{parameter}: cap {q.cap!r} is not one of {', '.join(CAPS)}")


for _e in EFFECTS.values():      # the catalogue's own entries (a plug-in's: when it is loaded)
    check_entry(_e)


def of_fmu(fmu: str) -> Tuple[Effect, ...]:
    """The effects that are options of FMU ``fmu``."""
    return tuple(e for e in EFFECTS.values() if e.fmu == fmu)


def fmu_variable(effect: str, parameter: str) -> str:
    """The SSP name (``valve.tau_spool``) of an effect parameter's FMU variable."""
    e = EFFECTS[effect]
    return f"{e.fmu}.{next(p for p in e.parameters if p.name == parameter).option}"


def effects_from_options(fmu: str, options: dict) -> dict:
    """The effects an FMU's option values switch on: ``{effect: {parameter: value}}``
    from ``{option: value}`` (the FMU's variables), only those that are on."""
    out = {}
    for e in of_fmu(fmu):
        params = {p.name: float(options[p.option]) for p in e.parameters}
        if e.is_on(params):
            out[e.name] = params
    return out


# ------------------------------------------------------------------ plug-ins
# A user's own effects, each one entry as above, from a module of theirs: a package
# registered under the entry point group ``boomfmi.effects`` (pyproject.toml:
# ``[project.entry-points."boomfmi.effects"] my_effects = "my_effects"``) or a Python file
# (``boomfmi --effects FILE``, ``$BOOMFMI_EFFECTS``).  The module defines
# ``effects(catalogue)``: given this module (an FMU passes its own bundled copy, so the
# plug-in imports nothing of boomfmi), its entries as :class:`Effect` of stateless stages;
# and, for the virtual rig, ``rig_effects(truth)`` (:mod:`boomfmi.rig.truth`).  The FMUs
# built with a plug-in loaded carry its module (``fmubuild``) and load it from there.
import os as _os
import sys as _sys
from types import ModuleType as _ModuleType

#: the entry point group of effect plug-ins
ENTRY_POINT_GROUP = "boomfmi.effects"
#: plug-in files (``os.pathsep``-separated) loaded by every process that imports the
#: catalogue: how ``--effects FILE`` reaches subprocesses, Dask workers and FMU builds
EFFECTS_ENV = "BOOMFMI_EFFECTS"
#: the stages a plug-in's effect may act in: those the model applies with no state of their own
PLUGIN_STAGES = ("command", "port", "seal", "friction")
#: the FMU that applies each stage (of the catalogue's own entries): a plug-in effect's option goes there
STAGE_FMU = {e.stage: e.fmu for e in EFFECTS.values() if e.stage in PLUGIN_STAGES}
#: where an FMU's bundle carries the plug-ins' modules (``<bundle>/<this>/``)
BUNDLED_PLUGINS = "effect_plugins"


class PluginError(ValueError):
    """A plug-in of effects that cannot be loaded: the message names it and its entry."""


class Plugin(NamedTuple):
    """A loaded plug-in: its name (the entry point's, or the file's path), its module,
    the names of the effects it added and where its source is (a module file, or a
    package's folder: what an FMU bundles)."""
    name: str
    module: _ModuleType
    effects: Tuple[str, ...]
    source: str


#: plug-in name -> :class:`Plugin`, in the order loaded
PLUGINS: dict = {}


def _bundled() -> bool:
    """Whether this catalogue is an FMU's bundled copy (its plug-ins come with it)."""
    return __package__ is not None and not __package__.startswith("boomfmi.")


def _plugin_problem(effect) -> str:
    """Why ``effect`` (an entry of a plug-in) cannot join the catalogue ('' if it can)."""
    if not isinstance(effect, Effect):
        return f"an entry must be a boomfmi Effect, got {type(effect).__name__} {effect!r:.60}"
    name = effect.name
    if not isinstance(name, str) or not name.isidentifier():
        return f"effect {name!r}: its name must be a plain identifier"
    if name in EFFECTS:
        other = next((p.name for p in PLUGINS.values() if name in p.effects), None)
        return (f"effect {name!r}: the name is taken by "
                + (f"plug-in {other!r}" if other else "the catalogue's own entry") + "; choose another")
    if effect.stage not in PLUGIN_STAGES:
        what = "a stateful stage, which needs the model's integrators" if effect.stage in STAGES else "unknown stage"
        return (f"effect {name!r}: stage {effect.stage!r} is {what}; a plug-in's effect acts in one of "
                f"{', '.join(PLUGIN_STAGES)}")
    if effect.fmu != STAGE_FMU[effect.stage]:
        return (f"effect {name!r}: the {effect.stage} stage is the {STAGE_FMU[effect.stage]} FMU's, "
                f"not {effect.fmu!r}")
    if not callable(effect.apply):
        return f"effect {name!r}: apply must be the stage's function, got {effect.apply!r}"
    if not effect.forms or not all(effect.forms):
        return f"effect {name!r}: needs at least one law, each with at least one parameter"
    options = {p.option: e.name for e in of_fmu(effect.fmu) for p in e.parameters}
    for p in effect.parameters:
        where = f"effect {name!r}, parameter {p.name!r}"
        if not isinstance(p, Parameter):
            return f"{where}: must be a boomfmi Parameter, got {type(p).__name__}"
        if not _bundled():            # checked where it is built; an FMU carries no pint
            from ..units import unit_problem
            problem = unit_problem(p.unit)
            if problem:
                return f"{where}: {problem}"
        if not (p.lower < p.upper and (p.lower > 0.0 or not p.log)):
            return f"{where}: fitting bounds {p.lower!r} .. {p.upper!r} must rise (and be > 0 on a log scale)"
        if not p.option.isidentifier():
            return f"{where}: FMU option {p.option!r} must be a plain identifier"
        if p.option in options:
            return (f"{where}: FMU option {p.option!r} is already {options[p.option]}'s in the "
                    f"{effect.fmu} FMU")
        if p.max is None and not p.no_max:
            return f"{where}: give its FMU variable's max, or why it has none (no_max)"
    return ""


def register(entries, owner: str) -> Tuple[str, ...]:
    """Add plug-in ``owner``'s ``entries`` (:class:`Effect`) to :data:`EFFECTS`, all or
    none: raises :class:`PluginError` naming the plug-in and the entry at fault."""
    try:
        entries = tuple(entries)
    except TypeError:
        raise PluginError(f"effect plug-in {owner}: effects(catalogue) must return its entries, "
                          f"got {type(entries).__name__}") from None
    if not entries:
        raise PluginError(f"effect plug-in {owner}: effects(catalogue) returned no entry")
    added = []
    try:
        for effect in entries:
            problem = _plugin_problem(effect)
            if not problem:
                try:
                    check_entry(effect)           # the catalogue's own rules for any entry
                except ValueError as e:
                    problem = str(e)
            if problem:
                raise PluginError(f"effect plug-in {owner}: {problem}")
            EFFECTS[effect.name] = effect
            added.append(effect.name)
    except BaseException:
        for name in added:
            del EFFECTS[name]
        raise
    return tuple(added)


def _add_module(name: str, module, source: str) -> Plugin:
    make = getattr(module, "effects", None)
    if not callable(make):
        raise PluginError(f"effect plug-in {name}: its module {module.__name__} defines no effects(catalogue)")
    try:
        entries = make(_sys.modules[__name__])
    except PluginError:
        raise
    except Exception as e:
        raise PluginError(f"effect plug-in {name}: effects(catalogue) failed: {type(e).__name__}: {e}") from e
    plugin = Plugin(name, module, register(entries, name), source)
    PLUGINS[name] = plugin
    return plugin


def load_file(path) -> Plugin:
    """Load the plug-in in the Python file ``path`` (once; again it is the loaded one)."""
    import importlib.util
    path = _os.path.abspath(_os.fspath(path))
    if path in PLUGINS:
        return PLUGINS[path]
    if not _os.path.isfile(path):
        raise PluginError(f"effect plug-in {path}: no such file")
    stem = _os.path.splitext(_os.path.basename(path))[0]
    module_name = f"boomfmi_effects_file_{stem}"
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or not stem.isidentifier():
        raise PluginError(f"effect plug-in {path}: not a Python module (a file name.py, name a plain identifier)")
    module = importlib.util.module_from_spec(spec)
    _sys.modules[module_name] = module          # by this name its functions pickle (Dask workers load the same file)
    try:
        spec.loader.exec_module(module)
    except Exception as e:
        del _sys.modules[module_name]
        raise PluginError(f"effect plug-in {path}: importing it failed: {type(e).__name__}: {e}") from e
    return _add_module(path, module, path)


def _module_source(module) -> str:
    """A module's source to bundle: its file, or its package's folder."""
    file = getattr(module, "__file__", None) or ""
    if _os.path.basename(file) == "__init__.py":
        return _os.path.dirname(file)
    return file


def load_plugins(files=(), entry_points: bool = True) -> Tuple[Plugin, ...]:
    """Load the effect plug-ins not loaded yet: the installed packages' entry points
    (group :data:`ENTRY_POINT_GROUP`), the files of :data:`EFFECTS_ENV` and ``files``.
    In an FMU's bundled catalogue: the plug-ins it was built with, from its bundle.
    Returns every loaded plug-in."""
    import importlib
    if _bundled():
        base = __package__.rsplit(".", 1)[0]
        try:
            carried = importlib.import_module(f"{base}.{BUNDLED_PLUGINS}")
        except ModuleNotFoundError:
            return tuple(PLUGINS.values())
        for name in carried.MODULES:
            if name not in PLUGINS:
                _add_module(name, importlib.import_module(f"{base}.{BUNDLED_PLUGINS}.{name}"), "")
        return tuple(PLUGINS.values())
    if entry_points:
        from importlib.metadata import entry_points as _entry_points
        for ep in _entry_points(group=ENTRY_POINT_GROUP):
            if ep.name in PLUGINS:
                continue
            try:
                module = ep.load()
            except Exception as e:
                raise PluginError(f"effect plug-in {ep.name} (entry point {ep.value}): importing it failed: "
                                  f"{type(e).__name__}: {e}") from e
            if not isinstance(module, _ModuleType):
                raise PluginError(f"effect plug-in {ep.name}: its entry point {ep.value} must name a module")
            _add_module(ep.name, module, _module_source(module))
    for path in [*(_os.environ.get(EFFECTS_ENV) or "").split(_os.pathsep), *files]:
        if str(path).strip():
            load_file(str(path).strip())
    return tuple(PLUGINS.values())


def remove_plugin(name: str) -> None:
    """Take plug-in ``name``'s effects out of the catalogue again (tests; a process that
    loaded a plug-in it must not keep)."""
    plugin = PLUGINS.pop(name)
    for effect in plugin.effects:
        EFFECTS.pop(effect, None)


load_plugins()


__all__ = [
    "STAGES", "STATEFUL", "INTEGRATORS", "LOAD_LAWS", "CAPS", "StageContext", "Parameter", "Effect",
    "SIZE_UNBOUNDED", "EFFECTS", "PENDING", "check_entry", "fit_hook", "capped", "of_fmu",
    "fmu_variable", "effects_from_options", "ENTRY_POINT_GROUP", "EFFECTS_ENV", "PLUGIN_STAGES",
    "STAGE_FMU", "BUNDLED_PLUGINS", "PluginError", "Plugin", "PLUGINS", "register", "load_file",
    "load_plugins", "remove_plugin",
]
