"""Bad input, as a careful user and as an attacker would give it (issue 15): every case
gets a clear error naming the file, row, column or variable, leaves what was already
written as it was, or is refused.  The view server's cases are in test_hostile_view.py;
docs/reliability.md lists them all with their outcomes."""
from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from boomfmi.diagnose import diagnose
from boomfmi.diagnose import report as diagnosis_report
from boomfmi.experiments import paper_multistep, random_steps
from boomfmi.identify import identify_recordings, write_outputs
from boomfmi import identify as identification
from boomfmi.recording import RecordingError, check_plausible, read_recording, write_recording
from boomfmi.rig.offline import run_offline
from boomfmi.simulate import run_experiment
from boomfmi.system import FmuError
from boomfmi.system.ssv import SspError

ROOT = Path(__file__).resolve().parents[1]


def cli(*args, cwd=None, env=None, timeout=120):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A paper-experiment recording and variants of it that are wrong in one way each."""
    d = tmp_path_factory.mktemp("hostile")
    prof = paper_multistep()
    df = run_offline({"seed": 1}, prof, prof.duration)
    write_recording(d / "run.csv", df)
    shutil.copy(d / "run.csv", d / "copy.csv")
    bar = df.copy()
    bar["p_a"] /= 1e5
    bar["p_b"] /= 1e5
    write_recording(d / "bar.csv", bar)
    slow = df.copy()
    slow["t"] *= 10.0
    write_recording(d / "slow.csv", slow)
    ms = df.copy()
    ms["t"] *= 1e3
    write_recording(d / "ms.csv", ms)
    write_recording(d / "short.csv", df.iloc[:20])
    other = run_offline({"seed": 2}, random_steps(2, duration=4.0), 4.0)
    write_recording(d / "other.csv", other)
    return d


# ------------------------------------------------------------------- silent wrong results
def test_pressures_in_bar_are_refused_at_once_by_identify_and_diagnose(runs):
    t0 = time.monotonic()
    with pytest.raises(RecordingError, match=r"bar\.csv, column 'p_a': .*bar or kPa"):
        identify_recordings([runs / "bar.csv"])
    with pytest.raises(RecordingError, match="bar or kPa"):
        diagnose([runs / "bar.csv"], [runs / "other.csv"], runs / "diag_bar")
    assert time.monotonic() - t0 < 10.0
    assert not (runs / "diag_bar" / "diagnosis.json").exists()


def test_time_stretched_tenfold_gives_an_error_not_a_negative_mass(runs):
    proc = cli("identify", runs / "slow.csv", "--out", runs / "slow" / "params.json")
    assert proc.returncode == 1
    assert "no machine has such values" in proc.stderr and "0.1 times as fast" in proc.stderr
    assert not (runs / "slow" / "params.ssv").exists()


def test_time_in_milliseconds_is_named(runs):
    with pytest.raises(RecordingError, match=r"ms\.csv, column 't': .* milliseconds"):
        identify_recordings([runs / "ms.csv"])


def test_too_few_samples_are_refused_with_the_count(runs):
    for n in (1, 2, 20):
        write_recording(runs / f"rows{n}.csv", read_recording(runs / "run.csv").data.iloc[:n])
        with pytest.raises(RecordingError, match=rf"rows{n}\.csv: {n} samples: .*at least 100"):
            identify_recordings([runs / f"rows{n}.csv"])


def test_a_holdout_that_is_a_fit_recording_is_refused(runs):
    for hold in ("run.csv", "copy.csv"):
        proc = cli("identify", runs / "run.csv", "--holdout", runs / hold, "--out", runs / "h" / "params.json")
        assert proc.returncode == 1 and "not fitted on" in proc.stderr, proc.stderr
        with pytest.raises(ValueError, match="not fitted on"):
            diagnose([runs / "run.csv"], [runs / hold], runs / "diag_same")


def test_identification_warnings_reach_the_console_and_the_report(runs):
    proc = cli("identify", runs / "other.csv", "--out", runs / "w" / "params.json")
    doc = json.loads((runs / "w" / "params.json").read_text())
    for w in doc["warnings"]:
        assert f"warning: {w}" in proc.stdout
    html = diagnosis_report._html({"verdict": [], "baseline": {"params": {"M": 20.0}, "nrmse_holdout": {},
                                                               "warnings": ["the data cannot identify F_s"]}}, [])
    assert "the data cannot identify F_s" in html


def test_a_step_beyond_the_stable_bound_is_refused_with_the_bound(ssp_path):
    for step in (1.0, 10.0, 0.005):
        with pytest.raises(ValueError, match=r"beyond what the cylinder's coupling .* \(2\.12 ms"):
            run_experiment(ssp_path, "paper_multistep", step)
    assert len(run_experiment(ssp_path, "paper_multistep", 0.002, stop_time=0.1)) == 51


# ------------------------------------------------------------------------ wrong messages
def test_a_rejected_fmu_parameter_is_named_by_the_fmu_that_rejected_it(ssp_path):
    with pytest.raises(FmuError, match=r"valve: fmi2ExitInitializationMode returned fmi2Error: parameter A_max"):
        run_experiment(ssp_path, "paper_multistep", parameters=[{"valve.A_max": -1.0}])
    proc = cli("simulate", ssp_path, "--set", "valve.A_max=-1", "--out", "x.csv", cwd=ssp_path.parent)
    assert proc.returncode == 1 and "parameter A_max = -1" in proc.stderr and "logged no message" not in proc.stderr


def test_supply_below_exhaust_and_static_below_coulomb_friction_are_rejected(ssp_path):
    with pytest.raises(FmuError, match="valve: .*P_s = 90000.* above the exhaust pressure"):
        run_experiment(ssp_path, parameters=[{"valve.P_s": 9.0e4}], stop_time=0.01)
    with pytest.raises(FmuError, match="boom_load: .*F_s = 50.* at least the Coulomb force"):
        run_experiment(ssp_path, parameters=[{"boom_load.F_s": 50.0}], stop_time=0.01)


def test_a_cylinder_stroke_that_differs_from_the_booms_is_refused(ssp_path):
    with pytest.raises(SspError, match=r"cylinder\.L = 0\.05, boom_load\.L = 0\.06"):
        run_experiment(ssp_path, parameters=[{"cylinder.L": 0.05}], stop_time=0.01)


def test_a_byte_order_mark_is_read_and_invisible_characters_are_shown(tmp_path, runs):
    text = (runs / "run.csv").read_text()
    (tmp_path / "bom.csv").write_text("\ufeff" + text, encoding="utf-8")
    assert list(read_recording(tmp_path / "bom.csv").data.columns[:5]) == ["t", "u", "p_a", "p_b", "alpha"]
    (tmp_path / "zw.csv").write_text("\u200b" + text, encoding="utf-8")
    with pytest.raises(RecordingError, match=r"'\\u200bt'"):
        read_recording(tmp_path / "zw.csv")


def test_an_unknown_sidecar_key_is_refused(tmp_path, runs):
    shutil.copy(runs / "run.csv", tmp_path / "r.csv")
    (tmp_path / "r.json").write_text(json.dumps({"rig": {}, "rigg": {"b": 0.3}}))
    with pytest.raises(RecordingError, match=r"r\.json: unknown key 'rigg'; a sidecar may hold rig, notes"):
        read_recording(tmp_path / "r.csv")


def test_corrupt_and_foreign_fmus_get_a_clear_error(tmp_path, ssp_path, fmu):
    (tmp_path / "not.fmu").write_text("hello")
    proc = cli("describe", tmp_path / "not.fmu")
    assert proc.returncode == 1 and "not an FMU (not a zip archive" in proc.stderr and "Traceback" not in proc.stderr
    bad_dir = tmp_path / "fmus"
    bad_dir.mkdir()
    data = fmu("valve").read_bytes()
    (bad_dir / "valve.fmu").write_bytes(data[: len(data) // 2])
    proc = cli("check", bad_dir)
    assert proc.returncode == 1 and "valve.fmu" in proc.stderr + proc.stdout and "Traceback" not in proc.stderr
    empty = tmp_path / "empty"
    empty.mkdir()
    proc = cli("check", empty)
    assert proc.returncode == 1 and "no .fmu files" in proc.stderr
    with zipfile.ZipFile(ssp_path) as zin, zipfile.ZipFile(tmp_path / "bad.ssp", "w") as zout:
        for item in zin.infolist():
            body = zin.read(item.filename)
            zout.writestr(item, body[:100] if item.filename.endswith("valve.fmu") else body)
    with pytest.raises(ValueError, match=r"valve\.fmu: not an FMU"):
        run_experiment(tmp_path / "bad.ssp", stop_time=0.01)


def test_out_of_range_ports_and_watchdogs_are_refused_by_the_command_line(tmp_path):
    for args in (("rig", "serve", "--port", "70000"), ("rig", "serve", "--port", "-1"),
                 ("rig", "serve", "--port", "0", "--watchdog", "-1"),
                 ("rig", "serve", "--port", "0", "--watchdog", "nan")):
        proc = cli(*args, env={**os.environ, "BOOMFMI_LINK_KEY": "0" * 32}, timeout=30)
        assert proc.returncode == 2 and ("--port" in proc.stderr or "--watchdog" in proc.stderr), proc.stderr
        assert "Traceback" not in proc.stderr


# ------------------------------------------------------------------ outputs as one set
def test_an_interrupted_identification_leaves_the_previous_set(runs, monkeypatch):
    out = runs / "set" / "params.json"
    result, recs, _ = identify_recordings([runs / "run.csv"])
    first = write_outputs(result, recs, out)
    before = {p: Path(p).read_bytes() for p in first["written"]}
    assert len(before) == 3

    def interrupted(*args, **kw):
        raise KeyboardInterrupt
    monkeypatch.setattr(identification.outputs, "plot_fit", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_outputs(result, recs, out)
    assert {p: Path(p).read_bytes() for p in before} == before
    assert not [p for p in out.parent.iterdir() if ".partial-" in p.name]


def test_the_papers_method_does_not_claim_an_old_plot(runs):
    out = runs / "paper" / "params.json"
    out.parent.mkdir()
    out.with_suffix(".png").write_bytes(b"an old plot")
    proc = cli("identify", runs / "run.csv", "--method", "paper", "--out", out)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(out.read_text())
    assert not out.with_suffix(".png").exists() and "params.png" not in proc.stdout
    assert all(Path(p).exists() for p in doc["written"])
    if any(w.startswith("not physical") for w in doc["warnings"]):
        assert not out.with_suffix(".ssv").exists()


def test_an_interrupted_report_leaves_the_previous_diagnosis(tmp_path, monkeypatch):
    old = {"diagnosis.json": b"{}", "report.html": b"old", "overlay_x.png": b"old png",
           "residual_breakdown.png": b"old"}
    for name, body in old.items():
        (tmp_path / name).write_bytes(body)

    def interrupted(*args, **kw):
        raise KeyboardInterrupt
    monkeypatch.setattr(diagnosis_report, "_plots", interrupted)
    with pytest.raises(KeyboardInterrupt):
        diagnosis_report._write(tmp_path, {"verdict": []}, object(), None, None)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == old
    diagnosis_report._write(tmp_path, {"judgeable": False, "reason": "no motion", "verdict": []}, None, None, None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["diagnosis.json", "report.html"]


# ------------------------------------------------------------------------------ size
def test_a_recording_beyond_the_size_limit_is_refused_before_it_is_read(runs, monkeypatch):
    monkeypatch.setenv("BOOMFMI_MAX_RECORDING_MB", "0.1")
    t0 = time.monotonic()
    with pytest.raises(RecordingError, match=r"run\.csv: \d+ MiB is more than the 0 MiB .*BOOMFMI_MAX_RECORDING_MB"):
        read_recording(runs / "run.csv")
    assert time.monotonic() - t0 < 0.5


# --------------------------------------------------------------------- recording safely
def _silent_port():
    """A UDP port on loopback where nobody answers."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    return s


