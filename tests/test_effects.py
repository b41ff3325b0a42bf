"""The candidate forms of the unmodelled effects (physics/effects.py) against closed forms."""
from __future__ import annotations

import math

import numpy as np
import pytest

from boomfmi.physics import Load, mass_flow
from boomfmi.physics import reference_rig
from boomfmi.physics import effects as fx


def test_every_effect_is_off_at_its_off_value():
    load = Load()
    assert fx.spool_lag_step(3.0, 1.0, 1e-3, 0.0) == 1.0
    assert fx.deadband_command(5.3, 0.0) == 5.3
    assert fx.thermal_relaxation_step(4e5, 1e-4, 3e-5, 1e-3, 0.0, 287.0, 293.15) == 4e5
    assert fx.leakage_flow(5e5, 2e5, 0.0) == 0.0
    assert fx.stribeck_load(load, 0.01, 0.0) is load
    assert fx.cushion_flow(-1e-3, 4e5, 0.0, 0.0, 1e-7, 1e5) == -1e-3
    assert fx.sensor_lag_step(0.1, 0.2, 1e-3, 0.0) == 0.2


def test_spool_lag_is_exact_first_order():
    y, tau = 5.0, 0.004
    for _ in range(10):
        y = fx.spool_lag_step(y, 1.0, 1e-3, tau)
    assert y == pytest.approx(1.0 + 4.0 * math.exp(-0.01 / tau), rel=1e-12)


def test_a_speed_limited_spool_slews_then_lags_and_matches_its_ode():
    """The closed form against its ODE dy/dt = clip((u - y) / tau, -rate, rate) (fine
    Euler), from any point: the spool slews at ``rate`` until within rate tau of u."""
    tau, rate, u = 0.004, 300.0, 1.0
    y, t_knee = 5.0, (4.0 - rate * tau) / rate          # 4 V to go, slewing down to 1.2 V
    assert fx.spool_lag_step(y, u, 0.5 * t_knee, tau, rate) == pytest.approx(5.0 - rate * 0.5 * t_knee, rel=1e-12)
    assert fx.spool_lag_step(y, u, t_knee + tau, tau, rate) == pytest.approx(1.0 + 1.2 * math.exp(-1.0), rel=1e-12)
    assert fx.spool_rate(y, u, tau, rate) == -rate and fx.spool_rate(1.1, u, tau, rate) == pytest.approx(-25.0)
    fine, h = 5.0, 1e-6
    for _ in range(int(0.03 / h)):
        fine += h * fx.spool_rate(fine, u, tau, rate)
    step = 5.0
    for _ in range(30):
        step = fx.spool_lag_step(step, u, 1e-3, tau, rate)
    assert step == pytest.approx(fine, abs=1e-4)
    assert fx.spool_lag_step(5.0, u, 1e-3, tau, 0.0) == fx.spool_lag_step(5.0, u, 1e-3, tau)   # 0: no limit


@pytest.mark.parametrize("u, expected", [(4.85, 5.0), (5.35, 5.0), (4.0, 5.0 - 0.8 * 5.0 / 4.8),
                                         (6.0, 5.0 + 0.6 * 5.0 / 4.6), (0.0, 0.0), (10.0, 10.0)])
def test_a_band_of_its_own_width_on_each_side_of_the_centre(u, expected):
    assert fx.deadband_command(u, 0.0, width_ext=0.2, width_ret=0.4) == pytest.approx(expected, rel=1e-12)
    # a side without its own width keeps the symmetric band's
    assert fx.deadband_command(5.25, 0.3, width_ext=0.1) == 5.0


@pytest.mark.parametrize("u, expected", [(5.2, 5.0), (4.7, 5.0), (0.0, 0.0), (10.0, 10.0),
                                         (2.65, 5.0 - 2.05 * 5.0 / 4.7)])
def test_deadband_closes_the_centre_and_keeps_the_range(u, expected):
    assert fx.deadband_command(u, 0.3) == pytest.approx(expected, rel=1e-12)


def test_thermal_relaxation_heads_for_the_isothermal_pressure():
    m, V, R, T = 2e-4, 4e-5, 287.0, 293.15
    p_iso = m * R * T / V
    p = fx.thermal_relaxation_step(1.2 * p_iso, m, V, 0.01, 0.01, R, T)
    assert p == pytest.approx(p_iso * (1 + 0.2 * math.exp(-1)), rel=1e-12)


def test_leak_runs_from_high_to_low():
    assert fx.leakage_flow(5e5, 2e5, 1e-10) == pytest.approx(3e-5)
    assert fx.leakage_flow(2e5, 5e5, 1e-10) == pytest.approx(-3e-5)


