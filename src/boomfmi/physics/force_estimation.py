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
(:func:`reflected_force`, per axis for the excavator's 3-axis joystick).

One core for one joint or four: :func:`observed_joint_forces` is the observer of a joint
set (the boom's one cylinder, with mass M, ``F_L sin(phi)`` among the known forces and
friction scale ``cos(phi)``; or the excavator's four through the linkage), the rest/hold
band (:func:`friction_band`) and the stop clipping written once.  The excavator's tip
force (least squares over the Jacobian transpose, what the joints can tell, the bounds,
the observer over a recording) is the last section of this module.
"""
from __future__ import annotations

import math

import numpy as np

from . import _xp as xp
from . import linkage as exc
from .chamber import chamber_volumes
from .geometry import phi_from_x
from .lag import first_order_step
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


def observer_filter_step(x_f: float, v_f: float, d_f: float, dd_f: float, x_measured: float, drive: float,
                         dt: float, omega: float):
    """One step of a joint observer's two filters (:func:`motion_filter_step`, corner
    ``omega`` [rad/s]): the measured position ``x_measured`` [m] and the known forces
    ``drive`` [N] (:func:`measured_drive_force`) through the same filter, so that the
    force and ``M a`` carry the same delay.  Returns the position filter's new state
    ``(x_f, v_f)``, its mean velocity and acceleration over the step, the force
    filter's new state ``(d_f, dd_f)`` and its mean over the step (the midpoint)."""
    x_f, v_f, v_mean, a_mean = motion_filter_step(x_f, v_f, x_measured, dt, omega)
    d_1, dd_f, _, _ = motion_filter_step(d_f, dd_f, drive, dt, omega)
    return x_f, v_f, v_mean, a_mean, d_1, dd_f, 0.5 * (d_f + d_1)


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


def friction_band(net: float, v: float, friction, scale: float, direction, margin: float = 0.0):
    """The interval ``(lo, hi)`` of the external force on one piston [N, positive against
    extension] that Eq. 8 and 9 allow, ``net`` [N] the known forces less the inertial
    ones, ``v`` [m/s] its velocity, ``friction`` its ``(K_v, F_s, F_d)`` and ``scale``
    their normal-force scale: sliding (``direction`` -1 or +1) the sliding law's value
    ``net - K_v v - F_d scale direction``; at rest (``direction`` None) anything that
    static friction can hold, ``net +- F_s scale``; widened by ``margin`` [N] each side."""
    K_v, F_s, F_d = friction
    if direction is None:
        hold = F_s * scale + margin
        return net - hold, net + hold
    f = net - K_v * v - direction * F_d * scale
    return f - margin, f + margin


def observed_joint_forces(net, x, v, strokes, friction, scale, v_rest: float = 2e-3, x_stop: float = 5e-4,
                          sliding=None, x_measured=None):
    """The external force on each piston of a joint set [N, positive against extension]
    that the equation of motion needs to explain the known forces: the boom's one
    cylinder (:func:`observed_external_force`) or the excavator's four through the
    linkage (:func:`observed_joint_torques`).  Per joint: ``net`` [N] the known forces
    less the inertial ones (drive - M a - bias, positive extending), position ``x``
    [m] (clipped to ``0 .. strokes``), velocity ``v`` [m/s], ``friction`` the
    ``(K_v, F_s, F_d)`` of Eq. 8 and 9 and ``scale`` their normal-force scale (the
    boom's ``cos(phi)``).

    Sliding (``|v|`` above ``v_rest`` [m/s]): ``net - K_v v - F_d scale sign(v)``.  At rest
    the force friction can hold (``F_s scale``) is taken off the unexplained force,
    towards zero (the force in :func:`friction_band` nearest none).  ``sliding``
    (optional, per joint -1, 0 or +1): a joint with a
    non-zero entry counts as sliding that way, whatever ``v`` says (a slow creep that a
    fast filter's speed, noisy with the angle sensor's steps, misses).  Within
    ``x_stop`` [m] of an end stop a force towards that stop is the stop's reaction and
    is not reported; ``x_measured`` (optional) [m]: the unfiltered positions, a joint
    within ``x_stop`` of a stop by either counts as there (an arrival's impact reaches
    the stop in the measurement a filter's delay before the filtered position does).

    Returns lists ``(f, resting, at_stop)``: the forces, and per joint whether it counted
    as at rest (its force then only what static friction cannot hold) and whether it
    is at an end stop.  Plain floats per joint: the boom's FMU calls it a thousand
    times a second."""
    f, resting, at_stop = [], [], []
    for i in range(len(net)):
        L = strokes[i]
        xi = min(max(x[i], 0.0), L)
        s = 0 if sliding is None else sliding[i]
        rest = s == 0 and abs(v[i]) <= v_rest
        sign = s if s != 0 else v[i]
        lo, hi = friction_band(net[i], v[i], friction[i], scale[i],
                               None if rest else (1.0 if sign > 0 else -1.0 if sign < 0 else 0.0))
        fi = lo if lo > 0.0 else (hi if hi < 0.0 else 0.0)     # the band's force nearest none
        xl = xi if x_measured is None else min(xi, x_measured[i])
        xu = xi if x_measured is None else max(xi, x_measured[i])
        if xl <= x_stop:
            fi = max(fi, 0.0)    # the lower stop pushes extension: f_ext < 0 cannot be told apart
        if xu >= L - x_stop:
            fi = min(fi, 0.0)
        f.append(fi)
        resting.append(rest)
        at_stop.append(xl <= x_stop or xu >= L - x_stop)
    return f, resting, at_stop


def observed_external_force(drive: float, x: float, v: float, a: float,
                            cyl: Cylinder = Cylinder(), geom: Geometry = Geometry(),
                            load: Load = Load(), v_rest: float = 2e-3, x_stop: float = 5e-4) -> float:
    """The external force [N, positive against extension] that Eq. 8 needs to explain
    the known forces ``drive`` [N] (:func:`measured_drive_force`, filtered like the
    motion), at position ``x`` [m], velocity ``v`` [m/s] and acceleration ``a`` [m/s^2]:
    :func:`observed_joint_forces` for the boom's one joint (mass ``M``, friction scale
    ``cos(phi)``).

    Below ``v_rest`` [m/s] the piston counts as at rest: the force friction can hold
    (``F_s cos(phi)``) is taken off the unexplained force, towards zero.  Within
    ``x_stop`` [m] of an end stop, a force towards that stop is the stop's reaction and
    is not reported."""
    c = math.cos(phi_from_x(min(max(x, 0.0), cyl.L), geom))
    f, _, _ = observed_joint_forces((drive - load.M * a,), (x,), (v,), (cyl.L,),
                                    ((load.K_v, load.F_s, load.F_d),), (c,), v_rest, x_stop)
    return f[0]


def reflected_force(f_est, f_prev, dt, gain, f_max, rate_max):
    """Joystick force command [N] after ``dt`` [s], a float or per axis (the excavator's
    3-axis joystick: arrays).

    The target ``gain * f_est`` is saturated to +-``f_max`` [N]; the command moves from
    ``f_prev`` towards it by at most ``rate_max * dt`` [N].
    """
    target = xp.clip(gain * f_est, -f_max, f_max)
    step = rate_max * dt
    return f_prev + xp.clip(target - f_prev, -step, step)


# ---------------------------------------------------------------------------------------
# The excavator: the tip force from four joints through the linkage
# ---------------------------------------------------------------------------------------
#
# The force of the environment on the bucket tip, and its 3-axis joystick.  Per joint
# :func:`observed_joint_forces` (the boom's observer) on each cylinder's equation of
# motion in piston coordinates (``linkage.piston_dynamics``) read backwards::
#
#     lam_i (J^T f_tip)_i = (M_x x'' + bias)_i - F_p,i + friction_i
#
# with x, x', x'' from the critically damped filter of the measured angles (through
# Eq. 12 and the triangles to piston positions), F_p the measured pressures' forces
# through the same filter, the bias the Coriolis, centrifugal and gravity forces.  A
# joint slides only where it is informative (:func:`informative_joints`); any other is
# at rest, and one that a slower filter sees still has no speed or acceleration of its
# own (the angle sensor's steps are not motion).
#
# The tip force (three unknowns) from the four joint torques by least squares over the
# Jacobian transpose, ``min |W (J^T f - tau)|``; the residual ``|J^T f - tau|`` [N m]
# says how far the four observers disagree (a force elsewhere than at the tip, or a
# model error, shows there).  A joint that rests (its torque only known to within its
# static friction) counts with weight ``rest_weight``, one at an end stop (a force towards
# the stop unknown) with ``stop_weight``.  That is the guess; the estimate is the force
# within the set consistent with the sample that best fits the sliding joints'
# equations, its last value and the guess (``consistent_tip_force``).

def _joint_terms(x, v, a, drive, ex: exc.Excavator, payload: float):
    """What the joints' force balances start from at one sample: the pistons' positions
    (clipped to the strokes) and velocities, their net known forces ``drive - (M_x a +
    bias)`` [N], the levers ``lam`` and the friction scale (the boom's ``cos(phi)``):
    ``(x, v, net, lam, scale)``."""
    x = np.clip(np.asarray(x, float), 0.0, ex.strokes)
    v = np.asarray(v, float)
    Mx, bias, lam = exc.piston_dynamics(x, v, payload, ex)
    net = np.asarray(drive, float) - (Mx @ np.asarray(a, float) + bias)
    return x, v, net, lam, exc.friction_scale(x, ex)


def observed_joint_torques(x, v, a, drive, ex: exc.Excavator = exc.Excavator(), payload: float = 0.0,
                           v_rest: float = 2e-3, x_stop: float = 5e-4, sliding=None, x_measured=None,
                           terms=None):
    """The joint torques [N m] the environment exerts (``J^T f_tip`` if all of it is at
    the tip), from the pistons' position ``x`` [m], velocity ``v`` [m/s], acceleration
    ``a`` [m/s^2] and the pneumatic forces ``drive`` [N] (4-vectors):
    :func:`observed_joint_forces` through the linkage (``v_rest``, ``x_stop``,
    ``sliding`` and ``x_measured`` are its) times each cylinder's lever.  Returns
    arrays ``(tau, resting, at_stop)``.  ``terms``: :func:`_joint_terms` of these
    arguments, where the caller has them (``observer_step``: once a sample)."""
    x, v, net, lam, scale = terms if terms is not None else _joint_terms(x, v, a, drive, ex, payload)
    f, resting, at_stop = observed_joint_forces(net, x, v, ex.strokes, [(c.K_v, c.F_s, c.F_d) for c in ex.actuators],
                                                scale, v_rest, x_stop, sliding, x_measured)
    return -np.asarray(f) / lam, np.asarray(resting), np.asarray(at_stop)


def tip_force_from_torques(q, tau, weights=None, ex: exc.Excavator = exc.Excavator(), JT=None):
    """The tip force [N] (world frame) whose ``J(q)^T f`` best matches the joint torques
    ``tau`` [N m] (weighted least squares, ``weights`` per joint, default 1), and the
    residual ``|J^T f - tau|`` [N m] (unweighted) of the four equations.  ``JT``:
    ``J(q)^T``, where the caller has it."""
    JT = exc.tip_jacobian(q, ex).T if JT is None else JT
    tau = np.asarray(tau, float)
    w = np.ones(4) if weights is None else np.asarray(weights, float)
    f, *_ = np.linalg.lstsq(JT * w[:, None], tau * w, rcond=None)
    return f, float(np.linalg.norm(JT @ f - tau))


def informative_joints(x, v, ex: exc.Excavator = exc.Excavator(), v_info: float = 1e-3,
                       x_stop: float = 2e-3) -> np.ndarray:
    """Which joints carry information on the tip force: those whose piston slides
    (speed ``v`` [m/s] above ``v_info``; the observer's slow filter's, which the angle
    sensor's steps do not shake) off its end stops by ``x_stop`` [m] (the measured
    position: an arrival's impact reaches the stop before the filters do).  A
    resting joint's torque is known only to within its static friction, one pressed on
    a stop not at all (the stop's reaction takes any force towards it): neither gives
    an equation, only a bound."""
    x = np.asarray(x, float)
    return (np.abs(np.asarray(v, float)) > v_info) & (x > x_stop) & (x < ex.strokes - x_stop)


def tip_force_determined(q, tau, informative, ex: exc.Excavator = exc.Excavator(), sv_min: float = 0.05,
                         miss_max: float = 0.1, JT=None):
    """The tip force [N] from the informative joints' torques alone, ``nan`` for every
    world component they do not determine ("cannot tell", instead of a guess).

    The informative rows of ``J^T`` span the directions of force they feel; directions
    with a singular value below ``sv_min`` [m] (a lever so short that a torque error is
    amplified more than 1 / sv_min) count as unfelt.  A world component ``k`` is
    determined when its axis lies within ``miss_max`` (the sine of the angle) of the
    felt directions: the swing alone feels the lateral force, so with the swing resting
    or on its stop a force along world x or y is undetermined wherever the upper
    structure is turned (x = r cos(theta) - t sin(theta)); with fewer than three joints
    sliding no component may be.  Returns ``(f, known)`` (``known``: bool per axis).
    ``JT``: ``J(q)^T``, where the caller has it."""
    info = np.asarray(informative, bool)
    f = np.full(3, np.nan)
    known = np.zeros(3, bool)
    if not info.any():
        return f, known
    A = (exc.tip_jacobian(q, ex).T if JT is None else JT)[info]
    _, s, vt = np.linalg.svd(A, full_matrices=False)
    r = int(np.sum(s >= sv_min))
    if r == 0:
        return f, known
    basis = vt[:r]
    sol = basis.T @ ((basis @ np.linalg.pinv(A) @ np.asarray(tau, float)[info]))
    miss = np.sqrt(np.clip(1.0 - np.sum(basis ** 2, axis=0), 0.0, None))
    known = miss <= miss_max
    f[known] = sol[known]
    return f, known


#: [N] The tip force bounds' box: no tip force beyond this along any world axis (some
#: ten times the cylinders' largest push at the tip).  A bound at +-F_BOUND says the
#: recording does not bound that side (a stop takes any force towards it, or the
#: joints that feel the axis stick with nothing to hold them from one side).
F_BOUND = 500.0
#: [1] The sliding law's tolerance per cylinder, as a share of its static friction
#: ``F_s`` (which scales with the bore, as the pressures' noise on the piston does):
#: what the angle sensor's noise and steps through the motion filter and the pressures'
#: noise make of the net force.
BAND_SLIDE = 0.1
#: [1] The tolerance's share of the filtered net force's change over the filters' delay.
BAND_RATE = 1.0
#: [m/s] The bounds take a joint's sliding law only above this speed (by both filters):
#: a joint that has just stopped still reads as sliding through the slow filter's
#: delay, and its static friction may hold more than its sliding friction; below it
#: its friction band (which holds any slow creep's) bounds it instead.  Was 3 mm/s: at
#: 1.5 mm/s the closed-loop dig's slow joints bound the force by their equations, the
#: interval's median width falls (closed_loop_soft y 17.0 -> 11.3 N, the digging cycle's
#: soft soil z 51.7 -> 31.1 N) with every scenario's coverage still >= 95 % per axis
#: (at 1 mm/s the load cell's push z RMSE rose 6.1 -> 7.5 %; ``docs/excavator.md``).
V_SLIDE_BOUNDS = 1.5e-3
#: [N/s] How fast the tip force may plausibly change: the weight of the previous
#: estimate in :func:`consistent_tip_force`.
F_RATE = 1000.0
#: [N] The weight of the least-squares guess (:func:`tip_force_from_torques`, the
#: resting joints' friction taken as what holds them) in :func:`consistent_tip_force`:
#: where nothing bounds a direction (a stop takes the force) the estimate relaxes to the
#: guess instead of wandering with the set's sides (over ``(F_GUESS / (F_RATE dt))^2``
#: samples: 0.4 s at 1 ms).
F_GUESS = 20.0
#: [N] The previous estimate holds along an axis only where the sample's set is
#: narrower than this (the friction bands of sticking joints, some 10 to 40 N at the
#: tip): a wider set (the digging cycle's fast moves in free air, a joint arriving at
#: its stop) bounds little, and a value held there would carry a transient's error on
#: (the digging cycle into soft soil, whole run, z: 13.6 % of its peak held in sets of
#: any width, 7.2 % with this).
HOLD_WIDTH = 100.0
#: [1] A direction counts as felt by the sliding joints' equations where the singular
#: value of their rows (each scaled to unit length) along it exceeds this (two rows
#: closer than about 8 deg feel one direction, not two): :func:`consistent_tip_force`
#: holds the last value there only as firmly as along its least-held world axis.
HOLD_FELT = 0.1
#: [s] The estimate's first-order low-pass (after :func:`consistent_tip_force`): the
#: angles' acceleration noise through the 15 Hz filters is the error left where every
#: joint slides (the load cell's push along z: 9.3 % of its peak with 4 ms, 6.1 % with
#: 20 ms, its delay 20 -> 36 ms).
TAU_EST = 0.02
#: [s] The bounds reported are the union of this long a window's samples' sets.
T_HOLD = 0.01
#: The triples of constraints whose planes' intersections are the candidate vertices
#: of the set of tip forces (four joints times two sides, and the box's six).
_TRIPLES = np.array([(a, b, c) for a in range(14) for b in range(a + 1, 14) for c in range(b + 1, 14)])
#: The pairs of those constraints (:func:`least_squares_in_set`'s two active ones).
_PAIRS = np.array([(a, b) for a in range(14) for b in range(a + 1, 14)])
#: For each triple (a, b, c) of :data:`_TRIPLES`, the rows of its pairs (b, c), (a, c)
#: and (a, b) in :data:`_PAIRS` (whose planes' cross products Cramer's rule takes).
_PAIR_OF = np.full((14, 14), -1)
_PAIR_OF[_PAIRS[:, 0], _PAIRS[:, 1]] = np.arange(len(_PAIRS))
_BC, _AC, _AB = (_PAIR_OF[_TRIPLES[:, i], _TRIPLES[:, j]] for i, j in ((1, 2), (0, 2), (0, 1)))


def joint_force_bands(x, v, a, drive, sliding, at_lower, at_upper, ex: exc.Excavator = exc.Excavator(),
                      payload: float = 0.0, band=BAND_SLIDE, terms=None):
    """Per joint, the interval ``(lo, hi)`` [N m] of ``(J^T f_tip)_i`` consistent with one
    sample within the tolerance ``band`` [N on the piston, one for all or per joint]:
    a sliding joint (``sliding`` -1 or +1) the sliding law's value +-``band``; any other
    its net force +- its static friction ``F_s scale`` (which also covers a slow creep's
    ``K_v v + F_d``) and ``band``, and where it moves (``v`` not zero: a joint the
    bounds do not take as sliding, arriving at its stop or slowing to a halt) reaching
    to the sliding law's value at ``v`` as well: a piston that still runs at speed
    ``v`` a millimetre before its stop carries its viscous force ``K_v v``, which no
    static band holds; a joint pressed on its lower stop (``at_lower``) no
    lower bound, on its upper (``at_upper``) no upper bound (``-inf`` / ``inf``).
    ``terms``: :func:`_joint_terms` of ``x``, ``v``, ``a``, ``drive``, where the caller has them."""
    x, v, net, lam, scale = terms if terms is not None else _joint_terms(x, v, a, drive, ex, payload)
    band = np.broadcast_to(np.asarray(band, float), (4,))
    sliding = np.asarray(sliding, float)
    lo, hi = np.empty(4), np.empty(4)
    for i, act in enumerate(ex.actuators):
        friction = (act.K_v, act.F_s, act.F_d)
        f_lo, f_hi = friction_band(net[i], v[i], friction, scale[i],
                                   np.sign(sliding[i]) if sliding[i] != 0 else None, band[i])
        if sliding[i] == 0 and v[i] != 0.0:
            s_lo, s_hi = friction_band(net[i], v[i], friction, scale[i], np.sign(v[i]), band[i])
            f_lo, f_hi = min(f_lo, s_lo), max(f_hi, s_hi)
        lo[i], hi[i] = -f_hi, -f_lo          # the pistons' side of J^T f_tip: against their external force
    lo = np.where(np.asarray(at_lower, bool), -np.inf, lo)
    hi = np.where(np.asarray(at_upper, bool), np.inf, hi)
    return lo / lam, hi / lam


def _tip_force_set(q, tau_lo, tau_hi, ex: exc.Excavator, f_bound: float, JT=None):
    """The set of tip forces ``tau_lo <= J(q)^T f <= tau_hi``, ``|f_k| <= f_bound`` as
    ``(A, b, vertices)``: ``A f <= b`` (14 rows: the joints' upper and lower sides, an
    open side as a far plane, and the box) and its vertices (m, 3), none where empty.
    ``JT``: ``J(q)^T``, where the caller has it."""
    JT = exc.tip_jacobian(q, ex).T if JT is None else JT
    A = np.vstack([JT, -JT, np.eye(3), -np.eye(3)])
    big = 1e3 * f_bound * max(1.0, float(np.max(np.abs(JT))))
    b = np.concatenate([np.minimum(np.asarray(tau_hi, float), big), np.minimum(-np.asarray(tau_lo, float), big),
                        np.full(6, float(f_bound))])
    # each triple's intersection by Cramer's rule on the planes' normals n_a, n_b, n_c:
    # (b_a n_b x n_c + b_b n_c x n_a + b_c n_a x n_b) / (n_a . n_b x n_c), the cross
    # products of every pair of planes formed once
    u, w = A[_PAIRS[:, 0]].T, A[_PAIRS[:, 1]].T
    cross = np.stack([u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]], axis=-1)
    bc, ac, ab = cross[_BC], cross[_AC], cross[_AB]
    ia, ib, ic = _TRIPLES.T
    det = np.einsum("ij,ij->i", A[ia], bc)
    ok = np.abs(det) > 1e-9
    verts = ((b[ia, None] * bc - b[ib, None] * ac + b[ic, None] * ab)[ok]) / det[ok, None]
    inside = np.all(verts @ A.T <= b + 1e-7 * (np.abs(b) + 1.0), axis=1)
    return A, b, verts[inside]


