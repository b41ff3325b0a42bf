"""hardware_bridge: the rig (or a virtual rig, or a recording) as an FMI 2.0 co-simulation FMU.

Input the valve command u [V]; outputs what the rig measures, as recorded (gauge
pressures p_a, p_b, the boom angle alpha), x from alpha by Eq. 12, the command the
valve actually got (u_applied), the true external force where the rig knows it, and
the link's state.

Modes (parameter ``mode``; the plumbing is ``boomfmi/rigbridge.py``'s, shared with the
excavator's bridge):

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
from boomfmi_hardware_bridge_lib.fmislave import GEOMETRY, U_MAX, U_MIN, input, output, rig_parameters
from boomfmi_hardware_bridge_lib.physics import Geometry, check_geometry, x_from_alpha
from boomfmi_hardware_bridge_lib.physics import reference_rig
from boomfmi_hardware_bridge_lib.rigbridge import RigBridge, link_variables, sensor_options


class HardwareBridge(RigBridge):
    description = "The rig through its DAQ: commands out, measurements in (replay a recording or talk UDP to a rig)"
    KIND = "boom"
    MEASURED = ("p_a", "p_b", "alpha")
    EXTRA = ("f_ext",)
    COMMANDS = ("u",)
    variables = (
        input("u", reference_rig.u_centre, "V", "valve command to send to the rig", min=U_MIN, max=U_MAX),
        output("p_a", 0.0, "Pa", "measured chamber A pressure, gauge (as recorded)"),
        output("p_b", 0.0, "Pa", "measured chamber B pressure, gauge (as recorded)"),
        output("alpha", 0.0, "rad", "measured boom angle"),
        output("x", 0.0, "m", "piston position from the measured alpha by Eq. 12"),
        output("u_applied", reference_rig.u_centre, "V", "command the valve got over the last step (5 V while the rig is in fail-safe)",
               min=U_MIN, max=U_MAX),
        output("f_ext", 0.0, "N", "true external force on the piston where the rig knows it (virtual rig, load cell), else 0"),
        *link_variables("rig"),
        *rig_parameters(*GEOMETRY),
        *sensor_options(),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "hardware_bridge"
        self._geom = Geometry()

    def check_parameters(self):
        self._geom = Geometry(a=self.a, b=self.b, h=self.h, l_min=self.l_min)
        check_geometry(self._geom, self.L)

    def measured(self, values):
        self.p_a, self.p_b, self.alpha = values
        self.x = x_from_alpha(self.alpha, self._geom)

    def sample_values(self, s):
        return (s.p_a, s.p_b, s.alpha), (s.f_ext,), (s.u_applied,)
