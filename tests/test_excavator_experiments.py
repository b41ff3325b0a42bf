"""The excavator's command experiments (``experiments.py``): the digging cycle's phases
move the joints the spec names in the order it names them, the identification
excitations are seeded and move every joint both ways, and the contact scenarios give
the tip force their description says."""
from __future__ import annotations

import math

import numpy as np
import pytest

from boomfmi.experiments import (CONTACTS, EXCAVATOR_PROFILES, JOINTS, TipContact, contact, digging_cycle,
                                 excavator_excitation, excavator_manoeuvres, excavator_profile,
                                 excavator_random_steps, held_joints, per_joint, random_steps)

KEYS = {f"u_{j}" for j in JOINTS}


def sample(profile, dt=1e-3):
    t = np.arange(0.0, profile.duration, dt)
    return t, {k: np.array([profile(s)[k] for s in t]) for k in KEYS}


@pytest.mark.parametrize("name", list(EXCAVATOR_PROFILES))
def test_every_profile_commands_the_four_valves_in_volts(name):
    p = excavator_profile(name)
    assert p.duration > 5
    t, u = sample(p, 5e-3)
    assert set(p(0.0)) == KEYS
    for k, v in u.items():
        assert np.all((v >= 0) & (v <= 10)), k
    assert all(0 < b < p.duration for b in p.breakpoints)


def test_unknown_names_are_refused_with_the_known_ones():
    with pytest.raises(ValueError, match="unknown excavator experiment 'dg'; known: digging_cycle"):
        excavator_profile("dg")
    with pytest.raises(ValueError, match="unknown contact scenario 'mud'; known: soft_soil, hard_soil"):
        contact("mud")


def test_the_digging_cycle_moves_each_joint_in_its_phase():
    p = digging_cycle()
    names = [n for n, _, _ in p.phases]
    assert names == ["rest", "swing to the trench", "boom down", "arm in", "bucket curl", "lift", "swing back",
                     "dump", "rest"]
    assert p.phases[-1][2] == pytest.approx(p.duration) == pytest.approx(10.5)
    at = {n: p(0.5 * (a + b)) for n, a, b in p.phases if n != "rest"}
    rest = p(0.1)
    assert rest == {k: 5.0 for k in KEYS} and p(p.duration - 0.1) == rest
    assert at["swing to the trench"]["u_swing"] < 4 and at["swing back"]["u_swing"] > 6   # out and back
    assert at["boom down"]["u_boom"] > 6 and at["lift"]["u_boom"] < 4                    # down, then up
    assert at["arm in"]["u_arm"] < 4 and at["dump"]["u_arm"] > 6
    assert at["bucket curl"]["u_bucket"] < 4 and at["dump"]["u_bucket"] > 6
    moving = {n: {k for k, v in u.items() if v != 5.0} for n, u in at.items()}
    assert moving["swing to the trench"] == {"u_swing"} and moving["bucket curl"] == {"u_bucket"}
    assert moving["arm in"] == {"u_arm", "u_boom"}
    slow = digging_cycle(level=0.5, pace=2.0)
    assert slow.duration == pytest.approx(21.0)
    assert slow(2 * 1.25)["u_swing"] == pytest.approx(5.0 - 1.0)


def test_the_digging_cycle_s_options_are_checked():
    with pytest.raises(ValueError, match=r"level scales the openings: in \(0, 2\], not 3"):
        digging_cycle(level=3)
    with pytest.raises(ValueError, match="pace scales the durations"):
        digging_cycle(pace=0)


def test_held_joints_checks_its_segments():
    with pytest.raises(ValueError, match="unknown joint 'stick'"):
        held_joints([(1.0, {"stick": 3.0})])
    with pytest.raises(ValueError, match=r"u_arm = 11.0 V lies outside 0 to 10 V"):
        held_joints([(1.0, {"arm": 11.0})])
    p = held_joints([(1.0, {"arm": 3.0}), (0.5, {})])
    assert p(0.5) == {"u_swing": 5.0, "u_boom": 5.0, "u_arm": 3.0, "u_bucket": 5.0}
    assert p(1.2)["u_arm"] == 5.0 and p.breakpoints == [1.0] and p.duration == 1.5


@pytest.mark.parametrize("make", [excavator_random_steps, excavator_manoeuvres, excavator_excitation])
def test_the_excitations_are_seeded_and_move_every_joint_both_ways(make):
    a, b, c = make(seed=3), make(seed=3), make(seed=4)
    t, ua = sample(a, 5e-3)
    _, ub = sample(b, 5e-3)
    _, uc = sample(c, 5e-3)
    for k in KEYS:
        assert np.array_equal(ua[k], ub[k])
        assert np.any(ua[k] < 4) and np.any(ua[k] > 6), k          # extends and retracts every joint
    assert any(not np.array_equal(ua[k], uc[k]) for k in KEYS)
    assert not np.array_equal(ua["u_arm"], ua["u_bucket"])          # joints drawn independently


def test_the_excitation_moves_one_or_two_joints_at_a_time():
    p = excavator_excitation(seed=1)
    t, u = sample(p, 5e-3)
    opened = sum((np.abs(u[k] - 5.0) > 1e-9).astype(int) for k in KEYS)
    assert opened.max() <= 2
    alone = {k: np.any((np.abs(u[k] - 5.0) > 0.4) & (opened == 1)) for k in KEYS}
    assert all(alone.values()), alone                               # each joint moves alone sometime


