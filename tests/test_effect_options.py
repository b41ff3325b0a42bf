"""The unmodelled effects as options of their FMUs (off by default), through fmpy."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from boomfmi.physics import reference_rig
from boomfmi.recording import write_recording
from boomfmi.system import FmuError, FmuInstance

k, R, T = reference_rig.k, reference_rig.R, reference_rig.T


def choked(A, P_u=reference_rig.P_s):
    return A * P_u * math.sqrt(k / (R * T)) * (2 / (k + 1)) ** ((k + 1) / (2 * (k - 1)))


def test_valve_dynamics_lags_the_opening(fmu):
    tau, dt = 0.004, 0.004
    with FmuInstance(fmu("valve")) as valve:
        valve.initialize(dict(tau_spool=tau), inputs=dict(u=5.0, p_a=1.5e5, p_b=1.5e5))
        valve.set(u=1.0)
        assert valve.get("mdot_a")["mdot_a"] == 0.0              # the spool still sits at 5 V
        valve.step_to(0.0, dt)
        y = 1.0 + 4.0 * math.exp(-dt / tau)                      # first-order, one tau later
        assert valve.get("mdot_a")["mdot_a"] == pytest.approx(choked(reference_rig.A_max * (5 - y) / 5), rel=1e-9)


def test_a_speed_limited_spool_slews_through_the_fmu(fmu):
    """rate_spool limits the spool's speed: after 4 ms of a step from 5 V to 1 V it has
    travelled rate x 4 ms (300 V/s: 1.2 V), not the lag's 4 (1 - 1/e) V."""
    tau, rate, dt = 0.004, 300.0, 0.004
    with FmuInstance(fmu("valve")) as valve:
        valve.initialize(dict(tau_spool=tau, rate_spool=rate), inputs=dict(u=5.0, p_a=1.5e5, p_b=1.5e5))
        valve.set(u=1.0)
        valve.step_to(0.0, dt)
        y = 5.0 - rate * dt
        assert valve.get("mdot_a")["mdot_a"] == pytest.approx(choked(reference_rig.A_max * (5 - y) / 5), rel=1e-9)


def test_a_spool_starts_at_the_first_command_where_the_host_sets_none_in_initialisation(fmu):
    """fmpy's, libcosim's and our SSP masters leave every input at its start value
    through initialisation and hand the first command with the first step: the spool
    starts there (as the reference's does), not at the start value's 5 V."""
    with FmuInstance(fmu("valve")) as valve:
        valve.initialize(dict(tau_spool=0.004))              # no input given in initialisation
        valve.set(u=1.0, p_a=1.5e5, p_b=1.5e5)
        valve.step_to(0.0, 1e-3)
        assert valve.get("mdot_a")["mdot_a"] == pytest.approx(choked(reference_rig.A_max * 4 / 5), rel=1e-9)


def test_valve_deadband_closes_small_commands(fmu):
    with FmuInstance(fmu("valve")) as valve:
        valve.initialize(dict(deadband=0.3), inputs=dict(u=5.0, p_a=1.5e5, p_b=1.5e5))
        valve.set(u=5.25)
        assert valve.get("mdot_a", "mdot_b") == {"mdot_a": 0.0, "mdot_b": 0.0}
        valve.set(u=1.0)
        opening = (4.0 - 0.3) * 5.0 / 4.7 / 5.0
        assert valve.get("mdot_a")["mdot_a"] == pytest.approx(choked(reference_rig.A_max * opening), rel=1e-9)


def test_piston_leakage_lets_the_chambers_creep_together_conserving_air(fmu):
    x = 0.03
    V_a, V_b = reference_rig.A_a * x + reference_rig.V_a0, reference_rig.A_b * (reference_rig.L - x) + reference_rig.V_b0
    with FmuInstance(fmu("cylinder")) as cyl:
        cyl.initialize(dict(C_leak=2e-11, p_a0=5e5, p_b0=2e5), inputs=dict(x=x))
        for i in range(200):
            cyl.step_to(i * 5e-3, 5e-3)
        p = cyl.get("p_a", "p_b")
    assert 2e5 < p["p_b"] < p["p_a"] < 5e5
    # each chamber isentropic, mass moved from A to B: dm = V dp / (k R T)
    assert (5e5 - p["p_a"]) * V_a == pytest.approx((p["p_b"] - 2e5) * V_b, rel=2e-2)