def test_stribeck_falls_from_static_to_coulomb():
    load = Load(F_s=120.0, F_d=80.0)
    assert fx.stribeck_load(load, 0.0, 0.01).F_d == pytest.approx(120.0)
    assert fx.stribeck_load(load, 0.01, 0.01).F_d == pytest.approx(80.0 + 40.0 / math.e)
    assert fx.stribeck_load(load, 1.0, 0.01).F_d == pytest.approx(80.0, abs=1e-9)


def test_cushion_port_cut_follows_the_spears_engagement():
    """The port's volume leaves the chamber as the spear enters: none outside the
    cushion, all of it past the chamfer (the first fifth of the length), linear between;
    arrays as floats."""
    V_p, l_c = 4e-6, 0.01
    assert fx.cushion_port_cut(0.02, l_c, V_p) == 0.0
    assert fx.cushion_port_cut(0.01, l_c, V_p) == 0.0
    assert fx.cushion_port_cut(0.009, l_c, V_p) == pytest.approx(0.5 * V_p, rel=1e-12)
    assert fx.cushion_port_cut(0.005, l_c, V_p) == V_p
    assert fx.cushion_port_cut(-1e-4, l_c, V_p) == V_p          # (against the stop)
    assert fx.cushion_port_cut(0.005, l_c, 0.0) == 0.0          # no port given
    assert fx.cushion_port_cut(0.005, 0.0, V_p) == 0.0          # no cushion
    d = np.array([0.02, 0.009, 0.005])
    assert np.allclose(fx.cushion_port_cut(d, l_c, V_p), [0.0, 0.5 * V_p, V_p], rtol=1e-12, atol=0.0)
    assert fx.cushion_engagement_slope(0.009, l_c) == pytest.approx(-1.0 / (0.2 * l_c), rel=1e-12)
    assert fx.cushion_engagement_slope(0.005, l_c) == 0.0


def test_cushion_flow_is_the_series_of_valve_and_needle():
    mdot_n = mass_flow(1e-7, reference_rig.P_s, reference_rig.P_e)
    full = fx.cushion_flow(-2 * mdot_n, reference_rig.P_s, 0.0, 0.01, 1e-7, reference_rig.P_e)
    assert full == pytest.approx(-2 * mdot_n / math.sqrt(5.0), rel=1e-12)
    half = fx.cushion_flow(-2 * mdot_n, reference_rig.P_s, 0.009, 0.01, 1e-7, reference_rig.P_e)   # spear half in
    assert half == pytest.approx(-2 * mdot_n / math.sqrt(3.0), rel=1e-12)
    assert -2 * mdot_n < half < full < 0.0
    assert fx.cushion_flow(1e-3, reference_rig.P_s, 0.0, 0.01, 1e-7, reference_rig.P_e) == 1e-3        # inflow: check valve
    assert fx.cushion_flow(-1e-3, reference_rig.P_s, 0.02, 0.01, 1e-7, reference_rig.P_e) == -1e-3     # outside the cushion


def test_without_a_free_check_valve_the_return_passes_needle_and_check_valve_in_series():
    """A_c > 0: an inflow within the cushion passes the needle and the check valve side by
    side (area A_n + A_c, from the supply) in series with the valve; outside, freely."""
    P_s, P_e, p = reference_rig.P_s, reference_rig.P_e, 2e5
    A_n, A_c = 1e-7, 2e-7
    m_r = mass_flow(A_n + A_c, P_s, p)
    args = (0.0, 0.01, A_n, P_e)
    assert fx.cushion_flow(2 * m_r, p, *args, P_s=P_s, A_c=A_c) == pytest.approx(2 * m_r / math.sqrt(5.0), rel=1e-12)
    assert fx.cushion_flow(2 * m_r, p, 0.02, 0.01, A_n, P_e, P_s=P_s, A_c=A_c) == 2 * m_r       # outside the cushion
    assert fx.cushion_flow(2 * m_r, p, *args) == 2 * m_r                                     # A_c = 0: a free return
    assert fx.cushion_flow(1e-3, P_s + 1.0, *args, P_s=P_s, A_c=A_c) == 0.0                  # nothing pushes air in


@pytest.mark.parametrize("m, s, more", [(-5e-3, -2e-8, {}), (5e-3, -2e-8, {"P_s": reference_rig.P_s, "A_c": 2e-7})])
def test_cushion_flow_slope_matches_a_finite_difference(m, s, more):
    args = (0.0, 0.01, 1e-7, reference_rig.P_e)
    p = 4e5
    h = 10.0
    fd = (fx.cushion_flow(m + s * h, p + h, *args, **more) - fx.cushion_flow(m - s * h, p - h, *args, **more)) / (2 * h)
    assert fx.cushion_flow_slope(m, s, p, *args, **more) == pytest.approx(fd, rel=1e-4)


def test_sensor_lag_is_exact_first_order():
    assert fx.sensor_lag_step(0.0, 1.0, 0.005, 0.005) == pytest.approx(1 - math.exp(-1), rel=1e-12)
