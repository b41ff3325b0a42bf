"""linkage: the whole excavator's four-joint rigid linkage as an FMI 2.0 (and 3.0) co-simulation FMU.

Inputs the eight absolute chamber pressures (``p_a_<joint>``, ``p_b_<joint>``) and the
force of the environment on the bucket tip (world frame); outputs each piston's position
and velocity (its states), each joint's angle (the recording's ``angle_<joint>``: the
swing angle, the boom's alpha of Eq. 12, the arm's and the bucket's relative angles) and
the tip's position.  The physics is ``physics/linkage.py`` (``shared/spec/excavator.md``;
Eq. 8 to 12 per cylinder): mass matrix, Coriolis and gravity of the four joints, each
cylinder acting through its lever arm, Eq. 9 friction and hard end stops per cylinder,
the tip force through the Jacobian transpose.  Within a step the inputs are held and the
motion is integrated in short substeps (``advance_linkage``).

Each cylinder's friction carries the catalogue's friction effects as options of its own
(``v_s_<joint>``, ``c_friction_sum_<joint>``, ...: the boom_load FMU's options with the
joint's suffix, ``fmislave.effect_options``), applied through a :class:`Boom` of that
joint (``model.machine.friction_hook``), so that any friction effect runs on
any joint.
"""
import math

from boomfmi_linkage_lib.fmislave import L_MAX, BoomSlave, effect_options, input, option_values, output, parameter
from boomfmi_linkage_lib.model import Boom, Model, effects_from_options
from boomfmi_linkage_lib.model.machine import friction_hook
from boomfmi_linkage_lib.physics import reference_rig
from boomfmi_linkage_lib.physics.linkage import (JOINTS, LINKS, Excavator, advance_linkage, angles_and_tip,
                                                   excavator_from_values, excavator_value_names)
from boomfmi_linkage_lib.physics.validation import ParameterError, require_non_negative

_EX = Excavator()
_DEG = math.pi / 180.0


def _joint_parameters(joint):
    a = getattr(_EX, joint)
    rows = [
        parameter(f"bore_{joint}", a.bore, "m", f"{joint} cylinder bore", min=0.0),
        parameter(f"rod_{joint}", a.rod, "m", f"{joint} cylinder piston-rod diameter", min=0.0),
        parameter(f"stroke_{joint}", a.stroke, "m", f"{joint} cylinder stroke L", min=0.0, max=L_MAX),
        parameter(f"c1_{joint}", a.c1, "m", f"{joint} mounting triangle: pivot to the cylinder's base eye"
                  + (" (Eq. 10, 12's a)" if joint == "boom" else ""), min=0.0),
        parameter(f"c2_{joint}", a.c2, "m", f"{joint} mounting triangle: pivot to the cylinder's rod eye"
                  + (" (Eq. 10, 12's b)" if joint == "boom" else ""), min=0.0),
        parameter(f"l_min_{joint}", a.l_min, "m", f"{joint} cylinder length eye to eye at x = 0 (Eq. 11)",
                  min=0.0),
        parameter(f"K_v_{joint}", a.K_v, "N.s/m", f"{joint} cylinder viscous friction coefficient (Eq. 8)",
                  min=0.0),
        parameter(f"F_s_{joint}", a.F_s, "N", f"{joint} cylinder static friction force (Eq. 9)", min=0.0),
        parameter(f"F_d_{joint}", a.F_d, "N", f"{joint} cylinder Coulomb friction force (Eq. 9)", min=0.0),
        parameter(f"x0_{joint}", 0.5 * a.stroke, "m", f"initial {joint} piston position, within [0, L]",
                  min=0.0, max=L_MAX),
    ]
    if joint != "boom":
        rows.insert(6, parameter(f"lower_{joint}", a.lower, "rad",
                                 f"{joint} joint angle at x = 0 (its lower limit)", min=-math.pi, max=math.pi))
    return rows


def _link_parameters(name, link):
    return [
        parameter(f"length_{name}", link.length, "m",
                  f"{name} length, pivot to the next pivot" + (" or to the tip" if name == "bucket" else ""),
                  min=0.0),
        parameter(f"mass_{name}", link.mass, "kg", f"{name} mass" + (" (empty)" if name == "bucket" else ""),
                  min=0.0),
        parameter(f"com_{name}", link.com, "m", f"{name} centre of mass from its pivot, along the link"),
    ]


