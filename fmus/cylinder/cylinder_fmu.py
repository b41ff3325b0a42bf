"""cylinder: the chambers of the DSNU 32-60 cylinder as an FMI 2.0 co-simulation FMU.

Inputs the mass flows into each chamber and the piston's position and velocity;
outputs the absolute chamber pressures, its states (Eq. 5 to 7).  Within a
communication step the flows are held and the piston moves linearly with the input
velocity; the energy balance of Eq. 4 is then integrated exactly, so the step is
stable for any step size.  Where the valve also passes each flow's slope with respect
to the chamber pressure, the chambers are integrated against that linearisation of the
flow (an exponential integrator, stable however short the chamber's time constant).

Unmodelled effects, off by default (``physics/effects.py``): ``C_leak`` > 0 adds a
laminar leak across the piston seal, ``A_leak`` > 0 a turbulent one through a gap of
that area by the orifice law (piston_leakage: whichever law fits the machine); ``h_wall`` > 0 lets each
chamber's air exchange heat with its wall, relaxing the pressure towards the isothermal
pressure of its air mass (which the FMU then tracks) with time constant
m c_v / (h_wall A_wall) (heat_transfer); ``l_cushion`` > 0 makes a chamber's outflow
within that distance of its end of stroke also pass the cushion needle of area
``A_cushion`` to the exhaust (end_cushioning; DSNU-PPVA).
"""
import math

from boomfmi_cylinder_lib.fmislave import CYLINDER, BoomSlave, input, output, parameter, rig_parameters
from boomfmi_cylinder_lib.physics import (Cylinder as CylinderParams, Gas, ParameterError,
                                          chamber_pressure_step, chamber_volumes, check_cylinder,
                                          check_gas)
from boomfmi_cylinder_lib.physics import reference_rig as rig
from boomfmi_cylinder_lib.physics.effects import (chamber_wall_area, cushion_outflow, cushion_outflow_slope,
                                                  leakage_flow, leakage_orifice_flow,
                                                  leakage_orifice_slopes, thermal_relaxation_step,
                                                  thermal_time_constant)


