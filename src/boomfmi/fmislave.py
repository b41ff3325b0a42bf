"""The thin base class of every boomfmi FMU, on top of pythonfmu's ``Fmi2Slave`` or
pythonfmu3's ``Fmi3Slave``.

An FMU declares its variables once, as a table of :class:`Variable` (name, causality,
SI unit, description, start, min, max, and for outputs the inputs that feed through);
this class registers them with pythonfmu, and ``boomfmi.fmubuild`` writes the same
table's units, bounds and dependencies into ``modelDescription.xml``.

The same adapter (``fmus/<name>/<name>_fmu.py``) makes the FMI 2.0 and the FMI 3.0 FMU:
this module targets FMI 2.0 (pythonfmu) unless the package it is bundled in sets
``FMI_VERSION = 3`` in its ``__init__`` (as ``boomfmi.fmubuild.fmi3`` does), and then
pythonfmu3.  Only this module knows the difference.

Errors are reported the FMI way rather than by raising: a bad parameter or a failed
step is logged with status ``fmi2Error`` (naming the parameter) and the call returns
that status through the FMU's status shim (see ``boomfmi/fmubuild/status_shim.c``;
for FMI 3.0 the shim of ``boomfmi/fmubuild/fmi3.py``).  pythonfmu and pythonfmu3 turn
any Python exception into ``fmi2Fatal``/``fmi3Fatal`` and free the instance's Python
object, which leaves the host nothing to recover.

The instance follows the FMI co-simulation state machine (FMI 2.0 section 4.2.4): a
step before or during initialisation, after ``fmi2Terminate`` or from a communication
point other than where the last step ended, a second ``fmi2Terminate`` and a fixed
parameter set after ``fmi2ExitInitializationMode`` are refused with fmi2Error and a
message, leaving the instance as it was.  No value leaves it as fmi2OK unless it is
finite: a step with an input that is not finite is refused naming the input, and so is
reading an output that depends on it directly.

An FMU's effect options (the catalogue's parameters of the effects that are its
options) are declared by :func:`effect_options` from ``model/catalogue.py``, not here.

This module is bundled into each FMU with the physics and the model, under a package
name of that FMU's own; it uses relative imports only.
"""
from __future__ import annotations

import math
import sys
from operator import attrgetter
from typing import NamedTuple, Optional, Tuple

from .model.catalogue import of_fmu
from .physics import reference_rig
from .physics.params import L_MAX
from .physics.validation import ParameterError

#: The FMI version this copy targets: 3 where the bundle's package says so, else 2.
FMI_VERSION = getattr(sys.modules.get(__package__ or ""), "FMI_VERSION", 2)

if FMI_VERSION == 3:
    from pythonfmu3 import (Boolean, Fmi3Causality as Causality, Fmi3Initial as Initial,
                            Fmi3Slave as _FmiSlave, Fmi3Status as Status, Fmi3StepResult,
                            Fmi3Variability as Variability, Float64 as Real, Int32 as Integer, String)
    #: what ``do_step`` returns on failure: pythonfmu3 passes the status through
    _STEP_FAILED = Fmi3StepResult(status=Status.error)
else:
    from pythonfmu import (Boolean, Fmi2Causality as Causality, Fmi2Slave as _FmiSlave,
                           Fmi2Variability as Variability, Integer, Real, String)
    from pythonfmu.enums import Fmi2Initial as Initial, Fmi2Status as Status
    #: pythonfmu makes False fmi2Discard; the status shim raises it to the logged fmi2Error
    _STEP_FAILED = False

#: The prefix of the FMI functions' names in messages: fmi2DoStep, fmi3DoStep.
_FMI = f"fmi{FMI_VERSION}"

