"""The FMI 3.0 versions of every FMU of the FMI 2.0 set (``build_fmus.py`` builds them
by default, ``--fmi 3`` alone; pythonfmu3): built from the same adapters as FMI 2.0,
they validate, declare what the FMI 2.0 FMUs declare, reproduce the FMI 2.0 reference
results through ``fmpy.simulate_fmu`` (the bridges: the FMI 2.0 bridge's replay, value
for value), and reject a bad parameter with fmi3Error and a message that names it."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmpy import extract, instantiate_fmu, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from test_invalid_parameters import INVALID

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("valve", "cylinder", "boom_load", "force_estimator", "hardware_bridge", "linkage", "excavator_bridge",
         "excavator_force_estimator")
#: those with reference results (fmus/<name>/<name>_in.csv, _ref.csv)
REFERENCED = tuple(n for n in NAMES if (ROOT / "fmus" / n / f"{n}_ref.csv").is_file())
FMI3_TYPE = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}


@pytest.fixture(scope="session")
def fmi3_dir(tmp_path_factory) -> Path:
    """The FMI 3.0 FMUs, built once per session by ``build_fmus.py --fmi 3`` into a tmp dir."""
    out = tmp_path_factory.mktemp("fmi3build")
    proc = subprocess.run([sys.executable, str(ROOT / "build_fmus.py"), "--fmi", "3", "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    for name in NAMES:
        assert f"built {out / 'fmi3' / name}.fmu" in proc.stdout
    return out / "fmi3"


class Log:
    """A logger for fmpy: collects (status, message)."""

    def __init__(self):
        self.messages = []

    def __call__(self, env, status, category, message):
        self.messages.append((int(status), message.decode("utf-8", "replace")))


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_fmu_validates_with_no_message(fmi3_dir, name):
    assert validate_fmu(str(fmi3_dir / f"{name}.fmu")) == []
    md = read_model_description(str(fmi3_dir / f"{name}.fmu"))
    assert md.fmiVersion == "3.0" and md.coSimulation.modelIdentifier == name


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_declares_what_fmi2_declares(fmi3_dir, fmu, name):
    """Same variables, value references, units, bounds, starts and output dependencies;
    FMI 3.0 adds time, its independent variable."""
    md2 = read_model_description(str(fmu(name)))
    md3 = read_model_description(str(fmi3_dir / f"{name}.fmu"))
    v3 = {v.name: v for v in md3.modelVariables}
    time = v3.pop("time")
    assert (time.causality, time.unit) == ("independent", "s")
    assert list(v3) == [v.name for v in md2.modelVariables]
    for v in md2.modelVariables:
        w = v3[v.name]
        assert w.type == FMI3_TYPE[v.type], v.name
        for attr in ("valueReference", "causality", "variability", "unit", "description"):
            assert getattr(w, attr) == getattr(v, attr), (v.name, attr)
        for attr in ("min", "max", "start"):
            a, b = getattr(v, attr), getattr(w, attr)
            assert (a is None) == (b is None), (v.name, attr)
            if a is not None:
                assert (float(a) == float(b)) if v.type == "Real" else (str(a) == str(b)), (v.name, attr)
    deps2 = {o.variable.name: [d.name for d in o.dependencies] for o in md2.outputs}
    deps3 = {o.variable.name: [d.name for d in o.dependencies] for o in md3.outputs}
    assert deps3 == deps2
    assert [u.variable.name for u in md3.initialUnknowns] == [u.variable.name for u in md2.initialUnknowns]


def test_every_fmu_of_the_fmi2_set_has_an_fmi3_version():
    import importlib.util
    spec = importlib.util.spec_from_file_location("build_fmus_script", ROOT / "build_fmus.py")
    build_fmus = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build_fmus)
    from boomfmi.fmubuild.fmi3 import FMI3_NAMES
    assert set(FMI3_NAMES) == set(build_fmus.FMU_NAMES) == set(NAMES)
    assert {"valve", "cylinder", "boom_load", "force_estimator", "linkage"} <= set(REFERENCED)


@pytest.mark.parametrize("name", REFERENCED)
def test_fmi3_reference_result(fmi3_dir, name):
    """fmus/<name>/<name>_in.csv through fmpy.simulate_fmu gives <name>_ref.csv, to the
    tolerance of the FMI 2.0 replay (test_reference_results.py).

    simulate_fmu samples the outputs at t_(i+1) right after the step, before it applies
    the inputs of t_(i+1); the FMI 2.0 replay sets the inputs of t_i and then reads.
    For a state the two agree.  An output that feeds through from the inputs (the
    valve's, declared by its dependencies; at its defaults the valve has no state) is
    at t_(i+1) what the reference has at t_i."""
    folder = ROOT / "fmus" / name
    inputs = pd.read_csv(folder / f"{name}_in.csv")
    expected = pd.read_csv(folder / f"{name}_ref.csv")
    path = fmi3_dir / f"{name}.fmu"
    md = read_model_description(str(path))
    signals = np.array(list(inputs.itertuples(index=False, name=None)),
                       dtype=[(c, np.float64) for c in inputs.columns])
    times = inputs["time"].to_numpy()
    result = simulate_fmu(str(path), start_time=float(times[0]), stop_time=float(times[-1]),
                          output_interval=float(times[1] - times[0]), input=signals,
                          output=list(expected.columns.drop("time")))
    assert len(result) == len(expected)
    np.testing.assert_allclose(result["time"], expected["time"], rtol=1e-12, atol=1e-12)
    feedthrough = any(o.dependencies for o in md.outputs)
    for col in expected.columns.drop("time"):
        got, want = result[col], expected[col].to_numpy()
        if feedthrough:
            assert all(o.dependencies for o in md.outputs), "a state beside feedthrough: align per output"
            want = np.r_[want[:1], want[:-1]]
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12, err_msg=col)


def test_fmi3_hardware_bridge_replays_as_the_fmi2_bridge(fmi3_dir, fmu, tmp_path):
    """The bridge (no reference file: its outputs are its recording's) in replay mode,
    FMI 3.0 against FMI 2.0 through fmpy.simulate_fmu: the same values."""
    from boomfmi.recording import write_recording
    rng = np.random.default_rng(3)
    t = np.round(np.arange(0, 0.2001, 1e-3), 6)
    data = pd.DataFrame({"t": t, "u": np.where(t < 0.1, 10.0, 2.5),
                         "p_a": rng.normal(3e5, 1e3, t.size), "p_b": rng.normal(2e5, 1e3, t.size),
                         "alpha": 0.7 + 0.1 * t + rng.normal(0, 1e-4, t.size), "f_ext": np.linspace(0, -50, t.size)})
    path = write_recording(tmp_path / "run.csv", data)
    outs = ["p_a", "p_b", "alpha", "x", "u_applied", "f_ext", "link_ok"]
    runs = [simulate_fmu(str(f), start_values={"mode": "replay", "recording": str(path)}, stop_time=0.2,
                         output_interval=1e-3, output=outs)
            for f in (fmu("hardware_bridge"), fmi3_dir / "hardware_bridge.fmu")]
    assert len(runs[0]) == len(runs[1]) == len(data)
    for col in outs:
        np.testing.assert_array_equal(runs[1][col], runs[0][col], err_msg=col)
    np.testing.assert_array_equal(runs[1]["p_a"], data["p_a"])


def _instance(path: Path, tmp: Path, log: Log):
    unzipdir = extract(str(path), unzipdir=str(tmp / path.stem))
    md = read_model_description(unzipdir)
    return unzipdir, md, instantiate_fmu(unzipdir, md, logger=log)


@pytest.mark.parametrize("name, params, culprit", INVALID,
                         ids=[f"{n}-{next(iter(p))}={next(iter(p.values()))}" for n, p, _ in INVALID])
def test_fmi3_invalid_parameter_is_an_fmi3_error_naming_it(fmi3_dir, tmp_path, name, params, culprit):
    log = Log()
    unzipdir, md, fmu = _instance(fmi3_dir / f"{name}.fmu", tmp_path, log)
    try:
        with pytest.raises(FMICallException) as err:
            simulate_fmu(unzipdir, model_description=md, fmu_instance=fmu, start_values=params,
                         stop_time=2e-3, output_interval=1e-3)
        assert err.value.function == "fmi3ExitInitializationMode"
        assert err.value.status == 3, "fmi3Error, not fmi3Fatal"
        assert any(s == 3 and f"parameter {culprit} =" in m for s, m in log.messages), log.messages
        # the instance is still safe to use: a later call fails cleanly too
        with pytest.raises(FMICallException) as again:
            fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
        assert again.value.status == 3
    finally:
        fmu.freeInstance()


def test_fmi3_python_exception_is_an_error_of_that_instance_only(fmi3_dir, tmp_path):
    """pythonfmu3 turns a Python exception into fmi3Fatal and releases the instance's
    Python object; the shim makes it fmi3Error, keeps later calls away from pythonfmu3,
    and another instance of the same FMU goes on."""
    path = fmi3_dir / "force_estimator.fmu"
    log = Log()
    _, md, broken = _instance(path, tmp_path, log)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    other_log = Log()
    _, _, other = _instance(path, tmp_path / "other", other_log)
    try:
        with pytest.raises(FMICallException) as err:
            broken.setFloat64([vr["method"]], [1.0])             # a String variable
        assert err.value.status == 3
        assert any("TypeError" in m for _, m in log.messages), log.messages
        with pytest.raises(FMICallException) as again:
            broken.enterInitializationMode()
        assert again.value.status == 3
        assert "cannot be used" in log.messages[-1][1]
        other.enterInitializationMode()
        other.setFloat64([vr["K_p"]], [2e4])
        other.exitInitializationMode()
        other.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
        assert other_log.messages == []
    finally:
        broken.freeInstance()
        other.terminate()
        other.freeInstance()