def test_record_against_a_rig_that_never_answers_leaves_an_existing_recording_alone(tmp_path, fmu):
    from boomfmi.record import record_experiment
    out = tmp_path / "run.csv"
    out.write_text("t,u,p_a,p_b,alpha\n0,5,0,0,1\n")
    out.with_suffix(".json").write_text('{"notes": "the good run"}')
    key = tmp_path / "key"
    key.write_text("ab" * 16)
    silent = _silent_port()
    try:
        with pytest.raises((FmuError, ValueError), match="no authenticated answer"):
            record_experiment(fmu("hardware_bridge"), f"udp://127.0.0.1:{silent.getsockname()[1]}", out,
                              key_file=str(key), timeout=0.05, stop_time=0.1)
    finally:
        silent.close()
    assert out.read_text() == "t,u,p_a,p_b,alpha\n0,5,0,0,1\n"
    assert out.with_suffix(".json").read_text() == '{"notes": "the good run"}'


def test_held_samples_are_not_taken_for_measurements(tmp_path, runs):
    df = read_recording(runs / "run.csv").data.copy()
    df["link_ok"] = 1.0
    df.loc[df.index[-50:], "link_ok"] = 0.0
    write_recording(tmp_path / "held.csv", df)
    with pytest.raises(RecordingError, match=r"50 samples were held .*link_ok = 0.*line \d+"):
        check_plausible(read_recording(tmp_path / "held.csv"))
