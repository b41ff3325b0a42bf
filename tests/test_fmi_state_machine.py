"""The FMUs follow the FMI 2.0 co-simulation state machine (section 4.2.4) and refuse
values that are not finite (issue 31, cases 9 to 11), through the built ``.fmu`` files
and fmpy's own calls:

* a fixed parameter set after fmi2ExitInitializationMode is refused with fmi2Error naming
  it, and neither its value nor the outputs change (case 9);
* fmi2DoStep before initialisation, in initialisation mode or after fmi2Terminate, a
  second fmi2Terminate and a currentCommunicationPoint that jumps ahead or back return
  fmi2Error with a message; the instance stays where it was and goes on (case 10);
* an input that is not finite is refused, naming it, at the step or the read of an output
  that would use it: no NaN leaves an FMU with fmi2OK (case 11).

"Nothing lost": after each refusal the instance goes on and ends where an instance that
was never sent the bad call ends, bit for bit.
"""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest
from fmpy.fmi1 import FMICallException

from boomfmi.system import FmuInstance

ROOT = Path(__file__).resolve().parents[1]
H = 1e-3
NAN, INF = float("nan"), float("inf")


def _vr(inst, *names):
    return [inst.variables[n].valueReference for n in names]


def _refused(inst, call, *args) -> str:
    """Make ``call``; it must fail with fmi2Error.  Its logged error messages, joined."""
    first = len(inst.messages)
    with pytest.raises(FMICallException, match=r"status 3 \(error\)"):
        call(*args)
    messages = [m for status, m in inst.messages[first:] if status >= 3]
    assert messages, "an fmi2Error must say why"
    return " ".join(messages)


def _start(inst, start_time=0.0, **inputs):
    f = inst.fmu
    f.setupExperiment(startTime=start_time)
    f.enterInitializationMode()
    for name, value in inputs.items():
        f.setReal(_vr(inst, name), [value])
    f.exitInitializationMode()


def _run(inst, t, n, **inputs):
    """``n`` steps of H from ``t`` with ``inputs`` set before each; the end time."""
    for name, value in inputs.items():
        inst.fmu.setReal(_vr(inst, name), [value])
    for _ in range(n):
        inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=H)
        t += H
    return t


VALVE_OUT = ("mdot_a", "mdot_b", "dmdot_a_dp_a", "dmdot_b_dp_b")
LOAD_OUT = ("x", "v", "alpha", "phi")


# -- case 9: a fixed parameter after initialisation -------------------------------------

@pytest.mark.parametrize("name, value", [("A_max", -1.0), ("P_s", 1.0)])
def test_a_fixed_parameter_set_after_initialisation_is_refused_naming_it(fmu, name, value):
    with FmuInstance(fmu("valve")) as inst, FmuInstance(fmu("valve")) as clean:
        for i in (inst, clean):
            _start(i, u=7.0, p_a=2e5, p_b=3e5)
            _run(i, 0.0, 3)
        before = inst.fmu.getReal(_vr(inst, name, *VALVE_OUT))
        message = _refused(inst, inst.fmu.setReal, _vr(inst, name), [value])
        assert f"parameter {name} is fixed" in message
        assert "fmi2ExitInitializationMode" in message and "nothing was set" in message
        # nothing was set: the parameter and the outputs are what they were
        assert inst.fmu.getReal(_vr(inst, name, *VALVE_OUT)) == before
        # the instance goes on, as one that never saw the call
        for i in (inst, clean):
            _run(i, 3 * H, 3, u=3.0)
        assert inst.fmu.getReal(_vr(inst, *VALVE_OUT)) == clean.fmu.getReal(_vr(clean, *VALVE_OUT))
        # with an input in the same call: the whole call is refused, the input kept too
        u = inst.fmu.getReal(_vr(inst, "u"))
        assert "parameter" in _refused(inst, inst.fmu.setReal, _vr(inst, "u", name), [9.0, value])
        assert inst.fmu.getReal(_vr(inst, "u")) == u
        inst.fmu.terminate()
        message = _refused(inst, inst.fmu.setReal, _vr(inst, name), [value])
        assert f"parameter {name} is fixed" in message and "terminated" in message


def test_a_fixed_string_parameter_set_after_initialisation_is_refused_too(fmu):
    with FmuInstance(fmu("force_estimator")) as inst:
        inst.initialize()
        vr = _vr(inst, "method")
        before = inst.fmu.getString(vr)
        message = _refused(inst, inst.fmu.setString, vr, ["kalman"])
        assert "fmi2SetString refused: parameter method is fixed" in message
        assert inst.fmu.getString(vr) == before
        inst.step(H)


def test_a_fixed_parameter_set_in_initialisation_mode_still_counts(fmu):
    """The refusal is after initialisation only: before it the parameter is taken (and
    checked there, naming it as ever)."""
    with FmuInstance(fmu("valve")) as inst:
        f = inst.fmu
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        f.setReal(_vr(inst, "A_max"), [-1.0])
        assert "parameter A_max" in _refused(inst, f.exitInitializationMode)
        # and a refused set after it says the parameter is fixed, not that it was invalid
        assert "parameter P_s is fixed" in _refused(inst, f.setReal, _vr(inst, "P_s"), [7e5])


