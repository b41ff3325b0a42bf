"""Issue 36, items 4 and 5: the lockstep rig starts each run from its initial state and
is not in fail-safe on a clean start; the small things (delimiter hint, ...)."""
from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from boomfmi.foreign import read_foreign
from boomfmi.record import record_experiment
from boomfmi.recording import RecordingError, read_recording
from boomfmi.rig.plant import VirtualRig
from boomfmi.rig.server import RigServer

ROOT = Path(__file__).resolve().parents[1]
KEY = "a shared key of more than sixteen bytes"
BRIDGE = ROOT / "build" / "fmus" / "hardware_bridge.fmu"


@pytest.fixture
def lockstep_rig(tmp_path, monkeypatch):
    monkeypatch.setenv("BOOMFMI_LINK_KEY", KEY)
    server = RigServer(VirtualRig(), KEY.encode(), lockstep=True, record=tmp_path / "rig.csv")
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    yield server
    server.stop()
    thread.join(10)


@pytest.mark.skipif(not BRIDGE.is_file(), reason="build/fmus/hardware_bridge.fmu not built")
def test_a_second_record_on_a_lockstep_rig_starts_from_the_initial_state(lockstep_rig, tmp_path):
    url = f"udp://127.0.0.1:{lockstep_rig.port}"
    record_experiment(BRIDGE, url, tmp_path / "one.csv", stop_time=0.5)
    time.sleep(0.1)                   # past the watchdog: the first run's driver has gone
    record_experiment(BRIDGE, url, tmp_path / "two.csv", stop_time=0.5)
    one = read_recording(tmp_path / "one.csv").data
    two = read_recording(tmp_path / "two.csv").data
    assert len(one) == len(two) == 501                            # nothing lost
    for rec in (one, two):
        assert rec["failsafe"].iloc[0] == 0                       # a clean start is not in fail-safe
        assert rec["failsafe"].sum() == 0
    np.testing.assert_allclose(two["t_rig"], one["t_rig"], atol=1e-9)     # rig time from 0 again
    np.testing.assert_allclose(two["p_b"].iloc[:5], one["p_b"].iloc[:5], atol=1.0)   # the same initial state
    assert lockstep_rig.counters.restarts == 1
    assert lockstep_rig.counters.failsafe_entries <= 2            # at most once after each run's end
    lockstep_rig.stop()
    time.sleep(0.3)
    rig = read_recording(tmp_path / "rig.csv").data               # the rig's own file stays in time order
    assert (np.diff(rig["t"]) > 0).all() and len(rig) >= 1002


def test_a_missing_delimiter_is_named_in_the_header_error(tmp_path):
    path = tmp_path / "daq.csv"
    path.write_text("Zeit_ms;Befehl_V;pA\n0;5,0;1,0\n1;5,0;1,0\n")
    with pytest.raises(RecordingError) as e:
        read_foreign(path, "t=Zeit_ms:ms,u=Befehl_V:V,p_a_abs=pA:bar", header=True)
    msg = str(e.value)
    assert "no column 'Zeit_ms'" in msg and "daq.csv" in msg
    assert "';'-separated" in msg and "--delimiter semicolon" in msg
    assert path.read_text().startswith("Zeit_ms;")                 # the file is untouched


def test_the_readme_import_examples_call_the_venv_boomfmi():
    text = (ROOT / "README.md").read_text()
    bare = [line for line in text.splitlines() if line.startswith("boomfmi ")]
    assert bare == [], bare


def test_pyproject_license_is_an_spdx_string():
    import tomllib
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert meta["project"]["license"] == "MIT"
    assert any(r.replace(" ", "").startswith("setuptools>=77") for r in meta["build-system"]["requires"])


@pytest.fixture(scope="module")
def boom_runs(tmp_path_factory):
    """Two fit recordings and holdouts of the boom: one of the same rig, one whose
    piston leaks (an effect the model lacks)."""
    from boomfmi.experiments import paper_multistep, random_steps
    from boomfmi.recording import write_recording
    from boomfmi.rig.offline import run_offline
    d = tmp_path_factory.mktemp("own36")
    prof = paper_multistep()
    steps = random_steps(3, duration=4.0)
    write_recording(d / "fit1.csv", run_offline({"seed": 1}, prof, prof.duration))
    write_recording(d / "fit2.csv", run_offline({"seed": 2}, steps, 4.0))
    write_recording(d / "hold.csv", run_offline({"seed": 3}, random_steps(4, duration=4.0), 4.0))
    leak = {"seed": 4, "effects": {"piston_leakage": {}}}
    write_recording(d / "leak.csv", run_offline(leak, random_steps(4, duration=4.0), 4.0))
    return d


def _cli(*args):
    import subprocess
    import sys
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=300)


def test_identify_judges_the_holdout_error_against_the_noise_floor(boom_runs):
    d = boom_runs
    r = _cli("identify", d / "fit1.csv", d / "fit2.csv", "--holdout", d / "hold.csv", "--holdout", d / "leak.csv",
             "--out", d / "out" / "params.json")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    hold = lines[[i for i, s in enumerate(lines) if s.startswith(f"holdout {d / 'hold.csv'}")][0] + 1]
    leak = lines[[i for i, s in enumerate(lines) if s.startswith(f"holdout {d / 'leak.csv'}")][0] + 1]
    assert "within the noise" in hold, r.stdout
    assert "large" in leak and "noise floor" in leak and "boomfmi diagnose" in leak, r.stdout
    doc = json.loads((d / "out" / "params.json").read_text())
    assert doc["holdout_gap"][str(d / "leak.csv")]["beyond_noise"] is True
    assert doc["holdout_gap"][str(d / "hold.csv")]["beyond_noise"] is False
    assert (d / "out" / "params.ssv").is_file() and (d / "out" / "params.png").is_file()   # nothing lost


def test_params_png_plots_each_fit_recording(boom_runs, monkeypatch):
    import matplotlib.figure
    from boomfmi import identify as identification
    from boomfmi.recording import read_recording
    d = boom_runs
    titles = []
    save = matplotlib.figure.Figure.savefig

    def spy(fig, *a, **kw):
        titles.extend(ax.get_title() for ax in fig.axes if ax.get_title())
        return save(fig, *a, **kw)
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", spy)
    result, recs, _ = identification.identify_recordings([d / "fit1.csv", d / "fit2.csv"])
    identification.write_outputs(result, recs, d / "png" / "params.json")
    assert any("fit1.csv" in t for t in titles) and any("fit2.csv" in t for t in titles), titles
    assert read_recording(d / "fit2.csv").data.shape[0] > 0