# -- the FMI state machine (FMI 2.0 section 4.2.4; FMI 3.0's co-simulation is the same for
# these calls).  An instance is instantiated, then in initialisation mode, then stepping
# (after fmi2ExitInitializationMode, also when that failed: the failure refuses the steps),
# then terminated; fmi2Reset makes a new Python object, in the first state again.
_INSTANTIATED, _INITIALIZING, _STEPPING, _TERMINATED = range(4)
#: Why a step is refused in each state but _STEPPING.
_NO_STEP = {
    _INSTANTIATED: (f"the instance is not initialised yet (call {_FMI}EnterInitializationMode "
                    f"and {_FMI}ExitInitializationMode first)"),
    _INITIALIZING: f"the instance is in initialisation mode (call {_FMI}ExitInitializationMode first)",
    _TERMINATED: (f"the instance was terminated ({_FMI}Terminate); only {_FMI}Reset or "
                  f"{_FMI}FreeInstance may follow"),
}
#: A step must start where the previous one ended (or, for the first, at the start time),
#: within this tolerance relative to the time and the step: a host that computes its
#: communication points as t0 + n h rather than by adding h differs by a few ulps only.
TIME_RTOL = 1e-9


class Variable(NamedTuple):
    """One FMU variable, as the FMU declares it.

    ``causality`` is ``"parameter"``, ``"input"`` or ``"output"``.  ``unit`` is an SI
    unit string known to ``boomfmi.units`` (``"1"`` for dimensionless).
    ``depends`` lists, for an output, the inputs it depends on directly within a
    communication point (``()`` for an output that is a state).
    """
    name: str
    causality: str
    unit: str
    description: str
    start: object = None
    min: Optional[float] = None
    max: Optional[float] = None
    type: str = "Real"
    depends: Tuple[str, ...] = ()


def parameter(name, start, unit, description, min=None, max=None, type="Real"):
    return Variable(name, "parameter", unit, description, start, min, max, type)


def input(name, start, unit, description, min=None, max=None, type="Real"):  # noqa: A001
    return Variable(name, "input", unit, description, start, min, max, type)


def output(name, start, unit, description, depends=(), min=None, max=None, type="Real"):
    return Variable(name, "output", unit, description, start, min, max, type, tuple(depends))


# -- physical bounds of the declared maxima ------------------------------------------------
# The longest stroke an FMU accepts [m] is physics.params.L_MAX: every piston position
# declares it as its max, since x <= L <= L_MAX.
#: The highest supply pressure an FMU accepts, absolute [Pa]: 10 bar gauge, the rating of
#: the rig's valve and cylinder and the range of its 0 to 10 bar gauge transducers
#: (``reference-rig.md`` supplies 6 bar).  The exhaust lies below the supply, so P_e too.
P_S_MAX = reference_rig.P_atm + 1.0e6
#: The largest ratio of specific heats of any ideal gas, 1 + 2/3 (a monatomic gas; air 1.4).
K_MAX = 5.0 / 3.0
#: The command range [V] (``reference-rig.md``: 0 to 10 V, 5 V closes every port).
U_MIN, U_MAX = reference_rig.u_min, reference_rig.u_max