def tip_force_interval(q, tau_lo, tau_hi, ex: exc.Excavator = exc.Excavator(), f_bound: float = F_BOUND):
    """Per world axis the smallest and largest tip force [N] with ``tau_lo <= J(q)^T f <=
    tau_hi`` (per joint, [N m], ``-inf`` / ``inf`` for an open side) and ``|f_k| <=
    f_bound``: ``(lo, hi, feasible)``, 3-vectors and a bool.  Exact (the set is a
    polytope in three dimensions: each end is one of its vertices, the intersections of
    three of its planes that satisfy every constraint), plain NumPy.  A side at
    ``+-f_bound`` is unbounded by the recording.  Where no force satisfies them all
    (``feasible`` false) the box, ``-f_bound .. f_bound``."""
    _, _, verts = _tip_force_set(q, tau_lo, tau_hi, ex, f_bound)
    if not len(verts):
        box = np.full(3, float(f_bound))
        return -box, box, False
    return verts.min(axis=0), verts.max(axis=0), True


def least_squares_in_set(H, g, A, b, vertices):
    """The minimum of ``f^T H f / 2 - g^T f`` (``H`` 3x3 positive definite) over the
    polytope ``A f <= b`` whose ``vertices`` (m >= 1, 3) are known: exact, plain NumPy.
    The minimum lies where some set of at most three constraints is active; each set's
    stationary point (none active: ``H^-1 g``; one or two: the equality-constrained
    step; three: a vertex) that satisfies every constraint is a candidate, and the one
    with the least objective is the minimum (a convex problem's)."""
    Hi = np.linalg.inv(H)
    f0 = Hi @ g
    tol = 1e-7 * (np.abs(b) + 1.0)
    if np.all(A @ f0 <= b + tol):
        return f0
    cands = [vertices]
    AH = A @ Hi                                          # rows a^T H^-1
    s1 = np.einsum("ij,ij->i", AH, A)
    cands.append(f0[None, :] - ((A @ f0 - b) / s1)[:, None] * AH)
    i, j = _PAIRS[:, 0], _PAIRS[:, 1]
    G = np.stack([np.stack([s1[i], np.einsum("kj,kj->k", AH[i], A[j])], -1),
                  np.stack([np.einsum("kj,kj->k", AH[j], A[i]), s1[j]], -1)], -2)
    r = np.stack([A[i] @ f0 - b[i], A[j] @ f0 - b[j]], -1)
    ok = np.abs(np.linalg.det(G)) > 1e-12 * (s1[i] * s1[j])
    mu = np.linalg.solve(G[ok], r[ok][..., None])[..., 0]
    cands.append(f0[None, :] - mu[:, :1] * AH[i[ok]] - mu[:, 1:] * AH[j[ok]])
    c = np.concatenate(cands)
    c = c[np.all(c @ A.T <= b + tol, axis=1)]
    return c[np.argmin(0.5 * np.einsum("ij,jk,ik->i", c, H, c) - c @ g)]


