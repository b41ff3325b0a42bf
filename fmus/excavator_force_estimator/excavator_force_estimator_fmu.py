"""excavator_force_estimator: the force of the environment on the excavator's bucket tip
(a 3-vector, world frame) from the machine's measurements, and the joystick's force.

Per-joint load observers (each cylinder's equation of motion through the four-joint
linkage, read backwards from the measured pressures and angles with the identified
friction per cylinder and the payload) combined into the tip force: the sliding joints'
equations and the previous estimate by least squares within the set of forces
consistent with the sample (``consistent_tip_force``: a sticking joint's friction band, a
stop's one side), the least-squares guess over the Jacobian transpose (``rest_weight``,
``stop_weight``) weighted by ``f_guess``, the previous estimate by ``f_rate`` where the
set bounds an axis; ``residual`` is the guess's misfit of the four equations [N m].
``physics/force_estimation.py`` holds the physics.  The measured
angles pass a critically damped second-order filter (``f_motion``; the swing's
``f_motion_swing``), the pneumatic forces the same filter; the estimate then a
first-order low-pass (``tau_est``).  ``f_reflect_*``, the joystick's 3-axis force
command, is ``gain * f_est`` per axis, saturated to
+-``f_max`` and rate-limited to ``rate_max``.  All outputs are states updated once per
communication step (no direct feedthrough).

What the joints can tell (``docs/excavator.md``, "Tip force: what the joints can
tell"): the least-squares ``f_est`` always has a value, a guess where the joints carry
no information on a direction.  Beside it, each step, ``n_informative`` counts the
informative joints (``informative_joints``: sliding, by both the fast filter and a
slower one of corner ``f_info``, above ``v_info``, and off both end stops), and
``determined_x/y/z`` says whether their rows of the Jacobian transpose determine that
world component of the tip force (``tip_force_determined``; with the swing resting or
on its stop, x and y are not determined wherever the upper structure is turned).
``f_det_x/y/z`` is the tip force from the informative joints alone (the same low-pass
``tau_est``) where ``determined_*`` is true; where it is false (the physics' ``nan``,
which an FMI output cannot carry) it holds its last determined value, 0 before the
first.  A host reads ``f_det_*`` only together with ``determined_*``.

Bounds where the machine cannot tell: ``f_tip_lo_x/y/z`` and ``f_tip_hi_x/y/z``, per
world axis the smallest and largest tip force consistent with the recording within its
noise (``observer_step``'s ``state["f_lo"]``, ``state["f_hi"]``: a sliding joint's
equation within its tolerance ``band_slide`` and ``band_rate``, a sticking joint's
friction band, one side open for a joint on a stop; the union over the last
``t_hold``).  An FMI Real cannot be infinite: a side the recording leaves open reads
``-f_bound`` or ``+f_bound`` exactly (the declared box), so a host treats
``f_tip_lo_* <= -f_bound`` and ``f_tip_hi_* >= f_bound`` as unbounded.
"""
import math
from dataclasses import replace
from functools import partial

import numpy as np

from boomfmi_excavator_force_estimator_lib.fmislave import BoomSlave, input, output, parameter
from boomfmi_excavator_force_estimator_lib.physics import reference_rig
from boomfmi_excavator_force_estimator_lib.physics.linkage import JOINTS, Excavator, check_excavator
from boomfmi_excavator_force_estimator_lib.physics.force_estimation import (BAND_RATE, BAND_SLIDE, F_BOUND, F_GUESS,
                                                                            F_MOTION, F_MOTION_SWING, F_RATE, T_HOLD,
                                                                            TAU_EST, observer_start, observer_step,
                                                                            reflected_force)
from boomfmi_excavator_force_estimator_lib.physics.validation import require_non_negative, require_positive

_EX = Excavator()
#: the measured inputs' names, per joint in the linkage's order
_ANGLES = tuple(f"angle_{j}" for j in JOINTS)
_P_A = tuple(f"p_a_{j}" for j in JOINTS)
_P_B = tuple(f"p_b_{j}" for j in JOINTS)
_AXES = "xyz"


def _friction(joint):
    a = getattr(_EX, joint)
    return [parameter(f"K_v_{joint}", a.K_v, "N.s/m", f"{joint} cylinder viscous friction coefficient (Eq. 8)", min=0.0),
            parameter(f"F_s_{joint}", a.F_s, "N", f"{joint} cylinder static friction force (Eq. 9)", min=0.0),
            parameter(f"F_d_{joint}", a.F_d, "N", f"{joint} cylinder Coulomb friction force (Eq. 9)", min=0.0)]


