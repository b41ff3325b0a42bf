"""The whole excavator's linkage (physics/linkage.py) and its FMU: closed-form checks.

Static equilibrium against a hand computation, energy conservation without friction, the
Jacobian, the lever arms and the joint maps against finite differences, the mass matrix,
the Coriolis vector against the Christoffel symbols, the boom-only reduction against
``physics.load``, and the built ``linkage.fmu`` through fmpy.
"""
from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi.physics import (JOINTS, ParameterError, advance_linkage, advance_load, coriolis,
                             excavator_parameters, forward_kinematics, gravity, joint_angles,
                             joint_limits, kinetic_energy, lever_arms, lumped_boom_load, mass_matrix,
                             phi_from_x, piston_accelerations, pistons_from_angles, potential_energy,
                             tip_jacobian)
from boomfmi.physics.linkage import Excavator, cylinder_forces, mass_matrix_derivative, piston_dynamics, tip_torques

ROOT = Path(__file__).resolve().parents[1]
EX = excavator_parameters()
G = 9.81
#: postures as fractions of each stroke
POSTURES = [(0.5, 0.5, 0.5, 0.5), (0.1, 0.2, 0.9, 0.3), (0.9, 0.8, 0.1, 0.95)]


def x_of(frac):
    return EX.strokes * np.asarray(frac)


def frictionless(ex=EX):
    return replace(ex, **{j: replace(getattr(ex, j), K_v=0.0, F_s=0.0, F_d=0.0) for j in JOINTS})


# --- kinematics -----------------------------------------------------------------------

@pytest.mark.parametrize("frac", POSTURES)
def test_joint_angles_and_pistons_round_trip(frac):
    x = x_of(frac)
    q = joint_angles(x)
    np.testing.assert_allclose(pistons_from_angles(q), x, atol=1e-12)
    np.testing.assert_allclose(joint_angles(pistons_from_angles(q)), q, atol=1e-12)


def test_retracted_cylinders_give_the_lower_limits():
    lim = joint_limits(EX)
    np.testing.assert_allclose(joint_angles(np.zeros(4)), lim[:, 0], atol=1e-12)
    np.testing.assert_allclose(joint_angles(EX.strokes), lim[:, 1], atol=1e-12)
    assert np.all(lim[:, 1] > lim[:, 0])
    # the chosen lower limits (docs/excavator.md); the swing symmetric about straight ahead
    np.testing.assert_allclose(lim[2:, 0], np.radians([50.0, 30.0]))
    assert lim[0, 0] == pytest.approx(-lim[0, 1])
    # the boom is Eq. 12's alpha: 36 to 60 degrees (reference-rig.md)
    assert math.degrees(lim[1, 0]) == pytest.approx(36.3, abs=0.1)
    assert math.degrees(lim[1, 1]) == pytest.approx(60.1, abs=0.1)


@pytest.mark.parametrize("frac", POSTURES)
def test_lever_arms_are_dl_dgamma(frac):
    """dl/dq by central differences of l(q) = l_min + x(q)."""
    q = joint_angles(x_of(frac))
    e = 1e-6
    for j in range(4):
        dq = np.zeros(4)
        dq[j] = e
        fd = (pistons_from_angles(q + dq)[j] - pistons_from_angles(q - dq)[j]) / (2 * e)
        assert lever_arms(x_of(frac))[j] == pytest.approx(fd, rel=1e-7)
    # the boom's through Eq. 12: dl/dalpha = a b sin(alpha) / l
    a, b = EX.boom.c1, EX.boom.c2
    l = EX.boom.l_min + x_of(frac)[1]
    assert lever_arms(x_of(frac))[1] == pytest.approx(a * b * math.sin(q[1]) / l, rel=1e-12)


@pytest.mark.parametrize("frac", POSTURES)
def test_cylinder_eyes_are_one_cylinder_length_apart(frac):
    x = x_of(frac)
    pts = forward_kinematics(joint_angles(x))
    for j, act in zip(JOINTS, EX.actuators):
        d = np.linalg.norm(pts[f"cyl_{j}_rod"] - pts[f"cyl_{j}_base"])
        assert d == pytest.approx(act.l_min + x[JOINTS.index(j)], rel=1e-12), j


