"""excavator_bridge: the whole excavator's rig (or its virtual rig, or a recording) as an FMI 2.0 co-simulation FMU.

Inputs the four valve commands ``u_<joint>`` [V] (swing, boom, arm, bucket); outputs
what the rig measures of each joint, as recorded (gauge pressures ``p_a_<joint>``,
``p_b_<joint>``, the joint angle ``angle_<joint>``), each piston's x from its measured
angle (``physics/excavator.py``'s joint maps), the commands the valves actually got
(``u_applied_<joint>``), the true force of the environment on the bucket tip where the
rig knows it (``f_tip_x/y/z``, world frame), and the link's state.  The boom's
``hardware_bridge`` does the same for the boom alone; this one speaks the link's
excavator datagrams (``link/protocol.py``, kinds 4 and 5).

Modes (parameter ``mode``), as the boom's bridge:

* ``replay``: plays the excavator recording ``recording``.  At each communication point
  t: linear interpolation between samples for pressures, angles and tip force, the
  last sample at or before t for the commands; outside it the nearest end is held and
  link_ok is false.
* ``udp``: talks to the rig at ``rig`` (udp://HOST:PORT, ``boomfmi rig serve --config
  examples/rig/excavator_*.json``) with authenticated datagrams (key from ``key_file``,
  else $BOOMFMI_LINK_KEY), retrying up to ``retries`` times within ``timeout``.  A rig
  in lockstep advances one sample per step and answers with the sample at t + dt; with
  a real-time rig the bridge paces itself to the wall clock (one exchange per step).
  A lost answer holds the last sample and clears link_ok; more than ``loss_budget``
  consecutive losses is an fmi2Error.
"""
import bisect
import math
import time

from boomfmi_excavator_bridge_lib.fmislave import U_MAX, U_MIN, BoomSlave, input, output, parameter
from boomfmi_excavator_bridge_lib.link.client import RigClient, parse_address, wait_until
from boomfmi_excavator_bridge_lib.link.protocol import LinkError, load_key
from boomfmi_excavator_bridge_lib.physics import reference_rig
from boomfmi_excavator_bridge_lib.physics.excavator import JOINTS, Excavator, pistons_from_angles
from boomfmi_excavator_bridge_lib.physics.params import L_MAX
from boomfmi_excavator_bridge_lib.physics.validation import ParameterError
from boomfmi_excavator_bridge_lib.recording import RecordingError, parse_recording, recording_kind

TIP = ("f_tip_x", "f_tip_y", "f_tip_z")
_AXES = {"f_tip_x": "world x (ahead at swing 0)", "f_tip_y": "world y", "f_tip_z": "world z (up)"}
_ANGLES = {"swing": "swing angle theta_swing (0 straight ahead, + counter-clockwise from above)",
           "boom": "boom angle alpha (Eq. 12)", "arm": "arm angle theta_arm, relative to the boom",
           "bucket": "bucket angle theta_bucket, relative to the arm"}
_EX = Excavator()


