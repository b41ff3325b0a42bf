"""Every Real variable with a physical bound declares a max (issue 17).

The bounds: the stroke (every piston position, x <= L <= fmislave.L_MAX), the command
range (0 to 10 V), the supply (P_s and the exhaust below it, <= fmislave.P_S_MAX), the
angles of Eq. 10 and 12 and the ratio of specific heats of an ideal gas.  A Real
variable without a max is listed in :data:`NO_MAX` with the reason it has none (an
effect's option: in its catalogue entry, ``Parameter.no_max``); the
test fails on a variable that has neither, and on an entry that has gone stale.  The
declared bounds hold in the reference runs (``fmus/<name>/<name>_in.csv``, ``_ref.csv``)
and at every parameter's start value.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from fmpy import read_model_description

from boomfmi.model.catalogue import EFFECTS

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("valve", "cylinder", "boom_load", "force_estimator", "hardware_bridge")

CHAMBER = ("a chamber pressure: the piston compressing a closed chamber drives it above the supply "
           "(isentropically towards its dead volume), and the model does not bound it")
CHAMBER_START = "an initial chamber pressure: as the chamber pressure it starts, a compressed chamber's may exceed the supply"
MEASURED = "a measurement, passed on as the sensor gave it (noise and calibration included): no bound to hold it to"
FLOW = ("a mass flow: grows with the upstream pressure (a compressed chamber's, unbounded) and the "
        "orifice area, which has no bound")
SPEED = "a piston speed: set by the flows, the pressures and the load, none of them bounded"
FORCE = "an external force: the environment's, not bounded by the model"
SIZE = ("a size of the valve or the cylinder: the model's scope bounds none but the stroke (which "
        "bounds the positions)")
GAS = "a property of the gas or the air's temperature: no physical upper bound"
LOAD = "a load or friction parameter of the identified machine: no physical upper bound"
GEOMETRY = ("boom geometry: bounded only relative to the others and the stroke (h <= a, a triangle "
            "over the stroke), which set-up checks")
SETTING = "a setting of the estimator or the joystick: a choice, not a physical quantity with a bound"
TIME = "a time: no bound"

#: (FMU, variable) -> why this Real variable declares no max; an effect's option is not
#: listed here but in its catalogue entry (``Parameter.no_max``), added below
NO_MAX = {
    ("valve", "p_a"): CHAMBER,
    ("valve", "p_b"): CHAMBER,
    ("valve", "mdot_a"): FLOW,
    ("valve", "mdot_b"): FLOW,
    ("valve", "A_max"): SIZE,
    ("valve", "T"): GAS,
    ("valve", "R"): GAS,
    ("cylinder", "mdot_a"): FLOW,
    ("cylinder", "mdot_b"): FLOW,
    ("cylinder", "v"): SPEED,
    ("cylinder", "p_a"): CHAMBER,
    ("cylinder", "p_b"): CHAMBER,
    ("cylinder", "A_a"): SIZE,
    ("cylinder", "A_b"): SIZE,
    ("cylinder", "V_a0"): SIZE,
    ("cylinder", "V_b0"): SIZE,
    ("cylinder", "R"): GAS,
    ("cylinder", "T"): GAS,
    ("cylinder", "p_a0"): CHAMBER_START,
    ("valve", "p_a_flow"): CHAMBER,
    ("valve", "p_b_flow"): CHAMBER,
    ("cylinder", "p_a_flow"): CHAMBER,
    ("cylinder", "p_b_flow"): CHAMBER,
    ("cylinder", "p_b0"): CHAMBER_START,
    ("boom_load", "p_a"): CHAMBER,
    ("boom_load", "p_b"): CHAMBER,
    ("boom_load", "f_ext"): FORCE,
    ("boom_load", "v"): SPEED,
    ("boom_load", "K_v"): LOAD,
    ("boom_load", "F_s"): LOAD,
    ("boom_load", "F_d"): LOAD,
    ("boom_load", "F_L"): LOAD,
    ("boom_load", "M"): LOAD,
    ("boom_load", "a"): GEOMETRY,
    ("boom_load", "b"): GEOMETRY,
    ("boom_load", "h"): GEOMETRY,
    ("boom_load", "l_min"): GEOMETRY,
    ("boom_load", "A_a"): SIZE,
    ("boom_load", "A_b"): SIZE,
    ("boom_load", "P_atm"): "the site's atmospheric pressure: no bound in the model",
    ("force_estimator", "v_model"): SPEED,
    ("force_estimator", "p_a_model"): CHAMBER,
    ("force_estimator", "p_b_model"): CHAMBER,
    ("force_estimator", "x_measured"): MEASURED,
    ("force_estimator", "p_a_measured"): MEASURED,
    ("force_estimator", "p_b_measured"): MEASURED,
    ("force_estimator", "f_est"): "the estimated external force: as unbounded as the force it estimates",
    ("force_estimator", "f_reflect"): ("within +-f_max, a setting with no physical bound (the joystick's "
                                       "actuator is not specified)"),
    ("force_estimator", "v_measured"): SPEED,
    ("force_estimator", "K_p"): SETTING,
    ("force_estimator", "D"): SETTING,
    ("force_estimator", "f_motion"): SETTING,
    ("force_estimator", "tau_est"): SETTING,
    ("force_estimator", "v_rest"): SETTING,
    ("force_estimator", "p_floor"): SETTING,
    ("force_estimator", "gain"): SETTING,
    ("force_estimator", "f_max"): SETTING,
    ("force_estimator", "rate_max"): SETTING,
    ("force_estimator", "K_v"): LOAD,
    ("force_estimator", "F_s"): LOAD,
    ("force_estimator", "F_d"): LOAD,
    ("force_estimator", "F_L"): LOAD,
    ("force_estimator", "M"): LOAD,
    ("force_estimator", "A_a"): SIZE,
    ("force_estimator", "A_b"): SIZE,
    ("force_estimator", "V_a0"): SIZE,
    ("force_estimator", "V_b0"): SIZE,
    ("force_estimator", "P_atm"): "the site's atmospheric pressure: no bound in the model",
    ("force_estimator", "a"): GEOMETRY,
    ("force_estimator", "b"): GEOMETRY,
    ("force_estimator", "h"): GEOMETRY,
    ("force_estimator", "l_min"): GEOMETRY,
    ("hardware_bridge", "p_a"): MEASURED,
    ("hardware_bridge", "p_b"): MEASURED,
    ("hardware_bridge", "alpha"): MEASURED,
    ("hardware_bridge", "x"): MEASURED + " (x from the measured angle by Eq. 12 may leave [0, L])",
    ("hardware_bridge", "f_ext"): FORCE,
    ("hardware_bridge", "t_rig"): TIME,
    ("hardware_bridge", "lateness"): TIME,
    ("hardware_bridge", "timeout"): "a link setting: no bound",
    ("hardware_bridge", "a"): GEOMETRY,
    ("hardware_bridge", "b"): GEOMETRY,
    ("hardware_bridge", "h"): GEOMETRY,
    ("hardware_bridge", "l_min"): GEOMETRY,
}
#: every effect option without a max, with the reason its catalogue entry gives
EFFECT_NO_MAX = {(e.fmu, p.option): p.no_max for e in EFFECTS.values() for p in e.parameters if p.max is None}
assert not set(NO_MAX) & set(EFFECT_NO_MAX), "an effect option's reason belongs in the catalogue"
NO_MAX.update(EFFECT_NO_MAX)

#: (FMU, variable) -> the parameter its physical bound is: its declared max must be safe
#: for that parameter's own declared max
BOUNDED_BY_PARAMETER = {
    ("cylinder", "x"): "L",
    ("boom_load", "x"): "L",
    ("boom_load", "x0"): "L",
    ("force_estimator", "x_model"): "L",
    ("valve", "P_e"): "P_s",
}


@pytest.fixture(scope="module")
def descriptions(fmu):
    return {name: read_model_description(str(fmu(name))) for name in NAMES}


def _reals(md):
    return {v.name: v for v in md.modelVariables if v.type == "Real"}


def _bound(v, which):
    value = getattr(v, which)
    return None if value is None else float(value)


def test_every_real_with_a_physical_bound_declares_a_max(descriptions):
    without = {(name, v.name) for name, md in descriptions.items()
               for v in _reals(md).values() if v.max is None}
    unlisted = sorted(without - set(NO_MAX))
    stale = sorted(set(NO_MAX) - without)
    assert not unlisted, f"Real variables with no max and no reason in NO_MAX: {unlisted}"
    assert not stale, f"NO_MAX lists variables that declare a max or do not exist: {stale}"
    assert all(reason.strip() for reason in NO_MAX.values())


def test_the_physical_bounds(descriptions):
    """The bounds the issue names, as declared."""
    from boomfmi.fmislave import K_MAX, L_MAX, P_S_MAX
    import math
    r = {name: _reals(md) for name, md in descriptions.items()}
    for name in ("valve", "hardware_bridge"):
        assert (_bound(r[name]["u"], "min"), _bound(r[name]["u"], "max")) == (0.0, 10.0)
    assert _bound(r["hardware_bridge"]["u_applied"], "max") == 10.0
    for name in ("cylinder", "boom_load", "force_estimator", "hardware_bridge"):
        assert _bound(r[name]["L"], "max") == L_MAX
    assert _bound(r["valve"]["P_s"], "max") == P_S_MAX == pytest.approx(1.101325e6)
    for name in ("valve", "cylinder"):
        assert _bound(r[name]["P_e"], "max") == P_S_MAX
        assert _bound(r[name]["k"], "max") == pytest.approx(K_MAX)
    assert _bound(r["boom_load"]["alpha"], "max") == pytest.approx(math.pi)
    assert _bound(r["boom_load"]["phi"], "max") == pytest.approx(math.pi)
    assert _bound(r["boom_load"]["phi"], "min") == pytest.approx(-0.5 * math.pi)


@pytest.mark.parametrize("name, var", sorted(BOUNDED_BY_PARAMETER))
def test_a_bound_that_is_a_parameter_is_declared_for_its_max(descriptions, name, var):
    reals = _reals(descriptions[name])
    param = reals.get(BOUNDED_BY_PARAMETER[(name, var)])
    assert param is not None and param.max is not None, "the parameter needs a max of its own"
    assert _bound(reals[var], "max") >= _bound(param, "max")


def _within(values, v, what):
    lo, hi = _bound(v, "min"), _bound(v, "max")
    values = pd.Series(values, dtype=float)
    if lo is not None:
        assert (values >= lo).all(), f"{what}: {values.min()!r} < min {lo!r}"
    if hi is not None:
        assert (values <= hi).all(), f"{what}: {values.max()!r} > max {hi!r}"


@pytest.mark.parametrize("name", ["valve", "cylinder", "boom_load", "force_estimator"])
def test_reference_runs_stay_within_the_declared_bounds(descriptions, name):
    reals = _reals(descriptions[name])
    folder = ROOT / "fmus" / name
    for csv in (folder / f"{name}_in.csv", folder / f"{name}_ref.csv"):
        table = pd.read_csv(csv)
        for col in table.columns.drop("time"):
            _within(table[col], reals[col], f"{csv.name}: {col}")


def test_parameter_starts_lie_within_their_bounds(descriptions):
    for name, md in descriptions.items():
        for v in _reals(md).values():
            if v.start is not None:
                _within([float(v.start)], v, f"{name}.{v.name} start")