def test_forward_kinematics_by_hand():
    q = np.array([0.3, math.radians(50.0), math.radians(80.0), math.radians(40.0)])
    pts = forward_kinematics(q)
    beta = math.asin(EX.boom_h / EX.boom.c1)
    pb = q[1] - beta
    pa = pb - q[2]
    pk = pa - q[3]
    r = 0.05 + 0.60 * math.cos(pb) + 0.35 * math.cos(pa) + 0.15 * math.cos(pk)
    z = 0.20 + 0.60 * math.sin(pb) + 0.35 * math.sin(pa) + 0.15 * math.sin(pk)
    np.testing.assert_allclose(pts["tip"], [r * math.cos(0.3), r * math.sin(0.3), z], atol=1e-14)
    np.testing.assert_allclose(pts["boom_pivot"], [0.05 * math.cos(0.3), 0.05 * math.sin(0.3), 0.2], atol=1e-14)
    np.testing.assert_allclose(pts["swing_axis"], [0, 0, 0], atol=1e-14)


@pytest.mark.parametrize("frac", POSTURES)
def test_tip_jacobian_against_finite_differences(frac):
    q = joint_angles(x_of(frac)) + np.array([0.4, 0.0, 0.0, 0.0])
    J = tip_jacobian(q)
    e = 1e-6
    for j in range(4):
        dq = np.zeros(4)
        dq[j] = e
        fd = (forward_kinematics(q + dq)["tip"] - forward_kinematics(q - dq)["tip"]) / (2 * e)
        np.testing.assert_allclose(J[:, j], fd, atol=1e-9)


# --- dynamics -------------------------------------------------------------------------

@pytest.mark.parametrize("frac", POSTURES)
@pytest.mark.parametrize("payload", [0.0, 2.0])
def test_mass_matrix_symmetric_positive_definite(frac, payload):
    M = mass_matrix(joint_angles(x_of(frac)), payload)
    np.testing.assert_allclose(M, M.T, atol=1e-15)
    assert np.linalg.eigvalsh(M).min() > 0.0
    # the swing is decoupled from the planar joints
    assert np.all(M[0, 1:] == 0.0)


def test_payload_adds_its_mass():
    q = joint_angles(x_of(POSTURES[0]))
    pts = forward_kinematics(q)
    dM = mass_matrix(q, 2.0) - mass_matrix(q, 0.0)
    r = math.hypot(*pts["bucket_com"][:2])
    assert dM[0, 0] == pytest.approx(2.0 * r * r, rel=1e-12)
    dG = gravity(q, 2.0) - gravity(q, 0.0)
    J = np.zeros((3, 4))
    e = 1e-6
    for j in range(4):
        dq = np.zeros(4)
        dq[j] = e
        J[:, j] = (forward_kinematics(q + dq)["bucket_com"] - forward_kinematics(q - dq)["bucket_com"]) / (2 * e)
    np.testing.assert_allclose(dG, 2.0 * G * J[2], atol=1e-7)


@pytest.mark.parametrize("frac", POSTURES)
def test_mass_matrix_derivative_and_coriolis(frac):
    q = joint_angles(x_of(frac)) + np.array([0.2, 0, 0, 0])
    dM = mass_matrix_derivative(q, 1.0)
    e = 1e-6
    fd = np.zeros((4, 4, 4))
    for k in range(4):
        dq = np.zeros(4)
        dq[k] = e
        fd[:, :, k] = (mass_matrix(q + dq, 1.0) - mass_matrix(q - dq, 1.0)) / (2 * e)
    np.testing.assert_allclose(dM, fd, atol=1e-8)
    qd = np.array([0.7, -0.4, 1.1, -2.0])
    christoffel = np.einsum("ijk,j,k->i", fd, qd, qd) - 0.5 * np.einsum("jki,j,k->i", fd, qd, qd)
    np.testing.assert_allclose(coriolis(q, qd, 1.0), christoffel, atol=1e-7)
    # C q' does no work against q' with the skew-symmetry of M' - 2C: q'^T (M' q' - 2 C q') = 0
    Mdot = np.einsum("ijk,k->ij", dM, qd)
    assert qd @ (Mdot @ qd - 2 * coriolis(q, qd, 1.0)) == pytest.approx(0.0, abs=1e-10)


def gravity_by_hand(q, payload=0.0):
    """dV/dq from the links' horizontal distances to each joint's pivot."""
    beta = math.asin(EX.boom_h / EX.boom.c1)
    pb = q[1] - beta
    pa = pb - q[2]
    pk = pa - q[3]
    r_boom_com = 0.30 * math.cos(pb)
    r_arm_piv = 0.60 * math.cos(pb)
    r_arm_com = r_arm_piv + 0.15 * math.cos(pa)
    r_bkt_piv = r_arm_piv + 0.35 * math.cos(pa)
    r_bkt_com = r_bkt_piv + 0.08 * math.cos(pk)
    m_b, m_a, m_k = 5.0, 2.5, 1.5 + payload
    # raising alpha turns everything about the boom pivot; theta_arm turns the arm and
    # bucket clockwise about the arm pivot (lowering what lies ahead of it), and so on
    g_alpha = G * (m_b * r_boom_com + m_a * r_arm_com + m_k * r_bkt_com)
    g_arm = -G * (m_a * (r_arm_com - r_arm_piv) + m_k * (r_bkt_com - r_arm_piv))
    g_bucket = -G * m_k * (r_bkt_com - r_bkt_piv)
    return np.array([0.0, g_alpha, g_arm, g_bucket])