# -- case 10: the state machine ---------------------------------------------------------

def test_do_step_before_initialisation_is_refused_and_the_instance_goes_on(fmu):
    with FmuInstance(fmu("boom_load")) as inst, FmuInstance(fmu("boom_load")) as clean:
        f = inst.fmu
        message = _refused(inst, f.doStep, 0.0, H)
        assert "fmi2DoStep refused" in message and "not initialised" in message
        assert "fmi2EnterInitializationMode" in message
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        message = _refused(inst, f.doStep, 0.0, H)
        assert "initialisation mode" in message and "fmi2ExitInitializationMode first" in message
        f.setReal(_vr(inst, "p_a"), [5e5])
        f.exitInitializationMode()
        _start(clean, p_a=5e5)
        for i in (inst, clean):     # nothing lost: it starts at 0 as one that was never refused
            _run(i, 0.0, 20)
        assert f.getReal(_vr(inst, *LOAD_OUT)) == clean.fmu.getReal(_vr(clean, *LOAD_OUT))
        assert f.getReal(_vr(inst, "x"))[0] > 0.0


def test_initialisation_out_of_order_is_refused(fmu):
    with FmuInstance(fmu("valve")) as inst:
        f = inst.fmu
        assert "fmi2EnterInitializationMode first" in _refused(inst, f.exitInitializationMode)
        _start(inst)
        assert "past it" in _refused(inst, f.enterInitializationMode)
        assert "fmi2SetupExperiment refused" in _refused(inst, f.setupExperiment, None, 5.0)
        assert "left initialisation mode already" in _refused(inst, f.exitInitializationMode)
        _run(inst, 0.0, 2)      # and it steps from its start, 0


def test_do_step_after_terminate_and_a_second_terminate_are_refused(fmu):
    with FmuInstance(fmu("boom_load")) as inst:
        _start(inst, p_a=5e5)
        t = _run(inst, 0.0, 5)
        out = inst.fmu.getReal(_vr(inst, *LOAD_OUT))
        inst.fmu.terminate()
        message = _refused(inst, inst.fmu.doStep, t, H)
        assert "fmi2DoStep refused" in message and "terminated" in message and "fmi2Reset" in message
        assert "terminated already" in _refused(inst, inst.fmu.terminate)
        # the results stay readable, unchanged (FMI 2.0 allows fmi2GetReal after fmi2Terminate)
        assert inst.fmu.getReal(_vr(inst, *LOAD_OUT)) == out
        # fmi2Reset brings it back to the start: it steps again
        inst.fmu.reset()
        _start(inst, p_a=5e5)
        _run(inst, 0.0, 5)
        assert inst.fmu.getReal(_vr(inst, *LOAD_OUT)) == out


@pytest.mark.parametrize("jump", [0.5, -2 * H, 1e-7, H / 2])
def test_a_communication_point_that_jumps_is_refused(fmu, jump):
    start = 1.7         # a start time that is not 0, and communication points as t0 + n h
    with FmuInstance(fmu("boom_load")) as inst, FmuInstance(fmu("boom_load")) as clean:
        for i in (inst, clean):
            _start(i, start_time=start, p_a=5e5)
            for n in range(10):
                i.fmu.doStep(currentCommunicationPoint=start + n * H, communicationStepSize=H)
        end = start + 9 * H + H
        out = inst.fmu.getReal(_vr(inst, *LOAD_OUT))
        message = _refused(inst, inst.fmu.doStep, end + jump, H)
        assert "fmi2DoStep refused: currentCommunicationPoint" in message
        assert f"{end + jump!r}" in message and "last step ended at" in message
        assert inst.fmu.getReal(_vr(inst, *LOAD_OUT)) == out
        for i in (inst, clean):         # it goes on from where it was, nothing lost
            for n in range(10, 20):
                i.fmu.doStep(currentCommunicationPoint=start + n * H, communicationStepSize=H)
        assert inst.fmu.getReal(_vr(inst, *LOAD_OUT)) == clean.fmu.getReal(_vr(clean, *LOAD_OUT))


def test_a_first_step_away_from_the_start_time_is_refused(fmu):
    with FmuInstance(fmu("valve")) as inst:
        _start(inst, start_time=2.0)
        message = _refused(inst, inst.fmu.doStep, 0.0, H)
        assert "experiment starts at 2.0 s" in message
        _run(inst, 2.0, 3)


# -- case 11: inputs that are not finite ------------------------------------------------

