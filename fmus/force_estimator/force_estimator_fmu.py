"""force_estimator: the external (digging) force on the boom, and the joystick's force.

Two methods (parameter ``method``), both giving ``f_est`` positive against extension,
like f_ext (``physics/force_estimation.py``):

* ``position_error`` (the paper's): ``K (x_model - x_measured) + D (v_model -
  v_measured)``, K the model's pneumatic stiffness k (p_a A_a^2/V_a + p_b A_b^2/V_b) at
  its current pressures and position (``K_p`` = 0), or a calibrated ``K_p`` > 0;
* ``observer``: Eq. 8 read backwards from the machine's measured pressures and motion
  with the identified load parameters, the pressures' force filtered like the motion
  (the same delay on both sides); at rest only the force that static friction cannot
  hold is reported; a pressure reading at the sensor's floor (``p_floor``, 0 Pa gauge)
  gives way to the model's where that is lower (vacuum).

The measured position passes a critically damped second-order filter (``f_motion``)
that gives the machine's velocity (output ``v_measured``, the mean over the last
step) and acceleration; the
estimate then passes a first-order low-pass (``tau_est``).  ``f_reflect``, the
joystick's force command, is ``gain * f_est`` saturated to +-``f_max`` and rate-limited
to ``rate_max``.  All outputs are states, updated once per communication step from the
inputs held over it (no direct feedthrough, so no algebraic loop in any coupling).
"""
import math

from boomfmi_force_estimator_lib.fmislave import (CYLINDER, GEOMETRY, L_MAX, LOAD,
                                                  BoomSlave, input, output, parameter, rig_parameters)
from boomfmi_force_estimator_lib.physics import (Cylinder, Gas, Geometry, Load, ParameterError, below_sensor_floor,
                                                 check_cylinder, check_gas, check_geometry, check_load,
                                                 measured_drive_force, motion_filter_step, first_order_step,
                                                 observed_external_force, observer_filter_step, pneumatic_stiffness,
                                                 position_error_force, reflected_force)
from boomfmi_force_estimator_lib.physics import reference_rig
from boomfmi_force_estimator_lib.physics.validation import require_non_negative, require_positive

METHODS = ("position_error", "observer")