@pytest.mark.parametrize("frac", POSTURES)
@pytest.mark.parametrize("payload", [0.0, 1.5])
def test_gravity_torques_by_hand(frac, payload):
    q = joint_angles(x_of(frac))
    np.testing.assert_allclose(gravity(q, payload), gravity_by_hand(q, payload), rtol=1e-12, atol=1e-12)


def test_gravity_at_mid_posture_value():
    """The hand computation's number at mid-stroke, as docs/excavator.md quotes it."""
    q = joint_angles(x_of(POSTURES[0]))
    assert gravity(q)[1] == pytest.approx(37.774, abs=1e-3)


@pytest.mark.parametrize("frac", POSTURES)
def test_forces_that_hold_the_posture_give_no_acceleration(frac):
    x = x_of(frac)
    q = joint_angles(x)
    f_tip = np.array([20.0, -5.0, -40.0])
    hold = (gravity(q, 1.0) - tip_torques(q, f_tip)) / lever_arms(x)
    np.testing.assert_allclose(piston_accelerations(x, np.zeros(4), hold, f_tip, 1.0), 0.0, atol=1e-10)
    # and the stepping keeps it still (friction off, so nothing else holds it)
    nf = frictionless()
    xs, vs = advance_linkage((x, np.zeros(4)), None, None, f_tip, 0.05, nf, payload=1.0, forces=hold)
    np.testing.assert_allclose(xs, x, atol=1e-12)
    np.testing.assert_allclose(vs, 0.0, atol=1e-9)
    # 10 % more force on the boom accelerates it upward
    more = hold.copy()
    more[1] *= 1.1
    assert piston_accelerations(x, np.zeros(4), more, f_tip, 1.0)[1] > 0.0


def test_piston_dynamics_on_rows_is_the_same_at_every_row():
    """``piston_dynamics`` on an (n, 4) array of states (identification's path: every
    sample of a recording at once) gives each row what one state gives, to rounding."""
    ex = Excavator()
    rng = np.random.default_rng(4)
    x = rng.uniform(0.02, 0.98, (50, 4)) * ex.strokes
    v = rng.normal(0.0, 0.2, (50, 4))
    for payload in (0.0, 1.5):
        Mx, bias, lam = piston_dynamics(x, v, payload, ex)
        assert Mx.shape == (50, 4, 4) and bias.shape == lam.shape == (50, 4)
        for k in range(50):
            one = piston_dynamics(x[k], v[k], payload, ex)
            for rows, single in zip((Mx, bias, lam), one):
                np.testing.assert_allclose(rows[k], single, rtol=1e-12, atol=1e-12 * np.max(np.abs(single)))


def test_pressures_map_to_piston_forces():
    P = EX.P_atm
    F = cylinder_forces([P + 1e5] * 4, [P] * 4)
    np.testing.assert_allclose(F, [1e5 * a.A_a for a in EX.actuators])
    assert EX.boom.A_a == pytest.approx(8.0425e-4, rel=1e-4)
    assert EX.arm.K_v == pytest.approx(2829.0 * (25 / 32) ** 2)


def test_static_friction_holds_below_and_slips_above():
    x = x_of(POSTURES[0])
    q = joint_angles(x)
    hold = gravity(q) / lever_arms(x)
    cap = EX.boom.F_s * math.cos(phi_from_x(x[1], EX.geometry))
    for share, moves in ((0.95, False), (1.05, True)):
        F = hold.copy()
        F[1] += share * cap
        xs, vs = advance_linkage((x, np.zeros(4)), None, None, np.zeros(3), 0.01, EX, forces=F)
        assert bool(xs[1] > x[1]) is moves
        np.testing.assert_allclose(xs[[0, 2, 3]], x[[0, 2, 3]], atol=1e-5)


