"""A host that is not a Python process runs the .ssp: the ecos command-line program
(from the ecospy wheel), with nothing in its environment about Python.

The FMUs' status shim loads the Python runtime they were built with (recorded in
resources/boomfmi_runtime.txt) and starts it itself, so ecos needs no LD_PRELOAD and no
PYTHONPATH where that runtime has numpy (here it does; elsewhere the FMU names what it
misses, tests/test_travel.py); only LD_LIBRARY_PATH, for ecos's own libtbb.  When the
runtime cannot be loaded the shim says why and stops the host (ecos itself would go on
with the instance fmi2Instantiate did not create, write zeros and exit 0).  Skipped where
the machine does not allow it: no ecospy, or a Python built without a shared libpython."""
from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import sysconfig
import textwrap
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from boomfmi.system import simulate_ssp

HOSTS = Path(__file__).resolve().parents[1] / "examples" / "hosts"
SCENARIO = (HOSTS / "ecos" / "scenario.xml").read_text()      # the example's (tests/test_hosts.py runs it)
CSV_CONFIG = (HOSTS / "ecos" / "csv.xml").read_text()
FMI2_CS_EXPORTS = ("fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate",
                   "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
                   "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset", "fmi2GetReal",
                   "fmi2SetReal", "fmi2GetString", "fmi2SetString", "fmi2DoStep", "fmi2GetStatus")


def libpython() -> Path | None:
    if not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return None
    path = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("LDLIBRARY")
    return path if path.exists() else None


def ecos_binary(tmp: Path) -> Path:
    import importlib.util
    spec = importlib.util.find_spec("ecospy")     # not imported: it loads libtbb in-process
    if spec is None or spec.origin is None:
        pytest.skip("ecospy (the ecos CLI) is not installed")
    binary = Path(spec.origin).parent / "binaries" / "ecos"
    if not binary.is_file():
        pytest.skip("this ecospy has no ecos binary for this platform")
    exe = tmp / "ecos"
    shutil.copy2(binary, exe)                      # the wheel installs it without an exec bit
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return exe


def run_ecos(ssp_path: Path, tmp: Path, stop_time: float = 1.5, **env_vars) -> subprocess.CompletedProcess:
    """ecos on the .ssp at its default log level, with no Python in its environment."""
    if libpython() is None:
        pytest.skip("this Python has no shared libpython for the FMUs to load")
    exe = ecos_binary(tmp)
    (tmp / "scenario.xml").write_text(SCENARIO)
    (tmp / "csv.xml").write_text(CSV_CONFIG)
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("PYTHON") and k not in ("LD_PRELOAD", "BOOMFMI_LIBPYTHON", "VIRTUAL_ENV")}
    env.update(LD_LIBRARY_PATH=os.path.join(sys.prefix, "lib"),   # libtbb.so.12 from the tbb wheel
               TMPDIR=str(tmp),                                   # ecos leaves its extractions behind
               **env_vars)
    from boomfmi.fmubuild.ssp import osp_ssp     # ecos refuses system connectors
    return subprocess.run([str(exe), "simulate", "--path", str(osp_ssp(ssp_path)), "--stepSize", "0.001",
                           "--stopTime", str(stop_time), "--parameterSet", "reference_rig",
                           "--scenarioConfig", "scenario.xml", "--csvConfig", "csv.xml"],
                          cwd=tmp, env=env, capture_output=True, text=True, timeout=300)


def data_rows(tmp: Path) -> int:
    csv = tmp / "excavator_boom.csv"
    return max(0, len(csv.read_text().splitlines()) - 1) if csv.is_file() else 0


def test_without_the_python_runtime_ecos_stops_and_says_why(ssp_path, tmp_path):
    missing = tmp_path / "nowhere" / "libpython3.11.so.1.0"
    proc = run_ecos(ssp_path, tmp_path, stop_time=0.1, BOOMFMI_LIBPYTHON=str(missing))
    said = proc.stdout + proc.stderr           # ecos's default log level: FMU messages are not in it
    assert proc.returncode != 0, said[-2000:]
    assert "cannot load the Python runtime that BOOMFMI_LIBPYTHON names" in said, said[-2000:]
    assert f"{missing}: cannot open shared object file: No such file or directory" in said  # dlerror()
    assert "stopping the process (exit status 1)" in said
    assert data_rows(tmp_path) == 0            # no zeros written in the model's place


