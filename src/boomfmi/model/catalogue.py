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
too.
"""
from __future__ import annotations

from typing import Callable, NamedTuple, Optional, Tuple

from ..physics import effects as fx
from ..physics.params import L_MAX

#: the stages of the boom model, in the order it applies them
STAGES = ("spool", "command", "port", "seal", "heat", "friction", "measurement")


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


class Effect(NamedTuple):
    """One unmodelled effect of ``effects.md``."""
    name: str
    fmu: str                                #: the FMU whose option it is
    stage: str                              #: see the module's table
    forms: Tuple[Tuple[Parameter, ...], ...]  #: the laws, each with its parameters
    summary: str
    apply: Optional[Callable] = None        #: a stateless stage's function, see :mod:`.boom`
    advice: str = ""                        #: what a technician can check or do where it is found

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
# command: (command [V], params, model) -> command [V]
def _deadband(u, q, model):
    return fx.deadband_command(u, q["width"], model.valve.u_centre, model.valve.u_span)


# port, seal: (mdot_a, mdot_b, s_a, s_b, p_a, p_b, x, params, model) -> (mdot_a, mdot_b, s_a, s_b);
# s_a, s_b (the flows' slopes in their chamber's pressure) may be None: not wanted
def _cushion(m_a, m_b, s_a, s_b, p_a, p_b, x, q, model):
    l_c, A_n, P_e, gas, L = q["length"], q["A_n"], model.valve.P_e, model.gas, model.cylinder.L
    if s_a is not None:
        s_a = fx.cushion_outflow_slope(m_a, s_a, p_a, x, l_c, A_n, P_e, gas)
        s_b = fx.cushion_outflow_slope(m_b, s_b, p_b, L - x, l_c, A_n, P_e, gas)
    return (fx.cushion_outflow(m_a, p_a, x, l_c, A_n, P_e, gas),
            fx.cushion_outflow(m_b, p_b, L - x, l_c, A_n, P_e, gas), s_a, s_b)


def _leak(m_a, m_b, s_a, s_b, p_a, p_b, x, q, model):
    C, A = q.get("C", 0.0), q.get("A", 0.0)
    leak = fx.leakage_flow(p_a, p_b, C) + fx.leakage_orifice_flow(p_a, p_b, A, model.gas)
    if s_a is not None:
        g_a, g_b = fx.leakage_orifice_slopes(p_a, p_b, A, model.gas)
        s_a, s_b = s_a - C + g_a, s_b - C + g_b
    return m_a - leak, m_b + leak, s_a, s_b


# friction: (load, v, p_a, p_b, params, model) -> load; the effects of this stage commute
# (the Stribeck curve runs between levels that the seals' pressure raises alike)
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
           ((_p("tau", "s", 2e-4, 0.05, True, "tau_spool",
                "valve_dynamics: time constant of the spool's first-order lag; 0: off",
                no_max=SIZE_UNBOUNDED),),),
           "first-order lag of the spool: dy/dt = (u - y) / tau",
           advice="the valve's spool follows the command late: check the valve's driver and pilot supply, and give the controller and the model the spool's lag"),
    Effect("valve_deadband", "valve", "command",
           ((_p("width", "V", 0.01, 1.5, True, "deadband",
                "valve_deadband: half-width of the closed band around 5 V; 0: off", max=4.9),),),
           "no opening for |u - 5| < width; linear beyond, full opening still at 0 and 10 V",
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
                  "no repair, but slow tests and the model need it"),
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
                  "joint's lubrication, and avoid slow moves in fine positioning"),
    Effect("end_cushioning", "cylinder", "port",
           ((_CUSHION_LENGTH, _CUSHION_AREA),
            (_CUSHION_LENGTH, _CUSHION_AREA,
             _p("V_p", "m3", 3e-7, 1.2e-5, True, "V_cushion_port",
                "end_cushioning: the port's volume (part of the dead volume, between the cushion's "
                "spear and the valve), cut off the chamber within the cushion; 0: none",
                switch=False, no_max="part of the dead volumes V_a0, V_b0, which have none: refused at "
                                     "initialisation where it is not smaller"))),
           "within length of a chamber's end, its outflow also passes the cushion needle "
           "(area A_n, to the exhaust) in series with the valve; inflow passes freely (the check "
           "valve); where the port's volume V_p is given, the chamber the sensor reads is left "
           "without it within the cushion, whichever fits",
           _cushion, advice="the cylinder's end cushions brake the last part of the stroke: check the cushion "
                            "needles' setting, or keep the work away from the stroke's ends"),
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
                  "swelling and the rod's lubrication"),
    Effect("sensor_lag", "hardware_bridge", "measurement",
           ((_TAU_SENSOR,),
            (_TAU_SENSOR, _p("delay", "s", 2e-4, 0.02, True, "delay_sensor",
                             "sensor_lag: dead time of every measured channel (before its lag); 0: none",
                             no_max=SIZE_UNBOUNDED))),
           "a first-order lag of every measured channel, or a dead time then the lag, whichever fits",
           advice="the sensors report late: check the DAQ's filters, sampling and the transducers' response"),
)}

#: the effects.md names that have no entry yet, with why (checked by the tests)
PENDING: dict = {}


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