def consistent_tip_force(tau, half, f_prev, step: float, A, b, vertices, f_guess=None, guess: float = F_GUESS):
    """The tip force [N] within the set consistent with one sample (``A f <= b`` and its
    ``vertices``, :func:`_tip_force_set` of the joints' bands: ``A``'s first four rows
    are ``J^T``) that best fits, by least squares:

    * each sliding joint's equation ``(J^T f)_i = tau_i`` [N m], weighted by its
      tolerance ``half_i`` [N m] (``inf``: a joint that sticks or sits on a stop gives
      no equation, only its side of the set);
    * the previous estimate ``f_prev`` [N] along each world axis the set bounds on both
      sides to within :data:`HOLD_WIDTH`, weighted by ``step`` [N] (how far the tip force may plausibly move in a
      sample, :data:`F_RATE` times it): where the sliding joints leave a direction
      open, the estimate keeps its last value as far as the friction bands allow
      (instead of a guess at the friction that holds a resting joint).  Along the
      directions the sliding joints' rows span (:data:`HOLD_FELT`) it holds only as
      firmly as along the least-held axis: a hold that pins some axes and not others
      there pushes an equation's error into the free axis, amplified by the row's small
      component along it (only the boom sliding in free air, y open: its noise read as
      -20 N along x);
    * the guess ``f_guess`` [N] (the least squares over all four joints,
      :func:`tip_force_from_torques`; default ``f_prev``), weighted by ``guess`` [N]:
      along an axis a stop leaves open the last value would wander with the set's
      open side, the guess is what the estimate goes to there.

    Exact, plain NumPy (:func:`least_squares_in_set`)."""
    JT = A[:4]
    f_guess = f_prev if f_guess is None else f_guess
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    f_bound = float(np.max(np.abs(b[-6:])))
    held = (hi - lo < HOLD_WIDTH) & (lo > -f_bound * (1 - 1e-9)) & (hi < f_bound * (1 - 1e-9))
    w_prev = np.where(held, 1.0 / step ** 2, 0.0)
    # the directions the sliding joints' equations feel (:data:`HOLD_FELT`) hold only as
    # firmly as the least-held axis; the others as their axes do
    P = np.eye(3)
    eqs = np.isfinite(half) & (np.asarray(half, float) > 0.0)
    if eqs.any():
        rows = JT[eqs] / np.linalg.norm(JT[eqs], axis=1, keepdims=True)
        _, sv, vt = np.linalg.svd(rows, full_matrices=False)
        felt = vt[sv > HOLD_FELT]
        P = P - felt.T @ felt
    W = P @ np.diag(w_prev) @ P + (np.eye(3) - P) * float(np.min(w_prev))
    H = W + np.eye(3) / guess ** 2
    g = W @ np.asarray(f_prev, float) + np.asarray(f_guess, float) / guess ** 2
    for i in range(len(tau)):
        if np.isfinite(half[i]) and half[i] > 0.0:
            H += np.outer(JT[i], JT[i]) / half[i] ** 2
            g += JT[i] * tau[i] / half[i] ** 2
    return least_squares_in_set(H, g, A, b, vertices)