#: The reference rig's constants as FMU parameters, declared once for every FMU that
#: needs them (``reference-rig.md``; SI, pressures absolute).
RIG_PARAMETERS = {v.name: v for v in (
    parameter("P_s", reference_rig.P_s, "Pa", "supply pressure, absolute", min=0.0, max=P_S_MAX),
    parameter("P_e", reference_rig.P_e, "Pa", "exhaust pressure, absolute", min=0.0, max=P_S_MAX),
    parameter("P_atm", reference_rig.P_atm, "Pa", "atmospheric pressure (it acts on the rod)", min=0.0),
    parameter("k", reference_rig.k, "1", "ratio of specific heats of air", min=1.0, max=K_MAX),
    parameter("R", reference_rig.R, "J/(kg.K)", "specific gas constant of air", min=0.0),
    parameter("T", reference_rig.T, "K", "air temperature", min=0.0),
    parameter("A_a", reference_rig.A_a, "m2", "cap-side piston area", min=0.0),
    parameter("A_b", reference_rig.A_b, "m2", "rod-side annulus area", min=0.0),
    parameter("L", reference_rig.L, "m", "stroke", min=0.0, max=L_MAX),
    parameter("V_a0", reference_rig.V_a0, "m3", "dead volume of chamber A incl. port and hose", min=0.0),
    parameter("V_b0", reference_rig.V_b0, "m3", "dead volume of chamber B incl. port and hose", min=0.0),
    parameter("K_v", reference_rig.K_v, "N.s/m", "viscous friction coefficient", min=0.0),
    parameter("F_s", reference_rig.F_s, "N", "static friction force", min=0.0),
    parameter("F_d", reference_rig.F_d, "N", "Coulomb friction force", min=0.0),
    parameter("F_L", reference_rig.F_L, "N", "load force from the backhoe's weight, acting as F_L sin(phi)"),
    parameter("M", reference_rig.M, "kg", "moving mass reduced to the piston", min=0.0),
    parameter("a", reference_rig.a, "m", "boom geometry a (Eq. 10, 12)", min=0.0),
    parameter("b", reference_rig.b, "m", "boom geometry b (Eq. 10, 12)", min=0.0),
    parameter("h", reference_rig.h, "m", "boom geometry h (Eq. 10)", min=0.0),
    parameter("l_min", reference_rig.l_min, "m", "cylinder length at x = 0 (Eq. 11)", min=0.0),
)}
LOAD = ("K_v", "F_s", "F_d", "F_L", "M")
GEOMETRY = ("a", "b", "h", "l_min", "L")
CYLINDER = ("A_a", "A_b", "L", "V_a0", "V_b0")


def rig_parameters(*names: str) -> Tuple[Variable, ...]:
    """The rows of :data:`RIG_PARAMETERS` for ``names``, in that order, each once."""
    return tuple(RIG_PARAMETERS[n] for n in dict.fromkeys(names))


def effect_options(fmu: str, joint: str = "") -> Tuple[Variable, ...]:
    """The parameter rows of FMU ``fmu``'s effect options, from the catalogue of effects
    (each off at its start value); with ``joint``, one joint's copy of them
    (``v_s_arm``, the excavator's linkage: its cylinders' friction)."""
    if joint:
        return tuple(parameter(f"{p.option}_{joint}", p.start, p.unit, f"{joint} cylinder, {p.description}",
                               min=0.0, max=p.max) for e in of_fmu(fmu) for p in e.parameters)
    return tuple(parameter(p.option, p.start, p.unit, p.description, min=0.0, max=p.max)
                 for e in of_fmu(fmu) for p in e.parameters)


def option_values(slave, fmu: str, joint: str = "") -> dict:
    """``{option: value}`` of FMU ``fmu``'s effect options on the instance ``slave``
    (with ``joint``: of that joint's copy, :func:`effect_options`)."""
    suffix = f"_{joint}" if joint else ""
    return {p.option: getattr(slave, p.option + suffix) for e in of_fmu(fmu) for p in e.parameters}


def _values_of(names):
    """A function of an object that returns the tuple of its attributes ``names``."""
    if len(names) > 1:
        return attrgetter(*names)
    if names:
        return lambda obj, get=attrgetter(names[0]): (get(obj),)
    return lambda obj: ()


def _are(items, noun: str) -> str:
    """``"input u = nan is"``, ``"inputs u = nan, p_a = inf are"`` (``noun`` may be "")."""
    plural = len(items) > 1
    return f"{noun}{'s' if plural and noun else ''}{' ' if noun else ''}{', '.join(items)} {'are' if plural else 'is'}"


_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}