class Cylinder(BoomSlave):
    description = "Pneumatic cylinder chambers: isentropic pressure dynamics (paper Eq. 5 to 7)"
    variables = (
        input("mdot_a", 0.0, "kg/s", "mass flow into chamber A"),
        input("mdot_b", 0.0, "kg/s", "mass flow into chamber B"),
        input("x", 0.0, "m", "piston position, 0 = fully retracted", min=0.0),
        input("v", 0.0, "m/s", "piston velocity, positive extending"),
        input("dmdot_a_dp_a", 0.0, "kg/(s.Pa)", "slope of mdot_a with respect to p_a; 0 holds mdot_a over the step", max=0.0),
        input("dmdot_b_dp_b", 0.0, "kg/(s.Pa)", "slope of mdot_b with respect to p_b; 0 holds mdot_b over the step", max=0.0),
        output("p_a", rig.P_atm, "Pa", "absolute pressure in chamber A (cap side)", min=0.0),
        output("p_b", rig.P_atm, "Pa", "absolute pressure in chamber B (rod side)", min=0.0),
        *rig_parameters(*CYLINDER, "k", "R", "T"),
        parameter("p_a0", rig.P_atm, "Pa", "initial absolute pressure in chamber A", min=0.0),
        parameter("p_b0", rig.P_atm, "Pa", "initial absolute pressure in chamber B", min=0.0),
        parameter("C_leak", 0.0, "kg/(s.Pa)", "piston_leakage: laminar conductance of the piston seal, A to B; 0: off", min=0.0),
        parameter("A_leak", 0.0, "m2", "piston_leakage: area of a turbulent leak gap across the piston seal (orifice law); 0: off", min=0.0),
        parameter("l_cushion", 0.0, "m", "end_cushioning: cushion length at each end of stroke; 0: off", min=0.0),
        parameter("A_cushion", 1e-7, "m2", "end_cushioning: cushion needle's orifice area", min=0.0),
        parameter("P_e", rig.P_e, "Pa", "end_cushioning: exhaust pressure behind the cushion needle, absolute", min=0.0),
        parameter("h_wall", 0.0, "W/(m2.K)", "heat_transfer: heat-transfer coefficient between the air and the chamber wall; 0: off", min=0.0),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "cylinder"
        self._cyl, self._gas = CylinderParams(), Gas()

    def setup(self):
        self._cyl = CylinderParams(A_a=self.A_a, A_b=self.A_b, L=self.L, V_a0=self.V_a0, V_b0=self.V_b0)
        self._gas = Gas(k=self.k, R=self.R, T=self.T)
        check_cylinder(self._cyl)
        check_gas(self._gas)
        if self.l_cushion > 0.0:
            if not 0.0 < self.l_cushion <= 0.5 * self.L:
                raise ParameterError("l_cushion", self.l_cushion, f"must lie in (0, L/2 = {0.5 * self.L:g}] m")
            for name in ("A_cushion", "P_e"):
                if not getattr(self, name) > 0.0:
                    raise ParameterError(name, getattr(self, name), "must be > 0 with the cushion on (l_cushion > 0)")
        for name in ("p_a0", "p_b0"):
            if not getattr(self, name) > 0.0:
                raise ParameterError(name, getattr(self, name), "an absolute pressure must be > 0")
        self.p_a, self.p_b = self.p_a0, self.p_b0
        V_a, V_b = chamber_volumes(min(max(self.x, 0.0), self.L), self._cyl)
        RT = self.R * self.T
        self._m_a, self._m_b = self.p_a * V_a / RT, self.p_b * V_b / RT    # air masses [kg]
        self._bore = math.sqrt(4.0 * self.A_a / math.pi)
        self._cushion = (self.l_cushion, self.A_cushion, self.P_e, self._gas)

    def step(self, t, dt):
        L = self._cyl.L
        x_0 = min(max(self.x, 0.0), L)
        x_1 = min(max(x_0 + self.v * dt, 0.0), L)
        V_a0, V_b0 = chamber_volumes(x_0, self._cyl)
        V_a1, V_b1 = chamber_volumes(x_1, self._cyl)
        mdot_a, mdot_b = self.mdot_a, self.mdot_b
        s_a, s_b = min(self.dmdot_a_dp_a, 0.0), min(self.dmdot_b_dp_b, 0.0)
        if self.l_cushion > 0.0:
            cushion = self._cushion
            s_a = cushion_outflow_slope(mdot_a, s_a, self.p_a, x_0, *cushion)
            s_b = cushion_outflow_slope(mdot_b, s_b, self.p_b, L - x_0, *cushion)
            mdot_a = cushion_outflow(mdot_a, self.p_a, x_0, *cushion)
            mdot_b = cushion_outflow(mdot_b, self.p_b, L - x_0, *cushion)
        q = leakage_flow(self.p_a, self.p_b, self.C_leak)      # held over the step
        mdot_a, mdot_b = mdot_a - q, mdot_b + q
        s_a, s_b = s_a - self.C_leak, s_b - self.C_leak
        if self.A_leak > 0.0:
            q = leakage_orifice_flow(self.p_a, self.p_b, self.A_leak, self._gas)
            g_a, g_b = leakage_orifice_slopes(self.p_a, self.p_b, self.A_leak, self._gas)
            mdot_a, mdot_b = mdot_a - q, mdot_b + q
            s_a, s_b = s_a + g_a, s_b + g_b
        p_a = chamber_pressure_step(self.p_a, V_a0, V_a1, mdot_a, dt, self._gas, s_a)
        p_b = chamber_pressure_step(self.p_b, V_b0, V_b1, mdot_b, dt, self._gas, s_b)
        if self.h_wall > 0.0:
            self._m_a += dt * (mdot_a + 0.5 * s_a * (p_a - self.p_a))
            self._m_b += dt * (mdot_b + 0.5 * s_b * (p_b - self.p_b))
            for side, m, V, A in (("a", self._m_a, V_a1, self.A_a), ("b", self._m_b, V_b1, self.A_b)):
                tau = thermal_time_constant(m, chamber_wall_area(V, A, self._bore), self.h_wall, self.k, self.R)
                if side == "a":
                    p_a = thermal_relaxation_step(p_a, m, V, dt, tau, self.R, self.T)
                else:
                    p_b = thermal_relaxation_step(p_b, m, V, dt, tau, self.R, self.T)
        if not (p_a > 0.0 and p_b > 0.0):
            raise ValueError(
                f"a chamber emptied (p_a = {p_a:g} Pa, p_b = {p_b:g} Pa): the outflow "
                f"exceeds the air in the chamber; reduce the communication step")
        self.p_a, self.p_b = p_a, p_b
