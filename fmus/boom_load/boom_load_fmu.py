"""boom_load: the boom's load, friction and end stops as an FMI 2.0 (and 3.0) co-simulation FMU.

Inputs the absolute chamber pressures and an external force along the cylinder axis;
outputs the piston's position and velocity (its states), the boom angle alpha and the
cylinder angle phi (Eq. 8 to 12).  Within a step the pressures and f_ext are held; the
motion is integrated in short substeps with the exact stick/slip rule of
``physics.load``, and x never leaves [0, L].

Unmodelled effects, off by default (``model/catalogue.py``, forms in ``physics/effects.py``): ``v_s`` > 0 makes the
Coulomb friction fall from F_s to F_d as speed rises (stribeck_friction); ``c_friction_sum``,
``c_friction_max`` or ``c_friction_diff`` > 0 raise F_s and F_d alike with the pressure the
seals hold (pressure_friction).  The end cushioning acts on the exhaust air, so it is the
cylinder's option.
"""
import math

from boomfmi_boom_load_lib.fmislave import (GEOMETRY, L_MAX, LOAD, BoomSlave, effect_options, input,
                                           option_values, output, parameter, rig_parameters)
from boomfmi_boom_load_lib.model import Boom, Model, effects_from_options
from boomfmi_boom_load_lib.physics import (Cylinder, Geometry, Load, ParameterError, alpha_from_x,
                                           check_geometry, check_load, phi_from_x)
from boomfmi_boom_load_lib.physics import reference_rig
from boomfmi_boom_load_lib.physics.validation import require_positive


class BoomLoad(BoomSlave):
    description = "Boom load with static/Coulomb/viscous friction and hard end stops (paper Eq. 8 to 12)"
    variables = (
        input("p_a", reference_rig.P_atm, "Pa", "absolute pressure in chamber A (cap side)", min=0.0),
        input("p_b", reference_rig.P_atm, "Pa", "absolute pressure in chamber B (rod side)", min=0.0),
        input("f_ext", 0.0, "N", "external force on the piston along the cylinder axis, positive against extension"),
        output("x", 0.0, "m", "piston position, 0 = fully retracted; within the stroke [0, L]", min=0.0, max=L_MAX),
        output("v", 0.0, "m/s", "piston velocity, positive extending"),
        output("alpha", 0.0, "rad", "boom angle (Eq. 12), an angle of the triangle a, b, l", min=0.0, max=math.pi),
        output("phi", 0.0, "rad", "angle between the cylinder axis and the horizontal (Eq. 10)",
               min=-0.5 * math.pi, max=math.pi),
        *rig_parameters(*LOAD, *GEOMETRY, "A_a", "A_b", "P_atm"),
        parameter("x0", 0.0, "m", "initial piston position, within the stroke [0, L]", min=0.0, max=L_MAX),
        *effect_options("boom_load"),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "boom_load"
        self._boom = None
        self._geom = Geometry()

    def setup(self):
        load = Load(K_v=self.K_v, F_s=self.F_s, F_d=self.F_d, F_L=self.F_L, M=self.M)
        self._geom = Geometry(a=self.a, b=self.b, h=self.h, l_min=self.l_min)
        check_load(load)
        if load.F_s < load.F_d:
            raise ParameterError("F_s", load.F_s, f"the static friction must be at least the Coulomb force "
                                                  f"F_d = {load.F_d:g} N (Eq. 9)")
        for name in ("L", "A_a", "A_b", "P_atm"):
            require_positive(name, getattr(self, name))
        check_geometry(self._geom, self.L)
        if not 0.0 <= self.x0 <= self.L:
            raise ParameterError("x0", self.x0, f"must lie within the stroke [0, {self.L:g}] m")
        effects = effects_from_options("boom_load", option_values(self, "boom_load"))
        self._boom = Boom(Model(cylinder=Cylinder(A_a=self.A_a, A_b=self.A_b, L=self.L), geometry=self._geom,
                                load=load, P_atm=self.P_atm, effects=effects), check=False)
        self.x, self.v = float(self.x0), 0.0

    @property
    def alpha(self):
        return alpha_from_x(self.x, self._geom)

    @property
    def phi(self):
        return phi_from_x(self.x, self._geom)

    def step(self, t, dt):
        self.x, self.v = self._boom.step_load(self.x, self.v, dt, self.p_a, self.p_b, self.f_ext)