def test_turbulent_piston_leakage_is_a_choked_orifice_at_a_large_pressure_ratio(fmu):
    """p_b / p_a = 0.3 is below the critical ratio: the gap passes the choked flow
    A p_a sqrt(k / (R T)) (2 / (k + 1))^((k + 1) / (2 (k - 1))), so over 1 ms chamber A
    (adiabatic) loses k R T mdot dt / V_a of pressure and B gains k R T mdot dt / V_b."""
    x, A, dt = 0.03, 2e-8, 1e-3
    V_a, V_b = reference_rig.A_a * x + reference_rig.V_a0, reference_rig.A_b * (reference_rig.L - x) + reference_rig.V_b0
    k, R, T = reference_rig.k, reference_rig.R, reference_rig.T
    mdot = A * 5e5 * math.sqrt(k / (R * T)) * (2 / (k + 1)) ** ((k + 1) / (2 * (k - 1)))
    with FmuInstance(fmu("cylinder")) as cyl:
        cyl.initialize(dict(A_leak=A, p_a0=5e5, p_b0=1.5e5), inputs=dict(x=x))
        cyl.step_to(0.0, dt)
        p = cyl.get("p_a", "p_b")
    assert 5e5 - p["p_a"] == pytest.approx(k * R * T * mdot * dt / V_a, rel=5e-3)
    assert p["p_b"] - 1.5e5 == pytest.approx(k * R * T * mdot * dt / V_b, rel=5e-3)


def test_heat_transfer_lets_a_filled_chamber_cool_down(fmu):
    """Filled fast, the chamber's air is hot (isentropic compression): with the valve shut
    the pressure falls towards the isothermal value of its air mass."""
    x = 0.02
    V = reference_rig.A_a * x + reference_rig.V_a0
    mdot, t_fill = 2e-3, 0.02
    final = {}
    for h in (0.0, 300.0):
        with FmuInstance(fmu("cylinder")) as cyl:
            cyl.initialize(dict(h_wall=h), inputs=dict(x=x))
            cyl.set(mdot_a=mdot)
            for i in range(20):
                cyl.step_to(i * 1e-3, 1e-3)
            after_fill = cyl.get("p_a")["p_a"]
            cyl.set(mdot_a=0.0)
            for i in range(20, 520):
                cyl.step_to(i * 1e-3, 1e-3)
            final[h] = (after_fill, cyl.get("p_a")["p_a"])
    assert final[0.0][0] == final[0.0][1]                          # off: the pressure holds
    m = reference_rig.P_atm * V / (R * T) + mdot * t_fill
    assert final[300.0][1] == pytest.approx(m * R * T / V, rel=1e-3)  # on: isothermal at the end
    assert final[300.0][1] < final[300.0][0]


def test_stribeck_friction_slows_the_breakaway(fmu):
    x0 = 0.03
    phi = math.pi - math.asin(reference_rig.h / reference_rig.a) - math.acos(
        (reference_rig.a**2 + (x0 + reference_rig.l_min)**2 - reference_rig.b**2) / (2 * reference_rig.a * (x0 + reference_rig.l_min)))
    p_a = reference_rig.P_atm + (reference_rig.F_L * math.sin(phi) + 1.3 * reference_rig.F_s * math.cos(phi)) / reference_rig.A_a
    v = {}
    for v_s in (0.0, 0.02):
        with FmuInstance(fmu("boom_load")) as boom:
            boom.initialize(dict(x0=x0, v_s=v_s), inputs=dict(p_a=p_a))
            boom.step_to(0.0, 0.01)
            v[v_s] = boom.get("v")["v"]
    assert 0.0 < v[0.02] < v[0.0]


def test_end_cushioning_throttles_the_exhaust_near_the_stroke_end(fmu):
    """Retracting into x = 0, chamber A exhausts; within l_cushion its outflow must also
    pass the needle, so p_a stays higher than without the cushion; far from the end the
    two agree."""
    def run(l_c, x, steps=20):
        with FmuInstance(fmu("cylinder")) as cyl:
            cyl.initialize(dict(p_a0=reference_rig.P_s, l_cushion=l_c, A_cushion=1e-7),
                           inputs=dict(x=x, mdot_a=-2e-3))
            for k_ in range(steps):
                cyl.step_to(k_ * 1e-3, 1e-3)
            return cyl.get("p_a")["p_a"]
    assert run(0.01, 0.005) > 1.05 * run(0.0, 0.005)
    assert run(0.01, 0.03) == pytest.approx(run(0.0, 0.03), rel=1e-12)


