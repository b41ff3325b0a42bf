"""A pair's joint fit (attribute.fit_pair_jointly), on an error of closed form: the
weaker effect screened beside the stronger in each of its laws, and the pairs fitted
whatever their starts show (``always``)."""
import math

import pytest

from boomfmi.diagnose.attribute import (PAIR_ALWAYS, PAIR_JOBS, SCREEN, fit_pair_jointly, law_of, simple_laws,
                                        wider_laws)

TAU = 0.006                       # the sensor's lag [s] the error is least at
H_WALL = 10 ** 1.2379             # a heat-transfer coefficient on the wall law's screen [W/(m2.K)]
FLOOR = 0.1                       # the error left with both effects right
LAG = [("tau", 2e-4, 0.03, True)]
HEAT_LAWS = [[("h", 1.0, 2000.0, True)], [("n", 1.0, 1.4, False)]]
LAWS = {"sensor_lag": [LAG], "heat_transfer": simple_laws(HEAT_LAWS)}   # each screened in these where it is the weaker


def error(effects: dict) -> float:
    """Least (FLOOR) at the lag TAU with heat exchanged with the wall at H_WALL; a
    polytropic exponent takes only part of that heat's shape (0.5 at best)."""
    tau = effects.get("sensor_lag", {}).get("tau", 1e-9)
    heat = effects.get("heat_transfer", {})
    if "h" in heat:
        miss = math.log10(heat["h"] / H_WALL) ** 2
    elif "n" in heat:
        miss = 0.5 + (heat["n"] - 1.3) ** 2
    else:
        miss = 1.0
    return FLOOR + 20.0 * math.log10(tau / TAU) ** 2 + miss


def test_the_weaker_is_screened_beside_the_stronger_in_each_of_its_laws():
    # alone, heat took the polytropic law; beside the lag, the wall's law fits
    start = {"sensor_lag": {"tau": TAU}, "heat_transfer": {"n": 1.3}}
    costs = {"sensor_lag": 0.5, "heat_transfer": 0.9}
    forms = {"sensor_lag": LAG, "heat_transfer": HEAT_LAWS[1]}
    assert error(start) > (1.0 - SCREEN) * 0.5          # the singles' fits together show nothing
    fx, cost = fit_pair_jointly(["sensor_lag", "heat_transfer"], start, costs, forms, LAWS, error)
    assert set(fx["heat_transfer"]) == {"h"}
    assert fx["heat_transfer"]["h"] == pytest.approx(H_WALL, rel=0.05)
    assert fx["sensor_lag"]["tau"] == pytest.approx(TAU, rel=0.05)
    assert cost == pytest.approx(error(fx)) and cost < FLOOR + 1e-3


def test_a_pair_no_start_lowers_is_fitted_only_where_it_must_be():
    # the lag alone fitted below every start of the pair: none lowers it by SCREEN
    start = {"sensor_lag": {"tau": 2 * TAU}, "heat_transfer": {"n": 1.2}}
    costs = {"sensor_lag": 0.05, "heat_transfer": 0.9}
    forms = {"sensor_lag": LAG, "heat_transfer": HEAT_LAWS[1]}
    args = (["sensor_lag", "heat_transfer"], start, costs, forms, LAWS, error)
    assert fit_pair_jointly(*args) is None
    fx, cost = fit_pair_jointly(*args, always=True)
    # fitted from the best start (the wall's law screened beside the held lag), never worse than it
    held = {"sensor_lag": {"tau": 2 * TAU}, "heat_transfer": {"h": H_WALL}}
    assert cost <= error(held) + 1e-12
    assert cost == pytest.approx(error(fx))
    assert fx["sensor_lag"]["tau"] == pytest.approx(TAU, rel=0.15)


def test_simple_laws_are_those_holding_no_other_laws_parameters():
    a, b = ("C", 1e-13, 5e-10, True), ("A", 1e-10, 2e-7, True)
    assert simple_laws([[a], [b], [a, b]]) == [[a], [b]]
    assert simple_laws(HEAT_LAWS) == HEAT_LAWS
    assert 0 < PAIR_ALWAYS <= PAIR_JOBS


def test_wider_laws_hold_a_law_s_parameters_and_name_the_further_ones():
    a, b, r = ("C", 1e-13, 5e-10, True), ("A", 1e-10, 2e-7, True), ("rate", 10.0, 5e3, True)
    laws = [[a], [b], [a, b], [a, r, b]]
    assert wider_laws(laws, [a]) == [([a, b], [b]), ([a, r, b], [r, b])]
    assert wider_laws(laws, [a, b]) == [([a, r, b], [r])]
    assert wider_laws(laws, [a, r, b]) == [] and wider_laws(HEAT_LAWS, HEAT_LAWS[0]) == []


def test_the_law_a_fit_holds_is_its_parameters_each_once_in_the_laws_order():
    a, b = ("C", 1e-13, 5e-10, True), ("A", 1e-10, 2e-7, True)
    laws = [[a], [b], [a, b]]
    assert law_of(laws, {"A": 1e-9}) == [b]
    assert law_of(laws, {"A": 1e-9, "C": 1e-12}) == [a, b]
    assert law_of(HEAT_LAWS, {"n": 1.3}) == HEAT_LAWS[1]


def test_pairs_are_fitted_where_the_most_probable_single_leaves_the_gap():
    """Calibration case 103 (a deadband beside a fast spool), its singles' figures: a
    sensor lag shrinks the holdout's gap most (0.40), to within the noise, but the fit
    recording prefers the deadband nine to one (shrink 0.28), and the singles weighed
    say "unexplained".  Pairs were not fitted, as the best by shrink left nothing; the
    pair of the truth then explained 0.85 of the gap.  Where the most probable single
    is the best by shrink and leaves nothing beyond the noise, none are fitted."""
    from boomfmi.diagnose.attribute import MIN_SHRINK, Candidate, pairs_needed
    beyond = 0.0175
    lag = Candidate("sensor_lag", {"tau": 2.7e-3}, 1.8e-4, {"p_a": 0.0045, "p_b": 0.0046, "x": 0.0031}, 0.396)
    band = Candidate("valve_deadband", {"width_ext": 0.05}, 4.7e-5, {"p_a": 0.0065, "p_b": 0.0065, "x": 0.0016},
                     0.277)
    cands = [lag, band]                    # sorted by shrink, as attribute() sorts them
    assert lag.shrink >= MIN_SHRINK and sum(lag.holdout.values()) < beyond
    assert pairs_needed(cands, {"unexplained": 0.9988, "valve_deadband": 0.0012, "none": 0.0}, beyond)
    assert pairs_needed(cands, {"valve_deadband": 0.9, "unexplained": 0.1}, beyond)    # it explains too little
    assert not pairs_needed(cands, {"sensor_lag": 0.9, "unexplained": 0.1}, beyond)
    assert not pairs_needed(cands, {"none": 0.9, "sensor_lag": 0.1}, beyond)
    assert pairs_needed([band], {"valve_deadband": 1.0}, beyond)        # the best by shrink, as before
    assert not pairs_needed([], {}, beyond)