class ExcavatorBridge(BoomSlave):
    description = ("The excavator's rig through its DAQ: four valve commands out, eight pressures, four angles "
                   "and the tip force in (replay a recording or talk UDP to a rig)")
    variables = (
        *(input(f"u_{j}", reference_rig.u_centre, "V", f"{j} valve command to send to the rig", min=U_MIN, max=U_MAX)
          for j in JOINTS),
        *(v for j in JOINTS for v in (
            output(f"p_a_{j}", 0.0, "Pa", f"measured {j} cylinder chamber A pressure, gauge (as recorded)"),
            output(f"p_b_{j}", 0.0, "Pa", f"measured {j} cylinder chamber B pressure, gauge (as recorded)"),
            output(f"angle_{j}", 0.0, "rad", f"measured {_ANGLES[j]}", min=-math.pi, max=math.pi),
            output(f"x_{j}", 0.0, "m", f"{j} piston position from the measured angle (excavator.md's joint map)",
                   min=0.0, max=L_MAX),
            output(f"u_applied_{j}", reference_rig.u_centre, "V",
                   f"command the {j} valve got over the last step (5 V while the rig is in fail-safe)",
                   min=U_MIN, max=U_MAX))),
        *(output(f, 0.0, "N", f"true force of the environment on the bucket tip, {_AXES[f]}, where the rig knows it "
                 "(virtual rig, load cell), else 0") for f in TIP),
        output("t_rig", 0.0, "s", "the rig's time of the current sample"),
        output("link_ok", True, "1", "the current sample is fresh (false: held after a lost answer, or outside the recording)", type="Boolean"),
        output("failsafe", False, "1", "the rig reports its fail-safe state (valves centred by its watchdog)", type="Boolean"),
        output("lost_packets", 0, "1", "answers lost so far (after retries)", type="Integer"),
        output("deadline_misses", 0, "1", "steps begun more than a step late against the wall clock (real-time rig only)", type="Integer"),
        output("lateness", 0.0, "s", "real-time rig: how late the last step began against the wall clock; else 0"),
        parameter("mode", "replay", "1", "replay: play the recording; udp: talk to the rig", type="String"),
        parameter("recording", "", "1", "replay mode: path of the excavator recording (CSV, recording format)", type="String"),
        parameter("rig", "udp://127.0.0.1:47800", "1", "udp mode: the rig's address, udp://HOST:PORT", type="String"),
        parameter("key_file", "", "1", "udp mode: file holding the shared link key; empty: $BOOMFMI_LINK_KEY", type="String"),
        parameter("timeout", 0.05, "s", "udp mode: longest wait for an answer in one step (retries included)", min=0.0),
        parameter("retries", 2, "1", "udp mode: resends of a command within the timeout", type="Integer", min=0),
        parameter("loss_budget", 20, "1", "udp mode: consecutive lost answers tolerated before fmi2Error", type="Integer", min=0),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "excavator_bridge"
        self._client = None
        self._losses = 0

    # -- set-up ----------------------------------------------------------------------------
    def setup(self):
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
            if recording_kind(self.recording) != "excavator":
                raise ParameterError("recording", self.recording,
                                     "is a boom's recording; the excavator bridge replays an excavator's")
            header, values, _, _ = parse_recording(self.recording)
        except RecordingError as e:
            raise ParameterError("recording", self.recording, str(e)) from None
        self._t = [float(v) for v in values["t"]]
        names = [f"{q}_{j}" for j in JOINTS for q in ("u", "p_a", "p_b", "angle")]
        self._cols = {c: [float(v) for v in values[c]] for c in names}
        for f in TIP:
            self._cols[f] = [float(v) for v in values[f]] if f in values else [0.0] * len(self._t)
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
        if not hasattr(sample, "angle"):
            raise ParameterError("rig", self.rig, "answers as the boom's rig; the excavator bridge needs an "
                                                   "excavator rig (boomfmi rig serve --config examples/rig/excavator_*.json)")
        self._realtime = not sample.lockstep
        self._rig_t0 = sample.t - self.start_time      # the rig's clock against ours (lockstep)
        self._wall0 = None
        self._show(sample)

    # -- outputs ---------------------------------------------------------------------------
    def _measured(self, p_a, p_b, angle):
        for k, j in enumerate(JOINTS):
            setattr(self, f"p_a_{j}", p_a[k])
            setattr(self, f"p_b_{j}", p_b[k])
            setattr(self, f"angle_{j}", angle[k])
        # x from the angles, clipped to the stroke (noise and quantisation may step past its ends)
        x = pistons_from_angles([min(max(a, lo), hi) for a, (lo, hi) in zip(angle, self._limits())], _EX)
        for k, j in enumerate(JOINTS):
            setattr(self, f"x_{j}", float(min(max(x[k], 0.0), _EX.actuators[k].stroke)))

    @staticmethod
    def _limits():
        return [(a.lower_limit, a.upper) for a in _EX.actuators]

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
        self._measured([at(f"p_a_{j}") for j in JOINTS], [at(f"p_b_{j}") for j in JOINTS],
                       [at(f"angle_{j}") for j in JOINTS])
        for f in TIP:
            setattr(self, f, at(f))
        for j in JOINTS:
            setattr(self, f"u_applied_{j}", cols[f"u_{j}"][i])
        self.t_rig = t
        if not inside and self.link_ok:
            self.log(f"replay: t = {t:g} s lies outside the recording ({ts[0]:g} to {ts[-1]:g} s); holding its end")
        self.link_ok = inside

    def _exchange(self, u, t, dt):
        attempts = self.retries + 1
        client = self._client
        client.timeout = self.timeout / attempts
        for _ in range(attempts):
            sample = client.exchange(u, t, dt) if u is not None else client.exchange(None, t)
            if sample is not None:
                return sample
        return None

    def _show(self, s):
        self._measured(s.p_a, s.p_b, s.angle)
        for f, value in zip(TIP, s.f_tip):
            setattr(self, f, value)
        for j, u in zip(JOINTS, s.u_applied):
            setattr(self, f"u_applied_{j}", u)
        self.t_rig, self.failsafe = s.t, s.failsafe
        self.link_ok = True

    def step(self, t, dt):
        if self.mode == "replay":
            self._show_replay(t + dt)
            return
        u = tuple(float(getattr(self, f"u_{j}")) for j in JOINTS)
        if self._realtime:
            now = time.perf_counter()
            if self._wall0 is None:
                self._wall0 = now - t
            self.lateness = now - (self._wall0 + t)
            if self.lateness > dt:
                self.deadline_misses += 1
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
