"""The excavator's virtual rig: four valves, eight chambers and the four-joint linkage.

:class:`ExcavatorRig` stands in for the whole machine of ``shared/spec/excavator.md``:
give it the four valve commands, it returns what the data acquisition would record of
each joint (two gauge pressures and the joint angle) plus the truth a real rig would
not give (each piston's x and v, the force of the ground on the bucket tip).  Its
configuration (:func:`boomfmi.rig.config.load_excavator_config`, JSON files
``examples/rig/excavator_*.json``) switches each effect of the boom's catalogue on per
joint, sets the sensors' noise per joint, adds a payload and a contact at the tip.

Physics
-------
Each joint's valve and chambers are the boom rig's (:class:`boomfmi.rig.plant.VirtualRig`,
one per joint with that joint's actuator: its A_max, bore areas, stroke, dead volumes,
friction and, for the angle, its mounting triangle as Eq. 12's a, b, l_min): the spool
and its overlap, the valve's flows per port (heat transfer, cushioning), the seal's
leak, the chambers' pressure step and the sensors' lag are its parts, with its
effects.  The four pistons move together through the linkage,
:func:`boomfmi.physics.excavator.advance_linkage` (mass matrix, Coriolis, gravity,
Eq. 9 stick/slip per cylinder, end stops, the tip force through J^T), under the
pressures predicted for the middle of each substep (as the boom rig does); the rig's
friction effects (stribeck_friction, pressure_friction) change that cylinder's F_s,
F_d over the substep.  Substeps are at most :data:`SUBSTEP` = 0.25 ms (shorter with a
stiff ground), Gauss-Seidel: the linkage moves, then the chambers follow the volumes.

Start: every piston at its ``x0`` (mid-stroke by default) at rest, valves centred, each
cylinder's chambers at the pressures that hold the machine there against gravity
(the holding force on the cap side if it pushes, on the rod side if it pulls, the
other chamber at P_atm), so that the machine stands still until commanded.

Tip contact (``contact``, the scenarios of :class:`boomfmi.experiments.TipContact`):

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

Sensors, per joint: Gaussian noise (``p_sigma`` [Pa], ``alpha_sigma`` [rad]) then a
12-bit ADC: pressures over 0 .. 10 bar gauge as the boom's, the angle over 0 .. pi
(boom, arm, bucket) or -pi/2 .. pi/2 (swing), LSB pi / 4096.

In Python the rig costs about 2 ms of wall time per millisecond simulated: serve it in
lockstep (``boomfmi rig serve --lockstep``); in real time it falls behind and counts
missed ticks.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..experiments import TipContact
from ..physics.chamber import pressure_rates
from ..physics.excavator import (JOINTS, Excavator, advance_linkage, joint_angles, lever_arms,
                                 mass_matrix, piston_dynamics, tip_jacobian, tip_position)
from .config import ExcavatorConfig, RigConfig, load_excavator_config
from .plant import ADC_BITS, P_LSB, P_RANGE, U_MAX, U_MIN, VirtualRig
from .truth import quantise, seal_friction_load, stribeck_load

#: Longest internal substep [s] (advance_linkage's default).
SUBSTEP = 2.5e-4
#: Each joint's angle range over the ADC [rad].
ANGLE_RANGES = {"swing": (-0.5 * math.pi, 0.5 * math.pi), "boom": (0.0, math.pi),
                "arm": (0.0, math.pi), "bucket": (0.0, math.pi)}
ANGLE_LSB = math.pi / 2**ADC_BITS
#: Columns of :func:`run_excavator_offline` (the excavator recording's, then the truth).
COLUMNS = (("t",) + tuple(f"{q}_{j}" for q in ("u", "p_a", "p_b", "angle") for j in JOINTS)
           + ("f_tip_x", "f_tip_y", "f_tip_z") + tuple(f"{q}_{j}" for q in ("x", "v") for j in JOINTS))
_QUIET = {"p_sigma": 0.0, "alpha_sigma": 0.0, "quantise": False}


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
    """The linkage the rig moves: ``physics.excavator``'s with the configuration's
    per-joint overrides (A_max, dead volumes, friction) and P_atm."""
    ex = Excavator()
    changes = {j: replace(getattr(ex, j), **config.joints[j]["overrides"])
               for j in JOINTS if config.joints[j]["overrides"]}
    if "P_atm" in config.params:
        changes["P_atm"] = config.params["P_atm"]
    return replace(ex, **changes) if changes else ex


def holding_pressures(x, ex: Excavator, payload: float = 0.0, P_atm: float | None = None):
    """Absolute chamber pressures [Pa] ``(p_a, p_b)`` (4-vectors) that hold the pistons
    at ``x`` [m] at rest against gravity: the holding force on the cap side if it
    pushes, on the rod side if it pulls, the other chamber at P_atm."""
    P_atm = ex.P_atm if P_atm is None else P_atm
    _, bias, _ = piston_dynamics(np.asarray(x, float), np.zeros(4), payload, ex)
    p_a = [P_atm + max(F, 0.0) / a.A_a for F, a in zip(bias, ex.actuators)]
    p_b = [P_atm + max(-F, 0.0) / a.A_b for F, a in zip(bias, ex.actuators)]
    return p_a, p_b


class ExcavatorRig:
    """The whole excavator as a machine: :meth:`step` it with four valve commands, read
    :class:`ExcavatorSample`; ``t`` is the current time [s], :attr:`truth` the true
    state.  See the module docstring (physics, contact, sensors) and
    :func:`boomfmi.rig.config.load_excavator_config` (the configuration)."""

    JOINTS = JOINTS

    def __init__(self, config: ExcavatorConfig | dict | str | None = None):
        self.config = cfg = load_excavator_config(config)
        self.ex = ex = machine(cfg)
        self.payload = cfg.payload
        self._P_atm = ex.P_atm
        x0 = [cfg.joints[j]["x0"] for j in JOINTS]
        p_a0, p_b0 = holding_pressures(x0, ex, self.payload)
        #: each joint's valve, chambers and sensors: the boom rig's parts
        self.joint_rigs = [
            VirtualRig(RigConfig(params=dict(cfg.joints[j]["params"], p_a0=p_a0[k], p_b0=p_b0[k]),
                                 effects=cfg.joints[j]["effects"], noise=dict(_QUIET), x0=x0[k]))
            for k, j in enumerate(JOINTS)]
        self._offsets = [a.offset for a in ex.actuators]
        self._friction = [(jr._stribeck, jr._seal_friction) for jr in self.joint_rigs]
        self._rubbing = any(s or q for s, q in self._friction)
        self._contact = tip_contact(cfg.contact)
        self._ground = self._contact is not None and self._contact.kind == "ground"
        h = SUBSTEP
        if self._ground:
            # the tip's lightest direction against the ground's stiffness and damping
            q = joint_angles(np.asarray(x0), ex)
            J = tip_jacobian(q, ex)
            w = float(np.max(np.linalg.eigvalsh(J @ np.linalg.solve(mass_matrix(q, self.payload, ex), J.T))))
            c = self._contact
            h = min(h, 0.2 / math.sqrt(c.stiffness * w))
            if c.damping > 0.0:
                h = min(h, 0.5 / (c.damping * w))
        self.substep = h        #: longest internal substep [s]
        self._noise = [cfg.joints[j]["noise"] for j in JOINTS]
        self.reset()

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to t = 0 and the initial state; the noise restarts from the seed."""
        for jr in self.joint_rigs:
            jr.reset()
        self.t = 0.0
        self._u = [jr._u for jr in self.joint_rigs]
        self._rng = np.random.default_rng(self.config.seed)
        self._h = None
        self._dt = None
        self._frame = None          # (x, the tip's frame there): see _tip_frame

    def _state(self):
        rigs = self.joint_rigs
        return ([r._p_a for r in rigs], [r._p_b for r in rigs], [r._x for r in rigs], [r._v for r in rigs])

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

    @property
    def truth(self) -> dict:
        """The true state: ``p_a``, ``p_b`` absolute [Pa], ``x`` [m], ``v`` [m/s],
        ``angle`` [rad] (4-vectors), ``tip`` [m] and ``f_tip`` [N] (world frame)."""
        p_a, p_b, x, v = self._state()
        q = joint_angles(np.asarray(x), self.ex)
        return {"p_a": np.array(p_a), "p_b": np.array(p_b), "x": np.array(x), "v": np.array(v),
                "angle": q, "tip": tip_position(q, self.ex), "f_tip": self.tip_force(self.t, x, v)}

    # ----------------------------------------------------------------- step
    def _linkage(self, p_am, p_bm, v):
        """The linkage with the rig's friction effects applied over this substep."""
        if not self._rubbing:
            return self.ex
        changes = {}
        for k, (j, (s, q)) in enumerate(zip(JOINTS, self._friction)):
            if not (s or q):
                continue
            a = getattr(self.ex, j)
            ld = self.joint_rigs[k]._load._replace(K_v=a.K_v, F_s=a.F_s, F_d=a.F_d)
            if s:
                ld = stribeck_load(ld, abs(v[k]), s["F_brk"], s["v_s"])
            if q:
                ld = seal_friction_load(ld, p_am[k], p_bm[k], self._P_atm, q["k_piston"], q["k_rod"])
            changes[j] = replace(a, F_s=ld.F_s, F_d=ld.F_d)
        return replace(self.ex, **changes)

    def step(self, u, dt: float = 1e-3) -> ExcavatorSample:
        """Apply the commands ``u`` [V] (4 in :data:`JOINTS` order, or ``{"u_<joint>": V}``;
        clipped to 0 .. 10) for ``dt`` [s]; return the sample measured at the end."""
        u = commands(u)
        if dt != self._dt:
            dt = float(dt)
            if not (dt > 0.0 and math.isfinite(dt)):
                raise ValueError(f"dt must be a finite number > 0 s, got {dt!r}")
            self._dt = dt
            self._n = max(1, math.ceil(dt / self.substep - 1e-9))
        n = self._n
        h = dt / n
        rigs = self.joint_rigs
        if h != self._h:
            self._h = h
            for jr in rigs:
                jr._prepare(h)
        p_a, p_b, x, v = self._state()
        t0, half = self.t, 0.5 * h
        ex, payload, contact = self.ex, self.payload, self._contact
        f_tip = (0.0, 0.0, 0.0)
        for i in range(n):
            t = t0 + i * h
            flows, p_am, p_bm = [], [], []
            for k, jr in enumerate(rigs):
                uv = jr._spool_command(u[k]) if jr._shaped else u[k]
                fl = jr._valve_flows(uv, p_a[k], p_b[k], x[k])
                if jr._leakage:
                    fl = jr._leak(p_a[k], p_b[k], fl)
                flows.append(fl)
                dpa, dpb = pressure_rates(p_a[k], p_b[k], fl[0], fl[1], x[k], v[k], jr._cyl, jr._gas)
                p_am.append(max(p_a[k] + half * dpa, 0.5 * p_a[k]))
                p_bm.append(max(p_b[k] + half * dpb, 0.5 * p_b[k]))
            if contact is not None:
                if not self._ground:
                    f_tip = contact.force(t + half, (0.0, 0.0, 0.0))
                elif i == 0:
                    tip0, J0, lam0, x0 = self._tip_frame(x)
                    f_tip = self._ground_force(t + half, tip0, J0 @ (lam0 * np.asarray(v)))
                else:
                    xa, va = np.asarray(x), np.asarray(v)
                    f_tip = self._ground_force(t + half, tip0 + J0 @ (lam0 * (xa - x0)), J0 @ (lam0 * va))
            x1, v1 = advance_linkage((x, v), p_am, p_bm, f_tip, h, self._linkage(p_am, p_bm, v), payload,
                                     max_substep=h)
            x1, v1 = x1.tolist(), v1.tolist()
            for k, jr in enumerate(rigs):
                p_a[k], p_b[k] = jr._chambers(p_a[k], p_b[k], x[k], x1[k], flows[k], h, t)
                if jr._lag:
                    jr._sense(p_a[k], p_b[k], x1[k], t0 + (i + 1) * h)
            x, v = x1, v1
        self.t = t0 + dt
        for k, jr in enumerate(rigs):
            jr._p_a, jr._p_b, jr._x, jr._v, jr.t, jr._u = p_a[k], p_b[k], x[k], v[k], self.t, u[k]
        self._u = u
        return self.measure()

    # -------------------------------------------------------------- sensors
    def measure(self) -> ExcavatorSample:
        """The sample at the current time (a fresh noise draw)."""
        rng = self._rng
        pa_m, pb_m, ang_m = [], [], []
        for k, (j, jr) in enumerate(zip(JOINTS, self.joint_rigs)):
            p_a, p_b, gamma = jr._sensed()
            angle = gamma + self._offsets[k]
            n = self._noise[k]
            if n["p_sigma"] > 0.0:
                p_a += n["p_sigma"] * rng.standard_normal()
                p_b += n["p_sigma"] * rng.standard_normal()
            if n["alpha_sigma"] > 0.0:
                angle += n["alpha_sigma"] * rng.standard_normal()
            if n["quantise"]:
                p_a = quantise(p_a - P_RANGE[0], P_LSB, ADC_BITS) + P_RANGE[0]
                p_b = quantise(p_b - P_RANGE[0], P_LSB, ADC_BITS) + P_RANGE[0]
                lo = ANGLE_RANGES[j][0]
                angle = quantise(angle - lo, ANGLE_LSB, ADC_BITS) + lo
            pa_m.append(p_a)
            pb_m.append(p_b)
            ang_m.append(angle)
        _, _, x, v = self._state()
        f = self.tip_force(self.t, x, v)
        return ExcavatorSample(self.t, tuple(self._u), tuple(pa_m), tuple(pb_m), tuple(ang_m),
                               (float(f[0]), float(f[1]), float(f[2])), tuple(x), tuple(v))


