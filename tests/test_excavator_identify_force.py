"""Identification per joint and the tip force estimate of the whole excavator, on the
excavator virtual rig's recordings (effect-free, realistic sensors)."""
import math

import numpy as np
import pandas as pd
import pytest

from boomfmi import experiments as E
from boomfmi.identify.joints import equation_error, identify_joints, true_values
from boomfmi.identify.preprocess import prepare_machine
from boomfmi.physics.force_estimation import estimate_tip_force
from boomfmi.rig import run_excavator_offline

PAYLOAD = 0.5


@pytest.fixture(scope="module")
def identified():
    recs = []
    for cmd in (E.digging_cycle(), E.excavator_excitation()):
        recs.append(run_excavator_offline({"machine": "excavator", "payload": PAYLOAD}, cmd, cmd.duration))
    return identify_joints(recs), true_values(payload=PAYLOAD)


def _err(result, truth, name):
    return abs(result.params[name].value - truth[name]) / truth[name]


@pytest.mark.parametrize("name", ["K_v_swing", "F_d_swing", "F_s_swing", "K_v_boom", "F_d_boom", "F_s_boom",
                                  "K_v_arm", "F_d_arm", "F_s_arm", "K_v_bucket", "F_d_bucket", "F_s_bucket",
                                  "payload"])
def test_identified_within_5_percent(identified, name):
    result, truth = identified
    assert _err(result, truth, name) < 0.05, (name, result.params[name], truth[name])
    lo, hi = result.params[name].ci95
    assert lo < result.params[name].value < hi


def test_held_force_bounds_static_friction_from_below(identified):
    """The largest force a joint is seen to hold at rest is a lower bound of its F_s
    only where the other joints' motion, whose share of the net force comes from
    filtered accelerations, does not prop it up: every joint's bound stays below the
    truth (the boom's read 128.6 N against 113.3 N while the swing and arm started)."""
    result, truth = identified
    for j in ("swing", "boom", "arm", "bucket"):
        assert result.details["static_friction"][j]["lower_bound_N"] <= truth[f"F_s_{j}"], j


def test_equation_error_is_unbiased_on_exact_sensors():
    """Exact sensors (no noise, no ADC): stage 1 recovers every K_v and F_d and the
    payload within 0.5 %.  It leaves out the rows around each start and stop, where the
    sliding mask cuts the filtered inertia's spread; with them the payload read +4.5 %
    and F_d_boom -2.4 % on these very recordings."""
    exact = {"machine": "excavator", "payload": PAYLOAD,
             "noise": {"p_sigma": 0.0, "alpha_sigma": 0.0, "quantise": False}}
    recs = [run_excavator_offline(exact, cmd, cmd.duration) for cmd in (E.digging_cycle(), E.excavator_excitation())]
    est, _ = equation_error([prepare_machine(r) for r in recs], n_boot=2)
    truth = true_values(payload=PAYLOAD)
    for name, e in est.items():
        assert abs(e.value - truth[name]) < 0.005 * truth[name], (name, e.value, truth[name])


@pytest.fixture(scope="module")
def push():
    cmd = E.digging_cycle()
    return run_excavator_offline({"machine": "excavator", "contact": E.contact("prescribed_push").config()},
                                 cmd, cmd.duration)


@pytest.fixture(scope="module")
def push_observed(push):
    """The observer over the whole push, once for its tests (:func:`_observer`; that it is
    ``estimate_tip_force``'s answers is checked in ``test_fmu_matches_physics_and_validates``)."""
    return _observer(push)


@pytest.mark.xfail(strict=True, reason="physically unobservable in this scenario: through the whole push the "
                                       "swing sits on its stop (lateral force unfelt) and never more than one "
                                       "joint slides (0 samples of 3983 with >= 2); measured RMSE 66/53/41 % "
                                       "of the peak (x/y/z); see docs/excavator.md")