class ExcavatorForceEstimator(BoomSlave):
    description = ("Excavator tip force estimation: per-joint load observers combined by least squares over the "
                   "Jacobian transpose, which components the sliding joints determine, and 3-axis joystick "
                   "force reflection")
    variables = (
        *(v for j in JOINTS for v in (
            input(f"p_a_{j}", 0.0, "Pa", f"measured pressure in the {j} cylinder's chamber A (cap side), gauge"),
            input(f"p_b_{j}", 0.0, "Pa", f"measured pressure in the {j} cylinder's chamber B (rod side), gauge"),
            input(f"angle_{j}", float(_EX.actuators[JOINTS.index(j)].lower_limit + 0.5 * (
                _EX.actuators[JOINTS.index(j)].upper - _EX.actuators[JOINTS.index(j)].lower_limit)), "rad",
                  f"measured {j} joint angle (the recording's angle_{j})", min=-2 * math.pi, max=2 * math.pi))),
        *(output(f"f_est_{c}", 0.0, "N", f"estimated force of the environment on the bucket tip, world {c}")
          for c in _AXES),
        *(output(f"f_reflect_{c}", 0.0, "N", f"joystick force command, axis {c}: gain * f_est_{c}, saturated and "
                 "rate-limited") for c in _AXES),
        output("residual", 0.0, "N.m", "misfit |J^T f - tau| of the four joints' torques to the estimated tip force",
               min=0.0),
        output("n_informative", 0, "1", "number of informative joints (sliding, off their end stops), whose "
               "torques alone give f_det", min=0, max=len(JOINTS), type="Integer"),
        *(output(f"determined_{c}", False, "1", f"true where the informative joints determine the tip force's world "
                 f"{c} component (then f_det_{c} is their estimate); false: cannot tell, f_est_{c} is a guess",
                 type="Boolean") for c in _AXES),
        *(output(f"f_det_{c}", 0.0, "N", f"tip force, world {c}, from the informative joints alone where "
                 f"determined_{c}; else held at its last determined value (0 before the first)") for c in _AXES),
        *(output(f"f_tip_lo_{c}", -F_BOUND, "N", f"smallest tip force, world {c}, consistent with the recording "
                 f"within its noise; -f_bound: unbounded below") for c in _AXES),
        *(output(f"f_tip_hi_{c}", F_BOUND, "N", f"largest tip force, world {c}, consistent with the recording "
                 f"within its noise; +f_bound: unbounded above") for c in _AXES),
        *(v for j in JOINTS for v in _friction(j)),
        parameter("payload", 0.0, "kg", "payload in the bucket (identified)", min=0.0),
        parameter("P_atm", reference_rig.P_atm, "Pa", "atmospheric pressure (gauge to absolute)", min=0.0),
        parameter("f_motion", F_MOTION, "Hz", "corner frequency of the critically damped filter of the measured "
                  "boom, arm and bucket angles and their pneumatic forces", min=0.0),
        parameter("f_motion_swing", F_MOTION_SWING, "Hz", "the same filter's corner for the swing (its row alone "
                  "feels the lateral force)", min=0.0),
        parameter("tau_est", TAU_EST, "s", "time constant of the estimate's low-pass; 0: none", min=0.0),
        parameter("rest_weight", 0.3, "1", "least-squares guess's weight of a joint at rest (1: a sliding joint's)",
                  min=0.0),
        parameter("stop_weight", 0.02, "1", "least-squares guess's weight of a joint at an end stop", min=0.0),
        parameter("f_rate", F_RATE, "N/s", "how fast the tip force may plausibly change: the previous estimate's "
                  "weight where the consistent set bounds an axis", min=0.0),
        parameter("f_guess", F_GUESS, "N", "the least-squares guess's weight (its tolerance) in the estimate",
                  min=0.0),
        parameter("v_info", 1e-3, "m/s", "above this piston speed (by both filters) a sliding joint is informative",
                  min=0.0),
        parameter("f_info", 3.0, "Hz", "corner frequency of the slower filter of the angles that tells sliding joints",
                  min=0.0),
        parameter("band_slide", BAND_SLIDE, "1", "tolerance of a sliding joint's equation in the bounds, as a share "
                  "of its static friction", min=0.0),
        parameter("band_rate", BAND_RATE, "1", "the bounds' tolerance's share of the filtered pneumatic force's "
                  "change over the filter's delay", min=0.0),
        parameter("f_bound", F_BOUND, "N", "the bounds' box: a side at -+f_bound is unbounded by the recording",
                  min=0.0),
        parameter("t_hold", T_HOLD, "s", "the bounds reported are the union over this long a window", min=0.0),
        parameter("gain", 0.05, "1", "joystick force per estimated force", min=0.0),
        parameter("f_max", 20.0, "N", "joystick force saturation, per axis", min=0.0),
        parameter("rate_max", 500.0, "N/s", "joystick force rate limit, per axis", min=0.0),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "excavator_force_estimator"
        self._reset()

    def _reset(self):
        """The outputs before the first step; the observer starts at the first measurement."""
        self._f = np.zeros(3)
        self._r = np.zeros(3)
        self._res = 0.0
        self._f_det = np.zeros(3)
        bound = float(getattr(self, "f_bound", F_BOUND))
        self._lo, self._hi = np.full(3, -bound), np.full(3, bound)
        self._state = None

    def setup(self):
        for name in ("payload", "tau_est", "rest_weight", "stop_weight", "gain", "v_info", "band_slide", "band_rate",
                     "t_hold"):
            require_non_negative(name, getattr(self, name))
        for name in ("f_motion", "f_motion_swing", "f_info", "f_max", "rate_max", "P_atm", "f_bound", "f_rate",
                     "f_guess"):
            require_positive(name, getattr(self, name))
        acts = {j: replace(getattr(_EX, j), K_v=getattr(self, f"K_v_{j}"), F_s=getattr(self, f"F_s_{j}"),
                           F_d=getattr(self, f"F_d_{j}")) for j in JOINTS}
        ex = replace(_EX, **acts, P_atm=self.P_atm)
        check_excavator(ex)
        self._ex = ex
        omega = 2.0 * math.pi * np.array([self.f_motion_swing] + [self.f_motion] * 3)     # swing, boom, arm, bucket
        self._observe = partial(observer_step, omega=omega, ex=ex, payload=self.payload,
                                tau_est=self.tau_est, rest_weight=self.rest_weight,
                                stop_weight=self.stop_weight, v_info=self.v_info, f_info=self.f_info,
                                band_slide=self.band_slide, band_rate=self.band_rate, f_bound=self.f_bound,
                                t_hold=self.t_hold, f_rate=self.f_rate, f_guess=self.f_guess)
        self._reset()

    def step(self, t, dt):
        q = [getattr(self, n) for n in _ANGLES]
        p_a = np.array([getattr(self, n) for n in _P_A]) + self.P_atm
        p_b = np.array([getattr(self, n) for n in _P_B]) + self.P_atm
        if self._state is None:             # the filters start at rest at the first measurement
            self._state = observer_start(q, p_a, p_b, self._ex)
        self._state, self._f, self._res, _ = self._observe(self._state, q, p_a, p_b, dt)
        self._r = reflected_force(self._f, self._r, dt, self.gain, self.f_max, self.rate_max)   # per axis
        known = self._state["f_known"]
        self._f_det = np.where(np.isfinite(known), known, self._f_det)     # held where undetermined
        self._lo, self._hi = self._state["f_lo"], self._state["f_hi"]


def _determined(self, i: int) -> bool:
    """Whether the informative joints determine world component ``i`` (the physics'
    ``f_known`` is nan where they cannot tell)."""
    return self._state is not None and bool(np.isfinite(self._state["f_known"][i]))


ExcavatorForceEstimator.residual = property(lambda self: float(self._res))
ExcavatorForceEstimator.n_informative = property(
    lambda self: 0 if self._state is None else int(np.sum(self._state["informative"])))
for _i, _c in enumerate(_AXES):
    setattr(ExcavatorForceEstimator, f"f_est_{_c}", property(lambda self, i=_i: float(self._f[i])))
    setattr(ExcavatorForceEstimator, f"f_reflect_{_c}", property(lambda self, i=_i: float(self._r[i])))
    setattr(ExcavatorForceEstimator, f"determined_{_c}", property(lambda self, i=_i: _determined(self, i)))
    setattr(ExcavatorForceEstimator, f"f_det_{_c}", property(lambda self, i=_i: float(self._f_det[i])))
    setattr(ExcavatorForceEstimator, f"f_tip_lo_{_c}", property(lambda self, i=_i: float(self._lo[i])))
    setattr(ExcavatorForceEstimator, f"f_tip_hi_{_c}", property(lambda self, i=_i: float(self._hi[i])))
