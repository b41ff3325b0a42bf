"""The force_estimator FMU through fmpy: both methods against closed forms, the joystick
force's saturation and rate limit, and the observer on virtual-rig recordings run
through the teleoperation system (no contact: no force; a known constant force: found)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from boomfmi import physics as ph
from boomfmi.physics import reference_rig
from boomfmi.system import FmuError, FmuInstance

DT = 1e-3


def run(estimator, steps, **inputs):
    estimator.set(**inputs)
    for _ in range(steps):
        estimator.step(DT)
    return estimator.get("f_est", "f_reflect", "v_measured")


@pytest.fixture
def make(fmu):
    opened = []

    def make(**parameters):
        inst = FmuInstance(fmu("force_estimator"))
        inst.__enter__()
        opened.append(inst)
        inst.initialize(parameters=parameters)
        return inst
    yield make
    for inst in opened:
        inst.__exit__(None, None, None)


def test_position_error_uses_the_models_pneumatic_stiffness(make):
    est = make(method="position_error", tau_est=0.0)
    p_a, p_b, x_m, dx = 5e5, 3e5, 0.03, 1e-3
    got = run(est, 3, x_model=x_m, v_model=0.0, p_a_model=p_a, p_b_model=p_b, x_measured=x_m - dx)
    K = reference_rig.k * (p_a * reference_rig.A_a ** 2 / (reference_rig.V_a0 + reference_rig.A_a * x_m) + p_b * reference_rig.A_b ** 2 / (reference_rig.V_b0 + reference_rig.A_b * (reference_rig.L - x_m)))
    assert got["f_est"] == pytest.approx(K * dx, rel=1e-9)
    assert got["f_est"] > 0          # the machine lags the model extending: a force against extension


def test_position_error_with_a_calibrated_gain_and_damping(make):
    est = make(method="position_error", tau_est=0.0, K_p=2e4, D=1000.0)
    got = run(est, 3, x_model=0.0301, v_model=0.02, x_measured=0.03)
    assert got["f_est"] == pytest.approx(2e4 * 1e-4 + 1000.0 * 0.02, rel=1e-9)


def test_observer_at_steady_motion_is_eq8_read_backwards(make):
    """Constant pressures and a position held at 30 mm, the filter settled: at rest,
    the force beyond static friction is reported, towards zero."""
    est = make(method="observer", tau_est=0.0)
    p_a = 4.5e5                         # gauge
    got = run(est, 500, x_measured=0.03, p_a_measured=p_a, p_b_measured=0.0)
    phi = ph.phi_from_x(0.03, ph.Geometry())
    drive = ph.piston_force(p_a + reference_rig.P_atm, reference_rig.P_atm) - reference_rig.F_L * math.sin(phi)
    expected = drive - reference_rig.F_s * math.cos(phi)      # what static friction cannot hold
    assert expected > 0
    assert got["f_est"] == pytest.approx(expected, rel=1e-6)


def test_observer_reports_nothing_friction_can_hold_at_rest(make):
    est = make(method="observer", tau_est=0.0)
    phi = ph.phi_from_x(0.03, ph.Geometry())
    # the pressure that balances the load, plus half the static friction
    p_a = (reference_rig.F_L * math.sin(phi) + 0.5 * reference_rig.F_s * math.cos(phi)) / reference_rig.A_a
    got = run(est, 300, x_measured=0.03, p_a_measured=p_a, p_b_measured=0.0)
    assert got["f_est"] == pytest.approx(0.0, abs=1e-9)


def test_observer_ignores_a_push_into_an_end_stop(make):
    est = make(method="observer", tau_est=0.0)
    got = run(est, 300, x_measured=0.0, p_a_measured=0.0, p_b_measured=5e5)    # pressed down on the stop
    assert got["f_est"] == 0.0


def test_observer_while_sliding_at_constant_speed(make):
    """x rising at 50 mm/s: Eq. 8 with viscous and Coulomb friction, no inertia; the
    known forces pass the motion's filter, whose delay on a ramp is 2 / omega."""
    est = make(method="observer", tau_est=0.0, f_motion=30.0)
    v, p_a, p_b = 0.05, 5e5, 1e5
    est.set(p_a_measured=p_a, p_b_measured=p_b)
    for k in range(400):
        est.set(x_measured=0.01 + v * k * DT)
        est.step(DT)
    got = est.get("f_est", "v_measured")
    x = 0.01 + v * 399 * DT - v * 2.0 / (2 * math.pi * 30.0)
    phi = ph.phi_from_x(x, ph.Geometry())
    expected = (ph.piston_force(p_a + reference_rig.P_atm, p_b + reference_rig.P_atm) - reference_rig.F_L * math.sin(phi)
                - reference_rig.K_v * v - reference_rig.F_d * math.cos(phi))
    assert got["v_measured"] == pytest.approx(v, rel=1e-6)
    assert got["f_est"] == pytest.approx(expected, abs=0.5)


