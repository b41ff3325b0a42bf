"""The monolithic reference with the candidate effects agrees with the FMUs' options."""
from __future__ import annotations

import numpy as np
import pytest

from boomfmi.experiments import paper_multistep
from boomfmi.physics import ParameterError
from boomfmi.model import Model
from boomfmi.model.reference import simulate_reference
from boomfmi.system import simulate_ssp

CASES = [
    ({"valve_deadband": {"width": 0.4}}, {"valve.deadband": 0.4}),
    ({"heat_transfer": {"h": 50.0}}, {"cylinder.h_wall": 50.0}),
    ({"piston_leakage": {"A": 1e-7}}, {"cylinder.A_leak": 1e-7}),
    ({"end_cushioning": {"length": 0.01, "A_n": 1e-7}},
     {"cylinder.l_cushion": 0.01, "cylinder.A_cushion": 1e-7}),
    ({"end_cushioning": {"length": 0.01, "A_n": 1e-7, "V_p": 8e-6}},
     {"cylinder.l_cushion": 0.01, "cylinder.A_cushion": 1e-7, "cylinder.V_cushion_port": 8e-6}),
    # the port's air leaves the heat's account of the chamber's air as the spear enters
    ({"end_cushioning": {"length": 0.01, "A_n": 1e-7, "V_p": 8e-6}, "heat_transfer": {"h": 50.0}},
     {"cylinder.l_cushion": 0.01, "cylinder.A_cushion": 1e-7, "cylinder.V_cushion_port": 8e-6,
      "cylinder.h_wall": 50.0}),
]


@pytest.mark.parametrize("effects, ssp_params", CASES, ids=["+".join(f"{n}({','.join(q)})" for n, q in c[0].items())
                                                             for c in CASES])
def test_reference_with_an_effect_matches_the_cosimulation_with_that_option(ssp_path, effects, ssp_params):
    prof = paper_multistep()
    stop = 4.5
    bps = [b for b in prof.breakpoints if b < stop]
    base = simulate_reference(Model(), prof, stop, breakpoints=bps)
    ref = simulate_reference(Model(effects=effects), prof, stop, breakpoints=bps)
    co = simulate_ssp(ssp_path, stop_time=stop, step=1e-3, inputs=lambda s: {"valve.u": prof(s)["u"]},
                      parameters=ssp_params)
    effect = gap = 0.0
    for ch, col in (("x", "boom_load.x"), ("p_a", "cylinder.p_a"), ("p_b", "cylinder.p_b")):
        span = ref[ch].max() - ref[ch].min()
        gap = max(gap, np.sqrt(np.mean((co[col].to_numpy() - ref[ch].to_numpy()) ** 2)) / span)
        effect = max(effect, np.sqrt(np.mean((base[ch].to_numpy() - ref[ch].to_numpy()) ** 2)) / span)
    assert gap < 0.01
    assert effect > 5 * gap


def test_sensor_lag_delays_what_is_reported():
    prof = paper_multistep()
    base = simulate_reference(Model(), prof, 2.0, breakpoints=[1.0])
    lagged = simulate_reference(Model(effects={"sensor_lag": {"tau": 0.005}}), prof, 2.0, breakpoints=[1.0])
    rising = (base.time > 1.0) & (base.time < 1.02)
    assert (lagged.p_a[rising] < base.p_a[rising]).all()
    np.testing.assert_allclose(lagged.p_a.iloc[-1], base.p_a.iloc[-1], rtol=1e-6)


def test_unknown_effects_are_refused():
    with pytest.raises(ParameterError, match="engine_vibration"):
        simulate_reference(Model(effects={"engine_vibration": {}}), paper_multistep(), 0.1)
    with pytest.raises(ParameterError, match="effects.valve_dynamics"):
        simulate_reference(Model(effects={"valve_dynamics": {"omega": 1.0}}), paper_multistep(), 0.1)
