"""excavator_bridge: the whole excavator's rig (or its virtual rig, or a recording) as an FMI 2.0 co-simulation FMU.

Inputs the four valve commands ``u_<joint>`` [V]; outputs what the rig measures of each
joint, as recorded (``p_a_<joint>``, ``p_b_<joint>``, ``angle_<joint>``), each piston's
x from its angle, ``u_applied_<joint>``, the true tip force ``f_tip_x/y/z`` where the
rig knows it, and the link's state (excavator datagrams, ``link/protocol.py`` kinds 4
and 5).  Modes (replay, udp) and the sensor_lag options: ``boomfmi/rigbridge.py``.
"""
from boomfmi_excavator_bridge_lib.rigbridge import RigBridge, bridge_variables


class ExcavatorBridge(RigBridge):
    description = ("The excavator's rig through its DAQ: four valve commands out, eight pressures, four angles "
                   "and the tip force in (replay a recording or talk UDP to a rig)")
    MACHINE = "excavator"
    variables = bridge_variables(MACHINE)