def _low_pass_known(prev, new, dt: float, tau: float):
    """The estimate's first-order low-pass, per component, restarted at the new value
    where the previous one was unknown (nan) and unknown where the new one is."""
    out = np.full(3, np.nan)
    for k in range(3):
        if np.isnan(new[k]):
            continue
        out[k] = new[k] if np.isnan(prev[k]) else first_order_step(prev[k], new[k], dt, tau)
    return out


#: [Hz] The filters' corner for the boom, arm and bucket: the estimate's z lags the
#: force by about 20 ms (the boom's force estimator's lag target) with a quarter of
#: the acceleration noise that one count of the 12-bit angle makes at 30 Hz.
F_MOTION = 15.0
#: [Hz] The swing's: its row of J^T alone feels the lateral force (no other joint's row
#: averages its noise there), and one count of its angle (46 um at its 60 mm crank)
#: through a 15 Hz filter reads, on the upper structure's 600 to 900 kg in piston
#: coordinates, as some 25 N sideways at the tip (3 N at 5 Hz); the lateral estimate
#: lags by about 60 ms instead.
F_MOTION_SWING = 5.0

#: [m/s] A joint on an end stop whose slower filter (``f_info``) still reads more than
#: this is arriving (decelerating), not pressed: the angle sensor's steps alone move
#: that filter by a millimetre or two per second (12 bits over pi at the swing's 60 mm
#: crank: one count is 46 um).
V_ARRIVAL = 10e-3


