"""Issue 31's readers (cases 13, 14, 18, 19, 20, 22): the one recording reader's
plausibility checks in every command that reads a recording, holdouts that overlap a fit
recording, fit recordings given twice, the units of a bench file's map, and Ctrl-C.

Each test asserts the clear error (or the refusal) and that nothing was lost: no output
written, an earlier one left as it was."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi.cli import main
from boomfmi.recording import read_recording, shared_run, write_recording

KEY = "a shared key of more than sixteen bytes"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two short recordings of the virtual rig (fit and holdout) and hostile versions
    of the fit one: cut short, one sample 1 Pa off, a copy with fewer digits, time in
    milliseconds, alpha in degrees."""
    from boomfmi.experiments import random_steps
    from boomfmi.rig.offline import run_offline
    d = tmp_path_factory.mktemp("readers")
    fit, hold = random_steps(3, duration=4.0), random_steps(4, duration=4.0)
    write_recording(d / "fit.csv", run_offline({"seed": 5}, fit, fit.duration))
    write_recording(d / "hold.csv", run_offline({"seed": 6}, hold, hold.duration))
    data = pd.read_csv(d / "fit.csv")
    data.iloc[:-1000].to_csv(d / "cut.csv", index=False)
    one = data.copy()
    one.loc[2000, "p_a"] += 1.0
    one.to_csv(d / "one_pa.csv", index=False)
    data.to_csv(d / "copy.csv", index=False, float_format="%.10g")
    (d / "same.csv").write_bytes((d / "fit.csv").read_bytes())
    data.assign(t=data["t"] * 1000.0).to_csv(d / "ms.csv", index=False)
    data.assign(alpha=np.degrees(data["alpha"])).to_csv(d / "deg.csv", index=False)
    return d