class ForceEstimator(BoomSlave):
    description = "External force estimation (the paper's position error, or a load observer) and joystick force reflection"
    variables = (
        input("x_model", 0.0, "m", "position_error: piston position of the model, within its stroke [0, L]", min=0.0, max=L_MAX),
        input("v_model", 0.0, "m/s", "position_error: piston velocity of the model"),
        input("p_a_model", reference_rig.P_atm, "Pa", "absolute chamber A pressure of the model (position_error: its stiffness; observer: below the sensor's floor)", min=0.0),
        input("p_b_model", reference_rig.P_atm, "Pa", "absolute chamber B pressure of the model (position_error: its stiffness; observer: below the sensor's floor)", min=0.0),
        input("x_measured", 0.0, "m", "piston position of the machine"),
        input("p_a_measured", 0.0, "Pa", "observer: measured chamber A pressure, gauge (as the bridge gives it)"),
        input("p_b_measured", 0.0, "Pa", "observer: measured chamber B pressure, gauge (as the bridge gives it)"),
        output("f_est", 0.0, "N", "estimated external force on the piston, positive against extension"),
        output("f_reflect", 0.0, "N", "joystick force command: gain * f_est, saturated and rate-limited"),
        output("v_measured", 0.0, "m/s", "the machine's piston velocity, from the filtered measured position"),
        parameter("method", "observer", "1", "position_error (the paper's) or observer", type="String"),
        parameter("K_p", 0.0, "N/m", "position_error: calibrated stiffness; 0: the model's pneumatic stiffness at its state", min=0.0),
        parameter("D", reference_rig.K_v, "N.s/m", "position_error: velocity-error gain; default the viscous friction K_v", min=0.0),
        parameter("f_motion", 30.0, "Hz", "corner frequency of the critically damped filter of the measured position", min=0.0),
        parameter("tau_est", 0.004, "s", "time constant of the estimate's low-pass; 0: none", min=0.0),
        parameter("v_rest", 2e-3, "m/s", "observer: below this filtered speed the piston counts as at rest", min=0.0),
        parameter("p_floor", 0.0, "Pa", "observer: the pressure sensors' lower limit, gauge (0: a 0 to 10 bar gauge transducer, blind to vacuum); a reading at it gives way to the model's lower pressure; -1e5 or less: off"),
        parameter("gain", 0.05, "1", "joystick force per estimated force", min=0.0),
        parameter("f_max", 20.0, "N", "joystick force saturation", min=0.0),
        parameter("rate_max", 500.0, "N/s", "joystick force rate limit", min=0.0),
        *rig_parameters(*LOAD, *CYLINDER, "k", "P_atm", *GEOMETRY),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "force_estimator"
        self._started = False

    def setup(self):
        if self.method not in METHODS:
            raise ParameterError("method", self.method, "must be 'position_error' or 'observer'")
        for name in ("K_p", "D", "tau_est", "v_rest", "gain"):
            require_non_negative(name, getattr(self, name))
        for name in ("f_motion", "f_max", "rate_max", "P_atm"):
            require_positive(name, getattr(self, name))
        self._cyl = Cylinder(A_a=self.A_a, A_b=self.A_b, L=self.L, V_a0=self.V_a0, V_b0=self.V_b0)
        self._gas = Gas(k=self.k)
        self._geom = Geometry(a=self.a, b=self.b, h=self.h, l_min=self.l_min)
        self._load = Load(K_v=self.K_v, F_s=self.F_s, F_d=self.F_d, F_L=self.F_L, M=self.M)
        check_cylinder(self._cyl)
        check_gas(self._gas)
        check_geometry(self._geom, self.L)
        check_load(self._load)
        self._omega = 2.0 * math.pi * self.f_motion
        self.f_est = self.f_reflect = self.v_measured = 0.0
        self._started = False

    def step(self, t, dt):
        if self.method == "observer":
            p_a = below_sensor_floor(self.p_a_measured, self.p_a_model - self.P_atm, self.p_floor) + self.P_atm
            p_b = below_sensor_floor(self.p_b_measured, self.p_b_model - self.P_atm, self.p_floor) + self.P_atm
            drive = measured_drive_force(p_a, p_b, self.x_measured, self._cyl, self._geom, self._load, self.P_atm)
            if not self._started:           # the filters start at rest at the first measurement
                self._x_f, self._v_f, self._d_f, self._dd_f = self.x_measured, 0.0, drive, 0.0
            (self._x_f, self._v_f, self.v_measured, a, self._d_f, self._dd_f,
             d_mid) = observer_filter_step(self._x_f, self._v_f, self._d_f, self._dd_f, self.x_measured, drive, dt,
                                           self._omega)
            force = observed_external_force(d_mid, self.x_measured, self.v_measured, a,
                                            self._cyl, self._geom, self._load, self.v_rest)
        else:
            if not self._started:
                self._x_f, self._v_f = self.x_measured, 0.0
            self._x_f, self._v_f, self.v_measured, _ = motion_filter_step(self._x_f, self._v_f, self.x_measured,
                                                                          dt, self._omega)
            x_m = min(max(self.x_model, 0.0), self.L)
            K = self.K_p or pneumatic_stiffness(self.p_a_model, self.p_b_model, x_m, self._cyl, self._gas)
            force = position_error_force(self.x_model, self.x_measured, self.v_model, self.v_measured, K, self.D)
        self._started = True
        self.f_est = first_order_step(self.f_est, force, dt, self.tau_est)
        self.f_reflect = reflected_force(self.f_est, self.f_reflect, dt, self.gain, self.f_max, self.rate_max)
