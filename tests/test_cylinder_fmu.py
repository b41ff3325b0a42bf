"""The cylinder FMU against closed forms of the chamber energy balance (Eq. 4 to 7)."""
from __future__ import annotations

import pytest

from boomfmi.physics import reference_rig
from boomfmi.system import FmuInstance

k, R, T = reference_rig.k, reference_rig.R, reference_rig.T


def V_a(x):
    return reference_rig.A_a * x + reference_rig.V_a0


def V_b(x):
    return reference_rig.A_b * (reference_rig.L - x) + reference_rig.V_b0


@pytest.mark.parametrize("dt", [1e-4, 1e-3, 2e-3])
def test_closed_chambers_keep_p_v_to_the_k_over_the_full_stroke(fmu, dt):
    """A piston driven over the whole stroke with no flow compresses A... and B."""
    p0 = 2.0e5
    v = 0.06
    n = round(1.0 / dt)
    with FmuInstance(fmu("cylinder")) as cyl:
        cyl.initialize(parameters=dict(p_a0=p0, p_b0=p0))
        x = 0.0
        worst = 0.0
        for _ in range(n):
            cyl.set(x=x, v=v, mdot_a=0.0, mdot_b=0.0)
            cyl.step(dt)
            x = min(x + v * dt, reference_rig.L)
            p = cyl.get("p_a", "p_b")
            worst = max(worst, abs(p["p_a"] * V_a(x) ** k / (p0 * V_a(0) ** k) - 1),
                        abs(p["p_b"] * V_b(x) ** k / (p0 * V_b(0) ** k) - 1))
        assert x == pytest.approx(reference_rig.L)
    assert worst < 1e-4


@pytest.mark.parametrize("mdot_a, mdot_b, x, v", [
    (1e-3, -2e-4, 0.01, 0.05), (0.0, 0.0, 0.03, -0.08), (-5e-4, 8e-4, 0.05, 0.0)])
def test_initial_pressure_rate_is_eq_7(fmu, mdot_a, mdot_b, x, v):
    p_a0, p_b0, dt = 3.0e5, 2.5e5, 1e-7
    with FmuInstance(fmu("cylinder")) as cyl:
        cyl.initialize(parameters=dict(p_a0=p_a0, p_b0=p_b0))
        cyl.set(mdot_a=mdot_a, mdot_b=mdot_b, x=x, v=v)
        cyl.step(dt)
        p = cyl.get("p_a", "p_b")
    rate_a = (k * R * T * mdot_a - k * p_a0 * reference_rig.A_a * v) / V_a(x)
    rate_b = (k * R * T * mdot_b + k * p_b0 * reference_rig.A_b * v) / V_b(x)
    assert (p["p_a"] - p_a0) / dt == pytest.approx(rate_a, rel=1e-5, abs=1e-3)
    assert (p["p_b"] - p_b0) / dt == pytest.approx(rate_b, rel=1e-5, abs=1e-3)


def test_filling_at_rest_matches_the_closed_form(fmu):
    """At rest, Eq. 7 is dp/dt = k R T mdot / V: the pressure rises linearly."""
    mdot, dt, n = 4e-4, 2e-3, 25
    with FmuInstance(fmu("cylinder")) as cyl:
        cyl.initialize()
        cyl.set(mdot_a=mdot, mdot_b=0.0, x=0.02, v=0.0)
        for _ in range(n):
            cyl.step(dt)
        p_a = cyl.get("p_a")["p_a"]
    assert p_a == pytest.approx(reference_rig.P_atm + k * R * T * mdot * n * dt / V_a(0.02), rel=1e-12)


def test_an_emptying_chamber_is_an_fmi_error_not_a_crash(fmu):
    from boomfmi.system import FmuError
    with FmuInstance(fmu("cylinder")) as cyl:
        cyl.initialize()
        cyl.set(mdot_b=-1.0)
        with pytest.raises(FmuError) as err:
            cyl.step(1e-3)
    assert err.value.status == 3 and "chamber emptied" in str(err.value)