def observer_start(angles, p_a, p_b, ex: exc.Excavator = exc.Excavator()):
    """The observer's state at its first measurement (``angles`` [rad], absolute
    pressures [Pa]): filters at rest there, no force."""
    x = exc.pistons_from_angles(np.asarray(angles, float), ex)
    F = exc.cylinder_forces(p_a, p_b, ex)
    return {"x_slow": x, "v_slow": np.zeros(4), "x": x, "v": np.zeros(4), "F": F, "dF": np.zeros(4), "f": np.zeros(3), "f_known": np.full(3, np.nan),
            "f_lo": np.full(3, -F_BOUND), "f_hi": np.full(3, F_BOUND),
            "informative": np.zeros(4, bool)}


def observer_step(state: dict, angles, p_a, p_b, dt: float, omega, ex: exc.Excavator = exc.Excavator(),
                  payload: float = 0.0, tau_est: float = TAU_EST, rest_weight: float = 0.3,
                  stop_weight: float = 0.02, v_info: float = 1e-3, f_info: float = 3.0,
                  band_slide=BAND_SLIDE, band_rate: float = BAND_RATE, f_bound: float = F_BOUND,
                  t_hold: float = T_HOLD, f_rate: float = F_RATE, f_guess: float = F_GUESS):
    """One step of the excavator's tip-force observer with the measurements held over
    ``dt`` [s]: joint ``angles`` [rad], absolute pressures [Pa] (4-vectors); ``omega``
    [rad/s] the filters' corner, one for all joints or one per joint (swing, boom,
    arm, bucket; see :data:`F_MOTION_SWING`).  Returns ``(state, f_est, residual, tau)``: the new
    state, the tip force [N] after the first-order low-pass ``tau_est`` [s], the
    least-squares guess's residual [N m] and the joint torques [N m].

    A joint slides when it is informative (:func:`informative_joints`: sliding by both
    the fast filter and a slower one of the angles, corner ``f_info`` [Hz], above
    ``v_info`` [m/s], off its stops); its torque then comes from the sliding law in
    the slow filter's direction.  Any other joint counts as at rest (its torque known to
    within its static friction), and one whose slow filter's speed is not above
    ``v_info`` has no speed and no acceleration of its own: what the fast filter makes
    of the angle sensor's steps there (a step of one count reads as metres per second
    squared, and the swing's crank turns that into hundreds of newtons) is noise, not
    motion.

    The estimate (before the low-pass) is :func:`consistent_tip_force`: within the
    sample's set of consistent forces (below), the informative joints' equations (each
    within its band's tolerance), the previous estimate along each axis the set bounds
    (``f_rate`` [N/s]) and the least-squares guess over all four joints, the resting
    ones with weight ``rest_weight``, those on a stop ``stop_weight``
    (:func:`tip_force_from_torques`, whose residual is returned; weighted by
    ``f_guess`` [N]).  Kept in ``state["f_c"]``.

    Beside it, the estimate from the
    informative joints alone, ``nan`` where they do not determine a component
    (:func:`tip_force_determined`), as ``state["f_known"]``, and their mask as
    ``state["informative"]``.

    The bounds where the machine cannot tell: ``state["f_lo"]``, ``state["f_hi"]`` [N]
    per world axis, the interval of tip forces consistent with the sample
    (:func:`joint_force_bands`, :func:`tip_force_interval`): a sliding joint's
    equation within ``band_slide`` times its static friction [N on the piston, a share
    per joint or one for all] plus ``band_rate`` times its
    filtered pneumatic force's change over the filter's delay (``2 / omega``); a
    resting joint's friction band; one side open for a joint on a stop; ``+-f_bound``
    where the recording leaves a side open.  Where no force fits the bands, they are
    widened twice by a factor of 4 before the box ``+-f_bound`` is reported.  The
    interval reported is the union of the last ``t_hold`` [s] of samples' (the
    classification of a joint as sliding or sticking flips with the sensor's noise
    around a start or a stop, and the sets of neighbouring samples with it).

    ``state["equation"]`` [N on the piston]: per joint the sliding law's value the bounds
    use (``nan`` where they do not take the joint as sliding), over free-air samples the
    joint's own equation error (``benchmarks/excavator_tip_force_bounds.py``'s causal
    fair bound takes its tolerances from it); ``state["speed"]`` [m/s] the speed they
    classify each joint by."""
    xm = exc.pistons_from_angles(np.asarray(angles, float), ex)
    Fm = exc.cylinder_forces(p_a, p_b, ex)
    omega = np.broadcast_to(np.asarray(omega, float), (4,))
    xs, vs, v_mean, a_mean = [], [], np.empty(4), np.empty(4)
    F_new, dF_new, F_mid = np.empty(4), np.empty(4), np.empty(4)
    for i in range(4):
        x1, v1, v_mean[i], a_mean[i], F_new[i], dF_new[i], F_mid[i] = observer_filter_step(
            state["x"][i], state["v"][i], state["F"][i], state["dF"][i], xm[i], Fm[i], dt, omega[i])
        xs.append(x1)
        vs.append(v1)
    x_mid = 0.5 * (np.asarray(state["x"]) + np.asarray(xs))
    w_info = 2.0 * math.pi * f_info
    x_slow, v_slow = np.empty(4), np.empty(4)
    for i in range(4):
        x_slow[i], v_slow[i], _, _ = motion_filter_step(state["x_slow"][i], state["v_slow"][i], xm[i], dt, w_info)
    # sliding by both filters the same way: the slow one is not shaken by the sensor's
    # steps, the fast one stops with the joint (the slow one lags it by 2 / w_info)
    v_both = np.where(np.sign(v_slow) == np.sign(v_mean), np.sign(v_slow) * np.minimum(np.abs(v_slow), np.abs(v_mean)),
                      0.0)
    # off the stops both as measured and as filtered (the filters carry an arrival's
    # impact for their delay after the measured position reached the stop)
    info = informative_joints(xm, v_both, ex, v_info) & informative_joints(x_mid, v_both, ex, v_info)
    # a joint still by both filters, or pressed on a stop, has no motion of its own: the
    # fast filter's speed and acceleration there are the sensor's steps; one that is
    # arriving at a stop is decelerating (its impact couples into the others' rows)
    arriving = np.abs(v_slow) > V_ARRIVAL
    moving = (np.abs(v_both) > v_info) & (arriving | informative_joints(xm, v_both, ex, v_info, x_stop=5e-4))
    v_obs, a_obs = np.where(moving, v_mean, 0.0), np.where(moving, a_mean, 0.0)
    terms = _joint_terms(x_mid, v_obs, a_obs, F_mid, ex, payload)    # (the torques' and the bands' alike)
    tau, resting, at_stop = observed_joint_torques(x_mid, v_obs, a_obs, F_mid, ex, payload, 0.0,
                                                   sliding=np.where(info, np.sign(v_slow), 0.0), x_measured=xm,
                                                   terms=terms)
    q = exc.joint_angles(np.clip(x_mid, 0.0, ex.strokes), ex)
    JT = exc.tip_jacobian(q, ex).T
    w = np.where(at_stop, stop_weight, np.where(resting, rest_weight, 1.0))
    f, residual = tip_force_from_torques(q, tau, w, ex, JT=JT)
    f_det, _ = tip_force_determined(q, tau, info, ex, JT=JT)
    band = (np.asarray(band_slide, float) * np.array([a.F_s for a in ex.actuators])
            + band_rate * np.abs(dF_new) * 2.0 / omega)
    sliding_dir = np.where(info & (np.abs(v_both) > V_SLIDE_BOUNDS), np.sign(v_slow), 0.0)
    xl, xu = np.minimum(x_mid, xm), np.maximum(x_mid, xm)
    for widen in (1.0, 4.0, 16.0):
        t_lo, t_hi = joint_force_bands(x_mid, v_obs, a_obs, F_mid, sliding_dir, xl <= 5e-4, xu >= ex.strokes - 5e-4,
                                       ex, payload, widen * band, terms=terms)
        A, b, verts = _tip_force_set(q, t_lo, t_hi, ex, f_bound, JT=JT)
        if len(verts):
            break
    lever = np.abs(exc.lever_arms(np.clip(x_mid, 0.0, ex.strokes), ex))
    if len(verts):
        f_lo, f_hi = verts.min(axis=0), verts.max(axis=0)
        half = np.where(info, widen * band * lever, np.inf)        # the sliding joints' equations, [N m]
        f_c = consistent_tip_force(tau, half, state.get("f_c", f), f_rate * dt, A, b, verts, f, f_guess)
    else:
        f_lo, f_hi = np.full(3, -float(f_bound)), np.full(3, float(f_bound))
        f_c = f
    f_est = np.array([first_order_step(state["f"][k], f_c[k], dt, tau_est) for k in range(3)])
    new = {"x_slow": x_slow, "v_slow": v_slow, "x": np.asarray(xs), "v": np.asarray(vs), "F": F_new, "dF": dF_new,
           "f": f_est, "f_c": f_c, "f_known": _low_pass_known(state.get("f_known", np.full(3, np.nan)), f_det, dt, tau_est),
           "informative": info,
           # per joint the sliding law's value the bounds use [N on the piston, nan where they do not take the
           # joint as sliding]: what its equation leaves for the tip force, in free air its equation's error;
           # and the speed they classify it by [m/s]
           "equation": np.where(sliding_dir != 0, 0.5 * (t_lo + t_hi) / lever, np.nan), "speed": np.abs(v_both)}
    n_hold = max(1, int(round(t_hold / dt)) + 1) if dt > 0 else 1
    new["bounds_recent"] = (state.get("bounds_recent", [])[-(n_hold - 1):] if n_hold > 1 else []) + [(f_lo, f_hi)]
    new["f_lo"] = np.min([b[0] for b in new["bounds_recent"]], axis=0)
    new["f_hi"] = np.max([b[1] for b in new["bounds_recent"]], axis=0)
    return new, f_est, residual, tau


