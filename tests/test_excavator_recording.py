"""The excavator's recording format (shared/spec/excavator.md): the same reader, checks
and crash-safe writer as the boom's, with the columns suffixed per joint; every
rejection names the file, the line and the column, and a boom-only recording stays
valid."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest

from boomfmi.recording import (EXCAVATOR_OPTIONAL, EXCAVATOR_REQUIRED, JOINTS, RecordingError, RecordingWriter,
                               check_plausible, read_recording, recording_kind, write_recording)

HEADER = ",".join(EXCAVATOR_REQUIRED)


def row(t, u=5.0, p_a=2e5, p_b=3e5, angles=(0.1, 0.7, -1.2, -0.5)):
    return ",".join(str(v) for v in (t, *[u] * 4, *[p_a] * 4, *[p_b] * 4, *angles))


GOOD = "\n".join([HEADER, row(0.0), row(0.001, u=7.5), row(0.002, u=2.0)]) + "\n"


def write(tmp_path, text, name="run.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def frame(n=400, **over) -> pd.DataFrame:
    t = np.arange(n) * 1e-3
    d = {"t": t}
    for k, j in enumerate(JOINTS):
        d[f"u_{j}"] = 5.0 + 2.0 * np.sin(2 * np.pi * t + k)
        d[f"p_a_{j}"] = 2e5 + 1e5 * np.sin(3 * t + k)
        d[f"p_b_{j}"] = 3e5 - 1e5 * np.sin(3 * t + k)
        d[f"angle_{j}"] = 0.3 * np.sin(t + k)
    d.update(over)
    return pd.DataFrame(d)


def test_the_columns_are_the_spec_s():
    assert JOINTS == ("swing", "boom", "arm", "bucket")
    assert EXCAVATOR_REQUIRED[0] == "t" and len(EXCAVATOR_REQUIRED) == 17
    for j in JOINTS:
        for q in ("u", "p_a", "p_b", "angle"):
            assert f"{q}_{j}" in EXCAVATOR_REQUIRED
    assert {"f_tip_x", "f_tip_y", "f_tip_z"} <= set(EXCAVATOR_OPTIONAL)


def test_reads_an_excavator_recording_and_keeps_every_row_and_column(tmp_path):
    text = GOOD.replace(HEADER, HEADER + ",f_tip_x,f_tip_y,f_tip_z,operator", 1)
    lines = text.splitlines()
    text = "\n".join([lines[0]] + [line + f",1.5,-2,{30 + i},ann" for i, line in enumerate(lines[1:])]) + "\n"
    rec = read_recording(write(tmp_path, text))
    assert rec.kind == "excavator" and recording_kind(rec.path) == "excavator"
    assert list(rec.data.columns) == [*EXCAVATOR_REQUIRED, "f_tip_x", "f_tip_y", "f_tip_z", "operator"]
    assert len(rec.data) == 3 and rec.data["u_arm"].iloc[1] == 7.5 and rec.data["f_tip_z"].iloc[2] == 32.0
    assert rec.data["angle_bucket"].iloc[0] == -0.5 and list(rec.data["operator"]) == ["ann"] * 3


def test_which_kind_a_recording_is(tmp_path):
    boom = write(tmp_path, "t,u,p_a,p_b,alpha\n0,5,0,0,0.6\n", "boom.csv")
    assert recording_kind(boom) == "boom" and read_recording(boom).kind == "boom"
    assert recording_kind(["t", "u", "p_a", "p_b", "alpha", "x"]) == "boom"
    assert recording_kind(EXCAVATOR_REQUIRED) == "excavator"
    assert recording_kind(["t", "angle_arm"]) == "excavator"      # and then the reader wants the rest
    with pytest.raises(RecordingError, match=r"nothing\.csv: no such file"):
        recording_kind(tmp_path / "nothing.csv")
    with pytest.raises(RecordingError, match=r"empty\.csv, line 1: empty file"):
        recording_kind(write(tmp_path, "", "empty.csv"))


def test_a_boom_recording_stays_valid_beside_an_excavator_column_named_alike(tmp_path):
    rec = read_recording(write(tmp_path, "t,u,p_a,p_b,alpha,u_ref\n0,5,0,0,0.6,1\n0.001,5,0,0,0.6,2\n"))
    assert rec.kind == "boom" and list(rec.data["u_ref"]) == [1.0, 2.0]


BAD = [
    ("missing column", GOOD.replace(",p_b_arm", "", 1), 1, "p_b_arm",
     "missing required column of an excavator recording"),
    ("text in a number", GOOD.replace(row(0.001, u=7.5), row(0.001, u=7.5).replace("-1.2", "abc", 1)), 3,
     "angle_arm", "'abc' is not a number"),
    ("NaN", GOOD.replace(row(0.002, u=2.0), row(0.002, u=2.0).replace("-0.5", "nan")), 4, "angle_bucket",
     "is not a finite number"),
    ("time going backwards", GOOD.replace(row(0.002, u=2.0), row(0.0005, u=2.0)), 4, "t", "time does not increase"),
    ("command out of range", GOOD.replace(row(0.001, u=7.5), row(0.001, u=7.5).replace("7.5", "10.5", 1)), 3,
     "u_swing", "outside 0 to 10 V"),
    ("bucket command out of range", GOOD.replace(row(0.001, u=7.5),
                                                 "0.001,7.5,7.5,7.5,-0.2," + row(0.001).split(",", 5)[5]), 3,
     "u_bucket", "-0.2 V lies outside 0 to 10 V"),
    ("pressure below vacuum", GOOD.replace(row(0.001, u=7.5), row(0.001, u=7.5, p_b=-2e5)), 3, "p_b_swing",
     "below -P_atm"),
    ("short row", GOOD.replace(row(0.001, u=7.5), row(0.001, u=7.5).rsplit(",", 1)[0]), 3, None, "16 fields"),
    ("duplicated column", GOOD.replace(HEADER, HEADER + ",u_arm").replace("\n0", ",5\n0"), 1, "u_arm",
     "appears twice"),
    ("header only", HEADER + "\n", 2, None, "no samples"),
]


@pytest.mark.parametrize("case, text, line, column, message", BAD, ids=[b[0] for b in BAD])
def test_rejections_name_file_line_and_column(tmp_path, case, text, line, column, message):
    path = write(tmp_path, text)
    with pytest.raises(RecordingError) as e:
        read_recording(path)
    err = e.value
    assert message in str(err)
    assert err.row == line and err.column == column
    assert str(err).startswith(f"{path}, line {line}" + (f", column {column!r}" if column else ""))


def test_the_command_line_names_the_fault_without_a_traceback(tmp_path):
    path = write(tmp_path, GOOD.replace(",p_b_arm", "", 1))
    out = subprocess.run([sys.executable, "-m", "boomfmi.cli", "view", "--replay", str(path), "--port", "0"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert "run.csv, line 1, column 'p_b_arm': missing required column of an excavator recording" in out.stderr


PLAUSIBLE = [
    ("too few samples", dict(n=50), None, "50 samples"),
    ("time in milliseconds", dict(t=np.arange(400) * 1.0), "t", "is it in milliseconds"),
    ("one joint's pressures in bar", dict(p_a_arm=np.full(400, 2.0), p_b_arm=np.full(400, 3.0)), "p_a_arm",
     "are they in bar or kPa"),
    ("one joint's pressures beyond the supply", dict(p_b_bucket=np.full(400, 5e6)), "p_a_bucket",
     "beyond the supply"),
    ("angles in degrees", dict(angle_boom=np.linspace(30.0, 40.0, 400)), "angle_boom", "is it in degrees"),
]


@pytest.mark.parametrize("case, over, column, message", PLAUSIBLE, ids=[p[0] for p in PLAUSIBLE])
def test_implausible_excavator_recordings_are_refused(tmp_path, case, over, column, message):
    over = dict(over)
    n = over.pop("n", 400)
    path = write_recording(tmp_path / "run.csv", frame(n, **over) if n == 400 else frame(n))
    rec = read_recording(path)
    with pytest.raises(RecordingError) as e:
        check_plausible(rec)
    assert message in str(e.value) and e.value.column == column and "run.csv" in str(e.value)


def test_a_plausible_excavator_recording_passes(tmp_path):
    rec = read_recording(write_recording(tmp_path / "run.csv", frame()))
    check_plausible(rec)
    assert rec.kind == "excavator"


def test_write_puts_the_required_columns_first_and_reads_back_exactly(tmp_path):
    d = frame(120)
    d["f_tip_z"] = np.linspace(0, 40, 120)
    d = d[["f_tip_z"] + list(reversed(EXCAVATOR_REQUIRED))]
    path = write_recording(tmp_path / "run.csv", d, sidecar={"notes": "digging"})
    rec = read_recording(path)
    assert list(rec.data.columns) == [*EXCAVATOR_REQUIRED, "f_tip_z"] and rec.notes == "digging"
    pd.testing.assert_frame_equal(rec.data, d[list(rec.data.columns)])


def test_the_writer_wants_every_joint_s_columns(tmp_path):
    with pytest.raises(ValueError, match=r"a recording needs column 'angle_bucket' \(an excavator's"):
        RecordingWriter(tmp_path / "run.csv", [c for c in EXCAVATOR_REQUIRED if c != "angle_bucket"])
    with pytest.raises(ValueError, match="columns must be distinct"):
        RecordingWriter(tmp_path / "run.csv", [*EXCAVATOR_REQUIRED, "u_arm"])


def test_the_writer_is_crash_safe(tmp_path):
    """A writer killed mid-run leaves a file whose every row is complete, and it reads."""
    path = tmp_path / "run.csv"
    script = textwrap.dedent(f"""
        import sys, time
        from boomfmi.recording import RecordingWriter, EXCAVATOR_REQUIRED
        w = RecordingWriter({str(path)!r}, EXCAVATOR_REQUIRED)
        i = 0
        while True:
            w.write([i * 1e-3] + [5.0] * 4 + [2e5] * 8 + [0.1, 0.7, -1.2, -0.5])
            i += 1
            if i == 200:
                print("ready", flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    rec = read_recording(path)
    assert len(rec.data) >= 200 and rec.kind == "excavator"
    assert np.allclose(np.diff(rec.data["t"]), 1e-3)
