"""boomfmi.physics on its own: scalar and array paths agree, closed forms hold."""
from __future__ import annotations

import math

import numpy as np
import pytest

from boomfmi import physics as ph
from boomfmi.physics import reference_rig


def test_scalar_and_array_paths_agree():
    rng = np.random.default_rng(1)
    u = rng.uniform(0, 10, 200)
    p_a = rng.uniform(0.9e5, 7.5e5, 200)
    p_b = rng.uniform(0.9e5, 7.5e5, 200)
    arr_a, arr_b = ph.chamber_flows(u, p_a, p_b)
    for i in range(200):
        sa, sb = ph.chamber_flows(float(u[i]), float(p_a[i]), float(p_b[i]))
        assert sa == pytest.approx(arr_a[i], rel=1e-13, abs=1e-18)
        assert sb == pytest.approx(arr_b[i], rel=1e-13, abs=1e-18)
    x = rng.uniform(0, reference_rig.L, 50)
    np.testing.assert_allclose(ph.phi_from_x(x), [ph.phi_from_x(float(v)) for v in x], rtol=1e-14)


def test_x_alpha_x_round_trip():
    x = np.linspace(0.0, reference_rig.L, 10001)
    np.testing.assert_allclose(ph.x_from_alpha(ph.alpha_from_x(x)), x, rtol=0, atol=1e-12)
    for v in (0.0, 0.017, reference_rig.L):
        assert abs(ph.x_from_alpha(ph.alpha_from_x(v)) - v) < 1e-12


def test_choked_branch_equals_subsonic_formula_at_critical_ratio():
    gas = ph.Gas()
    p_cr = ph.critical_pressure_ratio(gas.k)
    k, R, T = gas
    sub = math.sqrt(2 * k / (R * T * (k - 1))) * math.sqrt(p_cr ** (2 / k) - p_cr ** ((k + 1) / k))
    choked = math.sqrt(k / (R * T)) * (2 / (k + 1)) ** ((k + 1) / (2 * (k - 1)))
    assert sub == pytest.approx(choked, rel=1e-14)


def test_signed_flow_reverses_with_the_pressures():
    assert ph.signed_mass_flow(1e-6, 3e5, 2e5) == pytest.approx(-ph.signed_mass_flow(1e-6, 2e5, 3e5))
    assert ph.signed_mass_flow(1e-6, 3e5, 3e5) == 0.0


def test_chamber_step_is_exact_for_constant_volume_and_flow():
    V, mdot, dt = 3e-5, 2e-4, 0.01
    gas = ph.Gas()
    p = ph.chamber_pressure_step(2e5, V, V, mdot, dt, gas)
    assert p == pytest.approx(2e5 + gas.k * gas.R * gas.T * mdot * dt / V, rel=1e-13)


def test_chamber_step_matches_fine_integration_of_eq_4():
    """Held flow, moving piston: the closed form against RK4 on Eq. 4 with tiny steps."""
    gas, mdot, dt = ph.Gas(), 3e-4, 2e-3
    V0, V1 = 2.0e-5, 3.3e-5
    P = 2e5
    n = 20000
    for i in range(n):
        def f(s, P):
            V = V0 + (V1 - V0) * s / dt
            return (gas.k * gas.R * gas.T * mdot - gas.k * P * (V1 - V0) / dt) / V
        t, hh = i * dt / n, dt / n
        k1 = f(t, P); k2 = f(t + hh / 2, P + hh / 2 * k1); k3 = f(t + hh / 2, P + hh / 2 * k2)
        k4 = f(t + hh, P + hh * k3)
        P += hh / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert ph.chamber_pressure_step(2e5, V0, V1, mdot, dt, gas) == pytest.approx(P, rel=1e-10)


def test_slide_stops_exactly_when_velocity_reaches_zero():
    load = ph.Load()
    v0, F = 0.05, -50.0                                   # sliding up, drive pulls down
    dx, v = ph.slide_or_stick(v0, F, 1.0, 0.5, load)
    assert v == 0.0                                       # stuck: |F| < F_s
    F_net = F - load.F_d
    t_rest = load.M / load.K_v * math.log1p(-load.K_v * v0 / F_net)
    tau = load.M / load.K_v
    v_inf = F_net / load.K_v
    expected = v_inf * t_rest + (v0 - v_inf) * tau * (1 - math.exp(-t_rest / tau))
    assert dx == pytest.approx(expected, rel=1e-12)


