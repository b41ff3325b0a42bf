"""The valve FMU against closed forms of the orifice equation (through fmpy)."""
from __future__ import annotations

import math

import pytest

from boomfmi.physics import reference_rig
from boomfmi.system import FmuInstance

k, R, T = reference_rig.k, reference_rig.R, reference_rig.T
P_CR = (2 / (k + 1)) ** (k / (k - 1))


def by_hand(A, P_u, P_d):
    """Eq. 1 in its standard form, written out independently of boomfmi.physics."""
    r = P_d / P_u
    if r < P_CR:
        return A * P_u * math.sqrt(k / (R * T)) * (2 / (k + 1)) ** ((k + 1) / (2 * (k - 1)))
    return A * P_u * math.sqrt(2 * k / (R * T * (k - 1))) * math.sqrt(r ** (2 / k) - r ** ((k + 1) / k))


@pytest.fixture
def valve(fmu):
    with FmuInstance(fmu("valve")) as inst:
        inst.initialize()
        yield inst


def flows(valve, u, p_a, p_b):
    valve.set(u=u, p_a=p_a, p_b=p_b)
    out = valve.get("mdot_a", "mdot_b")
    return out["mdot_a"], out["mdot_b"]


def test_critical_ratio_is_the_corrected_value():
    assert P_CR == pytest.approx(0.528282, abs=1e-6)


@pytest.mark.parametrize("u, p_a", [(0.0, reference_rig.P_atm), (1.0, 2.0e5), (2.5, 3.5e5)])
def test_choked_flow_into_a(valve, u, p_a):
    A = reference_rig.A_max * min(abs(u - 5) / 5, 1)
    assert p_a / reference_rig.P_s < P_CR
    mdot_a, _ = flows(valve, u, p_a, 3e5)
    assert mdot_a == pytest.approx(by_hand(A, reference_rig.P_s, p_a), rel=1e-9)


@pytest.mark.parametrize("u, p_a", [(0.0, 4.5e5), (1.0, 6.0e5), (4.0, 7.0e5)])
def test_subsonic_flow_into_a(valve, u, p_a):
    A = reference_rig.A_max * min(abs(u - 5) / 5, 1)
    assert p_a / reference_rig.P_s >= P_CR
    mdot_a, _ = flows(valve, u, p_a, 3e5)
    assert mdot_a == pytest.approx(by_hand(A, reference_rig.P_s, p_a), rel=1e-9)


@pytest.mark.parametrize("p_b", [1.2e5, 1.9e5, 4.0e5, 7.0e5])
def test_exhaust_flow_out_of_b_while_extending(valve, p_b):
    _, mdot_b = flows(valve, 1.0, 3e5, p_b)
    assert mdot_b == pytest.approx(-by_hand(reference_rig.A_max * 0.8, p_b, reference_rig.P_atm), rel=1e-9)


def test_flow_is_continuous_at_the_critical_ratio(valve):
    p_cr = reference_rig.P_s * P_CR
    below, _ = flows(valve, 0.0, p_cr * (1 - 1e-9), 3e5)
    above, _ = flows(valve, 0.0, p_cr * (1 + 1e-9), 3e5)
    assert above == pytest.approx(below, rel=1e-7)
    assert below == pytest.approx(by_hand(reference_rig.A_max, reference_rig.P_s, p_cr), rel=1e-7)


def test_zero_flow_at_equal_pressures(valve):
    mdot_a, mdot_b = flows(valve, 0.0, reference_rig.P_s, reference_rig.P_atm)
    assert mdot_a == 0.0 and mdot_b == 0.0
    mdot_a, mdot_b = flows(valve, 10.0, reference_rig.P_atm, reference_rig.P_s)
    assert mdot_a == 0.0 and mdot_b == 0.0


def test_centred_valve_closes_every_port(valve):
    assert flows(valve, 5.0, 3e5, 4e5) == (0.0, 0.0)


def test_routing_follows_the_sign_of_u_minus_5(valve):
    # below 5 V supply -> A and B -> exhaust: the piston extends
    mdot_a, mdot_b = flows(valve, 2.0, 3e5, 3e5)
    assert mdot_a > 0 > mdot_b
    # above 5 V supply -> B and A -> exhaust: the piston retracts
    mdot_a, mdot_b = flows(valve, 8.0, 3e5, 3e5)
    assert mdot_b > 0 > mdot_a
    # symmetric commands open the same area
    assert flows(valve, 2.0, 3e5, 3e5)[0] == pytest.approx(flows(valve, 8.0, 3e5, 3e5)[1], rel=1e-12)


@pytest.mark.parametrize("u", [0.5, 1.0, 2.5, 4.0, 4.9, 6.0, 9.5])
def test_opening_is_linear_in_the_distance_from_centre(valve, u):
    """A(u) = A_max |u - 5| / 5: the choked flow into the supplied chamber scales with it."""
    p_low = 1.5e5                                            # choked: p / P_s < P_cr
    mdot_a, mdot_b = flows(valve, u, p_low, p_low)
    supplied = mdot_a if u < 5 else mdot_b
    assert supplied == pytest.approx(by_hand(reference_rig.A_max * abs(u - 5) / 5, reference_rig.P_s, p_low), rel=1e-9)


def test_laminar_region_near_equal_pressures(valve):
    """Within 0.1 % of equal pressures the flow is linear in the pressure difference and
    continuous with Eq. 1 at the edge (physics/orifice.py: an infinite slope at equal
    pressures would stall every implicit integrator)."""
    edge = reference_rig.P_s * 0.999
    at_edge, _ = flows(valve, 0.0, edge, 2e5)
    assert at_edge == pytest.approx(by_hand(reference_rig.A_max, reference_rig.P_s, edge), rel=1e-9)
    for r in (0.9995, 0.9999):
        inside, _ = flows(valve, 0.0, reference_rig.P_s * r, 2e5)
        assert inside == pytest.approx(at_edge * (1 - r) / (1 - 0.999), rel=1e-9)


def test_reference_result_agrees_with_the_closed_form():
    """fmus/valve/valve_ref.csv, which the tests replay through the FMU, is itself Eq. 1."""
    import pandas as pd
    from pathlib import Path
    folder = Path(__file__).resolve().parents[1] / "fmus" / "valve"
    inputs, ref = pd.read_csv(folder / "valve_in.csv"), pd.read_csv(folder / "valve_ref.csv")
    for (_, i), (_, r) in zip(inputs.iterrows(), ref.iterrows()):
        A = reference_rig.A_max * abs(i.u - 5) / 5
        port_a, port_b = (reference_rig.P_s, reference_rig.P_atm) if i.u < 5 else (reference_rig.P_atm, reference_rig.P_s)
        for port, p, got in ((port_a, i.p_a, r.mdot_a), (port_b, i.p_b, r.mdot_b)):
            if A == 0 or max(port, p) / min(port, p) < 1 / 0.999:
                continue
            want = by_hand(A, port, p) if port > p else -by_hand(A, p, port)
            assert got == pytest.approx(want, rel=1e-9)