@pytest.mark.parametrize("name, value", [("u", NAN), ("p_a", INF), ("p_b", -INF)])
def test_a_valve_input_that_is_not_finite_is_refused_naming_it(fmu, name, value):
    inputs = dict(u=7.0, p_a=2e5, p_b=3e5)
    with FmuInstance(fmu("valve")) as inst, FmuInstance(fmu("valve")) as clean:
        for i in (inst, clean):
            _start(i, **inputs)
            _run(i, 0.0, 3)
        inst.fmu.setReal(_vr(inst, name), [value])
        # the outputs depend on it directly: reading them is refused, naming it
        message = _refused(inst, inst.fmu.getReal, _vr(inst, *VALVE_OUT))
        assert f"fmi2GetReal refused: input {name} = {value!r} is not a finite number" in message
        assert "mdot_a, mdot_b, dmdot_a_dp_a, dmdot_b_dp_b depend on it directly" in message
        # so is the step that would use it
        message = _refused(inst, inst.fmu.doStep, 3 * H, H)
        assert "fmi2DoStep refused" in message and f"input {name} = {value!r}" in message
        assert "nothing was stepped" in message
        # a finite value again: it goes on from 3 ms, as one that never saw the value
        inst.fmu.setReal(_vr(inst, name), [inputs[name]])
        for i in (inst, clean):
            _run(i, 3 * H, 3)
        out = inst.fmu.getReal(_vr(inst, *VALVE_OUT))
        assert out == clean.fmu.getReal(_vr(clean, *VALVE_OUT)) and all(map(math.isfinite, out))


def test_a_boom_load_input_that_is_not_finite_refuses_the_step_and_keeps_the_state(fmu):
    with FmuInstance(fmu("boom_load")) as inst, FmuInstance(fmu("boom_load")) as clean:
        for i in (inst, clean):
            _start(i, p_a=5e5)
            _run(i, 0.0, 10)
        inst.fmu.setReal(_vr(inst, "p_a"), [NAN])
        message = _refused(inst, inst.fmu.doStep, 10 * H, H)
        assert "input p_a = nan is not a finite number" in message and "t = 0.01 s" in message
        # x, v are the state of the last step (no NaN; they do not depend on p_a directly)
        out = inst.fmu.getReal(_vr(inst, *LOAD_OUT))
        assert out == clean.fmu.getReal(_vr(clean, *LOAD_OUT)) and all(map(math.isfinite, out))
        # the input itself is not handed back as a number with fmi2OK either
        assert "p_a = nan is not a finite number" in _refused(inst, inst.fmu.getReal, _vr(inst, "p_a"))
        inst.fmu.setReal(_vr(inst, "p_a"), [5e5])
        for i in (inst, clean):
            _run(i, 10 * H, 10)
        assert inst.fmu.getReal(_vr(inst, *LOAD_OUT)) == clean.fmu.getReal(_vr(clean, *LOAD_OUT))


def test_a_cylinder_input_that_is_not_finite_is_refused_naming_it(fmu):
    with FmuInstance(fmu("cylinder")) as inst:
        _start(inst)
        _run(inst, 0.0, 2)
        inst.fmu.setReal(_vr(inst, "mdot_a", "v"), [INF, NAN])
        message = _refused(inst, inst.fmu.doStep, 2 * H, H)
        assert "inputs mdot_a = inf, v = nan are not a finite number" in message


# -- the same plumbing in the FMI 3.0 build -----------------------------------------------

@pytest.fixture(scope="module")
def valve3(tmp_path_factory):
    """The FMI 3.0 valve, built by ``build_fmus.py --fmi 3`` into a tmp dir."""
    out = tmp_path_factory.mktemp("fmi3")
    proc = subprocess.run([sys.executable, str(ROOT / "build_fmus.py"), "--fmi", "3", "--out", str(out), "valve"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    return out / "fmi3" / "valve.fmu"


def test_the_fmi3_build_follows_the_same_state_machine(valve3, tmp_path):
    from fmpy import extract, instantiate_fmu, read_model_description
    log = []
    unzipdir = extract(str(valve3), unzipdir=str(tmp_path / "valve"))
    md = read_model_description(unzipdir)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    f = instantiate_fmu(unzipdir, md, logger=lambda env, status, cat, msg: log.append((int(status), msg.decode())))

    def refused(call, *args):
        first = len(log)
        with pytest.raises(FMICallException, match=r"status 3 \(error\)"):
            call(*args)
        return " ".join(m for s, m in log[first:] if s >= 3)

    try:
        assert "fmi3DoStep refused at t = 0 s: the instance is not initialised" in refused(f.doStep, 0.0, H)
        f.enterInitializationMode()
        f.exitInitializationMode()
        f.doStep(0.5, H)            # FMI 3.0 (pythonfmu3) gives no start time: the first step sets it
        assert "last step ended at 0.501 s" in refused(f.doStep, 0.0, H)
        assert "fmi3SetFloat64 refused: parameter A_max is fixed" in refused(f.setFloat64, [vr["A_max"]], [-1.0])
        assert f.getFloat64([vr["A_max"]]) == [4e-06]
        f.setFloat64([vr["u"]], [NAN])
        assert "fmi3GetFloat64 refused: input u = nan" in refused(f.getFloat64, [vr["mdot_a"]])
        assert "input u = nan is not a finite number" in refused(f.doStep, 0.5 + H, H)
        f.setFloat64([vr["u"]], [7.0])
        f.doStep(0.5 + H, H)
        assert all(map(math.isfinite, f.getFloat64([vr["mdot_a"], vr["mdot_b"]])))
        f.terminate()
        assert "terminated already" in refused(f.terminate)
    finally:
        f.freeInstance()
