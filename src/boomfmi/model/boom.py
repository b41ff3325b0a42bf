"""The assembled boom: valve, effects, chambers and load, in one place.

:class:`Model` is the boom's parameter set (the reference rig's values by default) with
any set of the catalogue's effects switched on; :class:`Boom` is that model prepared
for stepping.  Every caller steps the boom through :class:`Boom`'s parts, which call
the physics of ``boomfmi.physics`` (the paper's Eq. 1 to 12) and the effects' forms
(``physics/effects.py``) in the order of the catalogue's stages:

* :meth:`Boom.spool_step` / :meth:`Boom.spool_rate` (``spool``) and
  :meth:`Boom.opening` (``command``): the command the orifices see;
* :meth:`Boom.valve_flows`: the valve's chamber flows and their slopes (Eq. 1);
* :meth:`Boom.inflows` (``port``, then ``seal``): the chambers' inflows;
* :meth:`Boom.step_chambers` (exact for a closed chamber, exponential against the
  flows' linearisation otherwise, then ``heat``) or, for an ODE solver,
  :meth:`Boom.pressure_rates` (Eq. 5 to 7, plus ``heat``);
* :meth:`Boom.load_at` (``friction``) and :meth:`Boom.step_load` (Eq. 8, 9 with the
  exact stick/slip rule and hard end stops);
* :meth:`Boom.measured` (``measurement``): what the sensors report.

The cylinder and boom-load FMUs, the valve FMU, the monolithic reference
(:mod:`.reference`), localisation and the virtual rig's baseline all step these parts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import physics as ph
from ..physics import effects as fx
from ..physics.lag import delayed
from ..physics import reference_rig
from .catalogue import EFFECTS, INTEGRATORS, check_entry


@dataclass
class Model:
    """All parameters of the boom model (defaults: the reference rig), its start state,
    and its effects: name (``effects.md``) -> parameters, e.g.
    ``{"valve_dynamics": {"tau": 0.004}, "piston_leakage": {"C": 2e-11}}``."""
    valve: ph.Valve = field(default_factory=ph.Valve)
    gas: ph.Gas = field(default_factory=ph.Gas)
    cylinder: ph.Cylinder = field(default_factory=ph.Cylinder)
    geometry: ph.Geometry = field(default_factory=ph.Geometry)
    load: ph.Load = field(default_factory=ph.Load)
    P_atm: float = reference_rig.P_atm
    p_a0: float = reference_rig.P_atm
    p_b0: float = reference_rig.P_atm
    x0: float = 0.0
    effects: dict = field(default_factory=dict)

    def check(self) -> None:
        """Raise :class:`physics.ParameterError` naming the first bad parameter."""
        check_effects(self.effects)
        ph.check_valve(self.valve)
        ph.check_gas(self.gas)
        ph.check_cylinder(self.cylinder)
        ph.check_load(self.load)
        ph.check_geometry(self.geometry, self.cylinder.L)
        check_caps(self.effects, self.cylinder)


def check_caps(effects: dict, cylinder: ph.Cylinder, where: str = "effects") -> None:
    """Every effect parameter with a ``cap`` (``Parameter.cap``) within it on ``cylinder``:
    a share of the dead volumes smaller than they are (``physics.effects.check_cushion_port``)."""
    for name, params in effects.items():
        for q in EFFECTS[name].parameters:
            if not q.cap:
                continue
            if q.cap != "dead_volume":
                raise ph.ParameterError(f"{where}.{name}.{q.name}", q.cap, "a cap the model does not know")
            fx.check_cushion_port(float(params.get(q.name, 0.0)), cylinder, f"{where}.{name}.{q.name}")


def check_effects(effects: dict) -> None:
    """Every effect a catalogue name, every parameter one of its own, finite and >= 0."""
    for name, params in effects.items():
        if name not in EFFECTS:
            raise ph.ParameterError("effects", name, f"not an effect of effects.md ({', '.join(EFFECTS)})")
        check_integrator(EFFECTS[name])
        known = tuple(p.name for p in EFFECTS[name].parameters)
        unknown = set(params) - set(known)
        if unknown:
            raise ph.ParameterError(f"effects.{name}", sorted(unknown), f"takes {known}")
        spec = {p.name: p for p in EFFECTS[name].parameters}
        for k, v in params.items():
            if not (v >= 0.0 and math.isfinite(v)):
                raise ph.ParameterError(f"effects.{name}.{k}", v, "must be a finite number >= 0")
            q = spec[k]
            if q.max is not None and v > q.max:
                raise ph.ParameterError(f"effects.{name}.{k}", v, f"must be at most {q.max:g}")
            if q.on_min is not None and 0.0 < v < q.on_min:
                raise ph.ParameterError(f"effects.{name}.{k}", v, f"must be 0 (off) or at least {q.on_min:g}")


def check_integrator(effect) -> None:
    """Raise :class:`physics.ParameterError` naming ``effect`` where the model cannot step
    it (``catalogue.check_entry``): a stage it does not have, a stateful stage's effect
    without an integrator of the model (``INTEGRATORS``) of that stage, a stateless
    stage's without its function."""
    try:
        check_entry(effect)
    except ValueError as e:
        raise ph.ParameterError(f"effects.{effect.name}", effect.stage, str(e)) from None


