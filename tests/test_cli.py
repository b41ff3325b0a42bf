"""The boomfmi command."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from boomfmi.cli import main
from boomfmi.recording import read_recording, write_recording
from boomfmi.system.ssv import write_ssv


def test_simulate_writes_a_valid_recording_with_x_and_v(ssp_path, tmp_path, capsys):
    out = tmp_path / "result.csv"
    assert main(["simulate", str(ssp_path), "--experiment", "paper_multistep", "--stop", "2",
                 "--out", str(out)]) == 0
    rec = read_recording(out)
    assert list(rec.data.columns) == ["t", "u", "p_a", "p_b", "alpha", "x", "v"]
    assert len(rec.data) == 2001 and rec.data["t"].iloc[-1] == pytest.approx(2.0)
    assert rec.data["p_a"].iloc[0] == 0.0              # gauge
    assert rec.data["x"].iloc[-1] == pytest.approx(0.06)
    assert "wrote" in capsys.readouterr().out


def test_simulate_replays_a_recordings_command_with_parameters(ssp_path, tmp_path):
    t = np.round(np.arange(0, 1.0005, 1e-3), 6)
    run = pd.DataFrame({"t": t, "u": np.where(t < 0.3, 10.0, 2.5), "p_a": 0.0, "p_b": 0.0, "alpha": 0.634})
    write_recording(tmp_path / "run.csv", run)
    params = write_ssv(tmp_path / "params.ssv", "p", {"boom_load.M": (30.0, "kg")})
    out = tmp_path / "model.csv"
    assert main(["simulate", str(ssp_path), "--experiment", str(tmp_path / "run.csv"),
                 "--params", str(params), "--algorithm", "jacobi", "--out", str(out)]) == 0
    model = read_recording(out).data
    np.testing.assert_array_equal(model["u"], run["u"])
    assert model["t"].iloc[-1] == pytest.approx(1.0)


@pytest.mark.parametrize("args, message", [
    (["simulate", "nowhere.ssp", "--out", "x.csv"], "nowhere.ssp: no such SSP file"),
    (["simulate", "{ssp}", "--experiment", "wobble", "--out", "x.csv"], "unknown experiment 'wobble'"),
    (["simulate", "{ssp}", "--experiment", "{bad}", "--out", "x.csv"], "bad.csv, line 1, column 'u': missing required column"),
    (["simulate", "{ssp}", "--stop", "0.01", "--out", "."], "Is a directory"),
])
def test_bad_input_is_a_one_line_error(ssp_path, tmp_path, args, message):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,p_a,p_b,alpha\n0,0,0,0.6\n")
    args = [a.format(ssp=ssp_path, bad=bad) for a in args]
    proc = subprocess.run([sys.executable, "-m", "boomfmi.cli", *args], cwd=tmp_path,
                          capture_output=True, text=True)
    assert proc.returncode == 1
    assert message in proc.stderr and "Traceback" not in proc.stderr


def test_a_recordings_sidecar_reaches_the_model(ssp_path, tmp_path):
    """A supply pressure of 5 bar in the sidecar: the simulated chamber fills to 5 bar."""
    t = np.round(np.arange(0, 1.5005, 1e-3), 6)
    run = pd.DataFrame({"t": t, "u": np.where(t < 0.5, 10.0, 1.0), "p_a": 0.0, "p_b": 0.0, "alpha": 0.634})
    write_recording(tmp_path / "run.csv", run, sidecar={"rig": {"supply_pressure_gauge": 5.0e5}})
    out = tmp_path / "model.csv"
    assert main(["simulate", str(ssp_path), "--experiment", str(tmp_path / "run.csv"), "--out", str(out)]) == 0
    assert read_recording(out).data["p_a"].iloc[-1] == pytest.approx(5.0e5, rel=5e-3)   # not 6 bar


def test_simulate_teleoperation_replay_with_a_parameter_set_on_the_command_line(ssp_path, tmp_path):
    """--replay plays the experiment's recording through the bridge, the model starting
    where it starts; --set picks the paper's estimator (an integer given for a real)."""
    from boomfmi.experiments import held
    from boomfmi.rig.offline import run_offline
    prof = held([(0.2, 5.0), (0.3, 3.5)])
    run = write_recording(tmp_path / "run.csv", run_offline({"x0": 0.02, "seed": 1}, prof, prof.duration))
    out = tmp_path / "tele.csv"
    assert main(["simulate", str(ssp_path.parent / "teleoperation.ssp"), "--experiment", str(run), "--replay",
                 "--set", "force_estimator.method=position_error", "--set", "force_estimator.K_p=20000",
                 "--out", str(out)]) == 0
    got = pd.read_csv(out, comment="#")
    assert {"x_measured", "f_ext", "f_est", "f_reflect"} <= set(got.columns)
    assert got["x"].iloc[0] == pytest.approx(got["x_measured"].iloc[0], abs=1e-4)
    assert np.all(got["link_ok"].iloc[:-1])
    assert main(["simulate", str(ssp_path.parent / "teleoperation.ssp"), "--experiment", "dig", "--replay",
                 "--out", str(out)]) == 1            # --replay needs a recording: a one-line error
