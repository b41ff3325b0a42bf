"""Force estimation from the model-minus-machine gap, and force reflection.

The paper's scheme (Sec. 2): the model runs on the operator's commands beside the
machine; with no load both move alike, and an external force on the machine makes it
lag the model.  The position-error estimator turns that lag into a force::

    f_est = K_p (x_model - x_measured) + D (v_model - v_measured)

positive against extension, like ``f_ext``.  K_p [N/m] plays the role of the drive's
pneumatic stiffness k (p_a A_a^2 / V_a + p_b A_b^2 / V_b) and D [N s/m] of its
viscous friction.  The joystick receives ``f_reflect``: ``f_est`` scaled, saturated and
rate-limited.
"""
from __future__ import annotations

from . import _xp as xp
from .chamber import chamber_volumes
from .params import Cylinder, Gas


def position_error_force(x_model, x_measured, v_model, v_measured, K_p, D):
    """Estimated external force [N] from the position [m] and velocity [m/s] gaps."""
    return K_p * (x_model - x_measured) + D * (v_model - v_measured)


def pneumatic_stiffness(p_a, p_b, x, cyl: Cylinder = Cylinder(), gas: Gas = Gas()):
    """Stiffness [N/m] of the two air springs at absolute pressures ``p_a``, ``p_b``
    [Pa] and piston position ``x`` [m]: ``k (p_a A_a^2 / V_a + p_b A_b^2 / V_b)``."""
    V_a, V_b = chamber_volumes(x, cyl)
    return gas.k * (p_a * cyl.A_a**2 / V_a + p_b * cyl.A_b**2 / V_b)


def reflected_force(f_est, f_prev, dt, gain, f_max, rate_max):
    """Joystick force command [N] after ``dt`` [s].

    The target ``gain * f_est`` is saturated to +-``f_max`` [N]; the command moves from
    ``f_prev`` towards it by at most ``rate_max * dt`` [N].
    """
    target = xp.clip(gain * f_est, -f_max, f_max)
    step = rate_max * dt
    return f_prev + xp.clip(target - f_prev, -step, step)
