"""One force estimation core for one joint or four (issue 32 item 1, step 5): the boom's
observer and the excavator's per-joint observers are ``observed_joint_forces``; the
joystick's reflection is one ``reflected_force`` for a float or per axis; the
excavator's tip-force section lives in ``physics/force_estimation.py``."""
import importlib
import math
from pathlib import Path

import numpy as np
import pytest

from boomfmi.physics import linkage as exc
from boomfmi.physics import force_estimation as fe
from boomfmi.physics.geometry import phi_from_x
from boomfmi.physics.params import Cylinder, Geometry, Load

ROOT = Path(__file__).resolve().parents[1]
FRICTION = ((40.0, 30.0, 20.0), (100.0, 60.0, 50.0))      # (K_v, F_s, F_d) per joint


def test_one_core_holds_friction_at_rest_and_slides_by_the_law():
    # joint 0 slides (v above v_rest); joint 1 rests, its friction holding F_s scale = 30 N of the 85 N
    f, resting, at_stop = fe.observed_joint_forces([100.0, 85.0], [0.1, 0.1], [0.01, 0.0], [0.2, 0.2], FRICTION,
                                                   [1.0, 0.5])
    assert f == pytest.approx([100.0 - 40.0 * 0.01 - 20.0, 85.0 - 30.0])
    assert resting == [False, True] and at_stop == [False, False]
    # a force friction can hold entirely reads as none
    f, _, _ = fe.observed_joint_forces([25.0], [0.1], [0.0], [0.2], FRICTION[1:], [0.5])
    assert f == [0.0]


def test_sliding_override_and_the_measured_position_at_a_stop():
    # sliding = -1 on a joint whose filtered speed is nil: the sliding law in that direction
    f, resting, _ = fe.observed_joint_forces([10.0], [0.1], [0.0], [0.2], FRICTION[:1], [1.0], sliding=[-1.0])
    assert resting == [False] and f == [pytest.approx(10.0 + 20.0)]
    # filtered 5 mm off the lower stop, measured on it: a force towards the stop (f < 0) is the stop's
    f, _, at_stop = fe.observed_joint_forces([-200.0], [0.005], [0.01], [0.2], FRICTION[:1], [1.0],
                                             x_measured=[0.0])
    assert at_stop == [True] and f == [0.0]
    f, _, at_stop = fe.observed_joint_forces([-200.0], [0.005], [0.01], [0.2], FRICTION[:1], [1.0])
    assert at_stop == [False] and f[0] < -150.0


@pytest.mark.parametrize("x, v", [(0.1, 0.02), (0.1, -0.02), (0.1, 0.0), (0.0002, 0.0), (0.1998, 0.05), (-0.01, 0.0)])
def test_the_booms_observer_is_the_one_joint_case(x, v):
    cyl, geom, load = Cylinder(), Geometry(), Load()
    drive, a = 150.0, -0.3
    c = math.cos(phi_from_x(min(max(x, 0.0), cyl.L), geom))
    f, _, _ = fe.observed_joint_forces([drive - load.M * a], [x], [v], [cyl.L], [(load.K_v, load.F_s, load.F_d)], [c])
    assert fe.observed_external_force(drive, x, v, a, cyl, geom, load) == f[0]


def test_the_excavators_joint_torques_are_the_core_through_the_linkage():
    ex = exc.Excavator()
    x = 0.5 * ex.strokes
    v = np.array([0.0, 0.01, -0.02, 0.0])
    a = np.array([0.1, -0.2, 0.3, 0.0])
    drive = np.array([50.0, 400.0, -100.0, 20.0])
    tau, resting, at_stop = fe.observed_joint_torques(x, v, a, drive, ex)
    Mx, bias, lam = exc.piston_dynamics(x, v, 0.0, ex)
    f, rest, stop = fe.observed_joint_forces(drive - (Mx @ a + bias), x, v, ex.strokes,
                                             [(c.K_v, c.F_s, c.F_d) for c in ex.actuators],
                                             exc.friction_scale(x, ex))
    np.testing.assert_array_equal(tau, -np.asarray(f) / lam)
    assert list(resting) == [True, False, False, True] and list(resting) == rest and not any(at_stop)


def test_observer_filter_step_is_the_same_filter_on_position_and_force():
    out = fe.observer_filter_step(0.1, 0.0, 200.0, 0.0, 0.101, 260.0, 0.001, 2 * math.pi * 15)
    x1, v1, vm, am = fe.motion_filter_step(0.1, 0.0, 0.101, 0.001, 2 * math.pi * 15)
    d1, dd1, _, _ = fe.motion_filter_step(200.0, 0.0, 260.0, 0.001, 2 * math.pi * 15)
    assert out == (x1, v1, vm, am, d1, dd1, 0.5 * (200.0 + d1))


def test_excavator_force_module_is_gone_and_one_reflection_serves_a_float_or_per_axis():
    f_est, f_prev = np.array([300.0, -1000.0, 10.0]), np.array([0.0, 0.0, 0.4])
    r = fe.reflected_force(f_est, f_prev, 0.001, 0.05, 20.0, 500.0)
    each = [fe.reflected_force(float(f_est[k]), float(f_prev[k]), 0.001, 0.05, 20.0, 500.0) for k in range(3)]
    np.testing.assert_array_equal(r, each)
    np.testing.assert_allclose(r, [0.5, -0.5, 0.5])
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("boomfmi.physics.excavator_force")
    for name in ("F_BOUND", "estimate_tip_force", "observer_start", "observer_step", "tip_force_interval",
                 "tip_force_figures", "informative_joints", "joint_force_bands"):
        assert hasattr(fe, name), name
    users = [p for d in ("src", "fmus", "benchmarks", "tests", "examples") for p in (ROOT / d).rglob("*.py")
             if p.name != Path(__file__).name and ("excavator_force import" in p.read_text()
                                                   or "reflected_force_3d" in p.read_text())]
    assert users == []
