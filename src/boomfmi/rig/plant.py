"""The virtual rig's plant: the physical machine, simulated sample by sample at 1 kHz.

One :class:`MachineRig` stands in for a machine: give it the valve commands, it returns
what the data acquisition would have recorded.  It is built as

* :class:`VirtualRig`, the boom of the paper (DSNU 32-60 cylinder, MPYE-5 valve,
  SDE5-D10 pressure sensors, a 10 kOhm potentiometer, a 12-bit PCI-1711): one joint,
  a :class:`Sample` per step; configuration :class:`RigConfig`, :func:`load_config`,
  JSON files in ``examples/rig/``: the unmodelled effects of
  ``shared/spec/effects.md``, the sensors' noise, a contact with the ground or a
  disturbance (documented in :mod:`boomfmi.rig.config`);
* :class:`ExcavatorRig`, the whole machine of ``shared/spec/excavator.md``: four joints
  (:data:`JOINTS`), an :class:`ExcavatorSample` per step (each joint's two gauge
  pressures and angle, plus the truth a real rig would not give: each piston's x and v,
  the force of the ground on the bucket tip); configuration
  :func:`boomfmi.rig.config.load_excavator_config`, ``examples/rig/excavator_*.json``:
  each effect of the boom's catalogue per joint, the sensors' noise per joint, a
  payload and a contact at the tip.

Physics
-------
Each joint is a :class:`JointPlant`: its valve and chambers as the paper's model, the
assembled boom (:class:`boomfmi.model.boom.Boom`, with that joint's actuator: A_max,
bore areas, stroke, dead volumes, friction and, for the angle, its mounting triangle as
Eq. 12's a, b, l_min) steps them through ``boomfmi.physics``: the valve's flows and
their slopes (:meth:`~boomfmi.model.boom.Boom.valve_flows`), each chamber's pressure
step (:meth:`~boomfmi.model.boom.Boom.step_chambers`: exact for a closed chamber,
exponential against the valve's linearisation otherwise).  Each substep of
:meth:`MachineRig.step` runs, for every joint, the spool and its overlap
(:meth:`JointPlant.spool_command`), the valve's flows (:meth:`JointPlant.valve_flows`,
per port with heat or cushioning), the seal's leak (:meth:`JointPlant.leak`); then the
mechanism moves the pistons under the pressures predicted for the middle of the
substep (:meth:`JointPlant.mid_pressures`, Eq. 7) with the rig's friction effects
(:meth:`JointPlant.friction_load`); then every joint's chambers follow the volume
change (:meth:`JointPlant.chambers`) and its sensors' filter (:meth:`JointPlant.sense`):
Gauss-Seidel.  The mechanisms:

* :class:`BoomLoad` (the boom): ``Boom.step_load`` (``advance_load`` with the paper's
  stick/slip rule and hard end stops) and the geometry of Eq. 10 to 12, substeps of at
  most :data:`SUBSTEP` = 0.1 ms (shorter with a stiff contact or a fast vibration).
  With every effect and the noise off it reproduces
  ``boomfmi.model.reference.simulate_reference`` to about 0.01 % NRMSE on the paper's
  experiment.
* :class:`Linkage` (the excavator): :func:`boomfmi.physics.linkage.advance_linkage`
  (mass matrix, Coriolis, gravity, Eq. 9 stick/slip per cylinder, end stops, the tip
  force through J^T); the friction effects change that cylinder's F_s, F_d over the
  substep.  Substeps are at most :data:`LINKAGE_SUBSTEP` = 0.25 ms (shorter with a
  stiff ground, and split in the ground where the soil's drag is stiff:
  :meth:`Linkage._drag_substeps`).  Start: every piston at its ``x0`` (mid-stroke by default) at rest,
  valves centred, each cylinder's chambers at the pressures that hold the machine
  there against gravity (:func:`vented_holding_pressures`).

The effects' own forms (not the model's candidate forms) are in
:mod:`boomfmi.rig.truth`.

Tip contact of the excavator (``contact``, the scenarios of
:class:`boomfmi.experiments.TipContact`):

* ``{"type": "ground", "ground_z": m, "stiffness": N/m, "damping": N s/m,
  "friction": 1, "v_slip": m/s}``: below the plane z = ground_z the ground pushes the
  tip up, ``f_z = k (ground_z - z) + c max(-v_z, 0)`` (never pulling), and drags it
  against its horizontal velocity, ``f_xy = -friction f_z v_xy / max(|v_xy|, v_slip)``;
* ``{"type": "prescribed", "force": [x, y, z] N, "start": s, "stop": s, "ramp": s}``:
  a known force whatever the tip does.

The force is evaluated at each substep's middle from the tip's position and velocity,
those to first order about the sample's start (``tip_position``, ``tip_jacobian`` and
the lever arms there: the tip moves well under a millimetre in a sample), and recorded
as ``f_tip`` (world frame, the force the environment exerts on the bucket) at each
sample exactly from the state at its time (:meth:`ExcavatorRig.tip_force`).

Sensors, per joint: the lag (sensor_lag), Gaussian noise (``p_sigma`` [Pa],
``alpha_sigma`` [rad]) then a 12-bit ADC: pressures over 0 .. 10 bar gauge, the angle
over 0 .. pi (boom, arm, bucket) or -pi/2 .. pi/2 (the excavator's swing), LSB
pi / 4096.

In Python the excavator's rig costs about 2 ms of wall time per millisecond simulated:
serve it in lockstep (``boomfmi rig serve --lockstep``); in real time it falls behind
and counts missed ticks.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..experiments import TipContact
from ..model.boom import Boom, Model
from ..physics import reference_rig
from ..physics.chamber import chamber_volumes, pressure_rates
from ..physics.linkage import (JOINTS, Excavator, advance_linkage, joint_angles, lever_arms,
                                 mass_matrix, piston_dynamics, tip_jacobian, tip_position)
from ..physics.geometry import alpha_from_x
from ..physics.orifice import signed_mass_flow, signed_mass_flow_slope
from ..physics.params import Gas
from ..physics.valve import orifice_area
from .config import ExcavatorConfig, RigConfig, load_config, load_excavator_config, model_parameters
from .truth import (RIG_FORMS, RigSite, breakaway_stribeck_load, chamber_temperature, chamber_wall_areas,
                    cushion_engagement, cushion_exhaust_area, first_order_coefficient, overlap_command,
                    piston_leak_flows, quantise, ramp_force, spool_step, spool_transition,
                    seal_friction_load, spring_contact_force, thermal_equivalent_flow,
                    vibration_force, wall_heat_flow)

#: Longest internal substep [s].  0.1 ms: the load moves under the pressures at the
#: start of a substep and a start of motion is tested at substep boundaries, so a
#: coarser substep delays every start by a fraction of it (0.25 ms biased starts from a
#: stop, where the drive force sweeps through the static band in about a millisecond).
SUBSTEP = 1.0e-4
#: Longest internal substep of the excavator's linkage [s] (advance_linkage's default).
LINKAGE_SUBSTEP = 2.5e-4
#: Command range of the valve [V].
U_MIN, U_MAX = reference_rig.u_min, reference_rig.u_max
#: ADC resolution [bit] and the measured ranges: pressure gauge [Pa], angle [rad].
ADC_BITS = 12
P_RANGE = (0.0, 1.0e6)
ALPHA_RANGE = (0.0, math.pi)
P_LSB = (P_RANGE[1] - P_RANGE[0]) / 2**ADC_BITS
ALPHA_LSB = (ALPHA_RANGE[1] - ALPHA_RANGE[0]) / 2**ADC_BITS
#: Each excavator joint's angle range over the ADC [rad] (LSB ALPHA_LSB, pi / 4096).
ANGLE_RANGES = {"swing": (-0.5 * math.pi, 0.5 * math.pi), "boom": ALPHA_RANGE,
                "arm": (0.0, math.pi), "bucket": (0.0, math.pi)}

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


class ExcavatorSample(NamedTuple):
    """One sample of the excavator's data acquisition (plus the truth), per joint in the
    order of :data:`JOINTS`."""
    t: float            #: time of the sample [s]
    u_applied: tuple    #: commands the valves got [V], 0 .. 10
    p_a: tuple          #: chamber A pressures, measured, gauge [Pa]
    p_b: tuple          #: chamber B pressures, measured, gauge [Pa]
    angle: tuple        #: joint angles, measured [rad] (theta_swing, alpha, theta_arm, theta_bucket)
    f_tip: tuple        #: true force of the environment on the bucket tip [N], world frame
    x: tuple            #: true piston positions [m]
    v: tuple            #: true piston velocities [m/s]


def commands(u) -> list:
    """The four valve commands [V] from a sequence in :data:`JOINTS` order or a mapping
    ``{"u_<joint>": V}`` (or ``{joint: V}``), clipped to 0 .. 10 V; ValueError on nan or a
    missing joint."""
    if isinstance(u, dict):
        try:
            u = [u[f"u_{j}"] if f"u_{j}" in u else u[j] for j in JOINTS]
        except KeyError as e:
            raise ValueError(f"the excavator needs a command for every joint ({', '.join(JOINTS)}); "
                             f"missing {e.args[0]!r}") from None
    u = [float(c) for c in u]
    if len(u) != len(JOINTS):
        raise ValueError(f"the excavator takes {len(JOINTS)} commands ({', '.join(JOINTS)}), not {len(u)}")
    out = []
    for j, c in zip(JOINTS, u):
        if c != c:
            raise ValueError(f"valve command u_{j} must be a number, got nan")
        out.append(min(max(c, U_MIN), U_MAX))
    return out


def tip_contact(contact: dict | None) -> TipContact | None:
    """The configuration's tip contact as an :class:`boomfmi.experiments.TipContact`."""
    if contact is None:
        return None
    c = dict(contact)
    kind = c.pop("type")
    if kind == "prescribed":
        c["stop"] = math.inf if c.get("stop") is None else c["stop"]
    return TipContact("rig", kind, **c)