def test_tip_force_rmse_within_10_percent_of_peak(push, push_observed):
    f = push_observed[0]
    ft = push[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy()
    for k in range(3):
        assert np.sqrt(np.mean((f[:, k] - ft[:, k]) ** 2)) < 0.1 * np.max(np.abs(ft[:, k]))


@pytest.fixture(scope="module", params=["soft_soil", "hard_soil"])
def soil(request):
    cmd = E.digging_cycle()
    d = run_excavator_offline({"machine": "excavator", "contact": E.contact(request.param).config()}, cmd, cmd.duration)
    f, f_known, _, _ = _observer(d)          # the observer once, for every test of the soil
    return request.param, d, f, f_known


#: (scenario, axis) whose RMSE is not yet within 10 % of the peak, and why
SOIL_NOT_YET = {
    ("hard_soil", "z"): "measured 12.1 %: pressed into the ground the boom sits on its lower stop and the bucket on its "
                        "stop, so only the arm slides and the force is bounded, not determined (see docs/excavator.md)",
}


@pytest.mark.slow
@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_tip_force_on_the_soils_within_10_percent_of_peak(soil, axis, request):
    """The digging cycle into soft soil and into hard ground: the least-squares tip force's
    RMSE over the whole cycle, per world axis, within 10 % of that axis' peak."""
    name, d, f, _ = soil
    if (name, axis) in SOIL_NOT_YET:
        request.applymarker(pytest.mark.xfail(strict=True, reason=SOIL_NOT_YET[(name, axis)]))
    k = "xyz".index(axis)
    ft = d[f"f_tip_{axis}"].to_numpy()
    assert np.sqrt(np.mean((f[:, k] - ft) ** 2)) < 0.1 * np.max(np.abs(ft))


@pytest.mark.slow
def test_tip_force_where_determined_within_10_percent(soil):
    """The informative joints' estimate on the soils, where it reports a component (z:
    boom, arm and bucket sliding; x and y never while the swing is on its stop), within
    10 % of the peak (RMSE)."""
    _, d, _, f = soil
    ft = d[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy()
    on = np.linalg.norm(ft, axis=1) > 0.5
    known = ~np.isnan(f[:, 2])
    assert (known & on).sum() > 0.04 * on.sum()
    rmse = np.sqrt(np.mean((f[known, 2] - ft[known, 2]) ** 2))
    assert rmse < 0.1 * np.max(np.abs(ft[:, 2]))
    assert np.all(np.isnan(f[on, 0])) and np.all(np.isnan(f[on, 1]))


def test_tip_force_cannot_tell_where_joints_carry_no_information(push, push_observed):
    """During the push at most one joint slides and the swing is on its stop: the
    estimate from the informative joints reports x and y as unknown (nan) throughout,
    instead of a guess."""
    _, f, n_info, _ = push_observed
    ft = push[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy()
    on = np.linalg.norm(ft, axis=1) > 0.5
    assert on.sum() > 3000
    assert np.all(n_info[on] <= 1)
    assert np.all(np.isnan(f[on, 0])) and np.all(np.isnan(f[on, 1]))
    # where no joint slides, nothing is reported
    assert np.all(np.isnan(f[n_info == 0]))


def _observer(d):
    """estimate_tip_force's loop (its defaults), run once for both its answers: the
    least-squares estimate, and per sample the informative joints' estimate (nan where
    undetermined), their number and the determined components (finite ``state["f_known"]``)."""
    from boomfmi.physics.linkage import JOINTS, Excavator
    from boomfmi.physics.force_estimation import F_MOTION, F_MOTION_SWING, observer_start, observer_step
    P = Excavator().P_atm
    Q = d[[f"angle_{j}" for j in JOINTS]].to_numpy()
    PA = d[[f"p_a_{j}" for j in JOINTS]].to_numpy() + P
    PB = d[[f"p_b_{j}" for j in JOINTS]].to_numpy() + P
    t = d["t"].to_numpy()
    f, f_known = np.zeros((len(t), 3)), np.full((len(t), 3), np.nan)
    n_info, det = np.zeros(len(t), int), np.zeros((len(t), 3), bool)
    omega = 2.0 * math.pi * np.array([F_MOTION_SWING, F_MOTION, F_MOTION, F_MOTION])
    state = observer_start(Q[0], PA[0], PB[0])
    for k in range(1, len(t)):
        state, f[k], _, _ = observer_step(state, Q[k], PA[k], PB[k], t[k] - t[k - 1], omega)
        f_known[k], n_info[k], det[k] = state["f_known"], np.sum(state["informative"]), np.isfinite(state["f_known"])
    return f, f_known, n_info, det


def test_fmu_matches_physics_and_validates(push):
    fmpy = pytest.importorskip("fmpy")
    from pathlib import Path
    fmu = Path(__file__).resolve().parents[1] / "build" / "fmus" / "excavator_force_estimator.fmu"
    if not fmu.exists():
        pytest.skip("build the FMU first: build_fmus.py excavator_force_estimator")
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fmu)) == []
    d = push.iloc[:1500]
    names = [f"{q}_{j}" for j in ("swing", "boom", "arm", "bucket") for q in ("p_a", "p_b", "angle")]
    inputs = np.zeros(len(d), dtype=[("time", float)] + [(n, float) for n in names])
    inputs["time"] = d["t"].to_numpy()
    for n in names:
        inputs[n] = d[n].to_numpy()
    res = fmpy.simulate_fmu(str(fmu), start_time=0.0, stop_time=float(d["t"].iloc[-1]), step_size=1e-3,
                            output_interval=1e-3, input=inputs,
                            output=["f_est_x", "f_est_y", "f_est_z", "f_reflect_z", "residual", "n_informative",
                                    "determined_x", "determined_y", "determined_z", "f_det_x", "f_det_y", "f_det_z"])
    f, f_known, n_info, det = _observer(d)
    # the observer's loop is estimate_tip_force's, both its answers (the other tests use it)
    np.testing.assert_array_equal(estimate_tip_force(d)[0], f)
    known, _, counted = estimate_tip_force(d, cannot_tell=True)
    np.testing.assert_array_equal(known, f_known)
    np.testing.assert_array_equal(counted, n_info)
    # the FMU's output at t_k holds the step that took the sample at t_(k-1): one step behind
    n = min(len(res), len(f)) - 1
    for k, c in enumerate("xyz"):
        assert np.allclose(res[f"f_est_{c}"][1:n + 1], f[:n, k], atol=1e-6, rtol=1e-6) or \
            np.allclose(res[f"f_est_{c}"][:n], f[:n, k], atol=1e-6, rtol=1e-6)
    # cannot tell: the physics' informative joints and determined components, step for step
    np.testing.assert_array_equal(res["n_informative"][1:n + 1], n_info[:n])
    assert np.array_equal(det, ~np.isnan(f_known))
    assert det[:, 1].sum() > 100 and not det[:, 0].any()    # the swing alone sliding: y only
    for k, c in enumerate("xyz"):
        np.testing.assert_array_equal(res[f"determined_{c}"][1:n + 1], det[:n, k], err_msg=c)
        held = pd.Series(f_known[:n, k]).ffill().fillna(0.0).to_numpy()    # the last determined value
        np.testing.assert_allclose(res[f"f_det_{c}"][1:n + 1], held, atol=1e-6, rtol=1e-6, err_msg=c)
    assert np.all(np.abs(res["f_reflect_z"]) <= 20.0 + 1e-9)
    from boomfmi.system import FmuError, FmuInstance
    with FmuInstance(fmu) as inst, pytest.raises(FmuError) as err:
        inst.initialize(parameters={"f_motion": -1.0})
    assert err.value.status == 3 and "f_motion" in str(err.value)


def test_tip_force_silent_while_the_angle_sensors_toggle_at_rest():
    """A machine at rest (pistons at mid-stroke, the pressures that hold it against
    gravity) whose angle sensors flip by one count of a 12-bit converter every 50 ms,
    as a sensor sitting on a code's edge does: no joint moves, so no force may appear.
    Through the fast filter each flip reads as an acceleration of about a metre per
    second squared (at the swing's crank, hundreds of newtons); the observer counts a
    joint that is not sliding by both filters as at rest, with no acceleration."""
    from boomfmi.physics.linkage import JOINTS, Excavator, joint_angles
    from boomfmi.rig import vented_holding_pressures
    ex = Excavator()
    x = 0.5 * np.asarray(ex.strokes)
    p_a, p_b = vented_holding_pressures(x, ex)
    q = joint_angles(x, ex)
    t = np.arange(0.0, 2.0, 1e-3)
    count = math.pi / 4096
    flips = (np.floor(t / 0.05) % 2)[:, None] * count * np.array([1.0, 1.0, -1.0, 1.0])
    d = pd.DataFrame({"t": t})
    for i, j in enumerate(JOINTS):
        d[f"angle_{j}"] = q[i] + flips[:, i]
        d[f"p_a_{j}"] = p_a[i] - ex.P_atm
        d[f"p_b_{j}"] = p_b[i] - ex.P_atm
    f, _ = estimate_tip_force(d)
    assert np.max(np.abs(f)) < 0.5, np.max(np.abs(f), axis=0)