def test_end_stops_hold_each_piston_in_its_stroke():
    x = x_of((0.02, 0.05, 0.95, 0.98))
    P = EX.P_atm
    st = (x, np.zeros(4))
    for _ in range(300):
        st = advance_linkage(st, [P, P, P + 5e5, P + 5e5], [P + 5e5, P + 5e5, P, P], np.zeros(3), 1e-3, EX)
        assert np.all(st[0] >= 0.0) and np.all(st[0] <= EX.strokes)
    np.testing.assert_array_equal(st[0], [0.0, 0.0, EX.arm.stroke, EX.bucket.stroke])
    np.testing.assert_array_equal(st[1], 0.0)


def test_energy_conserved_in_a_frictionless_free_swing_and_fall():
    """M, C and G together: the free motion conserves T + V over a second, through wide
    swings of every joint (no stops: the equations alone, integrated to 1e-10)."""
    from scipy.integrate import solve_ivp

    def rhs(t, y):
        q, qd = y[:4], y[4:]
        return np.concatenate([qd, np.linalg.solve(mass_matrix(q, 0.5), -coriolis(q, qd, 0.5) - gravity(q, 0.5))])

    q0 = joint_angles(EX.strokes * 0.7)
    sol = solve_ivp(rhs, (0.0, 1.0), np.concatenate([q0, [1.0, 0.5, -1.0, 2.0]]), rtol=1e-10, atol=1e-12,
                    t_eval=np.linspace(0.0, 1.0, 201))
    E = np.array([kinetic_energy(y[:4], y[4:], 0.5) + potential_energy(y[:4], 0.5) for y in sol.y.T])
    assert np.ptp(np.degrees(sol.y[1:4]), axis=1).min() > 90.0      # a real fall, not a wobble
    assert np.ptp(E) < 1e-6 * E[0]


def test_energy_conserved_by_the_stepping_without_friction():
    """advance_linkage, friction off, no net cylinder force: the linkage falls and swings
    freely (0.15 s, before a stop is reached); T + V stays within 0.02 % of the energy
    (first order in the substep)."""
    nf = frictionless()

    def energy(x, v):
        q = joint_angles(x)
        return kinetic_energy(q, v / lever_arms(x)) + potential_energy(q)

    st = (EX.strokes * np.array([0.5, 0.9, 0.5, 0.5]), np.array([0.05, 0.0, 0.0, 0.0]))
    e0 = energy(*st)
    drift = []
    for _ in range(150):
        st = advance_linkage(st, None, None, np.zeros(3), 1e-3, nf, forces=np.zeros(4), max_substep=1e-4)
        drift.append(energy(*st) - e0)
    assert np.all((st[0] > 0) & (st[0] < EX.strokes))
    assert abs(st[1][1]) > 0.3                                   # the boom fell fast
    assert np.max(np.abs(drift)) < 2e-4 * e0


@pytest.mark.parametrize("frac", [0.2, 0.5, 0.8])
def test_boom_only_reduction_agrees_with_physics_load(frac):
    """Swing, arm and bucket locked: the boom moves as the boom-only model (Eq. 8, 9)
    with the lumped M and F_L of lumped_boom_load at that posture."""
    x0 = x_of((0.5, frac, 0.5, 0.5))
    M, F_L = lumped_boom_load(joint_angles(x0))
    load = EX.load("boom", F_L=F_L, M=M)
    cyl = EX.boom.cylinder
    F0 = F_L * math.sin(phi_from_x(x0[1], EX.geometry))
    p_b = 2e5
    st, xb, vb = (x0, np.zeros(4)), x0[1], 0.0
    rows = []
    for i in range(150):
        t = i * 1e-3
        F = F0 + (250.0 if t < 0.04 else (-250.0 if t < 0.08 else 0.0))
        p_a = (F + p_b * cyl.A_b + EX.P_atm * (cyl.A_a - cyl.A_b)) / cyl.A_a
        st = advance_linkage(st, [p_a] * 4, [p_b] * 4, np.zeros(3), 1e-3, EX, locked=("swing", "arm", "bucket"))
        xb, vb = advance_load(xb, vb, 1e-3, p_a, p_b, 0.0, cyl, EX.geometry, load, EX.P_atm)
        rows.append((st[0][1], xb, st[1][1], vb))
        np.testing.assert_array_equal(st[0][[0, 2, 3]], x0[[0, 2, 3]])
    r = np.array(rows)
    excursion = np.ptp(r[:, 1])
    assert excursion > 1e-3
    assert np.max(np.abs(r[:, 0] - r[:, 1])) < 0.06 * excursion
    assert np.max(np.abs(r[:, 2] - r[:, 3])) < 0.03 * np.max(np.abs(r[:, 3]))
    assert r[-1, 2] == r[-1, 3] == 0.0                 # both stuck again at the end