def test_a_python_error_at_instantiation_stops_ecos_with_the_exception(ssp_path, tmp_path):
    fake = tmp_path / "fake"
    (fake / "numpy").mkdir(parents=True)
    (fake / "numpy" / "__init__.py").write_text('raise ImportError("numpy is hidden for this test")\n')
    proc = run_ecos(ssp_path, tmp_path, stop_time=0.1, PYTHONPATH=str(fake))  # the FMUs keep a PYTHONPATH that is set
    said = proc.stdout + proc.stderr
    assert proc.returncode != 0, said[-2000:]
    assert "pythonfmu could not instantiate the model" in said, said[-2000:]
    assert "not importable: numpy is hidden for this test" in said     # the FMU's requirements check
    assert f"PYTHONPATH={fake}" in said
    assert data_rows(tmp_path) == 0


def test_in_a_python_host_the_shim_leaves_python_alone(fmu, tmp_path):
    """fmpy already runs an interpreter: BOOMFMI_LIBPYTHON is not even looked at."""
    code = textwrap.dedent(f"""
        from fmpy import simulate_fmu
        result = simulate_fmu({str(fmu("valve"))!r}, stop_time=0.01, output_interval=1e-3)
        print(len(result))
    """)
    env = dict(os.environ, BOOMFMI_LIBPYTHON=str(tmp_path / "missing.so"))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert int(proc.stdout.split()[-1]) == 11


def _platforms(fmu_path: Path) -> dict[str, dict]:
    with zipfile.ZipFile(fmu_path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    tool = next(t for t in root.find("VendorAnnotations").findall("Tool") if t.get("name") == "boomfmi")
    return {p.get("name"): p.attrib for p in tool.find("Platforms").findall("Platform")} | \
        {"unsupported": tool.find("Platforms").find("Unsupported").attrib}


def test_model_descriptions_state_the_platforms(fmu):
    for name in ("valve", "cylinder", "boom_load", "force_estimator", "hardware_bridge"):
        platforms = _platforms(fmu(name))
        assert platforms["linux64"]["shim"] == "true"
        assert platforms["linux64"]["binary"] == f"binaries/linux64/{name}.so"
        assert "BOOMFMI_LIBPYTHON" in platforms["linux64"]["description"]
        assert platforms["win64"]["binary"] == f"binaries/win64/{name}.dll"
        assert {"darwin64", "aarch64"} <= set(platforms["unsupported"]["platforms"].split())
        with zipfile.ZipFile(fmu(name)) as z:
            record = z.read("resources/boomfmi_runtime.txt").decode()
        assert f"version={sys.version_info.major}.{sys.version_info.minor}\n" in record
        assert "linux64.libpython=" in record
        assert "linux64.path=" not in record            # no site-packages of the build (issue 37)


def test_the_win64_dll_is_the_shim_with_the_fmi2_exports(fmu, tmp_path):
    path = fmu("valve")
    if _platforms(path)["win64"]["shim"] != "true":
        pytest.skip("these FMUs were built without mingw-w64 (x86_64-w64-mingw32-gcc): "
                    "their win64 binary is pythonfmu's own, with no shim")
    objdump = shutil.which("x86_64-w64-mingw32-objdump") or shutil.which("objdump")
    if objdump is None:
        pytest.skip("no objdump to read the DLL's export table")
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        assert "binaries/win64/valve_pythonfmu.dll" in names
        dll = tmp_path / "valve.dll"
        dll.write_bytes(z.read("binaries/win64/valve.dll"))
    proc = subprocess.run([objdump, "-p", str(dll)], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.skip(f"{objdump} cannot read PE files: {proc.stderr.strip()[:200]}")
    exports = proc.stdout.split("[Ordinal/Name Pointer] Table")[-1]
    for fn in FMI2_CS_EXPORTS:
        assert f"] {fn}\n" in exports, fn
    imports = [line.split(":", 1)[1].strip().lower() for line in proc.stdout.splitlines()
               if line.strip().startswith("DLL Name:")]
    assert "python3.dll" not in imports        # the shim loads Python itself, pythonfmu's DLL imports it
    assert "kernel32.dll" in imports
