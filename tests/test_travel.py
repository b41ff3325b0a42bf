"""FMUs that travel (issue 37): copied to a fresh folder and run, with the build's venv
and checkout out of reach, by a minimal C FMI 2.0 host compiled here with the system's C
compiler (benchmarks/fmu_travel.py) under an ``env -i`` environment, and by ecos.

"Another machine" is this machine's own system Python (Debian's libpython3.11, without
numpy), named by BOOMFMI_LIBPYTHON: a portable FMU runs on it, a lean one fails with
fmi2Error naming numpy.  The host must exit 0 after freeing every instance (pythonfmu's
exit-time double free, PythonFMU pull request 213, is defused by the shim), and a wrong
PYTHONHOME is fmi2Error, not "Fatal Python error" inside fmi2Instantiate.  Skipped only
where there is no C compiler, no system libpython3.11, no ecos or no valgrind."""
from __future__ import annotations

import importlib.util
import os
import re
import shutil
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("fmu_travel", ROOT / "benchmarks" / "fmu_travel.py")
T = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(T)

VERSION = f"{sys.version_info.major}.{sys.version_info.minor}"
#: the machine's own Python runtime, not the one the FMUs were built with
SYSTEM_LIBPYTHON = Path(f"/usr/lib/x86_64-linux-gnu/libpython{VERSION}.so.1.0")
#: where the build's numpy is: the "build machine" case gives it as PYTHONPATH
SITE = str(Path(np.__file__).resolve().parents[1])


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler (cc or gcc) to compile the minimal FMI host")
    return T.compile_host(tmp_path_factory.mktemp("host"))


@pytest.fixture(scope="module")
def system_python():
    if not SYSTEM_LIBPYTHON.is_file():
        pytest.skip(f"no system Python {VERSION} runtime ({SYSTEM_LIBPYTHON}) to play another machine")
    return str(SYSTEM_LIBPYTHON)


@pytest.fixture(scope="module")
def portable_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("portable")


@pytest.fixture(scope="module")
def portable_valve(portable_dir):
    """The valve built portable (numpy inside for linux64; no download needed)."""
    from boomfmi.fmubuild import build_fmu
    return build_fmu(ROOT / "fmus" / "valve", portable_dir / "fmus", portable=("linux64",))


@pytest.fixture(scope="module")
def portable_ssp(portable_valve, portable_dir):
    """The boom's SSP packed from portable FMUs."""
    from boomfmi.fmubuild import build_fmu
    from boomfmi.fmubuild.ssp import pack_ssp
    for name in ("cylinder", "boom_load"):
        build_fmu(ROOT / "fmus" / name, portable_dir / "fmus", portable=("linux64",))
    return pack_ssp(ROOT / "ssp" / "SystemStructure.ssd", portable_dir / "fmus", portable_dir / "excavator_boom.ssp")


def logged_errors(stdout: str) -> list[str]:
    """The messages the FMU logged with fmi2Error (each to the next line the host printed)."""
    return re.findall(r"^log status=3 instance=travel category=\S*: (.*?)(?=^log |^load |^host done|\Z)",
                      stdout, re.M | re.S)


def test_fmus_record_no_path_of_the_build_and_state_their_requirements(fmu):
    venv, checkout = sys.prefix.encode(), str(ROOT).encode()
    for name in ("valve", "cylinder", "boom_load", "force_estimator", "hardware_bridge", "excavator_force_estimator"):
        with zipfile.ZipFile(fmu(name)) as z:
            for member in z.namelist():
                data = z.read(member)
                assert venv not in data and checkout not in data, f"{name}.fmu: {member} names the build's venv or checkout"
            req = z.read("resources/boomfmi_requirements.txt").decode()
            script = z.read(f"resources/{name}_fmu.py").decode()
        assert f"python={VERSION}\n" in req
        assert re.search(rf"^require=numpy>=\d+\.\d+,<\d+ built={re.escape(np.__version__)}$", req, re.M), req
        assert "\nportable=\n" in req                   # the default build is lean
        # the requirements are checked before the script imports anything else
        first = next(line for line in script.splitlines() if line.startswith(("import ", "from ")))
        assert first.startswith(f"import boomfmi_{name}_lib ")


def test_a_lean_fmu_on_another_machine_fails_at_instantiate_naming_numpy(fmu, host, system_python, tmp_path):
    tree, ident, guid, refs = T.unpack(fmu("valve"), tmp_path)
    proc = T.run_host(host, tree, ident, guid, {refs["u"]: 2.0}, [refs["mdot_a"]],
                      env=dict(T.CLEAN_ENV, BOOMFMI_LIBPYTHON=system_python))
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]     # the host lives on
    assert "load 0: fmi2Instantiate returned NULL" in proc.stdout
    errors = "\n".join(logged_errors(proc.stdout))                                # fmi2Error, not fmi2Fatal
    assert "this FMU needs, in the Python that runs it (Python 3." in errors, proc.stdout[-3000:]
    assert re.search(rf"numpy>=\S+ \(built with {re.escape(np.__version__)}\): not importable: "
                     r"No module named \\?'numpy", errors), errors
    assert f'-m pip install "numpy>=' in errors and "build_fmus.py --portable" in errors
    assert "status=4" not in proc.stdout
    assert T.values(proc.stdout) == {}                  # nothing computed with another numpy