def integrated(effects: dict, integrator: str) -> dict:
    """The parameters of the effect of ``effects`` (``{name: params}``) that the model's
    ``integrator`` steps (``Effect.integrator``; {} without one)."""
    if integrator not in INTEGRATORS:
        raise ValueError(f"{integrator!r} is not an integrator of the model ({', '.join(INTEGRATORS)})")
    out = {}
    for name, params in effects.items():
        if EFFECTS[name].integrator == integrator:
            out.update(params)
    return out


def measurement_lag(effects: dict) -> tuple[float, float]:
    """The sensors' ``(tau, delay)`` [s] from the measurement stage's effects of ``effects``
    (0, 0 without); ParameterError for a measurement effect the model cannot step."""
    for name in effects:
        if EFFECTS[name].stage == "measurement":
            check_integrator(EFFECTS[name])
    q = integrated(effects, "sensor_path")
    return float(q.get("tau", 0.0)), float(q.get("delay", 0.0))


def _param(effects: dict, integrator: str, parameter: str) -> float:
    return float(integrated(effects, integrator).get(parameter, 0.0))


class Boom:
    """A :class:`Model` prepared for stepping: its parameter groups, and the effects that
    are on, per stage.  ``check=False`` skips :meth:`Model.check` (the caller has checked
    the parameters its own way, as an FMU does)."""

    def __init__(self, model: Model, check: bool = True):
        if check:
            model.check()
        self.model = model
        self.valve, self.gas, self.cylinder = model.valve, model.gas, model.cylinder
        self.geometry, self.load, self.P_atm = model.geometry, model.load, model.P_atm
        on = {n: q for n, q in model.effects.items() if EFFECTS[n].is_on(q)}
        for n in on:
            check_integrator(EFFECTS[n])
        stage = lambda s: tuple((EFFECTS[n].apply, q) for n, q in on.items() if EFFECTS[n].stage == s)
        self.command_effects = stage("command")
        self.inflow_effects = stage("port") + stage("seal")   # port effects act on the valve's flow first
        self.friction_effects = stage("friction")
        self.tau_spool = _param(on, "spool_lag", "tau")
        self.rate_spool = _param(on, "spool_lag", "rate")   #: the spool's speed limit [V/s] (0: none)
        self.h_wall = _param(on, "wall_heat", "h")
        n_poly = _param(on, "wall_heat", "n")
        #: the gas as the chambers' process sees it: k replaced by the polytropic
        #: exponent where heat_transfer's second law is on (the orifices keep k)
        self.chamber_gas = self.gas._replace(k=n_poly) if n_poly > 0.0 else self.gas
        self.tau_sensor, self.delay_sensor = measurement_lag(on)
        self.bore = math.sqrt(4.0 * self.cylinder.A_a / math.pi)   #: for the wall's area [m]
        self.l_cushion = _param(on, "cushion_port", "length")
        #: end_cushioning's port volume [m^3], cut off the chamber within the cushion (0: none)
        self.V_port = _param(on, "cushion_port", "V_p") if self.l_cushion > 0.0 else 0.0

    # ------------------------------------------------------------------ valve
    def spool_step(self, y: float, u: float, dt: float) -> float:
        """The spool's position [V] after ``dt`` [s] of command ``u`` (valve_dynamics);
        without the effect, ``u``."""
        return fx.spool_lag_step(y, u, dt, self.tau_spool, self.rate_spool) if self.tau_spool > 0.0 else u

    def spool_rate(self, y: float, u: float) -> float:
        """d/dt of the spool's position [V/s] (valve_dynamics on)."""
        return fx.spool_rate(y, u, self.tau_spool, self.rate_spool)

    def opening(self, y: float) -> float:
        """The command [V] the orifices see at spool position ``y`` (``command`` stage)."""
        for apply, q in self.command_effects:
            y = apply(y, q, self)
        return y

    def valve_flows(self, cmd: float, p_a: float, p_b: float, slopes: bool = True):
        """The valve's flows into chambers A and B [kg/s] at the orifices' command ``cmd``
        [V] and absolute pressures [Pa] (Eq. 1), and each flow's slope in its chamber's
        pressure [kg/(s Pa)] (None unless ``slopes``)."""
        if not slopes:
            return (*ph.chamber_flows(cmd, p_a, p_b, self.valve, self.gas), None, None)
        return ph.chamber_flows_and_slopes(cmd, p_a, p_b, self.valve, self.gas)

    # --------------------------------------------------------------- chambers
    def inflows(self, m_a, m_b, s_a, s_b, p_a: float, p_b: float, x: float):
        """The chambers' net inflows [kg/s] (and slopes, where ``s_a`` is not None) from
        the valve's flows ``m_a``, ``m_b`` at piston position ``x`` [m]: the ``port``
        effects on each port's flow, then the ``seal`` effects between the chambers."""
        for apply, q in self.inflow_effects:
            m_a, m_b, s_a, s_b = apply(m_a, m_b, s_a, s_b, p_a, p_b, x, q, self)
        return m_a, m_b, s_a, s_b

    def chamber_inflows(self, cmd: float, p_a: float, p_b: float, x: float, slopes: bool = True):
        """:meth:`valve_flows` through :meth:`inflows`."""
        return self.inflows(*self.valve_flows(cmd, p_a, p_b, slopes), p_a, p_b, x)

    def cut(self, x: float):
        """The volumes [m^3] cut off chambers A and B at piston position ``x`` [m]: an end
        cushion's port within the cushion (``effects.cushion_port_cut``; 0 without)."""
        if self.V_port <= 0.0:
            return 0.0, 0.0
        return (fx.cushion_port_cut(x, self.l_cushion, self.V_port),
                fx.cushion_port_cut(self.cylinder.L - x, self.l_cushion, self.V_port))

    def volumes(self, x: float, cut=None):
        """The chambers' air volumes ``(V_a, V_b)`` [m^3] at piston position ``x`` [m]
        (Eq. 6, less :meth:`cut`; ``cut``: the cut to take instead, e.g. a step's start's)."""
        V_a, V_b = ph.chamber_volumes(x, self.cylinder)
        if self.V_port <= 0.0:
            return V_a, V_b
        c_a, c_b = self.cut(x) if cut is None else cut
        return V_a - c_a, V_b - c_b

    def air_masses(self, p_a: float, p_b: float, x: float):
        """The chambers' air masses [kg] at absolute pressures [Pa] and position ``x``, at
        the gas's temperature (Eq. 4)."""
        V_a, V_b = self.volumes(x)
        RT = self.gas.R * self.gas.T
        return p_a * V_a / RT, p_b * V_b / RT

    def air_mass_rates(self, m_a: float, m_b: float, x: float, v: float, masses):
        """d/dt of the chambers' air ``masses`` [kg/s]: the inflows ``m_a``, ``m_b``
        [kg/s], less the air an end cushion's port takes with it as the spear enters
        (the chamber's density times the cut's rate; the piston at ``x`` [m] moving at
        ``v`` [m/s])."""
        if self.V_port <= 0.0:
            return m_a, m_b
        V_a, V_b = self.volumes(x)
        l_c, V_p, L = self.l_cushion, self.V_port, self.cylinder.L
        dcut_a = V_p * fx.cushion_engagement_slope(x, l_c) * v
        dcut_b = -V_p * fx.cushion_engagement_slope(L - x, l_c) * v
        return m_a - masses[0] / V_a * dcut_a, m_b - masses[1] / V_b * dcut_b

    def separate(self, masses, x0: float, x1: float) -> None:
        """Scale the chambers' air ``masses`` [kg] (in place) for the cut's change from
        ``x0`` to ``x1`` [m]: the port's air leaves the chamber's account at its density."""
        if self.V_port <= 0.0:
            return
        start = self.cut(x0)
        for i, (V_kept, V_now) in enumerate(zip(self.volumes(x1), self.volumes(x1, start))):
            masses[i] *= V_kept / V_now

    def step_chambers(self, p_a: float, p_b: float, x0: float, x1: float, m_a: float, m_b: float,
                      s_a: float, s_b: float, dt: float, masses=None):
        """The chambers' absolute pressures [Pa] after ``dt`` [s] of inflows ``m_a``,
        ``m_b`` [kg/s] (slopes ``s_a``, ``s_b`` in their pressures), the piston moving
        linearly from ``x0`` to ``x1`` [m] (Eq. 5 to 7, exact for a closed chamber).
        With heat_transfer on, ``masses`` holds the chambers' air masses [kg], updated
        in place, and each pressure relaxes towards its isothermal level.  Returns
        ``(p_a, p_b)``."""
        cyl, gas = self.cylinder, self.chamber_gas
        # an end cushion's cut held over the step (it separates air, not compresses it)
        start = self.cut(x0)
        V_a0, V_b0 = self.volumes(x0, start)
        V_a1, V_b1 = self.volumes(x1, start)
        p_a1 = ph.chamber_pressure_step(p_a, V_a0, V_a1, m_a, dt, gas, s_a)
        p_b1 = ph.chamber_pressure_step(p_b, V_b0, V_b1, m_b, dt, gas, s_b)
        if self.h_wall > 0.0:
            R, T, k, h = gas.R, gas.T, self.gas.k, self.h_wall     # (c_v is the air's, whatever the process)
            # outflowing air leaves at the chamber's own temperature (from the mass held
            # at the step's start), not at the reference one
            p_a1 += dt * fx.outflow_temperature_rate(p_a, masses[0], V_a0, m_a, k, R, T)
            p_b1 += dt * fx.outflow_temperature_rate(p_b, masses[1], V_b0, m_b, k, R, T)
            masses[0] += dt * (m_a + 0.5 * s_a * (p_a1 - p_a))
            masses[1] += dt * (m_b + 0.5 * s_b * (p_b1 - p_b))
            if self.V_port > 0.0:
                self.separate(masses, x0, x1)
                V_a1, V_b1 = self.volumes(x1)
            tau = fx.thermal_time_constant(masses[0], fx.chamber_wall_area(V_a1, cyl.A_a, self.bore), h, k, R)
            p_a1 = fx.thermal_relaxation_step(p_a1, masses[0], V_a1, dt, tau, R, T)
            tau = fx.thermal_time_constant(masses[1], fx.chamber_wall_area(V_b1, cyl.A_b, self.bore), h, k, R)
            p_b1 = fx.thermal_relaxation_step(p_b1, masses[1], V_b1, dt, tau, R, T)
        return p_a1, p_b1

    def pressure_rates(self, p_a: float, p_b: float, m_a: float, m_b: float, x: float, v: float,
                       masses=None):
        """dp_a/dt, dp_b/dt [Pa/s] (Eq. 5 to 7), with heat_transfer's relaxation towards
        the isothermal pressure of the air ``masses`` [kg] where it is on."""
        dp_a, dp_b = ph.pressure_rates(p_a, p_b, m_a, m_b, x, v, self.cylinder, self.chamber_gas, self.cut(x))
        if self.h_wall > 0.0:
            cyl, (k, R, T) = self.cylinder, self.gas
            V_a, V_b = self.volumes(x)
            m = masses[0]
            tau = fx.thermal_time_constant(max(m, 1e-12), fx.chamber_wall_area(V_a, cyl.A_a, self.bore), self.h_wall, k, R)
            dp_a += fx.thermal_relaxation_rate(p_a, m, V_a, tau, R, T) + fx.outflow_temperature_rate(p_a, m, V_a, m_a, k, R, T)
            m = masses[1]
            tau = fx.thermal_time_constant(max(m, 1e-12), fx.chamber_wall_area(V_b, cyl.A_b, self.bore), self.h_wall, k, R)
            dp_b += fx.thermal_relaxation_rate(p_b, m, V_b, tau, R, T) + fx.outflow_temperature_rate(p_b, m, V_b, m_b, k, R, T)
        return dp_a, dp_b

    # ------------------------------------------------------------------- load
    def drive_force(self, p_a, p_b, x, f_ext):
        """Everything but friction that pushes the piston [N] (Eq. 8)."""
        return ph.drive_force(p_a, p_b, ph.phi_from_x(x, self.geometry), f_ext, self.cylinder,
                              self.load, self.P_atm)

    def load_at(self, load: ph.Load, v: float, p_a: float = 0.0, p_b: float = 0.0) -> ph.Load:
        """The load's parameters at speed ``v`` [m/s] and pressures [Pa] (``friction``
        stage; without such an effect, ``load``)."""
        for apply, q in self.friction_effects:
            load = apply(load, v, p_a, p_b, q, self)
        return load

    def step_load(self, x: float, v: float, dt: float, p_a: float, p_b: float, f_ext: float,
                  max_substep: float = 2e-4, load: ph.Load | None = None):
        """The piston's ``(x, v)`` after ``dt`` [s] with held pressures and external force
        (``physics.advance_load``: Eq. 8, 9, end stops), the ``friction`` effects applied
        at each substep; ``load`` in place of the model's (a rig's own friction)."""
        load_at = None
        if self.friction_effects:
            load_at = lambda ld, w: self.load_at(ld, w, p_a, p_b)
        return ph.advance_load(x, v, dt, p_a, p_b, f_ext, self.cylinder, self.geometry,
                               self.load if load is None else load, self.P_atm, max_substep, load_at)

    # ----------------------------------------------------------- measurement
    def measured(self, y: np.ndarray, t: np.ndarray) -> np.ndarray:
        """What the sensors report of the signal ``y`` on times ``t`` [s] (sensor_lag: a
        dead time, then a first-order lag; without it, ``y``)."""
        return measure(y, t, self.tau_sensor, self.delay_sensor)

    @property
    def measures(self) -> bool:
        """Whether the measurement path changes what is recorded (sensor_lag on)."""
        return self.tau_sensor > 0.0 or self.delay_sensor > 0.0


def lagged(y: np.ndarray, t: np.ndarray, tau: float) -> np.ndarray:
    """A first-order lag (``physics.effects.sensor_lag_step``) run along a signal."""
    out = np.empty_like(y)
    out[0] = y[0]
    for k in range(1, len(y)):
        out[k] = fx.sensor_lag_step(out[k - 1], y[k], t[k] - t[k - 1], tau)
    return out


def measure(y: np.ndarray, t: np.ndarray, tau: float = 0.0, delay: float = 0.0) -> np.ndarray:
    """The sensor_lag effect along a signal: ``delay`` [s] of dead time
    (``physics.lag.delayed``), then the first-order lag ``tau`` [s] (:func:`lagged`)."""
    if delay > 0.0:
        y = delayed(y, t, delay)
    return lagged(y, t, tau) if tau > 0.0 else y

__all__ = [
    "Model", "check_caps", "check_effects", "check_integrator", "integrated", "measurement_lag", "Boom",
    "lagged", "measure",
]
