"""The virtual rig's plant: the physical boom, simulated sample by sample at 1 kHz.

:class:`VirtualRig` stands in for the machine of the paper (DSNU 32-60 cylinder, MPYE-5
valve, SDE5-D10 pressure sensors, a 10 kOhm potentiometer, a 12-bit PCI-1711): give it
a valve command, it returns what the data acquisition would have recorded.  Its
configuration (:class:`RigConfig`, :func:`load_config`, JSON files in
``examples/rig/``) switches on the unmodelled effects of ``shared/spec/effects.md``,
sets the sensors' noise, and adds a contact with the ground or a disturbance: the
effects, contact, disturbance, sensors and parameters are documented in
:mod:`boomfmi.rig.config`.

Physics
-------
The baseline is the paper's model as the assembled boom (:class:`boomfmi.model.boom.Boom`)
steps it through ``boomfmi.physics``: the valve's flows and their slopes
(:meth:`~boomfmi.model.boom.Boom.valve_flows`), each chamber's pressure step
(:meth:`~boomfmi.model.boom.Boom.step_chambers`: exact for a closed chamber,
exponential against the valve's linearisation otherwise), the load
(:meth:`~boomfmi.model.boom.Boom.step_load`: ``advance_load`` with the paper's
stick/slip rule and hard end stops), and the geometry of Eq. 10 to 12.  Valve and
chambers are coupled Gauss-Seidel over internal substeps of at most ``SUBSTEP`` =
0.1 ms (shorter with a stiff contact or a fast vibration): the load moves under the
pressures predicted for the middle of the substep (Eq. 7), then the chambers follow the
volume change.  With every effect and the noise off it reproduces
``boomfmi.model.reference.simulate_reference`` to about 0.01 % NRMSE on the paper's
experiment.

Each substep of :meth:`VirtualRig.step` runs the parts in turn: the spool and its
overlap (``_spool_command``), the valve's flows (``_valve_flows``, per port with heat
or cushioning), the seal's leak (``_leak``), the load (``_move``), the chambers
(``_chambers``) and the sensors' filter (``_sense``).  The effects' own forms (not the
model's candidate forms) are in :mod:`boomfmi.rig.truth`.
"""
from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

import numpy as np

from ..model.boom import Boom, Model
from ..physics import reference_rig
from ..physics.chamber import chamber_volumes, pressure_rates
from ..physics.geometry import alpha_from_x
from ..physics.orifice import signed_mass_flow, signed_mass_flow_slope
from ..physics.params import Gas
from ..physics.valve import orifice_area
from .config import RigConfig, load_config, model_parameters
from .truth import (chamber_temperature, chamber_wall_areas, cushion_engagement,
                    cushion_exhaust_area, first_order_coefficient, overlap_command,
                    piston_leak_flows, quantise, ramp_force, spool_step, spool_transition,
                    seal_friction_load, spring_contact_force, stribeck_load, thermal_equivalent_flow,
                    vibration_force, wall_heat_flow)

#: Longest internal substep [s].  0.1 ms: the load moves under the pressures at the
#: start of a substep and a start of motion is tested at substep boundaries, so a
#: coarser substep delays every start by a fraction of it (0.25 ms biased starts from a
#: stop, where the drive force sweeps through the static band in about a millisecond).
SUBSTEP = 1.0e-4
#: Command range of the valve [V].
U_MIN, U_MAX = reference_rig.u_min, reference_rig.u_max
#: ADC resolution [bit] and the measured ranges: pressure gauge [Pa], angle [rad].
ADC_BITS = 12
P_RANGE = (0.0, 1.0e6)
ALPHA_RANGE = (0.0, math.pi)
P_LSB = (P_RANGE[1] - P_RANGE[0]) / 2**ADC_BITS
ALPHA_LSB = (ALPHA_RANGE[1] - ALPHA_RANGE[0]) / 2**ADC_BITS

