"""A host that is not a Python process runs the .ssp: the ecos command-line program
(from the ecospy wheel), with libpython preloaded as the README describes.

pythonfmu's binary takes Python from its host; a C++ host has none, so libpython is
preloaded (LD_PRELOAD) and the FMUs find numpy through PYTHONPATH.  Skipped where the
machine does not allow it: no ecospy, or a Python built without a shared libpython."""
from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi.system import simulate_ssp

SCENARIO = """<?xml version="1.0" encoding="UTF-8"?>
<ecos:Scenario xmlns:ecos="http://github.com/Ecos-platform/libecos/resources/schema/ScenarioConfig" eps="0.0001">
  <ecos:action t="0"><ecos:variable id="valve::u"><ecos:real value="10.0"/></ecos:variable></ecos:action>
  <ecos:action t="0.5"><ecos:variable id="valve::u"><ecos:real value="1.0"/></ecos:variable></ecos:action>
</ecos:Scenario>
"""
CSV_CONFIG = """<?xml version="1.0" encoding="UTF-8"?>
<ecos:CsvConfig xmlns:ecos="http://github.com/Ecos-platform/libecos/resources/schema/CsvConfig">
  <ecos:components>
    <ecos:component name="boom_load"><ecos:variable name="x"/></ecos:component>
    <ecos:component name="cylinder"><ecos:variable name="p_a"/><ecos:variable name="p_b"/></ecos:component>
  </ecos:components>
</ecos:CsvConfig>
"""


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


def test_ecos_runs_the_ssp_with_libpython_preloaded(ssp_path, tmp_path):
    lib = libpython()
    if lib is None:
        pytest.skip("this Python has no shared libpython to preload")
    exe = ecos_binary(tmp_path)
    (tmp_path / "scenario.xml").write_text(SCENARIO)
    (tmp_path / "csv.xml").write_text(CSV_CONFIG)
    env = dict(os.environ,
               LD_PRELOAD=str(lib),
               PYTHONPATH=sysconfig.get_paths()["purelib"],
               LD_LIBRARY_PATH=os.path.join(sys.prefix, "lib"),   # libtbb.so.12 from the tbb wheel
               TMPDIR=str(tmp_path))                             # ecos leaves its extractions behind
    proc = subprocess.run([str(exe), "simulate", "--path", str(ssp_path), "--stepSize", "0.001",
                           "--stopTime", "1.5", "--parameterSet", "reference_rig",
                           "--scenarioConfig", "scenario.xml", "--csvConfig", "csv.xml", "-l", "warn"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = pd.read_csv(tmp_path / "excavator_boom.csv", skipinitialspace=True)
    out.columns = [c.strip() for c in out.columns]
    x, p_a = "boom_load::x[REAL]", "cylinder::p_a[REAL]"
    assert out[x].iloc[-1] == pytest.approx(0.06)
    # ecos steps like boomfmi's Jacobi master (it writes 6 decimals)
    ours = simulate_ssp(ssp_path, stop_time=1.5, step=1e-3, algorithm="jacobi",
                        inputs=lambda t: {"valve.u": 10.0 if t < 0.5 else 1.0})
    theirs = out.set_index(np.round(out["time"].to_numpy(), 6))
    mine = ours.set_index(np.round(ours["time"].to_numpy(), 6))
    common = theirs.index.intersection(mine.index)
    assert len(common) > 1000
    np.testing.assert_allclose(theirs.loc[common, p_a], mine.loc[common, "cylinder.p_a"], rtol=1e-5)
    np.testing.assert_allclose(theirs.loc[common, x], mine.loc[common, "boom_load.x"], rtol=0, atol=2e-6)
