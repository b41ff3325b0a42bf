"""The boom_load FMU: stick/slip of Eq. 8 and 9, the end stops, and Eq. 10 to 12."""
from __future__ import annotations

import math

import numpy as np
import pytest

from boomfmi.physics import reference_rig
from boomfmi.system import FmuInstance

a, b, h, l_min = reference_rig.a, reference_rig.b, reference_rig.h, reference_rig.l_min


def phi_by_hand(x):
    l = x + l_min
    return math.pi - math.asin(h / a) - math.acos((a * a + l * l - b * b) / (2 * a * l))


def alpha_by_hand(x):
    l = x + l_min
    return math.acos((a * a + b * b - l * l) / (2 * a * b))


def p_a_for(drive):
    """Absolute p_a that gives the piston force ``drive`` [N] with p_b at atmosphere."""
    return reference_rig.P_atm + drive / reference_rig.A_a


@pytest.fixture
def boom(fmu):
    def make(x0=0.03, **params):
        inst = FmuInstance(fmu("boom_load"))
        inst.initialize(parameters=dict(x0=x0, **params))
        return inst
    return make


@pytest.mark.parametrize("share", [0.0, 0.5, 0.99, -0.5, -0.99])
def test_boom_holds_still_below_static_friction(boom, share):
    x0 = 0.03
    phi = phi_by_hand(x0)
    F = reference_rig.F_L * math.sin(phi) + share * reference_rig.F_s * math.cos(phi)
    with boom(x0) as inst:
        inst.set(p_a=p_a_for(F), p_b=reference_rig.P_atm)
        for _ in range(200):
            inst.step(2e-3)
        out = inst.get("x", "v")
    assert out == {"x": x0, "v": 0.0}


@pytest.mark.parametrize("share", [1.05, 1.5, -1.05, -1.5])
def test_boom_accelerates_per_eq_8_above_static_friction(boom, share):
    x0, dt = 0.03, 1e-4
    phi = phi_by_hand(x0)
    excess = share * reference_rig.F_s * math.cos(phi)
    with boom(x0) as inst:
        inst.set(p_a=p_a_for(reference_rig.F_L * math.sin(phi) + excess), p_b=reference_rig.P_atm)
        inst.step(dt)
        v = inst.get("v")["v"]
    F_net = excess - math.copysign(reference_rig.F_d * math.cos(phi), excess)
    # Eq. 8 with v(0) = 0 and constant forces: v = F_net / K_v (1 - exp(-K_v t / M))
    expected = F_net / reference_rig.K_v * (1 - math.exp(-reference_rig.K_v * dt / reference_rig.M))
    assert v == pytest.approx(expected, rel=1e-5)
    # ... which at t -> 0 is the acceleration of Eq. 8
    assert v / dt == pytest.approx(F_net / reference_rig.M, rel=1e-2)


def test_sliding_piston_comes_to_rest_and_sticks(boom):
    """Kick the piston, then drop the drive to the holding level: it stops and stays."""
    x0 = 0.02
    with boom(x0) as inst:
        phi = phi_by_hand(x0)
        inst.set(p_a=p_a_for(reference_rig.F_L * math.sin(phi) + 2 * reference_rig.F_s))
        inst.step(0.05)
        assert inst.get("v")["v"] > 0
        inst.set(p_a=p_a_for(reference_rig.F_L * math.sin(phi_by_hand(inst.get("x")["x"]))))
        for _ in range(100):
            inst.step(1e-3)
        x1 = inst.get("x")["x"]
        assert inst.get("v")["v"] == 0.0
        for _ in range(100):
            inst.step(1e-3)
        assert inst.get("x", "v") == {"x": x1, "v": 0.0}


@pytest.mark.parametrize("dt", [1e-4, 1e-3, 2e-3])
def test_x_never_leaves_the_stroke_and_does_not_bounce(boom, dt):
    with boom(0.03) as inst:
        xs, vs = [], []
        inst.set(p_a=reference_rig.P_s, p_b=reference_rig.P_atm)                 # hard into x = L
        for _ in range(round(1.0 / dt)):
            inst.step(dt)
            out = inst.get("x", "v")
            xs.append(out["x"]); vs.append(out["v"])
        assert xs[-1] == reference_rig.L and vs[-1] == 0.0
        inst.set(p_a=reference_rig.P_atm, p_b=reference_rig.P_s)                 # hard into x = 0
        for _ in range(round(1.5 / dt)):
            inst.step(dt)
            out = inst.get("x", "v")
            xs.append(out["x"]); vs.append(out["v"])
        assert xs[-1] == 0.0 and vs[-1] == 0.0
    xs = np.array(xs)
    assert xs.min() >= 0.0 and xs.max() <= reference_rig.L
    # no bounce: once at a stop the piston stays there while pushed into it
    at_L = np.flatnonzero(xs == reference_rig.L)
    assert np.all(xs[at_L[0]:len(xs) - round(1.5 / dt)] == reference_rig.L)
    at_0 = np.flatnonzero(xs == 0.0)
    assert np.all(xs[at_0[0]:] == 0.0)


def test_gravity_alone_retracts_the_boom_to_the_stop(boom):
    with boom(0.05) as inst:
        inst.set(p_a=reference_rig.P_atm, p_b=reference_rig.P_atm)
        for _ in range(1000):
            inst.step(2e-3)
        assert inst.get("x", "v") == {"x": 0.0, "v": 0.0}


def test_external_force_pushes_against_extension(boom):
    x0 = 0.03
    phi = phi_by_hand(x0)
    with boom(x0) as inst:
        inst.set(p_a=p_a_for(reference_rig.F_L * math.sin(phi)), f_ext=-(reference_rig.F_s + 50.0))
        inst.step(0.01)
        assert inst.get("v")["v"] > 0          # a negative f_ext pulls the piston out
        inst.set(f_ext=reference_rig.F_s + 300.0)
        inst.step(0.1)
        assert inst.get("v")["v"] < 0


@pytest.mark.parametrize("x0", [0.0, 0.013, 0.03, 0.06])
def test_angles_are_eq_10_and_12(boom, x0):
    with boom(x0) as inst:
        out = inst.get("alpha", "phi", "x")
    assert out["x"] == x0
    assert out["phi"] == pytest.approx(phi_by_hand(x0), rel=1e-14)
    assert out["alpha"] == pytest.approx(alpha_by_hand(x0), rel=1e-14)


def test_reference_geometry_spans_the_spec_angles():
    assert math.degrees(phi_by_hand(0.0)) == pytest.approx(43, abs=0.5)
    assert math.degrees(phi_by_hand(reference_rig.L)) == pytest.approx(71, abs=0.5)
    assert math.degrees(alpha_by_hand(0.0)) == pytest.approx(36, abs=0.5)
    assert math.degrees(alpha_by_hand(reference_rig.L)) == pytest.approx(60, abs=0.5)