def test_a_cushion_port_cut_off_stiffens_the_closed_chamber_as_the_closed_form(fmu):
    """A closed chamber A (no flow) driven into the cushion at constant speed: Eq. 7
    with the port's volume V_p leaving it as the spear enters (separated, not
    compressed) gives d ln p / dx = -k A_a / V(x), V = A_a x + V_a0 - V_p g(x) piecewise
    linear in x, so ln(p1/p0) is a sum of logarithms.  Without the port the FMU's step is
    exact; with it the cut is held over each step, first order in the step."""
    A, V0, l_c, V_p = reference_rig.A_a, reference_rig.V_a0, 0.01, 6e-6
    x0, x1, v, dt = 0.015, 0.004, -0.1, 1e-4

    def closed_form(V_p):
        # pieces of x where V is linear: a x + b
        pieces = [(l_c, x0, A, V0), (0.8 * l_c, l_c, A + V_p / (0.2 * l_c), V0 - V_p / 0.2),
                  (x1, 0.8 * l_c, A, V0 - V_p)]
        return math.exp(sum(-k * A / a * math.log((a * lo + b) / (a * hi + b)) for lo, hi, a, b in pieces))

    def run(V_p):
        with FmuInstance(fmu("cylinder")) as cyl:
            cyl.initialize(dict(p_a0=3e5, l_cushion=l_c, A_cushion=1e-7, V_cushion_port=V_p),
                           inputs=dict(x=x0, v=v, mdot_a=0.0, mdot_b=0.0))
            n = round((x0 - x1) / (-v * dt))
            for i in range(n):
                cyl.set(x=x0 + v * i * dt)
                cyl.step_to(i * dt, dt)
            return cyl.get("p_a")["p_a"] / 3e5
    assert run(0.0) == pytest.approx(closed_form(0.0), rel=1e-9)
    assert closed_form(V_p) > 1.1 * closed_form(0.0)          # the port's share is no detail
    assert run(V_p) == pytest.approx(closed_form(V_p), rel=2e-3)


def test_sensor_lag_smooths_what_the_bridge_reports(fmu, tmp_path):
    t = np.round(np.arange(0, 0.0505, 1e-3), 6)
    alpha = np.where(t < 0.01, 0.7, 0.8)
    path = write_recording(tmp_path / "step.csv", pd.DataFrame(
        {"t": t, "u": 5.0, "p_a": 0.0, "p_b": 0.0, "alpha": alpha}))
    with FmuInstance(fmu("hardware_bridge")) as b:
        b.initialize(dict(mode="replay", recording=str(path), tau_sensor=0.005))
        got = []
        for k_ in range(len(t) - 1):
            b.step_to(k_ * 1e-3, 1e-3)
            got.append(b.get("alpha")["alpha"])
    # one step after the jump at 10 ms: 0.7 + 0.1 (1 - e^(-1 ms / 5 ms))
    assert got[9] == pytest.approx(0.7 + 0.1 * (1 - math.exp(-0.2)), rel=1e-12)
    assert got[-1] == pytest.approx(0.8, abs=1e-4)


def test_a_sensor_dead_time_delays_what_the_bridge_reports_as_the_model_does(fmu, tmp_path):
    """delay_sensor = 3.5 ms, then tau_sensor: the FMU's outputs are the model's
    ``measure`` of the recording's samples (dead time, then the lag)."""
    from boomfmi.model import measure
    t = np.round(np.arange(0, 0.0505, 1e-3), 6)
    alpha = 0.7 + 0.1 * np.sin(60.0 * t)
    path = write_recording(tmp_path / "sine.csv", pd.DataFrame(
        {"t": t, "u": 5.0, "p_a": 0.0, "p_b": 0.0, "alpha": alpha}))
    with FmuInstance(fmu("hardware_bridge")) as b:
        b.initialize(dict(mode="replay", recording=str(path), delay_sensor=0.0035, tau_sensor=0.002))
        got = []
        for k_ in range(len(t) - 1):
            b.step_to(k_ * 1e-3, 1e-3)
            got.append(b.get("alpha")["alpha"])
    want = measure(alpha, t, 0.002, 0.0035)[1:]
    np.testing.assert_allclose(got, want, atol=1e-12)
    assert abs(got[20] - alpha[21]) > 5e-3          # it is late


@pytest.mark.parametrize("name, params, culprit", [
    ("valve", {"deadband": 5.0}, "deadband"), ("valve", {"tau_spool": -1e-3}, "tau_spool"),
    ("cylinder", {"C_leak": -1e-11}, "C_leak"), ("cylinder", {"A_leak": -1e-8}, "A_leak"),
    ("boom_load", {"v_s": -0.01}, "v_s"),
    ("hardware_bridge", {"tau_sensor": -1.0}, "tau_sensor"),
    ("hardware_bridge", {"delay_sensor": -1e-3}, "delay_sensor"),
    ("cylinder", {"n_poly": 0.5}, "n_poly"), ("cylinder", {"n_poly": 1.5}, "n_poly")])
def test_bad_effect_parameters_are_fmi_errors(fmu, name, params, culprit):
    with FmuInstance(fmu(name)) as inst:
        with pytest.raises(FmuError) as err:
            inst.initialize(params)
    assert err.value.status == 3 and f"parameter {culprit} =" in str(err.value)
