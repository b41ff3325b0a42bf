"""The force_estimator FMU: the position-error law, saturation and rate limit."""
from __future__ import annotations

import pytest

from boomfmi.system import FmuInstance

PARAMS = dict(K_p=2.0e4, D=2829.0, gain=0.05, f_max=20.0, rate_max=500.0)


@pytest.fixture
def estimator(fmu):
    with FmuInstance(fmu("force_estimator")) as inst:
        inst.initialize(parameters=PARAMS)
        yield inst


def test_zero_for_equal_positions_and_velocities(estimator):
    for x, v in [(0.0, 0.0), (0.03, 0.05), (0.06, -0.1)]:
        estimator.set(x_model=x, x_measured=x, v_model=v, v_measured=v)
        assert estimator.get("f_est")["f_est"] == 0.0
        estimator.step(1e-3)
        assert estimator.get("f_reflect")["f_reflect"] == 0.0


@pytest.mark.parametrize("dx, dv", [(1e-3, 0.0), (-2e-3, 0.0), (0.0, 0.01), (5e-4, -0.02)])
def test_follows_the_documented_law(estimator, dx, dv):
    estimator.set(x_model=0.03 + dx, x_measured=0.03, v_model=0.05 + dv, v_measured=0.05)
    expected = PARAMS["K_p"] * dx + PARAMS["D"] * dv
    assert estimator.get("f_est")["f_est"] == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_machine_lagging_the_model_means_force_against_extension(estimator):
    estimator.set(x_model=0.031, x_measured=0.030)
    assert estimator.get("f_est")["f_est"] > 0


def test_reflected_force_is_rate_limited_then_saturated(estimator):
    dt = 1e-3
    estimator.set(x_model=0.05, x_measured=0.0)        # f_est = 1000 N -> target 50 N > f_max
    history = []
    for _ in range(60):
        estimator.step(dt)
        history.append(estimator.get("f_reflect")["f_reflect"])
    steps = [b - a for a, b in zip([0.0] + history, history)]
    ramp = [s for s in steps if s > 0]
    assert all(s == pytest.approx(PARAMS["rate_max"] * dt, rel=1e-12) for s in ramp[:-1])
    assert max(history) == PARAMS["f_max"]
    assert history[-1] == PARAMS["f_max"]
    assert len(ramp) == pytest.approx(PARAMS["f_max"] / (PARAMS["rate_max"] * dt), abs=1)
    estimator.set(x_model=0.0, x_measured=0.05)         # reverse: -f_max, at the same rate
    estimator.step(dt)
    assert estimator.get("f_reflect")["f_reflect"] == pytest.approx(PARAMS["f_max"] - 0.5, rel=1e-12)


def test_small_estimates_are_scaled_by_the_gain(estimator):
    estimator.set(x_model=0.0101, x_measured=0.01)      # f_est = 2 N, target 0.1 N
    for _ in range(10):
        estimator.step(1e-3)
    assert estimator.get("f_reflect")["f_reflect"] == pytest.approx(0.05 * 2.0, rel=1e-9)