def machine(config: ExcavatorConfig) -> Excavator:
    """The linkage the rig moves: ``physics.linkage``'s with the configuration's
    per-joint overrides (A_max, dead volumes, friction) and P_atm."""
    ex = Excavator()
    changes = {j: replace(getattr(ex, j), **config.joints[j]["overrides"])
               for j in JOINTS if config.joints[j]["overrides"]}
    if "P_atm" in config.params:
        changes["P_atm"] = config.params["P_atm"]
    return replace(ex, **changes) if changes else ex


def vented_holding_pressures(x, ex: Excavator, payload: float = 0.0, P_atm: float | None = None):
    """Absolute chamber pressures [Pa] ``(p_a, p_b)`` (4-vectors) that hold the pistons
    at ``x`` [m] at rest against gravity: the holding force on the cap side if it
    pushes, on the rod side if it pulls, the other chamber at P_atm."""
    P_atm = ex.P_atm if P_atm is None else P_atm
    _, bias, _ = piston_dynamics(np.asarray(x, float), np.zeros(4), payload, ex)
    p_a = [P_atm + max(F, 0.0) / a.A_a for F, a in zip(bias, ex.actuators)]
    p_b = [P_atm + max(-F, 0.0) / a.A_b for F, a in zip(bias, ex.actuators)]
    return p_a, p_b