def test_slide_reverses_when_the_drive_exceeds_static_friction():
    load = ph.Load()
    dx, v = ph.slide_or_stick(0.01, -400.0, 1.0, 0.2, load)
    assert v < 0


def test_coulomb_friction_without_viscosity():
    load = ph.Load(K_v=0.0)
    dx, v = ph.slide_or_stick(0.0, 200.0, 1.0, 0.01, load)
    a = (200.0 - load.F_d) / load.M
    assert v == pytest.approx(a * 0.01, rel=1e-12)
    assert dx == pytest.approx(a * 0.01**2 / 2, rel=1e-12)


def test_friction_force_is_eq_9():
    load = ph.Load()
    phi = 0.9
    c = math.cos(phi)
    assert ph.friction_force(0.0, 50.0, phi, load) == 50.0
    assert ph.friction_force(0.0, 200.0, phi, load) == pytest.approx(load.F_d * c)
    assert ph.friction_force(-0.1, 0.0, phi, load) == pytest.approx(-load.F_d * c)
    arr = ph.friction_force(np.array([0.0, 0.0, 0.1]), np.array([50.0, -200.0, 0.0]), phi, load)
    np.testing.assert_allclose(arr, [50.0, -load.F_d * c, load.F_d * c])


def test_geometry_check_names_the_parameter():
    with pytest.raises(ph.ParameterError, match="parameter h"):
        ph.check_geometry(ph.Geometry(h=0.2), reference_rig.L)
    ph.check_geometry(ph.Geometry(), reference_rig.L)


def test_sliding_velocity_is_eq_8s_closed_form_under_a_held_force():
    """Under a constant net force F from rest, Eq. 8 gives v(t) = F / K_v (1 - exp(-K_v t / M));
    the recursion is exact at every sample, row by row for a 2-D force."""
    K_v, M, dt, F = 2829.0, 22.7, 1e-3, 150.0
    t = np.arange(200) * dt
    v = ph.sliding_velocity(0.0, np.full(200, F), K_v, M, dt)
    np.testing.assert_allclose(v, F / K_v * (1.0 - np.exp(-K_v * t / M)), rtol=1e-12, atol=1e-15)
    rows = ph.sliding_velocity(np.array([0.0, 0.05]), np.vstack([np.full(50, F), np.zeros(50)]), K_v, M, dt)
    np.testing.assert_allclose(rows[1], 0.05 * np.exp(-K_v * t[:50] / M), rtol=1e-12)
    np.testing.assert_allclose(rows[0], v[:50], rtol=1e-12)


def test_a_delay_line_reads_the_signal_late_and_agrees_with_delayed():
    from boomfmi.physics.lag import DelayLine, delayed
    t = np.arange(0.0, 0.1, 1e-3)
    y = np.sin(40.0 * t)
    line = DelayLine(0.0035)
    out = []
    for ti, yi in zip(t, y):
        line.push(ti, (yi, 2.0 * yi))
        out.append(line.read(ti))
    out = np.array(out)
    np.testing.assert_allclose(out[:, 0], delayed(y, t, 0.0035), atol=1e-12)
    np.testing.assert_allclose(out[:, 1], 2.0 * out[:, 0], atol=1e-12)
    assert out[0, 0] == y[0] and abs(out[50, 0] - np.sin(40.0 * (t[50] - 0.0035))) < 2e-3
    assert len(line.times) < 10          # it keeps only what a read still needs


def test_numpy_scalars_take_the_float_path():
    """Indexing an array gives numpy.float64: the elementary functions must treat it as
    a float (the math path), not as an array (a NumPy call per scalar is ~20 times slower)."""
    from boomfmi.physics import _xp
    x = np.array([0.25])[0]
    assert type(_xp.clip(x, 0.0, 0.2)) is float or _xp.clip(x, 0.0, 0.2) == 0.2
    assert _xp.where(np.bool_(True), 1.0, 2.0) == 1.0 and not isinstance(_xp.where(x > 0, 1.0, 2.0), np.ndarray)