def _hold_script_globals(cls) -> None:
    """Take one more reference to the globals of the FMU script that defines ``cls``
    (called as the script's class is created; not for the library's own subclasses).

    pythonfmu's ``findClass`` (run once per fmi2Instantiate) re-executes the script in
    its module's globals, which creates the class again, and then releases that
    dictionary once more than it took it.  A script whose functions hold its globals
    (methods defined in it) hides this for a while; a script that declares no methods
    (a bridge: its behaviour is all in ``rigbridge``) had its module's globals freed by
    the first instantiation, and the second crashed the host.  The reference taken here
    at each creation balances the release (one reference too many, held for the
    process's life)."""
    import ctypes
    module = sys.modules.get(cls.__module__)
    library = __name__.rpartition(".")[0]
    if module is not None and not cls.__module__.startswith(library + "."):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(module.__dict__))


class BoomSlave(_FmiSlave):
    """Base of the boomfmi FMUs.

    Subclasses set ``variables``, and implement :meth:`setup` (check the parameters
    and build what the step needs, once) and :meth:`step`.
    """

    author = "boomfmi"
    license = "MIT"
    variables: Tuple[Variable, ...] = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        _hold_script_globals(cls)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.failure: Optional[str] = None
        self._real_access: dict = {}     # get_real/set_real's resolved names, per value-reference group
        self.start_time = 0.0
        self._time = 0.0        # the last communication point
        self._stepped = False
        self._time_known = False    # whether _time is the start time or a step's end (FMI 3.0 has none before its first step)
        self._fmi_state = _INSTANTIATED
        #: the Real variables the host set in initialisation mode (an input it did not set
        #: there holds its start value until the host sets it, typically just before the
        #: first step: a state that starts from an input waits for it, ``valve``'s spool)
        self.set_in_initialisation: set = set()
        for var in self.variables:
            owner_attr = getattr(type(self), var.name, None)
            if not isinstance(owner_attr, property):
                setattr(self, var.name, var.start)
            if var.causality == "parameter":
                kw = dict(causality=Causality.parameter,
                          variability=Variability.fixed, initial=Initial.exact)
            elif var.causality == "input":
                kw = dict(causality=Causality.input,
                          variability=(Variability.continuous if var.type == "Real"
                                       else Variability.discrete))
            else:
                kw = dict(causality=Causality.output,
                          variability=(Variability.continuous if var.type == "Real"
                                       else Variability.discrete),
                          initial=Initial.calculated)
            self.register_variable(_TYPES[var.type](var.name, description=var.description, **kw))
        if FMI_VERSION == 3:    # FMI 3.0 declares time, the independent variable; registered
            # last so that every declared variable keeps its FMI 2.0 value reference
            self.register_variable(Real("time", causality=Causality.independent,
                                        variability=Variability.continuous,
                                        description="simulation time", getter=lambda: self._time))
        #: the fixed parameters, by value reference; the Real inputs, read at once by do_step
        parameters = {v.name for v in self.variables if v.causality == "parameter"}
        self._fixed = {vr: var.name for vr, var in self.vars.items() if var.name in parameters}
        self._input_names = tuple(v.name for v in self.variables if v.causality == "input" and v.type == "Real")
        self._inputs = _values_of(self._input_names)

    # -- FMI 2.0 Real access, pythonfmu's semantics with the look-ups done once ---------
    # pythonfmu's get_real/set_real look every value reference up, check its type and go
    # through a closure per value on every call; a host sets and gets the same groups
    # of variables every step, so each group's attribute names are resolved once.
    # Beyond pythonfmu: a value that is not finite is returned with status error (no NaN
    # leaves the FMU as fmi2OK), and a fixed parameter is refused after initialisation.
    def get_real(self, vrs):
        access = self._real_access.get(("get", *vrs))
        if access is None:
            access = self._real_access[("get", *vrs)] = (_values_of(self._real_names(vrs)),
                                                         self._feedthrough(vrs))
        get, inputs = access
        # one sum per call (finite values can overflow it: the report then finds none)
        if inputs is not None and not math.isfinite(sum(inputs(self))) and self._refuse_feedthrough(vrs):
            return [math.nan] * len(vrs)
        values = [float(value) for value in get(self)]
        if not math.isfinite(sum(values)):
            self._report_not_finite(vrs, values, f"{_FMI}GetReal")
        return values

    def set_real(self, vrs, values):
        access = self._real_access.get(("set", *vrs))
        if access is None:
            access = self._real_access[("set", *vrs)] = (
                self._real_names(vrs), tuple(self._fixed[vr] for vr in vrs if vr in self._fixed))
        names, fixed = access
        if fixed and self._fmi_state >= _STEPPING:
            self._refuse_fixed(fixed, f"{_FMI}SetReal")
            return
        if self._fmi_state == _INITIALIZING:
            self.set_in_initialisation.update(names)
        for name, value in zip(names, values):
            setattr(self, name, value)

    if FMI_VERSION == 3:    # pythonfmu3's own access, with the same two checks
        def get_float64(self, vrs):
            inputs = self._real_access.get(("inputs", *vrs), False)
            if inputs is False:
                inputs = self._real_access[("inputs", *vrs)] = self._feedthrough(vrs)
            if inputs is not None and not math.isfinite(sum(inputs(self))) and self._refuse_feedthrough(vrs):
                return [math.nan] * len(vrs)
            values = super().get_float64(vrs)
            if not math.isfinite(sum(values)):
                self._report_not_finite(vrs, values, "fmi3GetFloat64")
            return values

        def set_float64(self, vrs, values):
            if self._fmi_state == _INITIALIZING:
                self.set_in_initialisation.update(self._real_names(vrs))
            self._set_checked(super().set_float64, "fmi3SetFloat64", vrs, values)

        def set_int32(self, vrs, values):
            self._set_checked(super().set_int32, "fmi3SetInt32", vrs, values)
    else:
        def set_integer(self, vrs, values):
            self._set_checked(super().set_integer, "fmi2SetInteger", vrs, values)

    def set_boolean(self, vrs, values):
        self._set_checked(super().set_boolean, f"{_FMI}SetBoolean", vrs, values)

    def set_string(self, vrs, values):
        self._set_checked(super().set_string, f"{_FMI}SetString", vrs, values)

    def _set_checked(self, setter, function: str, vrs, values) -> None:
        """``setter(vrs, values)`` unless ``vrs`` hold a fixed parameter after initialisation."""
        fixed = tuple(self._fixed[vr] for vr in vrs if vr in self._fixed)
        if fixed and self._fmi_state >= _STEPPING:
            self._refuse_fixed(fixed, function)
        else:
            setter(vrs, values)

    def _refuse_fixed(self, names, function: str) -> None:
        """Log a set of fixed parameters ``names`` after initialisation as an error."""
        when = "was terminated" if self._fmi_state == _TERMINATED else "is initialised"
        self.log(f"{function} refused: parameter{'s' if len(names) > 1 else ''} {', '.join(names)} "
                 f"{'are' if len(names) > 1 else 'is'} fixed and can be set only before "
                 f"{_FMI}ExitInitializationMode, and this instance {when}; nothing was set",
                 Status.error)

    def _feedthrough(self, vrs):
        """What reads the Real inputs that outputs ``vrs`` depend on directly (their
        ``depends``), as a tuple; None when they depend on none."""
        spec = {v.name: v for v in self.variables}
        names = {d for vr in vrs if self.vars[vr].name in spec for d in spec[self.vars[vr].name].depends}
        names = [v.name for v in self.variables if v.name in names and v.type == "Real"]
        return _values_of(names) if names else None

    def _refuse_feedthrough(self, vrs) -> bool:
        """Log, as an error, the outputs among ``vrs`` that depend directly on an input
        that is not finite, naming both; False when there are none."""
        spec = {v.name: v for v in self.variables}
        bad = self._inputs_not_finite()
        outputs = [self.vars[vr].name for vr in vrs
                   if set(getattr(spec.get(self.vars[vr].name), "depends", ())) & set(bad)]
        if not outputs:
            return False
        self.log(f"{_FMI}{'GetFloat64' if FMI_VERSION == 3 else 'GetReal'} refused: "
                 + _are([f"{n} = {value!r}" for n, value in bad.items()], "input")
                 + f" not a finite number, and {', '.join(outputs)} depend{'s' if len(outputs) == 1 else ''} "
                 "on it directly (set a finite value)", Status.error)
        return True

    def _report_not_finite(self, vrs, values, function: str) -> None:
        """Log the non-finite ``values`` of ``vrs`` as an error, naming them and the
        non-finite inputs that made them; nothing when every value is finite."""
        bad = [f"{self.vars[vr].name} = {value!r}" for vr, value in zip(vrs, values) if not math.isfinite(value)]
        if bad:
            inputs = [f"{n} = {value!r}" for n, value in self._inputs_not_finite().items()]
            self.log(f"{function}: {_are(bad, '')} not a finite number"
                     + (f" ({_are(inputs, 'input')} not finite)" if inputs else ""), Status.error)

    def _inputs_not_finite(self) -> dict:
        """``{"u": nan, "p_a": inf}``: the Real inputs that are not finite."""
        return {n: value for n, value in zip(self._input_names, self._inputs(self)) if not math.isfinite(value)}

    def _real_names(self, vrs) -> Tuple[str, ...]:
        """The attribute names of Real variables ``vrs``; TypeError for another type, as
        pythonfmu."""
        names = []
        for vr in vrs:
            var = self.vars[vr]
            if not isinstance(var, Real):
                raise TypeError(f"Variable with valueReference={vr} is not of type Real!")
            names.append(var.local_name)
        return tuple(names)

    # -- to be provided by each FMU ------------------------------------------------
    def setup(self) -> None:
        """Check the parameters (raise :class:`ParameterError`) and prepare the step."""

    def step(self, t: float, dt: float) -> None:
        """Advance the FMU from ``t`` by ``dt`` [s] with the inputs held."""
        raise NotImplementedError

    def teardown(self) -> None:
        """Release what the FMU holds (a link, a file); called once, by fmi2Terminate."""

    # -- FMI plumbing ----------------------------------------------------------------
    def fail(self, message: str) -> None:
        """Report an error: logged with status fmi2Error, every later call fails too."""
        if self.failure is None:
            self.failure = message
        self.log(message, Status.error)

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        # pythonfmu3 0.3.4 never calls this: an FMI 3.0 instance counts from 0 until its
        # first step, which may start at any time
        if self._fmi_state != _INSTANTIATED:
            self.log(f"{_FMI}SetupExperiment refused: it comes before {_FMI}EnterInitializationMode, "
                     f"and this instance is past it; the start time stays {self.start_time:g} s", Status.error)
            return
        if not math.isfinite(start_time):
            self.log(f"{_FMI}SetupExperiment refused: startTime = {start_time!r} is not a finite number",
                     Status.error)
            return
        self.start_time = self._time = float(start_time)
        self._time_known = True

    def enter_initialization_mode(self):
        if self._fmi_state != _INSTANTIATED:
            self.log(f"{_FMI}EnterInitializationMode refused: it comes once, after {_FMI}Instantiate "
                     f"(or {_FMI}Reset), and this instance is past it", Status.error)
            return
        self._fmi_state = _INITIALIZING

    def exit_initialization_mode(self):
        if self._fmi_state != _INITIALIZING:
            self.log(f"{_FMI}ExitInitializationMode refused: "
                     + (f"call {_FMI}EnterInitializationMode first" if self._fmi_state == _INSTANTIATED
                        else "the instance has left initialisation mode already"), Status.error)
            return
        self._fmi_state = _STEPPING
        try:
            self._check_declared_bounds()
            self.setup()
        except ParameterError as e:
            self.fail(str(e))
        except (ValueError, ArithmeticError) as e:
            self.fail(f"initialisation failed: {e}")

    def terminate(self):
        if self._fmi_state == _TERMINATED:
            self.log(f"{_FMI}Terminate refused: the instance was terminated already", Status.error)
            return
        self._fmi_state = _TERMINATED
        self.teardown()

    def _check_declared_bounds(self) -> None:
        """Reject a Real parameter that is not finite or lies outside its declared min/max."""
        for var in self.variables:
            if var.causality != "parameter" or var.type != "Real":
                continue
            value = getattr(self, var.name)
            if not math.isfinite(value):
                raise ParameterError(var.name, value, "must be a finite number")
            if var.min is not None and value < var.min:
                raise ParameterError(var.name, value, f"must be >= {var.min:g} {var.unit}")
            if var.max is not None and value > var.max:
                raise ParameterError(var.name, value, f"must be <= {var.max:g} {var.unit}")
        for e in of_fmu(self.modelName):                # an effect option that is on but below its range
            for q in e.parameters:
                value = getattr(self, q.option, 0.0)
                if q.on_min is not None and 0.0 < value < q.on_min:
                    raise ParameterError(q.option, value, f"must be 0 (off) or at least {q.on_min:g} {q.unit}")

    def do_step(self, current_time, step_size):
        # The refusals below leave the instance as it was (its time, its state): the host
        # may call what the message says, or set finite inputs, and step again.
        if self._fmi_state != _STEPPING:
            self.log(f"{_FMI}DoStep refused at t = {current_time:g} s: {_NO_STEP[self._fmi_state]}", Status.error)
            return _STEP_FAILED
        if self.failure is not None:
            self.log(f"cannot step: {self.failure}", Status.error)
            return _STEP_FAILED
        if not 0.0 < step_size < math.inf:
            self.fail(f"communication step size must be a finite number > 0, got {step_size!r}")
            return _STEP_FAILED
        if self._time_known:
            if current_time != self._time and not (abs(current_time - self._time)
                                                   <= TIME_RTOL * (abs(self._time) + step_size)):
                self.log(f"{_FMI}DoStep refused: currentCommunicationPoint = {current_time!r} s, but "
                         + (f"the last step ended at {self._time!r} s" if self._stepped
                            else f"the experiment starts at {self._time!r} s")
                         + " (a step starts where the previous one ended); nothing was stepped", Status.error)
                return _STEP_FAILED
        elif not math.isfinite(current_time):
            self.log(f"{_FMI}DoStep refused: currentCommunicationPoint = {current_time!r} is not a finite number",
                     Status.error)
            return _STEP_FAILED
        if not math.isfinite(sum(self._inputs(self))):  # finite inputs can overflow the sum
            inputs = [f"{n} = {value!r}" for n, value in self._inputs_not_finite().items()]
            if inputs:
                self.log(f"{_FMI}DoStep refused at t = {current_time:g} s: {_are(inputs, 'input')} not a "
                         "finite number; nothing was stepped (set a finite value and step again)", Status.error)
                return _STEP_FAILED
        try:
            self.step(current_time, step_size)
        except (ValueError, ArithmeticError) as e:
            self.fail(f"step at t = {current_time:g} s failed: {e}")
            return _STEP_FAILED
        self._time = current_time + step_size
        self._time_known = self._stepped = True
        return True


__all__ = ["FMI_VERSION", "TIME_RTOL", "Variable", "parameter", "input", "output", "P_S_MAX", "K_MAX", "U_MIN",
           "U_MAX", "RIG_PARAMETERS", "LOAD", "GEOMETRY", "CYLINDER", "rig_parameters", "effect_options",
           "option_values", "BoomSlave"]
