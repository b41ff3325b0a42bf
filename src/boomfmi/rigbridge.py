"""The rig bridge's FMI plumbing, once for any machine: replay a recording or talk to a
rig over the authenticated UDP link, with the sensors' lag.

A bridge FMU (``fmus/hardware_bridge``: the boom, one joint; ``fmus/excavator_bridge``:
the four joints) is a :class:`RigBridge` that declares its own channels and says how a
sample becomes its outputs; everything else lives here:

* **modes** (parameter ``mode``): ``replay`` plays the recording ``recording``.  At each
  communication point t the outputs are the recording's values at t: linear
  interpolation between samples for the measured channels (so a sample time gives that
  sample exactly), and the last sample at or before t for the applied commands (a
  command is held until the next).  Outside the recording the nearest end is held and
  ``link_ok`` is false.  ``udp`` talks to the rig at ``rig`` (udp://HOST:PORT) with
  authenticated datagrams (``link/protocol.py``; key from ``key_file``, else
  $BOOMFMI_LINK_KEY).  Each step sends the commands, retrying up to ``retries`` times
  within ``timeout``.  A rig in lockstep advances one sample per step and answers with
  the sample at t + dt.  With a real-time rig the bridge paces itself to the wall clock:
  one exchange per step, as a DAQ tick, sends the command at the slot's start and
  outputs the rig's latest sample (measured at the rig's last tick, so up to one step
  old), then waits for the slot's end.  A lost answer holds the last sample and clears
  ``link_ok``; more than ``loss_budget`` consecutive losses is an fmi2Error.
* **the sensors** (sensor_lag, ``physics/effects.py``, ``physics/lag.py``; off by
  default): ``delay_sensor`` > 0 delays every measured channel by a dead time, then
  ``tau_sensor`` > 0 passes it through a first-order lag.

This module is bundled into the bridge FMUs (their ``bundle.txt``); it uses relative
imports only.
"""
from __future__ import annotations

import bisect
import math
import time

from .fmislave import GEOMETRY, U_MAX, U_MIN, BoomSlave, effect_options, input, output, parameter, rig_parameters
from .physics import Geometry, check_geometry, reference_rig, x_from_alpha
from .physics.linkage import JOINTS, Excavator, pistons_from_angles
from .physics.params import L_MAX
from .link.client import RigClient, parse_address, wait_until
from .link.protocol import LinkError, load_key
from .physics.effects import sensor_lag_step
from .physics.lag import DelayLine
from .physics.validation import ParameterError
from .recording import RecordingError, parse_recording, recording_kind


def link_variables(machine: str):
    """The outputs and parameters of the link every bridge has (``machine``: "rig",
    "excavator's rig" in their descriptions)."""
    return (
        output("t_rig", 0.0, "s", "the rig's time of the current sample"),
        output("link_ok", True, "1", "the current sample is fresh (false: held after a lost answer, or outside the "
               "recording)", type="Boolean"),
        output("failsafe", False, "1", f"the {machine} reports its fail-safe state (valves centred by its watchdog)",
               type="Boolean"),
        output("lost_packets", 0, "1", "answers lost so far (after retries)", type="Integer"),
        output("deadline_misses", 0, "1", "steps begun more than a step late against the wall clock (real-time rig "
               "only)", type="Integer"),
        output("lateness", 0.0, "s", "real-time rig: how late the last step began against the wall clock; else 0"),
        parameter("mode", "replay", "1", "replay: play the recording; udp: talk to the rig", type="String"),
        parameter("recording", "", "1", f"replay mode: path of the {machine}'s recording (CSV, recording format)",
                  type="String"),
        parameter("rig", "udp://127.0.0.1:47800", "1", "udp mode: the rig's address, udp://HOST:PORT", type="String"),
        parameter("key_file", "", "1", "udp mode: file holding the shared link key; empty: $BOOMFMI_LINK_KEY",
                  type="String"),
        parameter("timeout", 0.05, "s", "udp mode: longest wait for an answer in one step (retries included)", min=0.0),
        parameter("retries", 2, "1", "udp mode: resends of a command within the timeout", type="Integer", min=0),
        parameter("loss_budget", 20, "1", "udp mode: consecutive lost answers tolerated before fmi2Error",
                  type="Integer", min=0),
    )


def sensor_options():
    """The sensor_lag options every bridge has (the catalogue's, ``hardware_bridge``'s)."""
    return effect_options("hardware_bridge")


#: Each machine's bridge: its FMU, its joints, the true force it passes on.
MACHINES = {"boom": {"model": "hardware_bridge", "joints": ("boom",), "extra": ("f_ext",)},
            "excavator": {"model": "excavator_bridge", "joints": JOINTS, "extra": ("f_tip_x", "f_tip_y", "f_tip_z")}}
