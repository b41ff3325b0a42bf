"""Identification over the excavator rig's noise draws (issue 32, item 4).

The same commands under the rig's noise seed 3: F_s_boom came out 8.7 % low with a
95 % interval that ended at the truth and no "cannot tell" (each start bounds F_s
sharply from above and only softly from below: the posterior is flat-topped, the truth
near its upper edge, which its percentiles cut off).  Now every F_s is within 5 % or
flagged, and its interval holds the truth.
"""
import math

import pytest

from boomfmi import experiments as E
from boomfmi.identify.joints import JOINTS, PROMISE, honest_static, identify_joints, true_values
from boomfmi.identify.outputs import cannot_tell
from boomfmi.identify.fit import Estimate
from boomfmi.rig import run_excavator_offline

PAYLOAD = 0.5


@pytest.fixture(scope="module")
def seed3():
    cfg = {"machine": "excavator", "payload": PAYLOAD, "seed": 3}
    recs = [run_excavator_offline(cfg, c, c.duration) for c in (E.digging_cycle(), E.excavator_excitation(seed=0))]
    result = identify_joints(recs)
    return result, cannot_tell(result)


@pytest.mark.slow
def test_every_static_friction_on_a_noise_draw_is_within_5_percent_or_flagged_and_its_interval_holds_it(seed3):
    result, why = seed3
    truth = true_values(payload=PAYLOAD)
    for j in JOINTS:
        name = f"F_s_{j}"
        e = result.params[name]
        err = e.value / truth[name] - 1.0
        assert e.ci95[0] <= truth[name] <= e.ci95[1], (name, e, truth[name])
        if abs(err) > 0.05:
            assert why[name] is not None, f"{name} {100 * err:+.1f} % and not flagged"
            assert any(name in w for w in result.warnings), result.warnings
        # flagged or not, the value and its interval are reported (nothing dropped)
        assert math.isfinite(e.value) and e.ci95[0] < e.value < e.ci95[1]
    # the other parameters are still told (flags only where the data cannot tell)
    assert all(why[f"K_v_{j}"] is None and why[f"F_d_{j}"] is None for j in JOINTS)
    assert why["payload"] is None


def test_a_flat_topped_start_posterior_widens_the_interval_to_its_likelihood_range():
    e = Estimate(100.0, (96.0, 101.0), "N")
    wide, identified = honest_static(e, {"likelihood_range_N": [90.0, 104.0], "grid_N": [50.0, 200.0]})
    assert wide.value == 100.0
    assert wide.ci95[0] <= 90.0 and wide.ci95[1] >= 104.0
    assert not identified                         # wider than PROMISE on one side
    narrow, identified = honest_static(e, {"likelihood_range_N": [98.0, 100.5], "grid_N": [50.0, 200.0]})
    assert narrow.ci95[0] <= 96.0 and narrow.ci95[1] >= 101.0     # never narrower than the posterior's
    assert identified and narrow.relative_halfwidth < PROMISE
    # a range that reaches the grid's top: no start bounds F_s from above
    _, identified = honest_static(e, {"likelihood_range_N": [99.0, 200.0], "grid_N": [50.0, 200.0]})
    assert not identified


@pytest.mark.slow
def test_a_slow_slide_taken_for_rest_does_not_bias_the_viscous_friction(seed3):
    """On noise seed 3 a slide too slow to count as motion kept its velocity in stage 1's
    viscous column while its drive force was cut: K_v_boom -1.3 % and F_d_boom +3.6 %,
    both intervals beside the truth.  The column is G[s x'] now, as every other term."""
    result, why = seed3
    truth = true_values(payload=PAYLOAD)
    for j in JOINTS:
        for name in (f"K_v_{j}", f"F_d_{j}"):
            e = result.params[name]
            assert e.ci95[0] <= truth[name] <= e.ci95[1], (name, e, truth[name])
            assert abs(e.value / truth[name] - 1.0) < 0.02, (name, e.value, truth[name])