def test_per_joint_combines_boom_profiles():
    p = per_joint({j: random_steps(i, duration=5.0 + i) for i, j in enumerate(JOINTS)})
    assert p.duration == 5.0
    assert p(1.0)["u_arm"] == random_steps(2, 7.0)(1.0)["u"]
    with pytest.raises(ValueError, match="one profile for each of swing, boom, arm, bucket"):
        per_joint({"boom": random_steps()})


def test_soil_pushes_the_tip_up_below_its_surface_and_drags_it():
    soil = contact("soft_soil")
    assert soil.kind == "ground" and soil.ground_z == 0.0
    assert np.array_equal(soil.force(0.0, (0.8, 0.0, 0.01)), np.zeros(3))            # above: no contact
    f = soil.force(0.0, (0.8, 0.0, -0.01), (0.0, 0.0, 0.0))
    assert f == pytest.approx([0.0, 0.0, 1500.0 * 0.01])                                # k * depth, up
    f = soil.force(0.0, (0.8, 0.0, -0.01), (-0.2, 0.0, -0.1))                            # moving in and down
    fz = 1500.0 * 0.01 + 100.0 * 0.1
    assert f == pytest.approx([0.3 * fz, 0.0, fz])                                      # drag against the motion
    withdrawing = soil.force(0.0, (0.8, 0.0, -0.01), (0.0, 0.0, 5.0))                   # damped only going in:
    assert withdrawing == pytest.approx([0.0, 0.0, 15.0])                                # it never pulls
    slow = soil.force(0.0, (0.8, 0.0, -0.01), (0.0, 0.001, 0.0))                        # drag regularised near rest
    assert slow == pytest.approx([0.0, -0.3 * 15.0 * 0.001 / 0.01, 15.0])
    assert contact("hard_soil").force(0.0, (0.8, 0.0, -0.01))[2] == pytest.approx(150.0)


def test_the_digging_cycle_takes_the_tip_into_the_soil():
    """Pistons driven at a speed in proportion to their valve's opening from mid-stroke
    (a kinematic stand-in for the rig): the tip goes below the soil's surface in the
    boom-down and arm-in phases only, and comes out above it to dump."""
    from boomfmi.physics.linkage import excavator_parameters, forward_kinematics, joint_angles
    p, ex = digging_cycle(), excavator_parameters()
    t = np.arange(0.0, p.duration, 2e-3)
    x, xs = 0.5 * ex.strokes, []
    for s in t:
        u = p(s)
        x = np.clip(x + 0.03 * np.array([5.0 - u[f"u_{j}"] for j in JOINTS]) * 2e-3, 0.0, ex.strokes)
        xs.append(x)
    z = forward_kinematics(joint_angles(np.array(xs)))["tip"][:, 2]
    soil = contact("soft_soil")
    below = {n for n, a, b in p.phases if np.any(z[(t >= a) & (t < b)] < soil.ground_z)}
    assert below == {"boom down", "arm in", "bucket curl"}
    assert z[-1] > soil.ground_z + 0.1


def test_the_prescribed_force_is_known_whatever_the_tip_does():
    push = contact("prescribed_push")
    assert push.force(3.0, (0, 0, 0)) == pytest.approx([0, 0, 0])
    assert push.force(3.75, (0, 0, 0)) == pytest.approx([-7.5, 2.5, 12.5])            # half way up the ramp
    assert push.force(5.0, (9, 9, 9), (1, 1, 1)) == pytest.approx([-15.0, 5.0, 25.0])
    assert push.force(7.4, (0, 0, 0)) == pytest.approx(0.2 * np.array([-15.0, 5.0, 25.0]))
    assert push.config() == {"type": "prescribed", "force": [-15.0, 5.0, 25.0], "start": 3.5, "stop": 7.5,
                             "ramp": 0.5}
    assert contact("hard_soil").config()["stiffness"] == 15000.0
    assert set(CONTACTS) == {"soft_soil", "hard_soil", "prescribed_push", "mid_push"}     # mid_push: issue 33


@pytest.mark.parametrize("kwargs, message", [
    (dict(kind="mud"), "kind must be one of ground, prescribed"),
    (dict(kind="ground"), "the ground needs a stiffness > 0 N/m"),
    (dict(kind="ground", stiffness=-1.0), "stiffness must be >= 0"),
    (dict(kind="ground", stiffness=1e3, ground_z=math.nan), "ground_z must be a finite number"),
    (dict(kind="prescribed", force=(1.0, 2.0)), "force must be three finite numbers"),
    (dict(kind="prescribed", start=2.0, stop=1.0), "stop (1.0 s) must come after start (2.0 s)"),
])
def test_a_bad_contact_description_is_refused(kwargs, message):
    with pytest.raises(ValueError) as e:
        TipContact("x", **kwargs)
    assert message in str(e.value) and "contact 'x'" in str(e.value)


def test_the_joints_are_the_linkage_s_and_the_recording_s():
    from boomfmi import recording
    from boomfmi.physics import linkage
    assert JOINTS == linkage.JOINTS == recording.JOINTS
