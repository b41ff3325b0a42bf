"""valve: the proportional valve MPYE-5-1/4-010B as an FMI 2.0 (and 3.0) co-simulation FMU.

Inputs u [V] and the absolute chamber pressures; outputs the mass flows into each
chamber through the ports that the command opens (Eq. 1, standard form, and the
reference rig's routing and A(u)), and each flow's slope with respect to its chamber's
pressure, which lets the cylinder integrate its chambers against the valve's local
linearisation (stable coupling at any communication step), and the pressures they are
evaluated at (``p_a_flow``, ``p_b_flow``: a host stepping Jacobi hands the cylinder the
flows of the previous communication point, which it carries to its own pressures).  The
outputs depend directly on the inputs.

Unmodelled effects, off by default (``model/catalogue.py``, forms in ``physics/effects.py``): ``tau_spool`` > 0 lets the
spool follow the command with a first-order lag (valve_dynamics; the spool position is
then the FMU's state, starting where the command is as initialisation ends or, if the
host sets none there, at the first step's),
``rate_spool`` > 0 limits the spool's speed as well, ``deadband`` > 0 closes a band of
commands around 5 V (valve_deadband; ``deadband_ext`` and ``deadband_ret`` give each side
its own width, ``deadband_edge`` rounds its edges).
"""
from boomfmi_valve_lib.fmislave import (U_MAX, U_MIN, BoomSlave, effect_options, input, option_values, output,
                                       parameter, rig_parameters)
from boomfmi_valve_lib.model import Boom, Model, effects_from_options
from boomfmi_valve_lib.physics import Gas, Valve as ValveParams, check_gas, check_valve
from boomfmi_valve_lib.physics import reference_rig


class Valve(BoomSlave):
    description = "Proportional 5/3 valve: orifice mass flows into chambers A and B (paper Eq. 1)"
    variables = (
        input("u", reference_rig.u_centre, "V", "valve command; 5 V closes every port, below 5 V supply -> A (extend), above 5 V supply -> B (retract)", min=U_MIN, max=U_MAX),
        input("p_a", reference_rig.P_atm, "Pa", "absolute pressure in chamber A (cap side)", min=0.0),
        input("p_b", reference_rig.P_atm, "Pa", "absolute pressure in chamber B (rod side)", min=0.0),
        output("mdot_a", 0.0, "kg/s", "mass flow into chamber A (negative when A exhausts)", depends=("u", "p_a", "p_b")),
        output("mdot_b", 0.0, "kg/s", "mass flow into chamber B (negative when B exhausts)", depends=("u", "p_a", "p_b")),
        output("dmdot_a_dp_a", 0.0, "kg/(s.Pa)", "slope of mdot_a with respect to p_a (<= 0)", depends=("u", "p_a", "p_b"), max=0.0),
        output("dmdot_b_dp_b", 0.0, "kg/(s.Pa)", "slope of mdot_b with respect to p_b (<= 0)", depends=("u", "p_a", "p_b"), max=0.0),
        output("p_a_flow", reference_rig.P_atm, "Pa", "chamber A's pressure that mdot_a and its slope are evaluated at (the input p_a)", depends=("p_a",), min=0.0),
        output("p_b_flow", reference_rig.P_atm, "Pa", "chamber B's pressure that mdot_b and its slope are evaluated at (the input p_b)", depends=("p_b",), min=0.0),
        *rig_parameters("P_s", "P_e"),
        parameter("A_max", reference_rig.A_max, "m2", "orifice area of each port at full opening", min=0.0),
        *rig_parameters("T", "k", "R"),
        *effect_options("valve"),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "valve"
        self._boom = Boom(Model(), check=False)    # until setup: the reference rig, no effects
        self._key = None
        self._flows = (0.0, 0.0, 0.0, 0.0)
        self._spool = reference_rig.u_centre

    def setup(self):
        valve = ValveParams(A_max=self.A_max, P_s=self.P_s, P_e=self.P_e)
        gas = Gas(k=self.k, R=self.R, T=self.T)
        check_valve(valve)
        check_gas(gas)
        effects = effects_from_options("valve", option_values(self, "valve"))
        self._boom = Boom(Model(valve=valve, gas=gas, effects=effects), check=False)
        # the spool starts where the command is as initialisation ends; a host that sets
        # no command there (every connector at its start until the first step: fmpy's and
        # libcosim's SSP masters, ours) hands it the first with that step, where it starts
        self._spool = self.u if "u" in self.set_in_initialisation else None
        self._key = None

    def _current_flows(self):
        # the flows of the spool's (or the command's) position and the pressures, computed
        # once for each new combination: every output asks for them
        key = (self._spool if self.tau_spool > 0.0 and self._spool is not None else self.u, self.p_a, self.p_b)
        if key != self._key:
            if not (self.p_a >= 0.0 and self.p_b >= 0.0):
                self.fail(f"input pressures must be >= 0 Pa absolute, got p_a = {self.p_a!r}, p_b = {self.p_b!r}")
                self._flows = (0.0, 0.0, 0.0, 0.0)
            else:
                self._flows = self._boom.valve_flows(self._boom.opening(key[0]), self.p_a, self.p_b)
            self._key = key
        return self._flows

    @property
    def mdot_a(self):
        return self._current_flows()[0]

    @property
    def mdot_b(self):
        return self._current_flows()[1]

    @property
    def dmdot_a_dp_a(self):
        return self._current_flows()[2]

    @property
    def dmdot_b_dp_b(self):
        return self._current_flows()[3]

    @property
    def p_a_flow(self):
        return self.p_a

    @property
    def p_b_flow(self):
        return self.p_b

    def step(self, t, dt):
        self._spool = self._boom.spool_step(self.u if self._spool is None else self._spool, self.u, dt)