class JointPlant:
    """One joint's valve, chambers and sensors: the parts of a substep a machine rig
    runs for each of its joints, with that joint's effects (``config.effects``) and
    sensors (``config.noise``).  The mechanism that moves the pistons (the boom's load,
    :class:`BoomLoad`, or the linkage, :class:`Linkage`) is not here.

    ``angle_range`` is the angle's range over the ADC [rad]; ``offset`` [rad], when
    given, is added to the mounting triangle's angle (the excavator's joint angles)."""

    def __init__(self, config: RigConfig, name: str = "boom", angle_range=ALPHA_RANGE, offset=None):
        self.config = cfg = load_config(config)
        self.name, self.angle_range, self.offset = name, angle_range, offset
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
        self.lag = fx.get("sensor_lag")
        # the plug-ins' effects in their rig forms (rig/truth.py's RIG_FORMS), per stage
        self._site = RigSite(self._valve, self._gas, self._cyl, self._P_atm)
        plugged = lambda s: tuple((RIG_FORMS[n].apply, q) for n, q in fx.items()
                                  if n in RIG_FORMS and RIG_FORMS[n].stage == s)
        self._plugged_command, self._plugged_port = plugged("command"), plugged("port")
        self._plugged_seal, self._plugged_friction = plugged("seal"), plugged("friction")
        self._shaped = self._spool is not None or self._deadband is not None or bool(self._plugged_command)
        self._per_port = self._heat is not None or self._cushion is not None
        self.rubbing = self._stribeck is not None or self._seal_friction is not None or bool(self._plugged_friction)
        self._u_centre = self._valve.u_centre
        self.noise = cfg.noise
        self.reset()

    def reset(self) -> None:
        """Back to the initial state: ``u`` [V], ``p_a``, ``p_b`` [Pa], ``x`` [m], ``v`` [m/s]."""
        self.u = self._valve.u_centre
        self.p_a, self.p_b = self._p_a0, self._p_b0
        self.x, self.v = self.config.x0, 0.0
        self._y, self._y_dot = self._valve.u_centre, 0.0          # spool [V], [V/s]
        self._T_a = self._T_b = self._gas.T
        self._m_a, self._m_b = self._boom.air_masses(self.p_a, self.p_b, self.x)
        self._z = (self.p_a - self._P_atm, self.p_b - self._P_atm, alpha_from_x(self.x, self._geom))
        self._history = deque([(0.0, *self._z)])

    def prepare(self, h: float) -> None:
        """Constants that depend on the substep ``h`` [s]."""
        if self._spool:
            self._transition = spool_transition(self._spool["f_n"], self._spool["zeta"], h)
        if self.lag:
            self._c_lag = first_order_coefficient(h, self.lag["tau"])

    # ----------------------------------------------------- parts of a substep
    def inflows(self, u: float, p_a: float, p_b: float, x: float):
        """The chambers' inflows over a substep with the valve given ``u`` [V]: the
        spool (:meth:`spool_command`), the valve (:meth:`valve_flows`), the seal's leak
        (:meth:`leak`)."""
        uv = self.spool_command(u) if self._shaped else u
        flows = self.valve_flows(uv, p_a, p_b, x)
        for form, q in self._plugged_port:
            flows = form(*flows, p_a, p_b, x, q, self._site)
        if self._leakage:
            flows = self.leak(p_a, p_b, flows)
        for form, q in self._plugged_seal:
            flows = form(*flows, p_a, p_b, x, q, self._site)
        return flows

    def spool_command(self, u: float) -> float:
        """The command [V] the orifices see while the valve gets ``u`` [V]: the spool
        advanced over the substep (valve_dynamics), then its overlap (valve_deadband)."""
        uv = u
        if self._spool:
            self._y, self._y_dot = spool_step(self._y, self._y_dot, u, self._transition)
            uv = self._y
        d = self._deadband
        if d:
            uv = overlap_command(uv, d["overlap"], d["edge"], self._u_centre, self._valve.u_span)
        for form, q in self._plugged_command:
            uv = form(uv, q, self._site)
        return uv

    def valve_flows(self, uv: float, p_a: float, p_b: float, x: float):
        """The valve's flows into chambers A and B [kg/s] and their slopes in each
        chamber's pressure [kg/(s Pa)] at the orifices' command ``uv`` [V], absolute
        pressures [Pa] and piston position ``x`` [m]: ``(m_a, m_b, s_a, s_b)``, with
        heat_transfer on followed by the same times the temperature of the air they
        carry, ``(mT_a, mT_b, sT_a, sT_b)`` [kg K/s, kg K/(s Pa)]."""
        if uv == self._u_centre:
            return _CLOSED_HEAT if self._heat else _CLOSED
        if not self._per_port:
            return self._boom.valve_flows(uv, p_a, p_b)
        return self.port_flows(uv, p_a, p_b, x)

    def port_flows(self, uv: float, p_a: float, p_b: float, x: float):
        """:meth:`valve_flows` port by port: each port's orifice at its upstream
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

    def leak(self, p_a: float, p_b: float, flows):
        """``flows`` (as :meth:`valve_flows`) with the leak across the piston's seal
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

    def mid_pressures(self, p_a: float, p_b: float, x: float, v: float, flows, half: float):
        """The chambers' pressures [Pa] predicted for the middle of the substep (``half``
        of it [s]) from the inflows ``flows``, the piston at ``x``, ``v`` (a second-order
        coupling: pressures from the substep's start would delay every start of motion
        by half a substep); at least half the start's."""
        dpa, dpb = pressure_rates(p_a, p_b, flows[0], flows[1], x, v, self._cyl, self._gas)
        p_am, p_bm = p_a + half * dpa, p_b + half * dpb
        if 0.5 * p_a > p_am:      # max(p_am, 0.5 p_a), without the call
            p_am = 0.5 * p_a
        if 0.5 * p_b > p_bm:
            p_bm = 0.5 * p_b
        return p_am, p_bm

    def friction_load(self, load, v: float, p_am: float, p_bm: float):
        """``load`` (a :class:`~boomfmi.physics.params.Load`) with the rig's own
        Stribeck friction (stribeck_friction) at the piston's speed ``|v|`` and seal
        friction (pressure_friction) at the pressures ``p_am``, ``p_bm`` [Pa]."""
        s = self._stribeck
        ld = breakaway_stribeck_load(load, abs(v), s["F_brk"], s["v_s"]) if s else load
        q = self._seal_friction
        if q:
            ld = seal_friction_load(ld, p_am, p_bm, self._P_atm, q["k_piston"], q["k_rod"])
        for form, q in self._plugged_friction:
            ld = form(ld, v, p_am, p_bm, q, self._site)
        return ld

    def chambers(self, p_a: float, p_b: float, x0: float, x1: float, flows, h: float, t: float):
        """The chambers' absolute pressures [Pa] after the substep ``h`` [s] that
        started at ``t`` [s], the piston moving from ``x0`` to ``x1`` [m], with the
        inflows ``flows`` (as :meth:`valve_flows`).  With heat_transfer on, the energy
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

    def sense(self, p_a: float, p_b: float, x: float, t: float) -> None:
        """The sensors' first-order filter (sensor_lag) over one substep, ending at
        ``t`` [s] on the true pressures [Pa] and position [m]; recorded for the delay."""
        c, P_atm = self._c_lag, self._P_atm
        z_a, z_b, z_al = self._z
        z_a += c * (p_a - P_atm - z_a)
        z_b += c * (p_b - P_atm - z_b)
        z_al += c * (alpha_from_x(x, self._geom) - z_al)
        self._z = (z_a, z_b, z_al)
        self._history.append((t, z_a, z_b, z_al))

    def sensed(self, t: float):
        """What reaches the ADC at time ``t`` [s]: (p_a gauge, p_b gauge, the triangle's
        angle), through the sensor lag."""
        if not self.lag:
            return self.p_a - self._P_atm, self.p_b - self._P_atm, alpha_from_x(self.x, self._geom)
        history = self._history
        target = t - self.lag["delay"]
        while len(history) > 1 and history[1][0] <= target:
            history.popleft()
        e0 = history[0]
        if len(history) == 1 or target <= e0[0]:
            return e0[1], e0[2], e0[3]
        e1 = history[1]
        w = (target - e0[0]) / (e1[0] - e0[0])
        return (e0[1] + w * (e1[1] - e0[1]), e0[2] + w * (e1[2] - e0[2]),
                e0[3] + w * (e1[3] - e0[3]))


def _boom_command(u) -> list:
    """The boom's valve command [V] as a one-joint list, clipped to 0 .. 10."""
    u = float(u)
    if not u >= U_MIN:
        if u != u:
            raise ValueError("valve command u must be a number, got nan")
        u = U_MIN
    elif u > U_MAX:
        u = U_MAX
    return [u]


