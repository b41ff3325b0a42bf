"""Identification per joint and the tip force estimate of the whole excavator, on the
excavator virtual rig's recordings (effect-free, realistic sensors)."""
import math

import numpy as np
import pytest

from boomfmi import experiments as E
from boomfmi.identify.excavator import identify_excavator, true_values
from boomfmi.physics.excavator_force import estimate_tip_force
from boomfmi.rig.excavator import run_excavator_offline

PAYLOAD = 0.5


@pytest.fixture(scope="module")
def identified():
    recs = []
    for cmd in (E.digging_cycle(), E.excavator_excitation()):
        recs.append(run_excavator_offline({"machine": "excavator", "payload": PAYLOAD}, cmd, cmd.duration))
    return identify_excavator(recs), true_values(payload=PAYLOAD)


def _err(result, truth, name):
    return abs(result.params[name].value - truth[name]) / truth[name]


@pytest.mark.parametrize("name", ["K_v_swing", "F_d_swing", "K_v_boom", "F_d_boom", "K_v_arm", "F_d_arm",
                                  "F_s_arm", "payload"])
def test_identified_within_5_percent(identified, name):
    result, truth = identified
    assert _err(result, truth, name) < 0.05, (name, result.params[name], truth[name])
    lo, hi = result.params[name].ci95
    assert lo < result.params[name].value < hi


@pytest.mark.xfail(strict=True, reason="the bucket moves ~6 % of the time, in fast runs to its stops: K_v and F_d "
                                       "are confounded (measured +18 % / -48 %); F_s of swing, boom and bucket "
                                       "from the starts within 10 to 24 % only")
@pytest.mark.parametrize("name", ["K_v_bucket", "F_d_bucket", "F_s_swing", "F_s_boom", "F_s_bucket"])
def test_identified_within_5_percent_not_yet(identified, name):
    result, truth = identified
    assert _err(result, truth, name) < 0.05


@pytest.fixture(scope="module")
def push():
    cmd = E.digging_cycle()
    return run_excavator_offline({"machine": "excavator", "contact": E.contact("prescribed_push").config()},
                                 cmd, cmd.duration)


@pytest.mark.xfail(strict=True, reason="physically unobservable in this scenario: through the whole push the "
                                       "swing sits on its stop (lateral force unfelt) and never more than one "
                                       "joint slides (0 samples of 3983 with >= 2); measured RMSE 72/169/60 % "
                                       "of the peak (x/y/z); see docs/excavator.md")
def test_tip_force_rmse_within_10_percent_of_peak(push):
    f, _ = estimate_tip_force(push)
    ft = push[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy()
    for k in range(3):
        assert np.sqrt(np.mean((f[:, k] - ft[:, k]) ** 2)) < 0.1 * np.max(np.abs(ft[:, k]))


def test_tip_force_cannot_tell_where_joints_carry_no_information(push):
    """During the push at most one joint slides and the swing is on its stop: the
    estimate from the informative joints reports x and y as unknown (nan) throughout,
    instead of a guess."""
    f, _, n_info = estimate_tip_force(push, cannot_tell=True)
    ft = push[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy()
    on = np.linalg.norm(ft, axis=1) > 0.5
    assert on.sum() > 3000
    assert np.all(n_info[on] <= 1)
    assert np.all(np.isnan(f[on, 0])) and np.all(np.isnan(f[on, 1]))
    # where no joint slides, nothing is reported
    assert np.all(np.isnan(f[n_info == 0]))


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
                            output=["f_est_x", "f_est_y", "f_est_z", "f_reflect_z", "residual"])
    f, _ = estimate_tip_force(d)
    # the FMU's output at t_k holds the step that took the sample at t_(k-1): one step behind
    n = min(len(res), len(f)) - 1
    for k, c in enumerate("xyz"):
        assert np.allclose(res[f"f_est_{c}"][1:n + 1], f[:n, k], atol=1e-6, rtol=1e-6) or \
            np.allclose(res[f"f_est_{c}"][:n], f[:n, k], atol=1e-6, rtol=1e-6)
    assert np.all(np.abs(res["f_reflect_z"]) <= 20.0 + 1e-9)
    from boomfmi.system import FmuError, FmuInstance
    with FmuInstance(fmu) as inst, pytest.raises(FmuError) as err:
        inst.initialize(parameters={"f_motion": -1.0})
    assert err.value.status == 3 and "f_motion" in str(err.value)
