"""hardware_bridge: the rig (or a virtual rig, or a recording) as an FMI 2.0 co-simulation FMU.

Input the valve command u [V]; outputs what the rig measures, as recorded (p_a, p_b,
alpha), x from alpha by Eq. 12, u_applied, the true f_ext where the rig knows it, and
the link's state.  Modes (replay, udp) and the sensor_lag options: ``boomfmi/rigbridge.py``.
"""
from boomfmi_hardware_bridge_lib.rigbridge import RigBridge, bridge_variables


class HardwareBridge(RigBridge):
    description = "The rig through its DAQ: commands out, measurements in (replay a recording or talk UDP to a rig)"
    MACHINE = "boom"
    variables = bridge_variables(MACHINE)