_TIP_AXES = {"f_tip_x": "world x (ahead at swing 0)", "f_tip_y": "world y", "f_tip_z": "world z (up)"}
_ANGLES = {"swing": "swing angle theta_swing (0 straight ahead, + counter-clockwise from above)",
           "boom": "boom angle alpha (Eq. 12)", "arm": "arm angle theta_arm, relative to the boom",
           "bucket": "bucket angle theta_bucket, relative to the arm"}
_EX = Excavator()
#: each excavator joint's angle limits: noise and quantisation may step an angle past its ends
_LIMITS = [(a.lower_limit, a.upper) for a in _EX.actuators]


def channel(machine: str, quantity: str, joint: str) -> str:
    """The name of a joint's channel on a machine's bridge: the boom's alone (``p_a``,
    ``alpha`` for the angle), an excavator's per joint (``p_a_arm``, ``angle_arm``)."""
    if machine == "boom":
        return "alpha" if quantity == "angle" else quantity
    return f"{quantity}_{joint}"


def channels(machine: str):
    """``(MEASURED, EXTRA, COMMANDS)`` of a machine's bridge (see :class:`RigBridge`)."""
    joints = MACHINES[machine]["joints"]
    return (tuple(channel(machine, q, j) for q in ("p_a", "p_b", "angle") for j in joints),
            MACHINES[machine]["extra"], tuple(channel(machine, "u", j) for j in joints))


def bridge_variables(machine: str):
    """The variables of a machine's bridge FMU (``"boom"``: ``hardware_bridge``,
    ``"excavator"``: ``excavator_bridge``): the commands, each joint's measured
    pressures and angle, x from the angle and the applied command, the true force, the
    link's variables, the boom's geometry parameters, the sensor options."""
    joints = MACHINES[machine]["joints"]
    boom = machine == "boom"
    name = lambda q, j: channel(machine, q, j)
    of = (lambda j: "") if boom else (lambda j: f"{j} ")
    cyl = (lambda j: "") if boom else (lambda j: f"{j} cylinder ")
    commands = tuple(input(name("u", j), reference_rig.u_centre, "V", f"{of(j)}valve command to send to the rig",
                           min=U_MIN, max=U_MAX) for j in joints)
    outputs = []
    for j in joints:
        outputs += [output(name("p_a", j), 0.0, "Pa", f"measured {cyl(j)}chamber A pressure, gauge (as recorded)"),
                    output(name("p_b", j), 0.0, "Pa", f"measured {cyl(j)}chamber B pressure, gauge (as recorded)")]
        if boom:
            outputs += [output("alpha", 0.0, "rad", "measured boom angle"),
                        output("x", 0.0, "m", "piston position from the measured alpha by Eq. 12")]
        else:
            outputs += [output(name("angle", j), 0.0, "rad", f"measured {_ANGLES[j]}", min=-math.pi, max=math.pi),
                        output(name("x", j), 0.0, "m", f"{j} piston position from the measured angle "
                               "(excavator.md's joint map)", min=0.0, max=L_MAX)]
        outputs.append(output(name("u_applied", j), reference_rig.u_centre, "V",
                              f"command {'the ' + j + ' valve' if not boom else 'the valve'} got over the last step "
                              "(5 V while the rig is in fail-safe)", min=U_MIN, max=U_MAX))
    if boom:
        extra = (output("f_ext", 0.0, "N", "true external force on the piston where the rig knows it (virtual rig, "
                        "load cell), else 0"),)
    else:
        extra = tuple(output(f, 0.0, "N", f"true force of the environment on the bucket tip, {_TIP_AXES[f]}, where the "
                             "rig knows it (virtual rig, load cell), else 0") for f in MACHINES[machine]["extra"])
    return (*commands, *outputs, *extra, *link_variables("rig" if boom else "excavator's rig"),
            *(rig_parameters(*GEOMETRY) if boom else ()), *sensor_options())