#: The valve's flows and slopes with the valve closed (without and with heat_transfer).
_CLOSED = (0.0, 0.0, 0.0, 0.0)
_CLOSED_HEAT = _CLOSED + _CLOSED


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
    docstrings of :mod:`boomfmi.rig.plant` (the physics) and :mod:`boomfmi.rig.config`
    (the effects and the sensors).
    """

    def __init__(self, config: RigConfig | None = None):
        self.config = cfg = load_config(config)
        self._valve, self._gas, self._cyl, self._geom, self._load, p = model_parameters(cfg.params)
        self._P_atm, self._p_a0, self._p_b0 = p["P_atm"], p["p_a0"], p["p_b0"]
        self._boom = Boom(Model(valve=self._valve, gas=self._gas, cylinder=self._cyl,
                                geometry=self._geom, load=self._load, P_atm=self._P_atm))
        fx = cfg.effects
        self._spool = fx.get("valve_dynamics")
        self._deadband = fx.get("valve_deadband")
        self._heat = fx.get("heat_transfer")
        self._leakage = fx.get("piston_leakage")
        self._stribeck = fx.get("stribeck_friction")
        self._seal_friction = fx.get("pressure_friction")
        self._cushion = fx.get("end_cushioning")
        self._lag = fx.get("sensor_lag")
        self._shaped = self._spool is not None or self._deadband is not None
        self._per_port = self._heat is not None or self._cushion is not None
        self._u_centre = self._valve.u_centre
        c = cfg.contact or {}
        self._spring = c if c.get("type") == "spring" else None
        self._ramp = c if c.get("type") == "ramp" else None
        self._vib = cfg.disturbance
        self._forced = self._spring is not None or self._ramp is not None or self._vib is not None
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
        self._T_a = self._T_b = self._gas.T
        self._m_a, self._m_b = self._boom.air_masses(self._p_a, self._p_b, self._x)
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

        p_a, p_b, x, v, t0 = self._p_a, self._p_b, self._x, self._v, self.t
        shaped, forced, leakage, lag = self._shaped, self._forced, self._leakage, self._lag
        half = 0.5 * h
        for i in range(n):
            t = t0 + i * h
            uv = self._spool_command(u) if shaped else u
            f = self._force(t + half, x, v) if forced else 0.0
            flows = self._valve_flows(uv, p_a, p_b, x)
            if leakage:
                flows = self._leak(p_a, p_b, flows)
            x1, v = self._move(p_a, p_b, x, v, flows, f, h)
            p_a, p_b = self._chambers(p_a, p_b, x, x1, flows, h, t)
            x = x1
            if lag:
                self._sense(p_a, p_b, x, t0 + (i + 1) * h)

        self._p_a, self._p_b, self._x, self._v = p_a, p_b, x, v
        self.t = t0 + dt
        self._u = u
        return self.measure()

    # ----------------------------------------------------- parts of a substep
    def _spool_command(self, u: float) -> float:
        """The command [V] the orifices see while the valve gets ``u`` [V]: the spool
        advanced over the substep (valve_dynamics), then its overlap (valve_deadband)."""
        uv = u
        if self._spool:
            self._y, self._y_dot = spool_step(self._y, self._y_dot, u, self._transition)
            uv = self._y
        d = self._deadband
        if d:
            uv = overlap_command(uv, d["overlap"], d["edge"], self._u_centre, self._valve.u_span)
        return uv

    def _valve_flows(self, uv: float, p_a: float, p_b: float, x: float):
        """The valve's flows into chambers A and B [kg/s] and their slopes in each
        chamber's pressure [kg/(s Pa)] at the orifices' command ``uv`` [V], absolute
        pressures [Pa] and piston position ``x`` [m]: ``(m_a, m_b, s_a, s_b)``, with
        heat_transfer on followed by the same times the temperature of the air they
        carry, ``(mT_a, mT_b, sT_a, sT_b)`` [kg K/s, kg K/(s Pa)]."""
        if uv == self._u_centre:
            return _CLOSED_HEAT if self._heat else _CLOSED
        if not self._per_port:
            return self._boom.valve_flows(uv, p_a, p_b)
        return self._port_flows(uv, p_a, p_b, x)

    def _port_flows(self, uv: float, p_a: float, p_b: float, x: float):
        """:meth:`_valve_flows` port by port: each port's orifice at its upstream
        temperature (heat_transfer), the exhaust through the cushion's needle near the
        stroke's end (end_cushioning)."""
        valve, gas, cushion, heat = self._valve, self._gas, self._cushion, self._heat
        P_s, P_e = valve.P_s, valve.P_e
        A_v = orifice_area(uv, valve)
        extend = uv < valve.u_centre
        A_a = A_b = A_v
        if cushion:
            if not extend and p_a > P_e:      # A exhausts near x = 0
                A_a = cushion_exhaust_area(A_v, cushion["A_n"],
                                           cushion_engagement(x, cushion["l_c"], cushion["w"]))
            elif extend and p_b > P_e:        # B exhausts near x = L
                A_b = cushion_exhaust_area(A_v, cushion["A_n"],
                                           cushion_engagement(self._cyl.L - x, cushion["l_c"], cushion["w"]))
        if heat:
            T_s, T_a, T_b = heat["T_s"], self._T_a, self._T_b
        else:
            T_a = T_b = T_s = gas.T
        if extend:
            m_a, s_a, Tf_a = _port_flow(A_a, P_s, p_a, T_s, T_a, gas)
            m_b, s_b, Tf_b = _port_flow(A_b, P_e, p_b, gas.T, T_b, gas)
        else:
            m_a, s_a, Tf_a = _port_flow(A_a, P_e, p_a, gas.T, T_a, gas)
            m_b, s_b, Tf_b = _port_flow(A_b, P_s, p_b, T_s, T_b, gas)
        if heat:
            return m_a, m_b, s_a, s_b, m_a * Tf_a, m_b * Tf_b, s_a * Tf_a, s_b * Tf_b
        return m_a, m_b, s_a, s_b

    def _leak(self, p_a: float, p_b: float, flows):
        """``flows`` (as :meth:`_valve_flows`) with the leak across the piston's seal
        (piston_leakage) at the chambers' pressures [Pa], carrying the upstream
        chamber's temperature."""
        A_leak, gas = self._leakage["A_leak"], self._gas
        if self._heat:
            m_a, m_b, s_a, s_b, mT_a, mT_b, sT_a, sT_b = flows
            T_up = self._T_a if p_a >= p_b else self._T_b
            q, l_a, l_b = piston_leak_flows(A_leak, p_a, p_b, Gas(gas.k, gas.R, T_up))
            return (m_a - q, m_b + q, s_a + l_a, s_b + l_b,
                    mT_a - q * T_up, mT_b + q * T_up, sT_a + l_a * T_up, sT_b + l_b * T_up)
        m_a, m_b, s_a, s_b = flows
        q, l_a, l_b = piston_leak_flows(A_leak, p_a, p_b, gas)
        return m_a - q, m_b + q, s_a + l_a, s_b + l_b

    def _move(self, p_a: float, p_b: float, x: float, v: float, flows, f: float, h: float):
        """The piston's ``(x, v)`` after the substep ``h`` [s] under the external force
        ``f`` [N] and the pressures predicted for the middle of the substep from the
        chambers' inflows ``flows`` (a second-order coupling: pressures from the
        substep's start would delay every start of motion by half a substep), with the
        rig's own Stribeck friction (stribeck_friction) and seal friction (pressure_friction)."""
        half = 0.5 * h
        dpa, dpb = pressure_rates(p_a, p_b, flows[0], flows[1], x, v, self._cyl, self._gas)
        p_am, p_bm = p_a + half * dpa, p_b + half * dpb
        if 0.5 * p_a > p_am:      # max(p_am, 0.5 p_a), without the call
            p_am = 0.5 * p_a
        if 0.5 * p_b > p_bm:
            p_bm = 0.5 * p_b
        s = self._stribeck
        ld = stribeck_load(self._load, abs(v), s["F_brk"], s["v_s"]) if s else self._load
        q = self._seal_friction
        if q:
            ld = seal_friction_load(ld, p_am, p_bm, self._P_atm, q["k_piston"], q["k_rod"])
        return self._boom.step_load(x, v, h, p_am, p_bm, f, h, ld)

    def _chambers(self, p_a: float, p_b: float, x0: float, x1: float, flows, h: float,
                  t: float):
        """The chambers' absolute pressures [Pa] after the substep ``h`` [s] that
        started at ``t`` [s], the piston moving from ``x0`` to ``x1`` [m], with the
        inflows ``flows`` (as :meth:`_valve_flows`).  With heat_transfer on, the energy
        balance enters as an equivalent flow at the reference temperature, and the
        chambers' masses and temperatures follow."""
        heat = self._heat
        if not heat:
            m_a, m_b, s_a, s_b = flows
            p_a1, p_b1 = self._boom.step_chambers(p_a, p_b, x0, x1, m_a, m_b, s_a, s_b, h)
        else:
            gas, h_w = self._gas, heat["h_w"]
            T_ref = gas.T
            m_a, m_b, s_a, s_b, mT_a, mT_b, sT_a, sT_b = flows
            W_a, W_b = chamber_wall_areas(x0, heat["A_w0"], self._cyl)
            p_a1, p_b1 = self._boom.step_chambers(
                p_a, p_b, x0, x1,
                thermal_equivalent_flow(mT_a, wall_heat_flow(h_w, W_a, T_ref, self._T_a), gas),
                thermal_equivalent_flow(mT_b, wall_heat_flow(h_w, W_b, T_ref, self._T_b), gas),
                sT_a / T_ref, sT_b / T_ref, h)
            self._m_a += h * (m_a + 0.5 * s_a * (p_a1 - p_a))
            self._m_b += h * (m_b + 0.5 * s_b * (p_b1 - p_b))
            if not (self._m_a > 0.0 and self._m_b > 0.0):
                raise RuntimeError(f"a chamber emptied at t = {t:g} s")
            V_a1, V_b1 = chamber_volumes(x1, self._cyl)
            self._T_a = chamber_temperature(p_a1, V_a1, self._m_a, gas.R)
            self._T_b = chamber_temperature(p_b1, V_b1, self._m_b, gas.R)
        if not (p_a1 > 0.0 and p_b1 > 0.0):
            raise RuntimeError(f"a chamber emptied at t = {t:g} s "
                               f"(p_a = {p_a1:g} Pa, p_b = {p_b1:g} Pa)")
        return p_a1, p_b1

    def _sense(self, p_a: float, p_b: float, x: float, t: float) -> None:
        """The sensors' first-order filter (sensor_lag) over one substep, ending at
        ``t`` [s] on the true pressures [Pa] and position [m]; recorded for the delay."""
        c, P_atm = self._c_lag, self._P_atm
        z_a, z_b, z_al = self._z
        z_a += c * (p_a - P_atm - z_a)
        z_b += c * (p_b - P_atm - z_b)
        z_al += c * (alpha_from_x(x, self._geom) - z_al)
        self._z = (z_a, z_b, z_al)
        self._history.append((t, z_a, z_b, z_al))

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