class Linkage(BoomSlave):
    description = ("Excavator linkage: swing, boom, arm and bucket as rigid links driven by four cylinders, "
                   "with Eq. 9 friction and end stops per cylinder (excavator.md, paper Eq. 8 to 12)")
    variables = (
        *(v for j in JOINTS for v in (
            input(f"p_a_{j}", reference_rig.P_atm, "Pa", f"absolute pressure in the {j} cylinder's chamber A (cap side)",
                  min=0.0),
            input(f"p_b_{j}", reference_rig.P_atm, "Pa", f"absolute pressure in the {j} cylinder's chamber B (rod side)",
                  min=0.0))),
        input("f_tip_x", 0.0, "N", "force of the environment on the bucket tip, world x (ahead at swing 0)"),
        input("f_tip_y", 0.0, "N", "force of the environment on the bucket tip, world y"),
        input("f_tip_z", 0.0, "N", "force of the environment on the bucket tip, world z (up)"),
        *(v for j in JOINTS for v in (
            output(f"x_{j}", 0.0, "m", f"{j} piston position, 0 = fully retracted; within the stroke [0, L]",
                   min=0.0, max=L_MAX),
            output(f"v_{j}", 0.0, "m/s", f"{j} piston velocity, positive extending"))),
        output("angle_swing", 0.0, "rad", "swing angle theta_swing, 0 = straight ahead, positive counter-clockwise "
               "seen from above", min=-math.pi, max=math.pi),
        output("angle_boom", 0.0, "rad", "boom angle alpha (Eq. 12)", min=0.0, max=math.pi),
        output("angle_arm", 0.0, "rad", "arm angle relative to the boom, positive crowding in",
               min=-2 * math.pi, max=2 * math.pi),
        output("angle_bucket", 0.0, "rad", "bucket angle relative to the arm, positive curling in",
               min=-2 * math.pi, max=2 * math.pi),
        output("tip_x", 0.0, "m", "bucket tip, world x"),
        output("tip_y", 0.0, "m", "bucket tip, world y"),
        output("tip_z", 0.0, "m", "bucket tip, world z (0 = ground plane)"),
        *(v for j in JOINTS for v in _joint_parameters(j)),
        parameter("h", _EX.boom_h, "m", "boom geometry h (Eq. 10)", min=0.0),
        *(v for name, link in zip(LINKS, _EX.links) for v in _link_parameters(name, link)),
        parameter("pivot_forward", _EX.pivot_forward, "m", "boom pivot ahead of the swing axis"),
        parameter("pivot_height", _EX.pivot_height, "m", "boom pivot above the ground plane"),
        parameter("P_atm", reference_rig.P_atm, "Pa", "atmospheric pressure (it acts on the rods)", min=0.0),
        parameter("payload", 0.0, "kg", "payload in the bucket, at the bucket's centre of mass", min=0.0),
        parameter("max_substep", 2.5e-4, "s", "longest integration substep", min=1e-6, max=1e-2),
        *(v for j in JOINTS for v in effect_options("boom_load", j)),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "linkage"
        self._ex = _EX
        self._x = [0.0] * 4
        self._v = [0.0] * 4
        self._q = [0.0] * 4
        self._tip = (0.0, 0.0, 0.0)
        self._friction = None

    def setup(self):
        # the machine from this FMU's values, by their names (physics.excavator_from_values:
        # each link a slender rod, inertia m L^2 / 12 about its centre; the upper structure's
        # inertia about z and g are excavator.md's), checked naming the value
        declared = {v.name for v in self.variables}
        ex = excavator_from_values({n: getattr(self, n) for n in excavator_value_names() if n in declared}, _EX)
        require_non_negative("payload", self.payload)
        for j in JOINTS:
            x0, L = getattr(self, f"x0_{j}"), getattr(ex, j).stroke
            if not 0.0 <= x0 <= L:
                raise ParameterError(f"x0_{j}", x0, f"must lie within the stroke [0, {L:g}] m")
        self._ex = ex
        hooks = [friction_hook(Boom(Model(load=ex.load(j), P_atm=ex.P_atm,
                                          effects=effects_from_options("boom_load", option_values(self, "boom_load", j))),
                                    check=False), ex.load(j)) for j in JOINTS]
        self._friction = hooks if any(hooks) else None
        self._x = [float(getattr(self, f"x0_{j}")) for j in JOINTS]
        self._v = [0.0] * 4
        self._update()

    def _update(self):
        self._q, self._tip = angles_and_tip(self._x, self._ex)

    def step(self, t, dt):
        p_a = [self.p_a_swing, self.p_a_boom, self.p_a_arm, self.p_a_bucket]
        p_b = [self.p_b_swing, self.p_b_boom, self.p_b_arm, self.p_b_bucket]
        x, v = advance_linkage((self._x, self._v), p_a, p_b, (self.f_tip_x, self.f_tip_y, self.f_tip_z), dt,
                               self._ex, payload=self.payload, max_substep=self.max_substep,
                               friction=self._friction)
        self._x = x.tolist()
        self._v = v.tolist()
        self._update()


def _state_property(kind, i):
    return property(lambda self: (self._x if kind == "x" else self._v)[i])


for _i, _j in enumerate(JOINTS):
    setattr(Linkage, f"x_{_j}", _state_property("x", _i))
    setattr(Linkage, f"v_{_j}", _state_property("v", _i))
    setattr(Linkage, f"angle_{_j}", property(lambda self, i=_i: self._q[i]))
for _i, _c in enumerate("xyz"):
    setattr(Linkage, f"tip_{_c}", property(lambda self, i=_i: self._tip[i]))