class RigBridge(BoomSlave):
    """A bridge FMU's behaviour (see the module's docstring).  A bridge's script sets
    ``MACHINE`` (a key of :data:`MACHINES`: ``"boom"``, ``"excavator"``), its
    ``description`` and ``variables = bridge_variables(MACHINE)``; from the machine come

    * ``KIND``: the recording kind it replays (``recording.recording_kind``);
    * ``MEASURED``: the recording's measured columns, in the order :meth:`measured`
      takes them (each passes the sensor lag): every joint's p_a, then p_b, then angle;
    * ``EXTRA``: further interpolated columns that are outputs as they are (the true
      force: the boom's ``f_ext``, the excavator's ``f_tip_x/y/z``), 0 where the
      recording has none;
    * ``COMMANDS``: its command inputs, with the recording's applied-command column
      ``u_applied<suffix>`` for each ``u<suffix>``."""

    MACHINE = "boom"
    KIND = "boom"
    MEASURED: tuple = ()
    EXTRA: tuple = ()
    COMMANDS: tuple = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.KIND = cls.MACHINE
        cls.MEASURED, cls.EXTRA, cls.COMMANDS = channels(cls.MACHINE)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = MACHINES[self.MACHINE]["model"]
        self._geom = Geometry()
        self._client = None
        self._losses = 0
        self._t_meas = None
        self._delay = None
        self._lagged = None

    # -- the machine's channels ------------------------------------------------------------
    def measured(self, values: tuple) -> None:
        """Set the outputs from the measured channels' values (after the sensor lag), and
        each piston's x from its angle: the boom's by Eq. 12 with the bridge's geometry,
        the excavator's by its joint maps (the angles clipped to their limits and x to
        the stroke: noise and quantisation may step past their ends)."""
        for name, value in zip(self.MEASURED, values):
            setattr(self, name, value)
        if self.MACHINE == "boom":
            self.x = x_from_alpha(self.alpha, self._geom)
            return
        n = len(JOINTS)
        angle = values[2 * n:3 * n]
        x = pistons_from_angles([min(max(a, lo), hi) for a, (lo, hi) in zip(angle, _LIMITS)], _EX)
        for k, j in enumerate(JOINTS):
            setattr(self, f"x_{j}", float(min(max(x[k], 0.0), _EX.actuators[k].stroke)))

    def sample_values(self, s):
        """A link sample as ``(measured, extra, applied)`` tuples in the declared orders."""
        if self.MACHINE == "boom":
            return (s.p_a, s.p_b, s.alpha), (s.f_ext,), (s.u_applied,)
        return (*s.p_a, *s.p_b, *s.angle), tuple(s.f_tip), tuple(s.u_applied)

    def check_sample(self, s) -> None:
        """Raise :class:`ParameterError` where the rig's answer is not this machine's."""
        if self.MACHINE == "excavator" and not hasattr(s, "angle"):
            raise ParameterError("rig", self.rig, "answers as the boom's rig; the excavator bridge needs an "
                                                   "excavator rig (boomfmi rig serve --config examples/rig/excavator_*.json)")

    def check_parameters(self) -> None:
        """The machine's own parameters' checks (the boom's geometry), before the link is
        set up."""
        if self.MACHINE == "boom":
            self._geom = Geometry(a=self.a, b=self.b, h=self.h, l_min=self.l_min)
            check_geometry(self._geom, self.L)

    # -- set-up ----------------------------------------------------------------------------
    def setup(self):
        self._delay = DelayLine(self.delay_sensor) if self.delay_sensor > 0.0 else None
        self.check_parameters()
        if self.mode == "replay":
            self._setup_replay()
        elif self.mode == "udp":
            self._setup_udp()
        else:
            raise ParameterError("mode", self.mode, "must be 'replay' or 'udp'")

    def _setup_replay(self):
        if not self.recording:
            raise ParameterError("recording", self.recording, "replay mode needs a recording file")
        try:
            kind = recording_kind(self.recording)
            if kind != self.KIND:
                a = lambda k: f"{'an' if k[0] in 'aeiou' else 'a'} {k}'s"
                raise ParameterError("recording", self.recording,
                                     f"is {a(kind)} recording; {self.modelName} replays {a(self.KIND)}")
            header, values, _, _ = parse_recording(self.recording)
        except RecordingError as e:
            raise ParameterError("recording", self.recording, str(e)) from None
        self._t = [float(v) for v in values["t"]]
        n = len(self._t)
        self._cols = {c: [float(v) for v in values[c]] for c in (*self.COMMANDS, *self.MEASURED)}
        for c in self.EXTRA:
            self._cols[c] = [float(v) for v in values[c]] if c in values else [0.0] * n
        self._show_replay(self._t[0])

    def _setup_udp(self):
        for name in ("retries", "loss_budget"):
            if getattr(self, name) < 0:
                raise ParameterError(name, getattr(self, name), "must be >= 0")
        if not self.timeout > 0:
            raise ParameterError("timeout", self.timeout, "must be > 0 s")
        try:
            host, port = parse_address(self.rig)
        except LinkError as e:
            raise ParameterError("rig", self.rig, str(e)) from None
        try:
            key = load_key(self.key_file or None)
        except LinkError as e:
            raise ParameterError("key_file", self.key_file, str(e)) from None
        try:
            self._client = RigClient(host, port, key, self.timeout)
        except LinkError as e:
            raise ParameterError("rig", self.rig, str(e)) from None
        sample = self._exchange(None, self.start_time, 0.0)
        if sample is None:
            raise ParameterError("rig", self.rig, f"no authenticated answer from the rig within "
                                                   f"{self.timeout:g} s (is it running, with the same key?)")
        self.check_sample(sample)
        self._realtime = not sample.lockstep
        self._rig_t0 = sample.t - self.start_time      # the rig's clock against ours (lockstep)
        self._wall0 = None
        self._show(sample)

    # -- the outputs -----------------------------------------------------------------------
    def _sensed(self, values: tuple, t: float) -> None:
        """The measured channels through the sensor lag (dead time, then the first-order
        lag) when it is on, then to the outputs."""
        if self._delay is not None:
            self._delay.push(t, tuple(values))
            values = self._delay.read(t)
        tau = self.tau_sensor
        if tau > 0.0 and self._t_meas is not None and t > self._t_meas:
            dt = t - self._t_meas
            values = tuple(sensor_lag_step(y0, y, dt, tau) for y0, y in zip(self._lagged, values))
        self._lagged, self._t_meas = tuple(values), t
        self.measured(self._lagged)

    def _show_replay(self, t):
        ts = self._t
        i = bisect.bisect_right(ts, t + 1e-9) - 1
        inside = ts[0] - 1e-9 <= t <= ts[-1] + 1e-9
        if i < 0:
            i, w = 0, 0.0
        elif i >= len(ts) - 1 or abs(t - ts[i]) <= 1e-9:
            i, w = min(i, len(ts) - 1), 0.0
        else:
            w = (t - ts[i]) / (ts[i + 1] - ts[i])
        cols = self._cols

        def at(c):
            return cols[c][i] if w == 0.0 else cols[c][i] + w * (cols[c][i + 1] - cols[c][i])
        self._sensed(tuple(at(c) for c in self.MEASURED), t)
        for c in self.EXTRA:
            setattr(self, c, at(c))
        for c in self.COMMANDS:
            setattr(self, "u_applied" + c[1:], cols[c][i])
        self.t_rig = t
        if not inside and self.link_ok:
            self.log(f"replay: t = {t:g} s lies outside the recording ({ts[0]:g} to {ts[-1]:g} s); holding its end")
        self.link_ok = inside

    def _show(self, s):
        measured, extra, applied = self.sample_values(s)
        self._sensed(measured, s.t)
        for c, value in zip(self.EXTRA, extra):
            setattr(self, c, value)
        for c, value in zip(self.COMMANDS, applied):
            setattr(self, "u_applied" + c[1:], value)
        self.t_rig, self.failsafe = s.t, s.failsafe
        self.link_ok = True

    # -- the link --------------------------------------------------------------------------
    def _exchange(self, u, t, dt):
        attempts = self.retries + 1
        client = self._client
        client.timeout = self.timeout / attempts
        for _ in range(attempts):
            sample = client.exchange(u, t, dt) if u is not None else client.exchange(None, t)
            if sample is not None:
                return sample
        return None

    def _command(self):
        """The command to send: one number for a single valve, a tuple for several."""
        u = tuple(float(getattr(self, c)) for c in self.COMMANDS)
        return u[0] if len(u) == 1 else u

    def step(self, t, dt):
        if self.mode == "replay":
            self._show_replay(t + dt)
            return
        u = self._command()
        if self._realtime:
            now = time.perf_counter()
            if self._wall0 is None:
                self._wall0 = now - t
            self.lateness = now - (self._wall0 + t)
            if self.lateness > dt:
                self.deadline_misses += 1
            # one exchange, inside the slot: the command for [t, t + dt) out, the rig's
            # latest sample back (a DAQ tick: write the output, read the inputs), then
            # hold until the slot ends so the step returns on the wall clock's beat
            sample = self._exchange(u, t, dt)
            wait_until(self._wall0 + t + dt)
        else:
            sample = self._exchange(u, t, dt)              # lockstep: one command, one sample
            if sample is not None and abs(sample.t - (self._rig_t0 + t + dt)) > 0.5 * dt:
                raise ValueError(
                    f"the lockstep rig is at t = {sample.t:.6g} s where this bridge expects "
                    f"{self._rig_t0 + t + dt:.6g} s: another client is driving it")
        if sample is None:
            self.lost_packets += 1
            self._losses += 1
            self.link_ok = False
            if self._losses > self.loss_budget:
                raise ValueError(f"link to {self.rig} lost: {self._losses} answers in a row missing "
                                 f"(loss budget {self.loss_budget}); the rig is gone or the key differs")
            return
        self._losses = 0
        self._show(sample)

    def teardown(self):
        if self._client is not None:
            self._client.close()
            self._client = None


__all__ = ["link_variables", "sensor_options", "MACHINES", "channel", "channels", "bridge_variables", "RigBridge"]
