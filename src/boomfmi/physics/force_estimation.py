"""Estimating the external (digging) force on the piston, and reflecting it to the joystick.

Two estimators, both giving the force positive against extension, like ``f_ext``:

**Position error** (the paper's, Sec. 2).  The model runs on the operator's commands
beside the machine; with no load both move alike, and an external force on the machine
makes it lag the model.  The gap becomes a force::

    f_est = K (x_model - x_measured) + D (v_model - v_measured)

with K [N/m] the model's pneumatic stiffness at its current state,
``k (p_a A_a^2 / V_a + p_b A_b^2 / V_b)`` (:func:`pneumatic_stiffness`), or a fixed
calibrated gain, and D [N s/m] a damping gain (default the viscous coefficient K_v).

**Load observer** (beyond the paper).  Eq. 8 read backwards, from what the machine's
sensors give: the chamber pressures and the measured motion::

    f_ext = P_a A_a - P_b A_b - P_atm (A_a - A_b) - F_L sin(phi) - K_v v - F_c - M a

with v and a from a critically damped second-order filter of the measured position
(:func:`motion_filter_step`), the known forces (:func:`measured_drive_force`) through
the same filter so that both sides carry the same delay, and the result low-passed
(``lag.first_order_step``).  The
friction F_c is Eq. 9's: ``F_d cos(phi)`` against the motion while sliding.  At rest
Eq. 9 lets friction hold any force up to ``F_s cos(phi)``, which no sensor can tell
apart from an external force; the observer then reports only what friction cannot
hold (:func:`observed_external_force`), so a boom held still in free air shows no
force, and a bucket pressed into the ground shows the push beyond the static friction.
At an end stop the stop's reaction is likewise indistinguishable from a force towards
the stop, so only a force away from the stop is reported.  A gauge transducer cannot
read below atmospheric: where a chamber's reading sits at the sensor's floor, the
model's pressure stands in when it is lower (:func:`below_sensor_floor`).

The joystick receives ``f_reflect``: ``f_est`` scaled, saturated and rate-limited
(:func:`reflected_force`).
"""
from __future__ import annotations

import math

from . import _xp as xp
from .chamber import chamber_volumes
from .geometry import phi_from_x
from .load import piston_force
from .params import Cylinder, Gas, Geometry, Load


def position_error_force(x_model, x_measured, v_model, v_measured, K_p, D):
    """The paper's estimate [N] from the position [m] and velocity [m/s] gaps, with
    stiffness ``K_p`` [N/m] and damping ``D`` [N s/m]."""
    return K_p * (x_model - x_measured) + D * (v_model - v_measured)


def pneumatic_stiffness(p_a, p_b, x, cyl: Cylinder = Cylinder(), gas: Gas = Gas()):
    """Stiffness [N/m] of the two air springs at absolute pressures ``p_a``, ``p_b``
    [Pa] and piston position ``x`` [m]: ``k (p_a A_a^2 / V_a + p_b A_b^2 / V_b)``."""
    V_a, V_b = chamber_volumes(x, cyl)
    return gas.k * (p_a * cyl.A_a**2 / V_a + p_b * cyl.A_b**2 / V_b)


def motion_filter_step(x_f: float, v_f: float, x_measured: float, dt: float, omega: float):
    """The critically damped second-order filter of a measured position, after ``dt``
    [s] with ``x_measured`` [m] held: ``x_f'' = omega^2 (x_measured - x_f) - 2 omega
    x_f'`` (``omega`` [rad/s]), solved exactly.  Returns the filter's state at the end
    of the step, position [m] and velocity [m/s], and the mean velocity [m/s] and mean
    acceleration [m/s^2] over the step: on a sampled ramp these are exact, where the
    state at the step's end is biased by the held input (the acceleration by ``-omega^2
    v dt / 2``).  The group delay is ``2 / omega``."""
    e0 = x_f - x_measured
    c = v_f + omega * e0
    decay = math.exp(-omega * dt)
    e = (e0 + c * dt) * decay
    v = (v_f - omega * c * dt) * decay
    x_new = x_measured + e
    return x_new, v, (x_new - x_f) / dt, (v - v_f) / dt


def measured_drive_force(p_a: float, p_b: float, x: float, cyl: Cylinder = Cylinder(),
                         geom: Geometry = Geometry(), load: Load = Load(),
                         P_atm: float = 101_325.0) -> float:
    """The known forces on the piston [N, positive extending] from what the machine
    measures: the air's (absolute pressures ``p_a``, ``p_b`` [Pa]) less the boom's
    weight, ``piston_force - F_L sin(phi)`` at position ``x`` [m].  The observer passes
    it through the same filter as the position, so that it and ``M a`` carry the same
    delay: on a sharp acceleration the filtered acceleration lags the pressures, and
    the gap would read as a force."""
    phi = phi_from_x(min(max(x, 0.0), cyl.L), geom)
    return piston_force(p_a, p_b, cyl, P_atm) - load.F_L * math.sin(phi)


def below_sensor_floor(p_measured, p_model, p_floor):
    """A chamber pressure for the observer [Pa, gauge]: the measured ``p_measured``,
    unless it sits at or below the sensor's lower limit ``p_floor`` (a 0 to 10 bar gauge
    transducer reads 0 for any vacuum) while the model beside the machine has a lower
    ``p_model``; then the model's, the better guess of a pressure the sensor cannot
    show."""
    return p_model if (p_measured <= p_floor and p_model < p_measured) else p_measured


def observed_external_force(drive: float, x: float, v: float, a: float,
                            cyl: Cylinder = Cylinder(), geom: Geometry = Geometry(),
                            load: Load = Load(), v_rest: float = 2e-3, x_stop: float = 5e-4) -> float:
    """The external force [N, positive against extension] that Eq. 8 needs to explain
    the known forces ``drive`` [N] (:func:`measured_drive_force`, filtered like the
    motion), at position ``x`` [m], velocity ``v`` [m/s] and acceleration ``a`` [m/s^2].

    Below ``v_rest`` [m/s] the piston counts as at rest: the force friction can hold
    (``F_s cos(phi)``) is taken off the unexplained force, towards zero.  Within
    ``x_stop`` [m] of an end stop, a force towards that stop is the stop's reaction and
    is not reported."""
    c = math.cos(phi_from_x(min(max(x, 0.0), cyl.L), geom))
    residual = drive - load.M * a
    if abs(v) > v_rest:
        f = residual - load.K_v * v - math.copysign(load.F_d * c, v)
    else:
        hold = load.F_s * c
        f = residual - max(-hold, min(hold, residual))
    if x <= x_stop:
        f = max(f, 0.0)          # the stop at x = 0 pushes extension: f_ext < 0 cannot be told apart
    elif x >= cyl.L - x_stop:
        f = min(f, 0.0)
    return f


def reflected_force(f_est, f_prev, dt, gain, f_max, rate_max):
    """Joystick force command [N] after ``dt`` [s].

    The target ``gain * f_est`` is saturated to +-``f_max`` [N]; the command moves from
    ``f_prev`` towards it by at most ``rate_max * dt`` [N].
    """
    target = xp.clip(gain * f_est, -f_max, f_max)
    step = rate_max * dt
    return f_prev + xp.clip(target - f_prev, -step, step)