def test_a_scalar_orifice_flow_is_the_general_form_to_the_bit():
    """mass_flow's fast path for one state (only the branch taken is evaluated) gives
    exactly what the general form (every branch evaluated, one picked) gives on floats:
    choked, subsonic and laminar ratios, the ends of the ratio's range, a NaN pressure
    (choked, as the general form's comparison says); and the array form's value to
    within a unit in the last place (NumPy's power is not libm's)."""
    from boomfmi.physics import _xp as xp
    from boomfmi.physics.orifice import R_LAMINAR, _constants, _subsonic_root

    def general(A, P_u, P_d, gas=ph.Gas()):
        P_cr, C, choked, laminar_slope = _constants(*gas)
        r = xp.clip(P_d / P_u, 0.0, 1.0)
        subsonic = C * _subsonic_root(xp.minimum(r, R_LAMINAR), gas.k)
        laminar = laminar_slope * (1.0 - r)
        return A * P_u * xp.where(r >= P_cr, xp.where(r > R_LAMINAR, laminar, subsonic), choked)
    P_u = 6e5
    for r in [0.0, 0.2, ph.critical_pressure_ratio(1.4), 0.53, 0.8, 0.998, 0.999, 0.9995, 1.0, 1.2]:
        scalar = ph.mass_flow(2.5e-6, P_u, r * P_u)
        assert scalar == general(2.5e-6, P_u, r * P_u), r
        assert ph.mass_flow(np.float64(2.5e-6), np.float64(P_u), np.float64(r * P_u)) == scalar
        array = ph.mass_flow(np.array([2.5e-6]), np.array([P_u]), np.array([r * P_u]))[0]
        assert scalar == pytest.approx(array, rel=1e-15, abs=0.0)
    assert ph.mass_flow(2.5e-6, P_u, float("nan")) == general(2.5e-6, P_u, 0.0)     # choked


def test_flows_and_slopes_at_once_are_the_two_functions_to_the_bit():
    """chamber_flows_and_slopes (each port's orifice evaluated once, the branch found once)
    gives exactly chamber_flows and chamber_flow_slopes on one state: supply and exhaust
    ports, closed, half-open and fully open valves, choked, subsonic and laminar ratios,
    flow reversed (a chamber above the supply or below the exhaust); and the seal's leak
    likewise (leakage_orifice_flow_and_slopes against the orifice's flow and slopes); on arrays, the same two functions."""
    rng = np.random.default_rng(3)
    v, g = ph.Valve(), ph.Gas()
    near = lambda p: p * (1.0 + rng.uniform(-2e-3, 2e-3))          # the laminar band about a port
    states = [(u, p_a, p_b) for u in (0.0, 2.0, 4.95, 5.0, 5.03, 7.5, 10.0)
              for p_a in (6e4, v.P_e, near(v.P_e), 3e5, near(v.P_s), v.P_s, 8e5)
              for p_b in (v.P_e, 2e5, near(v.P_s), 7.5e5)]
    states += [tuple(s) for s in zip(rng.uniform(0, 10, 500), rng.uniform(5e4, 8e5, 500), rng.uniform(5e4, 8e5, 500))]
    for u, p_a, p_b in states:
        u, p_a, p_b = float(u), float(p_a), float(p_b)
        both = ph.chamber_flows_and_slopes(u, p_a, p_b, v, g)
        assert both == (*ph.chamber_flows(u, p_a, p_b, v, g), *ph.chamber_flow_slopes(u, p_a, p_b, v, g)), (u, p_a, p_b)
        for A in (0.0, 3e-8):
            leak = ph.effects.leakage_orifice_flow_and_slopes(p_a, p_b, A, g)
            slopes = ((ph.signed_mass_flow_slope(A, p_b, p_a, g), ph.signed_mass_flow_slope(A, p_a, p_b, g))
                      if A > 0.0 else (0.0, 0.0))        # d/dp_a of B -> A, d/dp_b of A -> B
            assert leak == (ph.effects.leakage_orifice_flow(p_a, p_b, A, g), *slopes), (p_a, p_b, A)
    u, p_a, p_b = (np.array(c, float) for c in zip(*states))
    m_a, m_b, s_a, s_b = ph.chamber_flows_and_slopes(u, p_a, p_b, v, g)
    np.testing.assert_array_equal(np.stack([m_a, m_b]), np.stack(ph.chamber_flows(u, p_a, p_b, v, g)))
    np.testing.assert_array_equal(np.stack([s_a, s_b]), np.stack(ph.chamber_flow_slopes(u, p_a, p_b, v, g)))