class BoomLoad:
    """The boom's mechanism: one piston under its load (``Boom.step_load``: Eq. 7 to 9,
    stick/slip, end stops) with the ground contact (spring or ramp) and the vibration of
    :mod:`boomfmi.rig.config`."""

    def __init__(self, joint: JointPlant, config: RigConfig):
        self.joint = joint
        c = config.contact or {}
        self._spring = c if c.get("type") == "spring" else None
        self._ramp = c if c.get("type") == "ramp" else None
        self._vib = config.disturbance
        self._forced = self._spring is not None or self._ramp is not None or self._vib is not None
        # substep: short enough for a stiff contact and a fast vibration
        h = SUBSTEP
        M = joint._load.M
        if self._spring:
            if self._spring["stiffness"] > 0.0:
                h = min(h, 0.1 / math.sqrt(self._spring["stiffness"] / M))
            if self._spring["damping"] > 0.0:
                h = min(h, 0.1 * M / self._spring["damping"])
        if self._vib and self._vib["frequency"] > 0.0:
            h = min(h, 1.0 / (40.0 * self._vib["frequency"]))
        self.substep = h
        self._load, self._rubbing = joint._load, joint.rubbing
        self._mid_pressures, self._step_load = joint.mid_pressures, joint._boom.step_load

    commands = staticmethod(_boom_command)

    def reset(self) -> None:
        pass

    def force(self, t: float, x: float, v: float) -> float:
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

    def move(self, i: int, t: float, h: float, p_a, p_b, x, v, flows):
        """The piston's ``([x], [v])`` after the substep ``h`` [s] that starts at ``t``
        [s] (the ``i``-th of the sample), under the external force at its middle."""
        x, v = x[0], v[0]
        half = 0.5 * h
        f = self.force(t + half, x, v) if self._forced else 0.0
        p_am, p_bm = self._mid_pressures(p_a[0], p_b[0], x, v, flows[0], half)
        ld = self._load
        if self._rubbing:
            ld = self.joint.friction_load(ld, v, p_am, p_bm)
        x1, v1 = self._step_load(x, v, h, p_am, p_bm, f, h, ld)
        return [x1], [v1]

    def sample(self, t: float, u, p_a, p_b, angle, x, v) -> Sample:
        return Sample(t, u[0], p_a[0], p_b[0], angle[0], self.force(t, x[0], v[0]), x[0])

    def truth(self, t: float, p_a, p_b, x, v) -> dict:
        return {"p_a": p_a[0], "p_b": p_b[0], "x": x[0], "v": v[0],
                "alpha": alpha_from_x(x[0], self.joint._geom), "f_ext": self.force(t, x[0], v[0])}