@pytest.mark.parametrize("p_floor, seen", [(0.0, -0.5e5), (-1e6, 0.0)])
def test_a_reading_at_the_sensors_floor_gives_way_to_the_models_vacuum(make, p_floor, seen):
    """Chamber B at -0.5 bar gauge reads 0 on a 0 to 10 bar sensor: the observer takes
    the model's -0.5 bar, unless the floor is switched off."""
    est = make(method="observer", tau_est=0.0, p_floor=p_floor)
    v, p_a = -0.05, 0.3e5
    est.set(p_a_measured=p_a, p_b_measured=0.0, p_a_model=p_a + reference_rig.P_atm, p_b_model=reference_rig.P_atm - 0.5e5)
    for k in range(400):
        est.set(x_measured=0.05 + v * k * DT)
        est.step(DT)
    x = 0.05 + v * 399 * DT - v * 2.0 / (2 * math.pi * 30.0)
    phi = ph.phi_from_x(x, ph.Geometry())
    expected = (ph.piston_force(p_a + reference_rig.P_atm, seen + reference_rig.P_atm) - reference_rig.F_L * math.sin(phi)
                - reference_rig.K_v * v + reference_rig.F_d * math.cos(phi))
    assert est.get("f_est")["f_est"] == pytest.approx(expected, abs=0.5)


def test_reflected_force_is_rate_limited_then_saturated(make):
    est = make(method="position_error", tau_est=0.0, K_p=2e4, gain=0.05, f_max=20.0, rate_max=500.0)
    est.set(x_model=0.05, x_measured=0.0)            # f_est = 1000 N -> target 50 N > f_max
    history = []
    for _ in range(60):
        est.step(DT)
        history.append(est.get("f_reflect")["f_reflect"])
    steps = np.diff([0.0] + history)
    ramp = steps[steps > 0]
    assert np.allclose(ramp[:-1], 500.0 * DT, rtol=1e-12)
    assert max(history) == history[-1] == 20.0
    assert len(ramp) == pytest.approx(20.0 / (500.0 * DT), abs=1)
    est.set(x_model=0.0, x_measured=0.05)            # reverse: towards -f_max at the same rate
    est.step(DT)
    assert est.get("f_reflect")["f_reflect"] == pytest.approx(20.0 - 0.5, rel=1e-12)


def test_small_estimates_are_scaled_by_the_gain(make):
    est = make(method="position_error", tau_est=0.0, K_p=2e4)
    got = run(est, 10, x_model=0.0101, x_measured=0.01)        # f_est = 2 N, target 0.1 N
    assert got["f_reflect"] == pytest.approx(0.05 * 2.0, rel=1e-9)


@pytest.mark.parametrize("bad", [{"method": "kalman"}, {"f_motion": 0.0}, {"f_max": 0.0},
                                 {"rate_max": -1.0}, {"M": 0.0}])
def test_bad_parameters_are_fmi_errors(fmu, bad):
    with FmuInstance(fmu("force_estimator")) as inst:
        with pytest.raises(FmuError, match=next(iter(bad))):
            inst.initialize(parameters=bad)


# -- through the teleoperation system, on virtual-rig recordings --------------------------
def _teleoperate(ssp_path, tmp_path, contact, method="observer"):
    from boomfmi.experiments import held
    from boomfmi.recording import write_recording
    from boomfmi.rig.offline import run_offline
    from boomfmi.simulate import replay_parameters, run_experiment
    cfg = {"x0": 0.01, "seed": 3}
    if contact:
        cfg["contact"] = contact
    prof = held([(0.3, 5.0), (0.6, 3.6), (0.4, 5.0), (0.5, 6.2), (0.2, 5.0)])
    path = write_recording(tmp_path / "run.csv", run_offline(cfg, prof, prof.duration))
    (tmp_path / "cfg.json").write_text(json.dumps(cfg))
    return run_experiment(ssp_path.parent / "teleoperation.ssp", str(path),
                          parameters=[{**replay_parameters(path), "force_estimator.method": method}])


def test_no_contact_gives_no_force_within_the_noise(ssp_path, tmp_path):
    out = _teleoperate(ssp_path, tmp_path, None)
    moving = np.abs(np.gradient(out["x_measured"], out["t"])) > 5e-3
    judged = (out["x_measured"] > 1e-3) & (out["x_measured"] < reference_rig.L - 1e-3)
    f = out["f_est"][judged].to_numpy()
    assert moving[judged].mean() > 0.3                       # the run does move
    assert np.sqrt(np.mean(f ** 2)) < 40.0                   # N: the rig's noise, through M a
    assert abs(np.mean(f)) < 15.0


def test_a_known_constant_force_is_found_with_its_sign(ssp_path, tmp_path):
    """150 N against extension from t = 0: lifting, the observer finds it."""
    out = _teleoperate(ssp_path, tmp_path, {"type": "ramp", "start": 0.0, "rate": 1e6, "max": 150.0, "sign": 1})
    judged = ((out["x_measured"] > 1e-3) & (out["x_measured"] < reference_rig.L - 1e-3) & (out["t"] > 0.35)).to_numpy()
    assert np.allclose(out["f_ext"][judged], 150.0)
    f = out["f_est"][judged].to_numpy()
    assert np.median(f) == pytest.approx(150.0, rel=0.1)
