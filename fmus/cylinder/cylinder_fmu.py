"""cylinder: the chambers of the DSNU 32-60 cylinder as an FMI 2.0 (and 3.0) co-simulation FMU.

Inputs the mass flows into each chamber and the piston's position and velocity;
outputs the absolute chamber pressures, its states (Eq. 5 to 7).  Within a
communication step the flows are held and the piston moves linearly with the input
velocity; the energy balance of Eq. 4 is then integrated exactly, so the step is
stable for any step size.  Where the valve also passes each flow's slope with respect
to the chamber pressure, the chambers are integrated against that linearisation of the
flow (an exponential integrator, stable however short the chamber's time constant);
where it passes the pressures it evaluated them at too (``p_a_flow``, ``p_b_flow``), the
flows are first carried along their slopes to the chambers' present pressures (a host
stepping Jacobi hands over the flows of the previous communication point).

Unmodelled effects, off by default (``model/catalogue.py``, forms in ``physics/effects.py``): ``C_leak`` > 0 adds a
laminar leak across the piston seal, ``A_leak`` > 0 a turbulent one through a gap of
that area by the orifice law (piston_leakage: whichever law fits the machine); ``h_wall`` > 0 lets each
chamber's air exchange heat with its wall, relaxing the pressure towards the isothermal
pressure of its air mass (which the FMU then tracks) with time constant
m c_v / (h_wall A_wall) (heat_transfer); ``l_cushion`` > 0 makes a chamber's outflow
within that distance of its end of stroke also pass the cushion needle of area
``A_cushion`` to the exhaust (end_cushioning; DSNU-PPVA), and ``V_cushion_port`` > 0
cuts that port's volume off the chamber's dead volume there (the sensed chamber is stiffer).
"""
from boomfmi_cylinder_lib.fmislave import (CYLINDER, L_MAX, P_S_MAX, BoomSlave, effect_options, input,
                                          option_values, output, parameter, rig_parameters)
from boomfmi_cylinder_lib.model import Boom, Model, effects_from_options
from boomfmi_cylinder_lib.physics import (Cylinder as CylinderParams, Gas, ParameterError,
                                          Valve, check_cylinder, check_gas, flow_at)
from boomfmi_cylinder_lib.physics import reference_rig
from boomfmi_cylinder_lib.physics.effects import check_cushion_port


class Cylinder(BoomSlave):
    description = "Pneumatic cylinder chambers: isentropic pressure dynamics (paper Eq. 5 to 7)"
    variables = (
        input("mdot_a", 0.0, "kg/s", "mass flow into chamber A"),
        input("mdot_b", 0.0, "kg/s", "mass flow into chamber B"),
        input("x", 0.0, "m", "piston position, 0 = fully retracted (held within the stroke [0, L])", min=0.0, max=L_MAX),
        input("v", 0.0, "m/s", "piston velocity, positive extending"),
        input("dmdot_a_dp_a", 0.0, "kg/(s.Pa)", "slope of mdot_a with respect to p_a; 0 holds mdot_a over the step", max=0.0),
        input("dmdot_b_dp_b", 0.0, "kg/(s.Pa)", "slope of mdot_b with respect to p_b; 0 holds mdot_b over the step", max=0.0),
        input("p_a_flow", 0.0, "Pa", "chamber A's pressure that mdot_a and its slope were evaluated at (the valve's p_a_flow): "
              "mdot_a is carried along its slope to p_a; 0: evaluated at p_a", min=0.0),
        input("p_b_flow", 0.0, "Pa", "chamber B's pressure that mdot_b and its slope were evaluated at (the valve's p_b_flow): "
              "mdot_b is carried along its slope to p_b; 0: evaluated at p_b", min=0.0),
        output("p_a", reference_rig.P_atm, "Pa", "absolute pressure in chamber A (cap side)", min=0.0),
        output("p_b", reference_rig.P_atm, "Pa", "absolute pressure in chamber B (rod side)", min=0.0),
        *rig_parameters(*CYLINDER, "k", "R", "T"),
        parameter("p_a0", reference_rig.P_atm, "Pa", "initial absolute pressure in chamber A", min=0.0),
        parameter("p_b0", reference_rig.P_atm, "Pa", "initial absolute pressure in chamber B", min=0.0),
        *effect_options("cylinder"),
        parameter("P_e", reference_rig.P_e, "Pa", "exhaust pressure behind the cushion needle (end_cushioning), absolute",
                  min=0.0, max=P_S_MAX),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "cylinder"
        self._boom = None
        self._masses = [0.0, 0.0]

    def setup(self):
        cyl = CylinderParams(A_a=self.A_a, A_b=self.A_b, L=self.L, V_a0=self.V_a0, V_b0=self.V_b0)
        gas = Gas(k=self.k, R=self.R, T=self.T)
        check_cylinder(cyl)
        check_gas(gas)
        if self.l_cushion > 0.0:
            if not 0.0 < self.l_cushion <= 0.5 * self.L:
                raise ParameterError("l_cushion", self.l_cushion, f"must lie in (0, L/2 = {0.5 * self.L:g}] m")
            for name in ("A_cushion", "P_e"):
                if not getattr(self, name) > 0.0:
                    raise ParameterError(name, getattr(self, name), "must be > 0 with the cushion on (l_cushion > 0)")
            check_cushion_port(self.V_cushion_port, cyl, "V_cushion_port")
        for name in ("p_a0", "p_b0"):
            if not getattr(self, name) > 0.0:
                raise ParameterError(name, getattr(self, name), "an absolute pressure must be > 0")
        effects = effects_from_options("cylinder", option_values(self, "cylinder"))
        self._boom = Boom(Model(valve=Valve(P_e=self.P_e), gas=gas, cylinder=cyl, effects=effects), check=False)
        self.p_a, self.p_b = self.p_a0, self.p_b0
        self._masses = list(self._boom.air_masses(self.p_a, self.p_b, min(max(self.x, 0.0), self.L)))

    def step(self, t, dt):
        boom, L = self._boom, self.L
        x_0 = min(max(self.x, 0.0), L)
        x_1 = min(max(x_0 + self.v * dt, 0.0), L)
        s_a, s_b = min(self.dmdot_a_dp_a, 0.0), min(self.dmdot_b_dp_b, 0.0)
        # the valve's flows at this step's pressures (a Jacobi host's are a step old)
        mdot_a = flow_at(self.mdot_a, s_a, self.p_a, self.p_a_flow) if self.p_a_flow > 0.0 else self.mdot_a
        mdot_b = flow_at(self.mdot_b, s_b, self.p_b, self.p_b_flow) if self.p_b_flow > 0.0 else self.mdot_b
        mdot_a, mdot_b, s_a, s_b = boom.inflows(mdot_a, mdot_b, s_a, s_b, self.p_a, self.p_b, x_0)
        p_a, p_b = boom.step_chambers(self.p_a, self.p_b, x_0, x_1, mdot_a, mdot_b, s_a, s_b, dt, self._masses)
        if not (p_a > 0.0 and p_b > 0.0):
            raise ValueError(
                f"a chamber emptied (p_a = {p_a:g} Pa, p_b = {p_b:g} Pa): the outflow "
                f"exceeds the air in the chamber; reduce the communication step")
        self.p_a, self.p_b = p_a, p_b