def estimate_tip_force(data, ex: exc.Excavator = exc.Excavator(), payload: float = 0.0, f_motion: float = F_MOTION,
                       tau_est: float = TAU_EST, rest_weight: float = 0.3, stop_weight: float = 0.02, P_atm=None,
                       cannot_tell: bool = False, v_info: float = 1e-3, f_info: float = 3.0,
                       f_motion_swing: float = F_MOTION_SWING, bounds: bool = False, band_slide=BAND_SLIDE,
                       band_rate: float = BAND_RATE, f_bound: float = F_BOUND, t_hold: float = T_HOLD,
                       f_rate: float = F_RATE, f_guess: float = F_GUESS, equations: bool = False):
    """The observer run over an excavator recording (a DataFrame with its columns,
    pressures gauge): arrays ``f`` (n, 3) [N] and ``residual`` (n,) [N m].

    ``cannot_tell``: ``f`` from the sliding joints alone (``state["f_known"]``, see
    :func:`tip_force_determined`), ``nan`` where they do not determine a component,
    and a third array, the number of informative joints per sample.

    ``bounds``: ``(f, residual, f_lo, f_hi)``, the last two (n, 3) [N], per sample
    and world axis the interval of tip forces consistent with the recording within
    its noise (``observer_step``'s ``state["f_lo"]``, ``state["f_hi"]``; a side at
    ``+-f_bound`` is open: a stop or a sticking joint leaves it unbounded).  With
    ``equations`` as well a fifth and a sixth, (n, 4) each: per sample and joint the
    sliding law's value the bounds use [N on the piston] (``state["equation"]``, ``nan``
    where the joint does not count as sliding; over free-air samples the joint's own
    equation error) and the speed the bounds classify it by [m/s] (``state["speed"]``)."""
    P_atm = ex.P_atm if P_atm is None else P_atm
    t = data["t"].to_numpy(float)
    Q = np.column_stack([data[f"angle_{j}"].to_numpy(float) for j in exc.JOINTS])
    PA = np.column_stack([data[f"p_a_{j}"].to_numpy(float) for j in exc.JOINTS]) + P_atm
    PB = np.column_stack([data[f"p_b_{j}"].to_numpy(float) for j in exc.JOINTS]) + P_atm
    omega = 2.0 * math.pi * np.array([f_motion_swing, f_motion, f_motion, f_motion])
    state = observer_start(Q[0], PA[0], PB[0], ex)
    f = np.zeros((len(t), 3))
    res = np.zeros(len(t))
    f_known = np.full((len(t), 3), np.nan)
    n_info = np.zeros(len(t), int)
    f_lo, f_hi = np.full((len(t), 3), -float(f_bound)), np.full((len(t), 3), float(f_bound))
    eq, speed = np.full((len(t), 4), np.nan), np.zeros((len(t), 4))
    for k in range(1, len(t)):
        state, f[k], res[k], _ = observer_step(state, Q[k], PA[k], PB[k], t[k] - t[k - 1], omega, ex, payload,
                                               tau_est, rest_weight, stop_weight, v_info, f_info, band_slide,
                                               band_rate, f_bound, t_hold, f_rate, f_guess)
        f_known[k] = state["f_known"]
        n_info[k] = int(np.sum(state["informative"]))
        f_lo[k], f_hi[k] = state["f_lo"], state["f_hi"]
        eq[k], speed[k] = state["equation"], state["speed"]
    if bounds:
        return (f, res, f_lo, f_hi, eq, speed) if equations else (f, res, f_lo, f_hi)
    if cannot_tell:
        return f_known, res, n_info
    return f, res