def _run(capsys, *args):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _earlier(folder: Path) -> dict:
    """An earlier run's params.json in ``folder``: its bytes, to check it is left alone."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "params.json").write_text('{"earlier": true}')
    return {"params.json": b'{"earlier": true}'}


def _unchanged(folder: Path, before: dict) -> None:
    assert sorted(p.name for p in folder.iterdir()) == sorted(before)
    for name, content in before.items():
        assert (folder / name).read_bytes() == content


# --- 13: a holdout that overlaps a fit recording -------------------------------------

@pytest.mark.parametrize("holdout, lines", [("cut.csv", "lines 2 to 3002"), ("one_pa.csv", "lines 2 to 2001")])
def test_13_a_holdout_that_is_part_of_a_fit_recording_is_refused(runs, capsys, holdout, lines):
    out = runs / f"out13_{holdout}"
    before = _earlier(out)
    code, _, err = _run(capsys, "identify", runs / "fit.csv", "--holdout", runs / holdout, "--out", out / "params.json")
    assert code == 1
    assert f"holdout {runs / holdout} shares" in err and f"consecutive samples with {runs / 'fit.csv'}" in err
    assert f"its {lines} are" in err and "a holdout must be a recording that is not fitted on" in err
    _unchanged(out, before)
    code, _, err = _run(capsys, "diagnose", runs / "fit.csv", "--holdout", runs / holdout, "--out", out)
    assert code == 1 and f"holdout {runs / holdout} shares" in err
    _unchanged(out, before)


def test_13_recordings_of_their_own_share_no_run(runs):
    fit, hold = read_recording(runs / "fit.csv"), read_recording(runs / "hold.csv")
    assert shared_run(fit, hold) is None
    assert shared_run(fit, read_recording(runs / "one_pa.csv"))[0] == 2000


# --- 14: a fit recording given twice ---------------------------------------------------

@pytest.mark.parametrize("second, message", [
    ("fit.csv", "fit.csv is given twice as a fit recording"),
    ("same.csv", "same.csv holds the same samples as"),      # a copy beside it
    ("copy.csv", "copy.csv shares 4001 consecutive samples with"),   # written with 10 digits: equal once quantised
    ("cut.csv", "cut.csv shares 3001 consecutive samples with"),
])
def test_14_a_recording_given_twice_is_refused(runs, capsys, second, message):
    out = runs / f"out14_{second}"
    before = _earlier(out)
    code, _, err = _run(capsys, "identify", runs / "fit.csv", runs / second, "--out", out / "params.json")
    assert code == 1 and message in err and "Traceback" not in err
    assert second == "fit.csv" or "would count" in err
    _unchanged(out, before)
    code, _, err = _run(capsys, "diagnose", runs / "fit.csv", runs / second, "--holdout", runs / "hold.csv",
                        "--out", out)
    assert code == 1 and message in err
    _unchanged(out, before)


# --- 18: one reader: simulate's experiment gets the same checks -----------------------

def test_18_simulate_refuses_an_experiment_in_milliseconds_as_identify_does(runs, capsys, ssp_path):
    result = runs / "sim18.csv"
    result.write_text("earlier\n")
    message = "column 't': the samples are 1 s apart (median): t must be in seconds"
    for extra in ([], ["--replay"]):
        ssp = ssp_path if not extra else ssp_path.parent / "teleoperation.ssp"
        t0 = time.monotonic()
        code, _, err = _run(capsys, "simulate", ssp, "--experiment", runs / "ms.csv", *extra, "--out", result)
        assert code == 1 and message in err and "is it in milliseconds?" in err
        assert time.monotonic() - t0 < 20                # refused at once, not 9000 s simulated
        assert result.read_text() == "earlier\n"
    code, _, err = _run(capsys, "identify", runs / "ms.csv", "--out", runs / "o18" / "params.json")
    assert code == 1 and message in err and not (runs / "o18").exists()


# --- 19: alpha in degrees --------------------------------------------------------------

def test_19_an_angle_beyond_the_booms_range_is_named_as_degrees(runs, capsys, ssp_path, tmp_path):
    for args in (["identify", runs / "deg.csv", "--out", tmp_path / "o" / "params.json"],
                 ["diagnose", runs / "deg.csv", "--holdout", runs / "hold.csv", "--out", tmp_path / "o"],
                 ["simulate", ssp_path.parent / "teleoperation.ssp", "--experiment", runs / "deg.csv", "--replay",
                  "--out", tmp_path / "o" / "sim.csv"]):
        code, _, err = _run(capsys, *args)
        assert code == 1, err
        assert "deg.csv, line 2, column 'alpha': the boom angle 36.34" in err
        assert "lies outside its physical range, 0.6342 to 1.048 rad" in err and "is it in degrees" in err
        assert "DLASCL" not in err and "SVD" not in err and not (tmp_path / "o").exists()
    # the same data imported with alpha taken for radians: the import converts, identify names it
    src = tmp_path / "daq.csv"
    pd.read_csv(runs / "deg.csv").to_csv(src, index=False, header=False)
    rec = tmp_path / "imported.csv"
    assert _run(capsys, "recording", "import", src, "--delimiter", "comma", "--map",
                "t=1:s,u=2:V,p_a_gauge=3:Pa,p_b_gauge=4:Pa,alpha=5:rad", "--out", rec)[0] == 0
    code, _, err = _run(capsys, "identify", rec, "--out", tmp_path / "o" / "params.json")
    assert code == 1 and "imported.csv, line 2, column 'alpha'" in err and "is it in degrees" in err


# --- 20: the bench's maps --------------------------------------------------------------

def _friction_test(path: Path, p_bar: float, seed: int, sign: float = 1.0) -> Path:
    """A friction test in the zillen2021 layout (tab separated, t ms, x mm, p bar, F N):
    a rod stroked over 35 mm at 10 to 16 mm/s, Eq. 9's friction (F_d 4 N, K_v 200 N s/m)
    plus noise; ``sign`` -1: a load cell that reads the force the other way."""
    rng = np.random.default_rng(seed)
    dt, parts, prev = 0.01, [], -0.01
    for k in range(8):
        d = 1 if k % 2 == 0 else -1
        speed = rng.uniform(0.010, 0.016)
        parts += [np.linspace(prev, d * speed, 11)[1:], np.full(int(0.033 / speed / dt), d * speed)]
        prev = d * speed
    v = np.concatenate([np.zeros(15), *parts])
    n = len(v)
    t, x = np.arange(n) * dt, np.cumsum(v) * dt + 0.001 + rng.normal(0, 1.5e-5, n)
    p = p_bar * 1e5 - 3e3 * np.sign(v) + rng.normal(0, 200.0, n)
    F = sign * (p * 4.95e-4 + 1.5 + 4.0 * np.sign(v) + 200.0 * v + rng.normal(0, 0.3, n))
    cols = np.column_stack([1e3 * t, np.full(n, 3.5), np.full(n, 1.5), np.full(n, 3.2), 1e3 * x, p / 1e5, F])
    path.write_text("\n".join("\t".join(f"{c:.5f}" for c in row) for row in cols) + "\n")
    return path


@pytest.mark.parametrize("mapping, sign, message, hint", [
    ("t=1:ms,x=5:m,p_gauge=6:bar,F=7:N", 1.0, "column '5': the rod travels 34 m at up to 15.5 m/s: a cylinder's rod "
                                              "moves at most a few m/s", "is x in mm where the map says otherwise? "
                                              "Give its unit in --map (map entry 'x=5:m', e.g. x=COLUMN:mm)"),
    ("t=1:ms,x=6:mm,p_gauge=5:bar,F=7:N", 1.0, "column '6': the rod travels 0.0", "does the map's x (map entry "
                                               "'x=6:mm') name the position's column, not the pressure's (x and p "
                                               "swapped?)"),
    ("t=1:s,x=5:mm,p_gauge=6:bar,F=7:N", 1.0, "column '1': the samples are 10 s apart (median), and a friction "
                                              "test's are 1e-06 to 1 s apart", "(map entry 't=1:s'), e.g. t=COLUMN:ms"),
    ("t=1:ms,x=5:mm,p_gauge=6:bar,F=7:N", -1.0, "negative friction (eq9: F_s_", "a friction cannot be negative"),
])
def test_20_a_friction_map_that_cannot_be_the_files_is_named(tmp_path, capsys, mapping, sign, message, hint):
    files = [_friction_test(tmp_path / f"f{i}.csv", p, 30 + i, sign) for i, p in enumerate((3, 5, 4))]
    out = tmp_path / "out"
    code, _, err = _run(capsys, "bench", "friction", files[0], files[1], "--holdout", files[2], "--area", "490.9 mm^2",
                        "--map", mapping, "--n-boot", "10", "--out", out)
    assert code == 1 and message in err and hint in err, err
    assert "Traceback" not in err and not out.exists()


def _leak_file(path: Path) -> Path:
    """A leak-down run in the zillen2021-leak layout: ';' separated, t in us written
    with '.' between thousands (``1.000.000``), the gauge pressure in bar, 0.1 s apart."""
    k = np.arange(1500)
    p = 1.0 + 6.3 * np.exp(-k * 0.1 / 3000.0)
    rows = [f"{f'{100000 * i:,}'.replace(',', '.')};{v:.4f};7.315" for i, v in zip(k, p)]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_20_a_leak_runs_time_unit_and_thousands_are_named(tmp_path, capsys):
    run = _leak_file(tmp_path / "leak.csv")
    out = tmp_path / "out"
    base = ["bench", "leak", run, "--volume", "0.5 L", "--delimiter", "semicolon", "--out", out]
    code, _, err = _run(capsys, *base, "--map", "t=1:s,p_gauge=2:bar", "--thousands", "t=.")
    assert code == 1 and "column '1': the samples are 100000 s apart (median)" in err
    assert "(map entry 't=1:s')" in err and not out.exists()
    code, _, err = _run(capsys, *base, "--map", "t=1:us,p_gauge=2:bar")
    assert code == 1 and "line 11, column '1': '1.000.000' is not a number (digits grouped by '.': thousands " \
                         "separators? give --thousands ., or --thousands t=. for this column only)" in err
    assert not out.exists()
    code, got, err = _run(capsys, *base, "--map", "t=1:us,p_gauge=2:bar", "--thousands", "t=.")
    assert code == 0 and "in 150 s" in got, err                      # the same file with the right map


# --- 22: Ctrl-C ----------------------------------------------------------------------

def test_22_every_command_says_interrupted_with_no_traceback(runs, capsys, monkeypatch):
    import boomfmi.identify

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(boomfmi.identify, "identify_recordings", interrupted)
    code, _, err = _run(capsys, "identify", runs / "fit.csv", "--out", runs / "o22" / "params.json")
    assert code == 130 and err.strip() == "boomfmi identify: interrupted"
    assert not (runs / "o22").exists()


def test_22_sigint_during_record_marks_it_interrupted(tmp_path, fmu):
    env = dict(os.environ, BOOMFMI_LINK_KEY=KEY)
    rig = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0", "--lockstep"],
                           env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = re.search(r"udp://127\.0\.0\.1:(\d+)", rig.stdout.readline()).group(1)
        out = tmp_path / "run.csv"
        rec = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "record", "--rig", f"udp://127.0.0.1:{port}",
                                "--fmu", str(fmu("hardware_bridge")), "--out", str(out)],
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        t0 = time.monotonic()
        while time.monotonic() - t0 < 60 and (not out.exists() or out.read_text().count("\n") < 100):
            time.sleep(0.05)
        rec.send_signal(signal.SIGINT)
        _, err = rec.communicate(timeout=60)
    finally:
        rig.send_signal(signal.SIGTERM)
        rig.communicate(timeout=10)
    assert rec.returncode == 130 and err.strip() == "boomfmi record: interrupted", err
    side = json.loads(out.with_suffix(".json").read_text())
    assert re.fullmatch(r"interrupted at t = [0-9.]+ s \(Ctrl-C or SIGINT\)", side["incomplete"])
    assert len(read_recording(out).data) >= 100                # the rows received are kept


def test_22_sigint_during_campaign_says_interrupted(runs, tmp_path):
    manifest = tmp_path / "manifest.csv"
    manifest.write_text(f"machine,date,role,recording\nA,2025-01-06,fit,{runs / 'fit.csv'}\n"
                        f"A,2025-01-06,holdout,{runs / 'hold.csv'}\n")
    # as a terminal's foreground job gets it: SIGINT at its default (a job started in the
    # background of a non-interactive shell inherits it ignored, as POSIX has it, and
    # Python then installs no KeyboardInterrupt: the suite run that way saw the case end)
    proc = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "campaign", str(manifest), "--out",
                             str(tmp_path / "camp"), "--workers", "1"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen = []
    started = threading.Event()

    def read():
        while chunk := proc.stderr.read(1):
            seen.append(chunk)
            if "cases" in "".join(seen[-200:]):
                started.set()
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    assert started.wait(90), "".join(seen)
    time.sleep(1.0)
    os.killpg(proc.pid, signal.SIGINT)                 # Ctrl-C: the whole process group
    proc.wait(timeout=90)
    reader.join(timeout=10)
    err = "".join(seen)
    assert proc.returncode == 130, err
    assert err.rstrip().endswith("boomfmi campaign: interrupted") and "Traceback" not in err
    assert "KeyboardInterrupt" not in err
