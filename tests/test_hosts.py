"""The host examples (issue 36, item 3) run as written and agree with boomfmi's master:
``examples/hosts/fmpy_ssp.py`` (fmpy's own SSP runner, a changing command and the
parameter set), ``examples/hosts/libcosim_ssp.py`` and ``examples/hosts/ecos/`` (the
scenario and CSV configuration, and the command line).  Each runs paper_multistep on the
boom; fmpy's and libcosim's rows are compared with the Jacobi master step for step, the
boom's whole stroke and every pressure included."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi.experiments import paper_multistep
from boomfmi.system import simulate_ssp

from conftest import ROOT

HOSTS = ROOT / "examples" / "hosts"
H = 1e-3
LATE = 0.05         # [s] fmpy's first step hands the valve 0 V (docs/hosts.md): compared after it


@pytest.fixture(scope="module")
def master(ssp_path):
    profile = paper_multistep()
    return simulate_ssp(ssp_path, profile.duration, H, "jacobi", inputs=profile)


def run_example(args, cwd: Path, env=None) -> subprocess.CompletedProcess:
    proc = subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return proc


def nrmse(theirs: np.ndarray, ours: np.ndarray) -> float:
    return float(np.sqrt(np.mean((theirs - ours) ** 2)) / np.ptp(ours))


def test_the_fmpy_example_runs_paper_multistep_as_the_jacobi_master(ssp_path, master, tmp_path):
    proc = run_example([sys.executable, str(HOSTS / "fmpy_ssp.py"), str(ssp_path), "--out", "run.csv"], tmp_path)
    assert "fmpy ran excavator_boom.ssp for 9 s" in proc.stdout
    theirs = pd.read_csv(tmp_path / "run.csv")
    n = round(paper_multistep().duration / H)
    assert len(theirs) >= n
    np.testing.assert_allclose(theirs["time"][:n], master["time"][:n], rtol=0, atol=1e-9)
    # the command of each row at every breakpoint too (3 s is 2.9999999999997806 in fmpy's time)
    np.testing.assert_array_equal(theirs["valve.u"][:n], master["valve.u"][:n])
    late = master["time"].to_numpy()[:n] >= LATE
    figures = {c: nrmse(theirs[c].to_numpy()[:n][late], master[c].to_numpy()[:n][late])
               for c in ("boom_load.x", "cylinder.p_a", "cylinder.p_b")}
    assert max(figures.values()) < 1e-3, figures          # 2.4e-8, 5.8e-4, 1.9e-5 seen
    assert np.ptp(theirs["boom_load.x"]) == pytest.approx(0.06)     # the parameter set: the full stroke


def test_the_libcosim_example_runs_paper_multistep_as_the_jacobi_master(ssp_path, master, tmp_path):
    pytest.importorskip("libcosimpy", reason="libcosimpy is a test dependency")
    proc = run_example([sys.executable, str(HOSTS / "libcosim_ssp.py"), str(ssp_path), "--out", "run.csv"], tmp_path)
    assert "[debug]" not in proc.stdout + proc.stderr            # its log level lowered
    theirs = pd.read_csv(tmp_path / "run.csv")
    ours = master.iloc[1:len(theirs) + 1]          # libcosim's k-th sample is the master's row at t_(k+1)
    assert len(theirs) == round(paper_multistep().duration / H) == len(ours)
    np.testing.assert_allclose(theirs["time"], ours["time"], rtol=0, atol=1e-12)
    for col in ("boom_load.x", "boom_load.v", "cylinder.p_a", "cylinder.p_b"):
        np.testing.assert_allclose(theirs[col], ours[col], rtol=1e-6, atol=1e-9, err_msg=col)
    assert np.ptp(theirs["boom_load.x"]) == pytest.approx(0.06)


def test_the_ecos_example_runs_its_scenario_as_the_jacobi_master(ssp_path, master, tmp_path):
    from test_native_host import ecos_binary, libpython
    if libpython() is None:
        pytest.skip("this Python has no shared libpython for the FMUs to load")
    ecos_binary(tmp_path)                          # skips where the wheel has no ecos
    from boomfmi.fmubuild.ssp import osp_ssp
    # nothing about Python in ecos's environment: each FMU loads the Python it was built with
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("PYTHON") and k not in ("LD_PRELOAD", "BOOMFMI_LIBPYTHON", "VIRTUAL_ENV")}
    env.update(SSP=str(osp_ssp(ssp_path)), PY=sys.executable)
    proc = run_example([str(HOSTS / "ecos" / "run.sh")], tmp_path, env)
    assert "ecos wrote" in proc.stdout
    out = pd.read_csv(tmp_path / "excavator_boom.csv", skipinitialspace=True)
    out.columns = [c.strip() for c in out.columns]
    theirs = out.set_index(np.round(out["time"].to_numpy(), 6))
    mine = master.set_index(np.round(master["time"].to_numpy(), 6))
    common = theirs.index.intersection(mine.index)[1:]     # row 0: ecos writes the start value (5 V)
    assert len(common) >= 8990
    # the scenario is paper_multistep: ecos writes with each row the command of the step
    # that led to it, the master's command one row earlier
    before = master.set_index(np.round(master["time"].to_numpy() + H, 6))
    np.testing.assert_array_equal(theirs.loc[common, "valve::u[REAL]"], before.loc[common, "valve.u"])
    np.testing.assert_allclose(theirs.loc[common, "cylinder::p_a[REAL]"], mine.loc[common, "cylinder.p_a"], rtol=1e-5)
    np.testing.assert_allclose(theirs.loc[common, "boom_load::x[REAL]"], mine.loc[common, "boom_load.x"],
                               rtol=0, atol=1e-6)             # ecos writes 6 decimals
