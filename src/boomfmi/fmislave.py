"""The thin base class of every boomfmi FMU, on top of pythonfmu's ``Fmi2Slave``.

An FMU declares its variables once, as a table of :class:`Variable` (name, causality,
SI unit, description, start, min, max, and for outputs the inputs that feed through);
this class registers them with pythonfmu, and ``boomfmi.fmubuild`` writes the same
table's units, bounds and dependencies into ``modelDescription.xml``.

Errors are reported the FMI way rather than by raising: a bad parameter or a failed
step is logged with status ``fmi2Error`` (naming the parameter) and the call returns
that status through the FMU's status shim (see ``boomfmi/fmubuild/status_shim.c``).
pythonfmu itself turns any Python exception into ``fmi2Fatal`` and frees the instance's
Python object, which leaves the host nothing to recover.

This module is bundled into each FMU with the physics, under a package name of that
FMU's own; it uses relative imports only.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional, Tuple

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Initial, Fmi2Status

from .physics import reference_rig as rig
from .physics.validation import ParameterError


class Variable(NamedTuple):
    """One FMU variable, as the FMU declares it.

    ``causality`` is ``"parameter"``, ``"input"`` or ``"output"``.  ``unit`` is an SI
    unit string known to ``boomfmi.fmubuild.units`` (``"1"`` for dimensionless).
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


#: The reference rig's constants as FMU parameters, declared once for every FMU that
#: needs them (``reference-rig.md``; SI, pressures absolute).
RIG_PARAMETERS = {v.name: v for v in (
    parameter("P_s", rig.P_s, "Pa", "supply pressure, absolute", min=0.0),
    parameter("P_e", rig.P_e, "Pa", "exhaust pressure, absolute", min=0.0),
    parameter("P_atm", rig.P_atm, "Pa", "atmospheric pressure (it acts on the rod)", min=0.0),
    parameter("k", rig.k, "1", "ratio of specific heats of air", min=1.0),
    parameter("R", rig.R, "J/(kg.K)", "specific gas constant of air", min=0.0),
    parameter("T", rig.T, "K", "air temperature", min=0.0),
    parameter("A_a", rig.A_a, "m2", "cap-side piston area", min=0.0),
    parameter("A_b", rig.A_b, "m2", "rod-side annulus area", min=0.0),
    parameter("L", rig.L, "m", "stroke", min=0.0),
    parameter("V_a0", rig.V_a0, "m3", "dead volume of chamber A incl. port and hose", min=0.0),
    parameter("V_b0", rig.V_b0, "m3", "dead volume of chamber B incl. port and hose", min=0.0),
    parameter("K_v", rig.K_v, "N.s/m", "viscous friction coefficient", min=0.0),
    parameter("F_s", rig.F_s, "N", "static friction force", min=0.0),
    parameter("F_d", rig.F_d, "N", "Coulomb friction force", min=0.0),
    parameter("F_L", rig.F_L, "N", "load force from the backhoe's weight, acting as F_L sin(phi)"),
    parameter("M", rig.M, "kg", "moving mass reduced to the piston", min=0.0),
    parameter("a", rig.a, "m", "boom geometry a (Eq. 10, 12)", min=0.0),
    parameter("b", rig.b, "m", "boom geometry b (Eq. 10, 12)", min=0.0),
    parameter("h", rig.h, "m", "boom geometry h (Eq. 10)", min=0.0),
    parameter("l_min", rig.l_min, "m", "cylinder length at x = 0 (Eq. 11)", min=0.0),
)}
LOAD = ("K_v", "F_s", "F_d", "F_L", "M")
GEOMETRY = ("a", "b", "h", "l_min", "L")
CYLINDER = ("A_a", "A_b", "L", "V_a0", "V_b0")


def rig_parameters(*names: str) -> Tuple[Variable, ...]:
    """The rows of :data:`RIG_PARAMETERS` for ``names``, in that order, each once."""
    return tuple(RIG_PARAMETERS[n] for n in dict.fromkeys(names))


_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}


class BoomSlave(Fmi2Slave):
    """Base of the boomfmi FMUs.

    Subclasses set ``variables``, and implement :meth:`setup` (check the parameters
    and build what the step needs, once) and :meth:`step`.
    """

    author = "boomfmi"
    license = "MIT"
    variables: Tuple[Variable, ...] = ()

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.failure: Optional[str] = None
        self.start_time = 0.0
        for var in self.variables:
            owner_attr = getattr(type(self), var.name, None)
            if not isinstance(owner_attr, property):
                setattr(self, var.name, var.start)
            if var.causality == "parameter":
                kw = dict(causality=Fmi2Causality.parameter,
                          variability=Fmi2Variability.fixed, initial=Fmi2Initial.exact)
            elif var.causality == "input":
                kw = dict(causality=Fmi2Causality.input,
                          variability=(Fmi2Variability.continuous if var.type == "Real"
                                       else Fmi2Variability.discrete))
            else:
                kw = dict(causality=Fmi2Causality.output,
                          variability=(Fmi2Variability.continuous if var.type == "Real"
                                       else Fmi2Variability.discrete),
                          initial=Fmi2Initial.calculated)
            self.register_variable(_TYPES[var.type](var.name, description=var.description, **kw))

    # -- to be provided by each FMU ------------------------------------------------
    def setup(self) -> None:
        """Check the parameters (raise :class:`ParameterError`) and prepare the step."""

    def step(self, t: float, dt: float) -> None:
        """Advance the FMU from ``t`` by ``dt`` [s] with the inputs held."""
        raise NotImplementedError

    # -- FMI plumbing ----------------------------------------------------------------
    def fail(self, message: str) -> None:
        """Report an error: logged with status fmi2Error, every later call fails too."""
        if self.failure is None:
            self.failure = message
        self.log(message, Fmi2Status.error)

    def setup_experiment(self, start_time, stop_time, tolerance):
        self.start_time = float(start_time)

    def exit_initialization_mode(self):
        try:
            self._check_declared_bounds()
            self.setup()
        except ParameterError as e:
            self.fail(str(e))
        except (ValueError, ArithmeticError) as e:
            self.fail(f"initialisation failed: {e}")

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

    def do_step(self, current_time, step_size):
        if self.failure is not None:
            self.log(f"cannot step: {self.failure}", Fmi2Status.error)
            return False
        if not step_size > 0.0:
            self.fail(f"communication step size must be > 0, got {step_size!r}")
            return False
        try:
            self.step(current_time, step_size)
        except (ValueError, ArithmeticError) as e:
            self.fail(f"step at t = {current_time:g} s failed: {e}")
            return False
        return True