def test_lumped_values_documented():
    """docs/excavator.md's table of the lumped M and F_L."""
    table = {0.0: (130.67, 427.68), 0.5: (108.06, 302.80), 1.0: (103.22, 247.22)}
    for frac, (M, F_L) in table.items():
        m, f = lumped_boom_load(joint_angles(x_of((0.5, frac, 0.5, 0.5))))
        assert (m, f) == (pytest.approx(M, abs=0.01), pytest.approx(F_L, abs=0.01))


def test_parameter_checks_name_the_parameter():
    with pytest.raises(ParameterError, match="l_min_arm"):
        excavator_parameters(arm=replace(EX.arm, l_min=0.2))          # shorter than |c1 - c2|
    with pytest.raises(ParameterError, match="F_s_bucket"):
        excavator_parameters(bucket=replace(EX.bucket, F_s=1.0))
    with pytest.raises(ParameterError, match="mass_arm"):
        from boomfmi.physics import Link
        excavator_parameters(arm_link=Link(0.35, 0.0, 0.15, 0.0))
    with pytest.raises(ParameterError, match="h"):
        excavator_parameters(boom_h=0.2)


# --- the FMU --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def linkage_fmu() -> Path:
    """build/fmus/linkage.fmu, rebuilt (alone) when its sources are newer."""
    fmu = ROOT / "build" / "fmus" / "linkage.fmu"
    sources = [*ROOT.joinpath("src", "boomfmi", "physics").rglob("*.py"), ROOT / "src" / "boomfmi" / "fmislave.py",
               ROOT / "fmus" / "linkage" / "linkage_fmu.py"]
    if not fmu.is_file() or any(s.stat().st_mtime > fmu.stat().st_mtime for s in sources):
        subprocess.run([sys.executable, str(ROOT / "build_fmus.py"), "linkage"], check=True, cwd=ROOT)
    return fmu


def test_fmu_validates(linkage_fmu):
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(linkage_fmu)) == []


@pytest.mark.parametrize("params, culprit", [({"l_min_arm": 0.2}, "l_min_arm"), ({"x0_boom": 0.07}, "x0_boom"),
                                             ({"F_s_swing": 1.0}, "F_s_swing"), ({"mass_boom": 0.0}, "mass_boom")])
def test_fmu_rejects_a_bad_parameter_naming_it(linkage_fmu, params, culprit):
    from boomfmi.system import FmuError, FmuInstance
    with FmuInstance(linkage_fmu) as inst:
        with pytest.raises(FmuError) as err:
            inst.initialize(parameters=params)
        assert err.value.status == 3
        assert f"parameter {culprit} =" in str(err.value)


def test_fmu_run_matches_the_python_physics(linkage_fmu):
    from boomfmi.fmubuild.references import INPUTS
    from boomfmi.system.instance import run_table
    table = INPUTS["linkage"]()
    out = run_table(linkage_fmu, table, parameters={"payload": 0.5})
    st = (EX.strokes * 0.5, np.zeros(4))
    for i in range(len(table)):
        row = out.iloc[i]
        np.testing.assert_allclose([row[f"x_{j}"] for j in JOINTS], st[0], atol=1e-12)
        np.testing.assert_allclose([row[f"v_{j}"] for j in JOINTS], st[1], atol=1e-12)
        q = joint_angles(st[0])
        np.testing.assert_allclose([row[f"angle_{j}"] for j in JOINTS], q, atol=1e-12)
        np.testing.assert_allclose([row["tip_x"], row["tip_y"], row["tip_z"]], forward_kinematics(q)["tip"],
                                   atol=1e-12)
        if i + 1 < len(table):
            r = table.iloc[i]
            st = advance_linkage(st, [r[f"p_a_{j}"] for j in JOINTS], [r[f"p_b_{j}"] for j in JOINTS],
                                 [r["f_tip_x"], r["f_tip_y"], r["f_tip_z"]], table.time[i + 1] - table.time[i],
                                 EX, payload=0.5)
    assert np.ptp(out["x_boom"]) > 1e-3 and np.ptp(out["angle_swing"]) > 0.01


def test_fmu_reference_result(linkage_fmu):
    from boomfmi.system.instance import run_table
    folder = ROOT / "fmus" / "linkage"
    inputs = pd.read_csv(folder / "linkage_in.csv")
    expected = pd.read_csv(folder / "linkage_ref.csv")
    result = run_table(linkage_fmu, inputs)
    assert list(result.columns) == list(expected.columns)
    for col in expected.columns:
        np.testing.assert_allclose(result[col], expected[col], rtol=1e-9, atol=1e-12, err_msg=col)