class Linkage:
    """The excavator's mechanism: the four pistons moved together through the linkage
    (:func:`boomfmi.physics.linkage.advance_linkage`: mass matrix, Coriolis, gravity,
    Eq. 9 stick/slip per cylinder, end stops, the tip force through J^T) with the
    payload and the tip contact; the joints' friction effects change each cylinder's
    F_s, F_d over the substep."""

    def __init__(self, joints, ex: Excavator, payload: float, contact: dict | None, x0):
        self.joints, self.ex, self.payload = joints, ex, payload
        self._rubbing = any(jp.rubbing for jp in joints)
        self._contact = tip_contact(contact)
        self._ground = self._contact is not None and self._contact.kind == "ground"
        h = LINKAGE_SUBSTEP
        if self._ground:
            # the tip's lightest direction against the ground's stiffness and damping
            q = joint_angles(np.asarray(x0), ex)
            J = tip_jacobian(q, ex)
            w = float(np.max(np.linalg.eigvalsh(J @ np.linalg.solve(mass_matrix(q, payload, ex), J.T))))
            c = self._contact
            h = min(h, 0.2 / math.sqrt(c.stiffness * w))
            if c.damping > 0.0:
                h = min(h, 0.5 / (c.damping * w))
        self.substep = h
        self.reset()

    commands = staticmethod(commands)

    def reset(self) -> None:
        self._frame = None          # (x, the tip's frame there): see _tip_frame
        self._w = None              # (that frame's x, the tip's largest mobility): see _drag_substeps
        self._f_tip = (0.0, 0.0, 0.0)

    def tip_force(self, t: float, x, v) -> np.ndarray:
        """The force of the environment on the bucket tip [N] (world frame) at time ``t``
        [s] with the pistons at ``x`` [m] moving at ``v`` [m/s]."""
        c = self._contact
        if c is None:
            return np.zeros(3)
        if not self._ground:
            return c.force(t, (0.0, 0.0, 0.0))
        tip, J, lam, _ = self._tip_frame(x)
        if tip[2] >= c.ground_z:
            return np.zeros(3)
        return c.force(t, tip, J @ (lam * np.asarray(v, float)))

    def _tip_frame(self, x):
        """At the pistons' ``x``: the tip [m], d tip / dq and dq/dx, for the first-order
        tip within a sample."""
        key = tuple(float(c) for c in x)
        if self._frame is None or self._frame[0] != key:
            x = np.array(key)
            q = joint_angles(x, self.ex)
            self._frame = key, (tip_position(q, self.ex), tip_jacobian(q, self.ex), 1.0 / lever_arms(x, self.ex), x)
        return self._frame[1]

    def _ground_force(self, t, tip, vt):
        if tip[2] >= self._contact.ground_z:
            return (0.0, 0.0, 0.0)
        return self._contact.force(t, tip, vt)

    def _linkage(self, p_am, p_bm, v):
        """The linkage with the rig's friction effects applied over this substep."""
        if not self._rubbing:
            return self.ex
        changes = {}
        for k, (j, jp) in enumerate(zip(JOINTS, self.joints)):
            if not jp.rubbing:
                continue
            a = getattr(self.ex, j)
            ld = jp.friction_load(jp._load._replace(K_v=a.K_v, F_s=a.F_s, F_d=a.F_d), v[k], p_am[k], p_bm[k])
            changes[j] = replace(a, K_v=ld.K_v, F_s=ld.F_s, F_d=ld.F_d)     # (a plug-in may change K_v)
        return replace(self.ex, **changes)

    def move(self, i: int, t: float, h: float, p_a, p_b, x, v, flows):
        """The pistons' ``(x, v)`` after the substep ``h`` [s] that starts at ``t`` [s]
        (the ``i``-th of the sample) under the pressures predicted for its middle and
        the tip force there: the tip to first order about the sample's start."""
        half = 0.5 * h
        p_am, p_bm = [], []
        for k, jp in enumerate(self.joints):
            a, b = jp.mid_pressures(p_a[k], p_b[k], x[k], v[k], flows[k], half)
            p_am.append(a)
            p_bm.append(b)
        contact, f_tip = self._contact, self._f_tip
        if contact is not None:
            if not self._ground:
                f_tip = contact.force(t + half, (0.0, 0.0, 0.0))
            elif i == 0:
                self._tip0 = tip0, J0, lam0, x0 = self._tip_frame(x)
                f_tip = self._ground_force(t + half, tip0, J0 @ (lam0 * np.asarray(v)))
            else:
                tip0, J0, lam0, x0 = self._tip0
                xa, va = np.asarray(x), np.asarray(v)
                f_tip = self._ground_force(t + half, tip0 + J0 @ (lam0 * (xa - x0)), J0 @ (lam0 * va))
            self._f_tip = f_tip
            if self._ground and f_tip[2] > 0.0:
                return self._drag_substeps(t, h, p_am, p_bm, x, v, f_tip)
        x1, v1 = advance_linkage((x, v), p_am, p_bm, f_tip, h, self._linkage(p_am, p_bm, v), self.payload,
                                 max_substep=h)
        return x1.tolist(), v1.tolist()

    def _drag_substeps(self, t: float, h: float, p_am, p_bm, x, v, f_tip):
        """The substep ``h`` [s] in the ground, split where the soil's drag is too stiff
        for it: the drag ``friction f_z v_xy / max(|v_xy|, v_slip)`` is a damper of up
        to ``friction f_z / v_slip`` (some 5,000 N s/m on hard soil) about a slow tip,
        and held over a substep longer than ``1 / (w c)`` (``w`` [1/kg] the tip's
        largest mobility, ``c`` the drag's slope) it overshoots: the tip's velocity and
        the drag alternate from substep to substep (50.8 / 9.2 N on the closed-loop dig
        in hard soil, the recording's ``f_tip`` one phase of it, some 20 N off the mean
        that acted).  The pieces are short enough that it does not (``h w c <= 1`` each);
        the ground force evaluated at each piece's middle as in :meth:`move`."""
        c = self._contact
        tip0, J0, lam0, x0 = self._tip0
        if self._w is None or self._w[0] is not x0:           # once per sample's frame
            q = joint_angles(np.asarray(x0), self.ex)
            M = mass_matrix(q, self.payload, self.ex)
            self._w = x0, float(np.max(np.linalg.eigvalsh(J0 @ np.linalg.solve(M, J0.T))))
        w = self._w[1]
        vt = J0 @ (lam0 * np.asarray(v))
        slope = c.friction * f_tip[2] / max(float(np.hypot(vt[0], vt[1])), c.v_slip)
        n = max(1, math.ceil(h * w * slope - 1e-9))
        hk = h / n
        for k in range(n):
            if n > 1:
                xa, va = np.asarray(x), np.asarray(v)
                f_tip = self._ground_force(t + (k + 0.5) * hk, tip0 + J0 @ (lam0 * (xa - x0)), J0 @ (lam0 * va))
            x1, v1 = advance_linkage((x, v), p_am, p_bm, f_tip, hk, self._linkage(p_am, p_bm, v), self.payload,
                                     max_substep=hk)
            x, v = x1.tolist(), v1.tolist()
        self._f_tip = f_tip
        return x, v

    def sample(self, t: float, u, p_a, p_b, angle, x, v) -> "ExcavatorSample":
        f = self.tip_force(t, x, v)
        return ExcavatorSample(t, tuple(u), tuple(p_a), tuple(p_b), tuple(angle),
                               (float(f[0]), float(f[1]), float(f[2])), tuple(x), tuple(v))

    def truth(self, t: float, p_a, p_b, x, v) -> dict:
        q = joint_angles(np.asarray(x), self.ex)
        return {"p_a": np.array(p_a), "p_b": np.array(p_b), "x": np.array(x), "v": np.array(v),
                "angle": q, "tip": tip_position(q, self.ex), "f_tip": self.tip_force(t, x, v)}


