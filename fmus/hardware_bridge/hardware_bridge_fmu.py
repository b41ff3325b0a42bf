"""hardware_bridge: the rig (or a virtual rig, or a recording) as an FMI 2.0 co-simulation FMU.

Input the valve command u [V]; outputs what the rig measures, as recorded (gauge
pressures p_a, p_b, the boom angle alpha), x from alpha by Eq. 12, the command the
valve actually got (u_applied), the true external force where the rig knows it, and
the link's state.

Modes (parameter ``mode``):

* ``replay``: plays the recording ``recording`` (recording format).  At each
  communication point t the outputs are the recording's values at t: linear
  interpolation between samples for p_a, p_b, alpha and f_ext (so a sample time gives
  that sample exactly), and the last sample at or before t for u_applied (a command is
  held until the next).  Outside the recording the nearest end is held and link_ok is
  false.
* ``udp``: talks to the rig at ``rig`` (udp://HOST:PORT) with authenticated datagrams
  (``link/protocol.py``; key from ``key_file``, else $BOOMFMI_LINK_KEY).  Each step
  sends the command, retrying up to ``retries`` times within ``timeout``.  A rig in
  lockstep advances one sample per step and answers with the sample at t + dt.  With a
  real-time rig the bridge paces itself to the wall clock: one exchange per step, as a
  DAQ tick, sends the command at the slot's start and outputs the rig's latest sample
  (measured at the rig's last tick, so up to one step old), then waits for the slot's
  end; the round trip falls inside the slot, not after it.  A lost answer holds the
  last sample and clears link_ok; more than ``loss_budget`` consecutive losses is an
  fmi2Error.

Unmodelled effect, off by default: ``tau_sensor`` > 0 passes p_a, p_b and alpha (and
so x) through a first-order lag, the sensors and their conditioning, and
``delay_sensor`` > 0 delays them by a dead time before it (sensor_lag,
``physics/effects.py``, ``physics/lag.py``).
"""
import bisect
import time

from boomfmi_hardware_bridge_lib.fmislave import (GEOMETRY, U_MAX, U_MIN, BoomSlave, effect_options, input, output,
                                                 parameter, rig_parameters)
from boomfmi_hardware_bridge_lib.link.client import RigClient, parse_address, wait_until
from boomfmi_hardware_bridge_lib.link.protocol import LinkError, load_key
from boomfmi_hardware_bridge_lib.physics import Geometry, ParameterError, check_geometry, x_from_alpha
from boomfmi_hardware_bridge_lib.physics import reference_rig
from boomfmi_hardware_bridge_lib.physics.effects import sensor_lag_step
from boomfmi_hardware_bridge_lib.physics.lag import DelayLine
from boomfmi_hardware_bridge_lib.recording import RecordingError, parse_recording

MEASURED = ("p_a", "p_b", "alpha", "f_ext")


