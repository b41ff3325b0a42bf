"""excavator_bridge: the whole excavator's rig (or its virtual rig, or a recording) as an FMI 2.0 co-simulation FMU.

Inputs the four valve commands ``u_<joint>`` [V] (swing, boom, arm, bucket); outputs
what the rig measures of each joint, as recorded (gauge pressures ``p_a_<joint>``,
``p_b_<joint>``, the joint angle ``angle_<joint>``), each piston's x from its measured
angle (``physics/excavator.py``'s joint maps), the commands the valves actually got
(``u_applied_<joint>``), the true force of the environment on the bucket tip where the
rig knows it (``f_tip_x/y/z``, world frame), and the link's state.  The boom's
``hardware_bridge`` does the same for the boom alone; this one speaks the link's
excavator datagrams (``link/protocol.py``, kinds 4 and 5).

Modes (parameter ``mode``), as the boom's bridge (the plumbing is ``boomfmi/rigbridge.py``'s, shared
with it):

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

Unmodelled effect, off by default, as the boom's bridge: ``tau_sensor`` > 0 passes every
pressure and angle (and so x) through a first-order lag, and ``delay_sensor`` > 0 delays
them by a dead time before it (sensor_lag).
"""
import math

from boomfmi_excavator_bridge_lib.fmislave import U_MAX, U_MIN, input, output
from boomfmi_excavator_bridge_lib.physics import reference_rig
from boomfmi_excavator_bridge_lib.physics.excavator import JOINTS, Excavator, pistons_from_angles
from boomfmi_excavator_bridge_lib.physics.params import L_MAX
from boomfmi_excavator_bridge_lib.physics.validation import ParameterError
from boomfmi_excavator_bridge_lib.rigbridge import RigBridge, link_variables, sensor_options

TIP = ("f_tip_x", "f_tip_y", "f_tip_z")
_AXES = {"f_tip_x": "world x (ahead at swing 0)", "f_tip_y": "world y", "f_tip_z": "world z (up)"}
_ANGLES = {"swing": "swing angle theta_swing (0 straight ahead, + counter-clockwise from above)",
           "boom": "boom angle alpha (Eq. 12)", "arm": "arm angle theta_arm, relative to the boom",
           "bucket": "bucket angle theta_bucket, relative to the arm"}
_EX = Excavator()
#: each joint's angle limits: noise and quantisation may step an angle past its ends
_LIMITS = [(a.lower_limit, a.upper) for a in _EX.actuators]


class ExcavatorBridge(RigBridge):
    description = ("The excavator's rig through its DAQ: four valve commands out, eight pressures, four angles "
                   "and the tip force in (replay a recording or talk UDP to a rig)")
    KIND = "excavator"
    MEASURED = tuple(f"{q}_{j}" for q in ("p_a", "p_b", "angle") for j in JOINTS)
    EXTRA = TIP
    COMMANDS = tuple(f"u_{j}" for j in JOINTS)
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
        *link_variables("excavator's rig"),
        *sensor_options(),
    )


    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "excavator_bridge"

    def measured(self, values):
        super().measured(values)
        angle = values[8:12]
        # x from the angles, clipped to the stroke (noise and quantisation may step past its ends)
        x = pistons_from_angles([min(max(a, lo), hi) for a, (lo, hi) in zip(angle, _LIMITS)], _EX)
        for k, j in enumerate(JOINTS):
            setattr(self, f"x_{j}", float(min(max(x[k], 0.0), _EX.actuators[k].stroke)))

    def sample_values(self, s):
        return (*s.p_a, *s.p_b, *s.angle), tuple(s.f_tip), tuple(s.u_applied)

    def check_sample(self, s):
        if not hasattr(s, "angle"):
            raise ParameterError("rig", self.rig, "answers as the boom's rig; the excavator bridge needs an "
                                                   "excavator rig (boomfmi rig serve --config examples/rig/excavator_*.json)")
