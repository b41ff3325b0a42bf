"""Every invalid parameter makes initialisation fail with fmi2Error and a message that
names it; nothing crashes, and the failed instance stays safe to call and free."""
from __future__ import annotations

import pytest

from boomfmi.system import FmuError, FmuInstance

INVALID = [
    ("valve", {"A_max": -1e-6}, "A_max"),
    ("valve", {"P_s": 0.0}, "P_s"),
    ("valve", {"T": -5.0}, "T"),
    ("valve", {"k": 1.0}, "k"),
    ("cylinder", {"A_a": 0.0}, "A_a"),
    ("cylinder", {"A_b": -1e-4}, "A_b"),
    ("cylinder", {"L": 0.0}, "L"),
    ("cylinder", {"V_a0": 0.0}, "V_a0"),
    ("cylinder", {"V_b0": -1e-6}, "V_b0"),
    ("cylinder", {"p_a0": 0.0}, "p_a0"),
    ("cylinder", {"l_cushion": 0.05}, "l_cushion"),
    ("cylinder", {"l_cushion": 0.01, "A_cushion": 0.0}, "A_cushion"),
    ("cylinder", {"l_cushion": 0.01, "V_cushion_port": 1.5e-5}, "V_cushion_port"),   # the whole dead volume
    ("boom_load", {"M": 0.0}, "M"),
    ("boom_load", {"M": -22.7}, "M"),
    ("boom_load", {"L": 0.0}, "L"),
    ("boom_load", {"A_a": 0.0}, "A_a"),
    ("boom_load", {"K_v": -1.0}, "K_v"),
    ("boom_load", {"a": 0.0}, "a"),
    ("boom_load", {"h": 0.2}, "h"),                 # arcsin(h/a) undefined
    ("boom_load", {"l_min": 0.1}, "l_min"),         # shorter than |a - b|: no triangle
    ("boom_load", {"L": 0.3}, "l_min"),             # longer than a + b at x = L
    ("boom_load", {"x0": 0.07}, "x0"),
    ("force_estimator", {"f_max": 0.0}, "f_max"),
    ("force_estimator", {"K_p": -1.0}, "K_p"),
    ("force_estimator", {"rate_max": 0.0}, "rate_max"),
    ("force_estimator", {"method": "kalman"}, "method"),
    ("force_estimator", {"f_motion": 0.0}, "f_motion"),
    ("force_estimator", {"tau_est": -0.004}, "tau_est"),
    ("force_estimator", {"v_rest": -1e-3}, "v_rest"),
    ("force_estimator", {"M": 0.0}, "M"),
]


@pytest.mark.parametrize("name, params, culprit", INVALID,
                         ids=[f"{n}-{next(iter(p))}={next(iter(p.values()))}" for n, p, _ in INVALID])
def test_invalid_parameter_is_an_fmi_error_naming_it(fmu, name, params, culprit):
    with FmuInstance(fmu(name)) as inst:
        with pytest.raises(FmuError) as err:
            inst.initialize(parameters=params)
        assert err.value.status == 3, "fmi2Error, not fmi2Fatal"
        assert err.value.function == "fmi2ExitInitializationMode"
        assert f"parameter {culprit} =" in str(err.value)
        # the instance is still safe to use: later calls fail cleanly too
        with pytest.raises(FmuError) as again:
            inst.step(1e-3)
        assert again.value.status == 3


def test_valid_defaults_initialise(fmu):
    for name in ("valve", "cylinder", "boom_load", "force_estimator"):
        with FmuInstance(fmu(name)) as inst:
            inst.initialize()
            inst.step(1e-3)