class HardwareBridge(BoomSlave):
    description = "The rig through its DAQ: commands out, measurements in (replay a recording or talk UDP to a rig)"
    variables = (
        input("u", reference_rig.u_centre, "V", "valve command to send to the rig", min=U_MIN, max=U_MAX),
        output("p_a", 0.0, "Pa", "measured chamber A pressure, gauge (as recorded)"),
        output("p_b", 0.0, "Pa", "measured chamber B pressure, gauge (as recorded)"),
        output("alpha", 0.0, "rad", "measured boom angle"),
        output("x", 0.0, "m", "piston position from the measured alpha by Eq. 12"),
        output("u_applied", reference_rig.u_centre, "V", "command the valve got over the last step (5 V while the rig is in fail-safe)",
               min=U_MIN, max=U_MAX),
        output("f_ext", 0.0, "N", "true external force on the piston where the rig knows it (virtual rig, load cell), else 0"),
        output("t_rig", 0.0, "s", "the rig's time of the current sample"),
        output("link_ok", True, "1", "the current sample is fresh (false: held after a lost answer, or outside the recording)", type="Boolean"),
        output("failsafe", False, "1", "the rig reports its fail-safe state (valve centred by its watchdog)", type="Boolean"),
        output("lost_packets", 0, "1", "answers lost so far (after retries)", type="Integer"),
        output("deadline_misses", 0, "1", "steps begun more than a step late against the wall clock (real-time rig only)", type="Integer"),
        output("lateness", 0.0, "s", "real-time rig: how late the last step began against the wall clock; else 0"),
        parameter("mode", "replay", "1", "replay: play the recording; udp: talk to the rig", type="String"),
        parameter("recording", "", "1", "replay mode: path of the recording (CSV, recording format)", type="String"),
        parameter("rig", "udp://127.0.0.1:47800", "1", "udp mode: the rig's address, udp://HOST:PORT", type="String"),
        parameter("key_file", "", "1", "udp mode: file holding the shared link key; empty: $BOOMFMI_LINK_KEY", type="String"),
        parameter("timeout", 0.05, "s", "udp mode: longest wait for an answer in one step (retries included)", min=0.0),
        parameter("retries", 2, "1", "udp mode: resends of a command within the timeout", type="Integer", min=0),
        parameter("loss_budget", 20, "1", "udp mode: consecutive lost answers tolerated before fmi2Error", type="Integer", min=0),
        *rig_parameters(*GEOMETRY),
        *effect_options("hardware_bridge"),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "hardware_bridge"
        self._client = None
        self._geom = Geometry()
        self._losses = 0
        self._t_meas = None
        self._delay = None

    # -- set-up ----------------------------------------------------------------------------
    def setup(self):
        self._delay = DelayLine(self.delay_sensor) if self.delay_sensor > 0.0 else None
        self._geom = Geometry(a=self.a, b=self.b, h=self.h, l_min=self.l_min)
        check_geometry(self._geom, self.L)
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
            header, values, _, _ = parse_recording(self.recording)
        except RecordingError as e:
            raise ParameterError("recording", self.recording, str(e)) from None
        self._t = [float(v) for v in values["t"]]
        self._cols = {c: [float(v) for v in values[c]] for c in ("u", "p_a", "p_b", "alpha")}
        self._cols["f_ext"] = [float(v) for v in values["f_ext"]] if "f_ext" in values else [0.0] * len(self._t)
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
        self._realtime = not sample.lockstep
        self._rig_t0 = sample.t - self.start_time      # the rig's clock against ours (lockstep)
        self._wall0 = None
        self._show(sample)

    # -- replay ----------------------------------------------------------------------------
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
        values = {c: (self._cols[c][i] if w == 0.0 else self._cols[c][i] + w * (self._cols[c][i + 1] - self._cols[c][i]))
                  for c in MEASURED}
        self._measured(values["p_a"], values["p_b"], values["alpha"], t)
        self.f_ext = values["f_ext"]
        self.u_applied = self._cols["u"][i]
        self.t_rig = t
        if not inside and self.link_ok:
            self.log(f"replay: t = {t:g} s lies outside the recording ({ts[0]:g} to {ts[-1]:g} s); holding its end")
        self.link_ok = inside

    # -- udp -------------------------------------------------------------------------------
    def _exchange(self, u, t, dt):
        attempts = self.retries + 1
        client = self._client
        client.timeout = self.timeout / attempts
        for _ in range(attempts):
            sample = client.exchange(u, t, dt) if u is not None else client.exchange(None, t)
            if sample is not None:
                return sample
        return None

    def _measured(self, p_a, p_b, alpha, t):
        """Set the measured outputs, through the sensor lag (dead time, then the
        first-order lag) when it is on."""
        if self._delay is not None:
            self._delay.push(t, (p_a, p_b, alpha))
            p_a, p_b, alpha = self._delay.read(t)
        tau = self.tau_sensor
        if tau > 0.0 and self._t_meas is not None and t > self._t_meas:
            dt = t - self._t_meas
            p_a = sensor_lag_step(self.p_a, p_a, dt, tau)
            p_b = sensor_lag_step(self.p_b, p_b, dt, tau)
            alpha = sensor_lag_step(self.alpha, alpha, dt, tau)
        self.p_a, self.p_b, self.alpha, self._t_meas = p_a, p_b, alpha, t
        self.x = x_from_alpha(alpha, self._geom)

    def _show(self, s):
        self._measured(s.p_a, s.p_b, s.alpha, s.t)
        self.f_ext = s.f_ext
        self.u_applied, self.t_rig, self.failsafe = s.u_applied, s.t, s.failsafe
        self.link_ok = True

    def step(self, t, dt):
        if self.mode == "replay":
            self._show_replay(t + dt)
            return
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
            sample = self._exchange(self.u, t, dt)
            wait_until(self._wall0 + t + dt)
        else:
            sample = self._exchange(self.u, t, dt)              # lockstep: one command, one sample
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