def sample_row(s: ExcavatorSample, u) -> list:
    """One row of :data:`COLUMNS` from the sample ``s`` and the commands ``u`` applied
    from its time on."""
    return [s.t, *u, *s.p_a, *s.p_b, *s.angle, *s.f_tip, *s.x, *s.v]


def run_excavator_offline(config, command, duration: float, dt: float = 1e-3) -> pd.DataFrame:
    """Step an excavator rig (``config``: see :func:`load_excavator_config`) under
    ``command(t) -> {"u_<joint>": V}`` (e.g. ``experiments.digging_cycle()``) for
    ``duration`` seconds; one row per sample, t0 included, in :data:`COLUMNS`: the
    excavator recording's columns (the sample measured at t and the commands applied
    from t on) plus the true tip force, x and v per joint.

    A closed-loop profile (``command.closed_loop`` true, e.g.
    :class:`boomfmi.experiments.JointTrajectoryController`) is called as
    ``command(t, angles)`` with the joint angles measured at ``t`` (noise and ADC
    included): a controller that is part of the experiment, as an operator is."""
    plant = ExcavatorRig(config)
    n = int(round(duration / dt))
    rows = np.empty((n + 1, len(COLUMNS)))
    s = plant.measure()
    closed = bool(getattr(command, "closed_loop", False))
    if closed and hasattr(command, "reset"):
        command.reset()
    for k in range(n + 1):
        u = commands(command(k * dt, s.angle) if closed else command(k * dt))
        rows[k] = sample_row(s, u)
        if k < n:
            s = plant.step(u, dt)
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    df["t"] = np.round(df["t"].to_numpy(), 9)
    return df
