"""force_estimator: the paper's position-error force estimator and the joystick force.

Inputs the model's and the machine's piston positions and velocities; outputs the
estimated external force ``f_est = K_p (x_model - x_measured) + D (v_model - v_measured)``
(positive against extension, like f_ext) and ``f_reflect``, the joystick force command:
``gain * f_est`` saturated to +-f_max and rate-limited to rate_max, updated once per
communication step.
"""
from boomfmi_force_estimator_lib.fmislave import BoomSlave, input, output, parameter
from boomfmi_force_estimator_lib.physics import position_error_force, reflected_force
from boomfmi_force_estimator_lib.physics.validation import require_non_negative, require_positive


class ForceEstimator(BoomSlave):
    description = "Position-error force estimation and joystick force reflection (paper Sec. 2)"
    variables = (
        input("x_model", 0.0, "m", "piston position of the model"),
        input("x_measured", 0.0, "m", "piston position of the machine"),
        input("v_model", 0.0, "m/s", "piston velocity of the model"),
        input("v_measured", 0.0, "m/s", "piston velocity of the machine"),
        output("f_est", 0.0, "N", "estimated external force on the piston, positive against extension",
               depends=("x_model", "x_measured", "v_model", "v_measured")),
        output("f_reflect", 0.0, "N", "joystick force command: gain * f_est, saturated and rate-limited"),
        parameter("K_p", 2.0e4, "N/m", "position-error gain; default: the pneumatic stiffness "
                  "k (p_a A_a^2/V_a + p_b A_b^2/V_b) of the reference rig extending at mid-stroke", min=0.0),
        parameter("D", 2829.0, "N.s/m", "velocity-error gain; default: the viscous friction K_v", min=0.0),
        parameter("gain", 0.05, "1", "joystick force per estimated force", min=0.0),
        parameter("f_max", 20.0, "N", "joystick force saturation", min=0.0),
        parameter("rate_max", 500.0, "N/s", "joystick force rate limit", min=0.0),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "force_estimator"

    def setup(self):
        require_non_negative("K_p", self.K_p)
        require_non_negative("D", self.D)
        require_non_negative("gain", self.gain)
        require_positive("f_max", self.f_max)
        require_positive("rate_max", self.rate_max)
        self.f_reflect = 0.0

    @property
    def f_est(self):
        return position_error_force(self.x_model, self.x_measured, self.v_model,
                                    self.v_measured, self.K_p, self.D)

    def step(self, t, dt):
        self.f_reflect = reflected_force(self.f_est, self.f_reflect, dt, self.gain,
                                         self.f_max, self.rate_max)