def tip_force_figures(t, f_true, f_est, f_lo=None, f_hi=None, max_lag: float = 0.2) -> dict:
    """The tip force estimate's figures over the contact samples only (those where the
    true force ``f_true`` (n, 3) [N] is not zero), as the benchmarks report them:
    ``rmse`` [N] per axis, ``peak`` [N] the true force's largest magnitude,
    ``rmse_share`` each axis' RMSE over that peak, ``delay`` [s] per axis the shift of
    the estimate behind the truth that correlates them best over the contact samples
    (up to ``max_lag``; 0 where an axis' true force does not vary), and with the bounds ``f_lo``, ``f_hi`` (n, 3): ``coverage`` per axis
    and ``coverage_all`` (the share of contact samples where the true force lies
    within the interval, per axis and on all three at once), ``median_width`` [N] per
    axis.  ValueError without contact samples."""
    t = np.asarray(t, float)
    f_true, f_est = np.asarray(f_true, float), np.asarray(f_est, float)
    on = np.linalg.norm(f_true, axis=1) > 0.0
    if not on.any():
        raise ValueError("no contact samples: the true tip force is zero throughout")
    peak = float(np.max(np.linalg.norm(f_true[on], axis=1)))
    rmse = np.sqrt(np.mean((f_est[on] - f_true[on]) ** 2, axis=0))
    dt = float(np.median(np.diff(t)))
    idx = np.flatnonzero(on)
    delay, best = np.zeros(3), np.full(3, -np.inf)
    for lag in range(0, int(round(max_lag / dt)) + 1):
        k = idx[idx + lag < len(t)]
        a = f_est[k + lag] - f_est[k + lag].mean(axis=0)
        b = f_true[k] - f_true[k].mean(axis=0)
        norm = np.sqrt(np.sum(a * a, axis=0) * np.sum(b * b, axis=0))
        corr = np.where(norm > 0, np.sum(a * b, axis=0) / np.where(norm > 0, norm, 1.0), -np.inf)
        better = corr > best
        best, delay = np.where(better, corr, best), np.where(better, lag * dt, delay)
    out = {"contact_samples": int(on.sum()), "peak": peak, "rmse": rmse, "rmse_share": rmse / peak, "delay": delay}
    if f_lo is not None:
        lo, hi = np.asarray(f_lo, float)[on], np.asarray(f_hi, float)[on]
        inside = (f_true[on] >= lo) & (f_true[on] <= hi)
        out.update(coverage=inside.mean(axis=0), coverage_all=float(np.all(inside, axis=1).mean()),
                   median_width=np.median(hi - lo, axis=0))
    return out

__all__ = [
    "position_error_force", "pneumatic_stiffness", "motion_filter_step", "observer_filter_step",
    "measured_drive_force", "below_sensor_floor", "friction_band", "observed_joint_forces",
    "observed_external_force", "reflected_force", "observed_joint_torques", "tip_force_from_torques",
    "informative_joints", "tip_force_determined", "F_BOUND", "BAND_SLIDE", "BAND_RATE",
    "V_SLIDE_BOUNDS", "F_RATE", "F_GUESS", "HOLD_WIDTH", "HOLD_FELT", "TAU_EST", "T_HOLD", "joint_force_bands",
    "tip_force_interval", "least_squares_in_set", "consistent_tip_force", "F_MOTION", "F_MOTION_SWING",
    "V_ARRIVAL", "observer_start", "observer_step", "estimate_tip_force", "tip_force_figures",
]