class MachineRig:
    """A machine as a rig: its joints' valves, chambers and sensors
    (:class:`JointPlant`) and the mechanism that moves their pistons (:class:`BoomLoad`
    or :class:`Linkage`).  :meth:`step` it with the valve commands, read samples; ``t``
    is the current time [s], :attr:`truth` the true state.  Built as the boom's
    :class:`VirtualRig` or the excavator's :class:`ExcavatorRig`."""

    #: the joints' names when a sample holds one value per joint (the excavator's), else None
    JOINTS = None

    def __init__(self, config, joints, mechanism, seed: int):
        self.config, self.joints, self.mechanism, self._seed = config, list(joints), mechanism, seed
        self.substep = mechanism.substep   #: longest internal substep [s]
        self.reset()

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to t = 0 and the initial state; the noise restarts from the seed."""
        for jp in self.joints:
            jp.reset()
        self.mechanism.reset()
        self.t = 0.0
        self._u = [jp.u for jp in self.joints]
        self._rng = np.random.default_rng(self._seed)
        self._normals, self._k_normal = [], 0
        self._h = None
        self._dt = None

    def _normal(self) -> float:
        if self._k_normal >= len(self._normals):
            self._normals = self._rng.standard_normal(3000).tolist()
            self._k_normal = 0
        z = self._normals[self._k_normal]
        self._k_normal += 1
        return z

    def _state(self):
        js = self.joints
        return [j.p_a for j in js], [j.p_b for j in js], [j.x for j in js], [j.v for j in js]

    @property
    def truth(self) -> dict:
        """The true state: the boom's ``p_a``, ``p_b`` absolute [Pa], ``x`` [m], ``v``
        [m/s], ``alpha`` [rad], ``f_ext`` [N]; the excavator's the same per joint
        (4-vectors, ``angle`` for alpha), ``tip`` [m] and ``f_tip`` [N] (world frame)."""
        return self.mechanism.truth(self.t, *self._state())

    # ----------------------------------------------------------------- step
    def step(self, u, dt: float = 1e-3):
        """Apply the commands ``u`` [V] (the boom's one; the excavator's four in
        :data:`JOINTS` order or ``{"u_<joint>": V}``; clipped to 0 .. 10) for ``dt``
        [s]; return the sample measured at the end."""
        u = self.mechanism.commands(u)
        if dt != self._dt:
            dt = float(dt)
            if not (dt > 0.0 and math.isfinite(dt)):
                raise ValueError(f"dt must be a finite number > 0 s, got {dt!r}")
            self._dt = dt
            self._n = max(1, math.ceil(dt / self.substep - 1e-9))
        n = self._n
        h = dt / n
        joints, move = self.joints, self.mechanism.move
        if h != self._h:
            self._h = h
            for jp in joints:
                jp.prepare(h)
        p_a, p_b, x, v = self._state()
        t0 = self.t
        numbered = tuple(enumerate(joints))
        for i in range(n):
            t = t0 + i * h
            flows = [jp.inflows(u[k], p_a[k], p_b[k], x[k]) for k, jp in numbered]
            x1, v = move(i, t, h, p_a, p_b, x, v, flows)
            for k, jp in numbered:
                p_a[k], p_b[k] = jp.chambers(p_a[k], p_b[k], x[k], x1[k], flows[k], h, t)
                if jp.lag:
                    jp.sense(p_a[k], p_b[k], x1[k], t0 + (i + 1) * h)
            x = x1
        for k, jp in enumerate(joints):
            jp.p_a, jp.p_b, jp.x, jp.v, jp.u = p_a[k], p_b[k], x[k], v[k], u[k]
        self.t = t0 + dt
        self._u = u
        return self.measure()

    # -------------------------------------------------------------- sensors
    def measure(self):
        """The sample at the current time (a fresh noise draw): each joint's gauge
        pressures and angle through its sensors (lag, noise, 12-bit ADC)."""
        pa_m, pb_m, ang_m = [], [], []
        for jp in self.joints:
            p_a, p_b, angle = jp.sensed(self.t)
            if jp.offset is not None:
                angle = angle + jp.offset
            n = jp.noise
            if n["p_sigma"] > 0.0:
                p_a += n["p_sigma"] * self._normal()
                p_b += n["p_sigma"] * self._normal()
            if n["alpha_sigma"] > 0.0:
                angle += n["alpha_sigma"] * self._normal()
            if n["quantise"]:
                p_a = quantise(p_a - P_RANGE[0], P_LSB, ADC_BITS) + P_RANGE[0]
                p_b = quantise(p_b - P_RANGE[0], P_LSB, ADC_BITS) + P_RANGE[0]
                lo = jp.angle_range[0]
                angle = quantise(angle - lo, ALPHA_LSB, ADC_BITS) + lo
            pa_m.append(p_a)
            pb_m.append(p_b)
            ang_m.append(angle)
        _, _, x, v = self._state()
        return self.mechanism.sample(self.t, self._u, pa_m, pb_m, ang_m, x, v)


class VirtualRig(MachineRig):
    """The boom as a machine: one :class:`JointPlant` under the boom's load
    (:class:`BoomLoad`); :meth:`step` it with a valve command, read :class:`Sample`.
    See the module docstrings of :mod:`boomfmi.rig.plant` (the physics) and
    :mod:`boomfmi.rig.config` (the effects and the sensors)."""

    def __init__(self, config: RigConfig | None = None):
        cfg = load_config(config)
        joint = JointPlant(cfg)
        super().__init__(cfg, [joint], BoomLoad(joint, cfg), cfg.seed)


class ExcavatorRig(MachineRig):
    """The whole excavator as a machine: four :class:`JointPlant` moved by the
    :class:`Linkage`; :meth:`step` it with four valve commands, read
    :class:`ExcavatorSample`.  See the module docstring (physics, contact, sensors) and
    :func:`boomfmi.rig.config.load_excavator_config` (the configuration)."""

    JOINTS = JOINTS

    def __init__(self, config: ExcavatorConfig | dict | str | None = None):
        cfg = load_excavator_config(config)
        self.ex = ex = machine(cfg)
        self.payload = cfg.payload
        x0 = [cfg.joints[j]["x0"] for j in JOINTS]
        p_a0, p_b0 = vented_holding_pressures(x0, ex, self.payload)
        joints = [JointPlant(RigConfig(params=dict(cfg.joints[j]["params"], p_a0=p_a0[k], p_b0=p_b0[k]),
                                       effects=cfg.joints[j]["effects"], noise=cfg.joints[j]["noise"], x0=x0[k]),
                             j, ANGLE_RANGES[j], a.offset)
                  for k, (j, a) in enumerate(zip(JOINTS, ex.actuators))]
        super().__init__(cfg, joints, Linkage(joints, ex, self.payload, cfg.contact, x0), cfg.seed)

    def tip_force(self, t: float, x, v) -> np.ndarray:
        """The force of the environment on the bucket tip [N] (world frame) at time ``t``
        [s] with the pistons at ``x`` [m] moving at ``v`` [m/s]."""
        return self.mechanism.tip_force(t, x, v)

__all__ = [
    "SUBSTEP", "LINKAGE_SUBSTEP", "U_MAX", "U_MIN", "ADC_BITS", "P_RANGE", "ALPHA_RANGE", "P_LSB",
    "ALPHA_LSB", "ANGLE_RANGES", "Sample", "ExcavatorSample", "commands", "tip_contact", "machine",
    "vented_holding_pressures", "JointPlant", "BoomLoad", "Linkage", "MachineRig", "VirtualRig", "ExcavatorRig",
]
