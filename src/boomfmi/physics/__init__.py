"""The boom's physics, once: plain functions on floats and NumPy arrays, SI units.

Every caller (the FMUs, the monolithic reference solver, the virtual rig,
identification and diagnosis) uses these functions.  Only relative imports are used
inside this package, so that ``build_fmus.py`` can bundle it into each FMU under a
name of that FMU's own.
"""
from . import effects, reference_rig
from .chamber import chamber_inflows, chamber_pressure_step, chamber_volumes, pressure_rates
from .linkage import (JOINTS, Actuator, Excavator, Link, advance_linkage, check_excavator,
                        coriolis, cylinder_forces, cylinder_torques, excavator_parameters,
                        forward_kinematics, gravity, joint_angles, joint_limits, kinetic_energy,
                        lever_arms, lumped_boom_load, mass_matrix, piston_accelerations,
                        pistons_from_angles, potential_energy, tip_jacobian, tip_torques)
from .force_estimation import (below_sensor_floor, measured_drive_force, motion_filter_step,
                               observed_external_force, observed_joint_forces, observer_filter_step,
                               pneumatic_stiffness, position_error_force, reflected_force)
from .geometry import (alpha_from_x, check_geometry, cylinder_length, linkage_points,
                       phi_from_x, x_from_alpha)
from .lag import first_order_step
from .load import (acceleration, advance_load, drive_force, friction_force, piston_force,
                   slide_or_stick, sliding_acceleration, sliding_velocity, end_stops)
from .orifice import (critical_pressure_ratio, flow_at, mass_flow, mass_flow_slope, signed_mass_flow,
                      signed_mass_flow_and_slope, signed_mass_flow_slope)
from .params import (Cylinder, Gas, Geometry, Load, Valve, check_cylinder, check_gas,
                     check_load, check_valve)
from .validation import ParameterError
from .valve import chamber_flow_slopes, chamber_flows, chamber_flows_and_slopes, orifice_area

__all__ = [
    "effects", "reference_rig", "chamber_pressure_step", "chamber_volumes", "pressure_rates",
    "pneumatic_stiffness", "position_error_force", "reflected_force", "first_order_step",
    "motion_filter_step", "observed_external_force", "observed_joint_forces", "observer_filter_step",
    "measured_drive_force", "below_sensor_floor", "alpha_from_x",
    "check_geometry", "cylinder_length", "phi_from_x", "x_from_alpha", "linkage_points",
    "acceleration",
    "advance_load", "end_stops", "drive_force", "friction_force", "piston_force", "slide_or_stick", "sliding_velocity",
    "critical_pressure_ratio", "mass_flow", "signed_mass_flow", "Cylinder", "Gas",
    "Geometry", "Load", "Valve", "check_cylinder", "check_gas", "check_load",
    "check_valve", "ParameterError", "chamber_flows", "orifice_area", "chamber_flow_slopes",
    "chamber_flows_and_slopes", "signed_mass_flow_and_slope",
    "mass_flow_slope", "signed_mass_flow_slope", "flow_at", "chamber_inflows", "sliding_acceleration",
    "JOINTS", "Actuator", "Excavator", "Link", "advance_linkage", "check_excavator", "coriolis",
    "cylinder_forces", "cylinder_torques", "excavator_parameters", "forward_kinematics", "gravity",
    "joint_angles", "joint_limits", "kinetic_energy", "lever_arms", "lumped_boom_load", "mass_matrix",
    "piston_accelerations", "pistons_from_angles", "potential_energy", "tip_jacobian", "tip_torques",
]