def test_a_portable_fmu_runs_on_another_machine_as_in_fmpy(portable_valve, host, system_python, tmp_path):
    from fmpy import simulate_fmu
    with zipfile.ZipFile(portable_valve) as z:
        assert "resources/python/linux64/numpy/__init__.py" in z.namelist()
        assert "\nportable=linux64\n" in z.read("resources/boomfmi_requirements.txt").decode()
    tree, ident, guid, refs = T.unpack(portable_valve, tmp_path)
    proc = T.run_host(host, tree, ident, guid, {refs["u"]: 2.0}, [refs["mdot_a"], refs["mdot_b"]],
                      env=dict(T.CLEAN_ENV, BOOMFMI_LIBPYTHON=system_python))
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "load 0: status 0" in proc.stdout, proc.stdout[-3000:]
    got = T.values(proc.stdout)
    ours = simulate_fmu(str(portable_valve), start_values={"u": 2.0}, stop_time=0.01, step_size=1e-3,
                        output=["mdot_a", "mdot_b"])
    assert got[refs["mdot_a"]] > 0
    assert got[refs["mdot_a"]] == pytest.approx(ours["mdot_a"][-1], rel=1e-12)
    assert got[refs["mdot_b"]] == pytest.approx(ours["mdot_b"][-1], rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("name", ["valve", "cylinder"])
def test_the_c_host_exits_cleanly_after_freeing_every_instance(fmu, host, name, tmp_path):
    tree, ident, guid, refs = T.unpack(fmu(name), tmp_path)
    out = [r for r, c in refs.items() if c >= 0][:3]
    env = dict(T.CLEAN_ENV, PYTHONPATH=SITE)             # the build machine's numpy, given explicitly
    results = []
    for _ in range(3):
        proc = T.run_host(host, tree, ident, guid, gets=[refs[v] for v in out], env=env)
        assert proc.returncode == 0, f"rc {proc.returncode}: {proc.stderr[-1500:]}"   # was 134 (SIGABRT)
        assert "free(): corrupted" not in proc.stderr
        assert "load 0: status 0" in proc.stdout and "host done" in proc.stdout, proc.stdout[-2000:]
        results.append(T.values(proc.stdout))
    assert results[0] and results[0] == results[1] == results[2]


def test_load_run_free_and_reload_ten_times_in_one_process(fmu, host, tmp_path):
    tree, ident, guid, refs = T.unpack(fmu("valve"), tmp_path)
    proc = T.run_host(host, tree, ident, guid, {refs["u"]: 2.0}, [refs["mdot_a"]], loads=10,
                      env=dict(T.CLEAN_ENV, PYTHONPATH=SITE))
    assert proc.returncode == 0, f"rc {proc.returncode}: {proc.stderr[-1500:]}"
    assert len(re.findall(r"^load \d: status 0$", proc.stdout, re.M)) == 10, proc.stdout[-2000:]
    first = T.values(proc.stdout, 0)[refs["mdot_a"]]
    assert first > 0
    assert all(T.values(proc.stdout, k)[refs["mdot_a"]] == first for k in range(10))


def test_a_wrong_pythonhome_is_fmi2error_not_a_fatal_exit(fmu, host, tmp_path):
    tree, ident, guid, refs = T.unpack(fmu("valve"), tmp_path / "fmu")
    other = tmp_path / "other" / "lib" / "python3.99" / "encodings"       # another Python's home
    other.mkdir(parents=True)
    (other / "__init__.py").write_text("")
    for home, found in (("/nonexistent", "/nonexistent/lib: No such file or directory"),
                        (str(tmp_path / "other"), "it holds the standard library of another Python: python3.99")):
        proc = T.run_host(host, tree, ident, guid, gets=[refs["mdot_a"]], env=dict(T.CLEAN_ENV, PYTHONHOME=home))
        assert proc.returncode == 0, f"rc {proc.returncode}: {proc.stderr[-1500:]}"   # was 1, "Fatal Python error"
        assert "Fatal Python error" not in proc.stderr
        assert "load 0: fmi2Instantiate returned NULL" in proc.stdout
        errors = "\n".join(logged_errors(proc.stdout))
        assert f"PYTHONHOME={home} does not hold the standard library of Python {VERSION}" in errors, proc.stdout
        assert f"{home}/lib/python{VERSION}/encodings/__init__.py: No such file or directory" in errors
        assert found in errors


def test_an_interpreter_that_cannot_start_is_fmi2error(fmu, host, tmp_path):
    """PYTHONHOME holds an encodings package, but one that cannot be imported: the start
    fails later, inside the interpreter, and is still reported, not fatal."""
    tree, ident, guid, refs = T.unpack(fmu("valve"), tmp_path / "fmu")
    broken = tmp_path / "broken" / "lib" / f"python{VERSION}" / "encodings"
    broken.mkdir(parents=True)
    (broken / "__init__.py").write_text('raise ImportError("broken standard library")\n')
    proc = T.run_host(host, tree, ident, guid, gets=[refs["mdot_a"]],
                      env=dict(T.CLEAN_ENV, PYTHONHOME=str(tmp_path / "broken")))
    assert proc.returncode == 0, f"rc {proc.returncode}: {proc.stderr[-1500:]}"
    assert "Fatal Python error" not in proc.stderr
    errors = "\n".join(logged_errors(proc.stdout))
    assert "could not start: init_fs_encoding: failed to get the Python codec of the filesystem encoding" in errors, \
        proc.stdout[-2000:]
    assert f"PYTHONHOME={tmp_path / 'broken'}" in errors


def test_ecos_with_a_lean_ssp_on_another_machine_stops_naming_numpy(ssp_path, system_python, tmp_path):
    from test_native_host import data_rows, run_ecos
    copy = tmp_path / "copy" / ssp_path.name
    copy.parent.mkdir()
    shutil.copy2(ssp_path, copy)
    proc = run_ecos(copy, tmp_path, stop_time=0.1, BOOMFMI_LIBPYTHON=system_python, PATH="/usr/bin:/bin")
    said = proc.stdout + proc.stderr
    assert proc.returncode != 0, said[-2000:]
    assert re.search(r"not importable: No module named \\?'numpy", said) and '-m pip install "numpy>=' in said, \
        said[-3000:]
    assert data_rows(tmp_path) == 0


@pytest.mark.slow
def test_ecos_runs_a_portable_ssp_on_another_machine_as_our_master(portable_ssp, ssp_path, system_python, tmp_path):
    import pandas as pd

    from test_native_host import run_ecos

    from boomfmi.system import simulate_ssp
    copy = tmp_path / "copy" / portable_ssp.name
    copy.parent.mkdir()
    shutil.copy2(portable_ssp, copy)
    proc = run_ecos(copy, tmp_path, BOOMFMI_LIBPYTHON=system_python, PATH="/usr/bin:/bin")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    out = pd.read_csv(tmp_path / "excavator_boom.csv", skipinitialspace=True)
    out.columns = [c.strip() for c in out.columns]
    from boomfmi.experiments import paper_multistep     # the command of examples/hosts/ecos/scenario.xml
    ours = simulate_ssp(ssp_path, stop_time=1.5, step=1e-3, algorithm="jacobi",      # the lean build, in fmpy
                        inputs=lambda t: {"valve.u": paper_multistep()(t)["u"]})
    theirs = out.set_index(np.round(out["time"].to_numpy(), 6))
    mine = ours.set_index(np.round(ours["time"].to_numpy(), 6))
    common = theirs.index.intersection(mine.index)
    assert len(common) > 1000
    np.testing.assert_allclose(theirs.loc[common, "cylinder::p_a[REAL]"], mine.loc[common, "cylinder.p_a"], rtol=1e-5)
    np.testing.assert_allclose(theirs.loc[common, "boom_load::x[REAL]"], mine.loc[common, "boom_load.x"], atol=1e-6)


@pytest.mark.slow
def test_valgrind_finds_no_invalid_access_in_the_shim_or_pythonfmu(fmu, host, tmp_path):
    if shutil.which("valgrind") is None:
        pytest.skip("valgrind is not installed (scripts/bootstrap.sh installs it as root)")
    tree, ident, guid, refs = T.unpack(fmu("valve"), tmp_path)
    # ten loads in one process, as test_load_run_free_and_reload_ten_times_in_one_process
    proc = T.run_host(host, tree, ident, guid, {refs["u"]: 2.0}, [refs["mdot_a"]], loads=10, timeout=600,
                      env=dict(T.CLEAN_ENV, PYTHONPATH=SITE), prefix=("valgrind",))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert len(re.findall(r"^load \d: status 0$", proc.stdout, re.M)) == 10, proc.stdout[-2000:]
    assert "ERROR SUMMARY" in proc.stderr
    # was: an invalid read in finalizePythonInterpreter of a block an exit handler freed
    ours, _ = T.invalid_accesses(proc.stderr, ident)
    assert not ours, "\n\n".join(ours)[:4000]
