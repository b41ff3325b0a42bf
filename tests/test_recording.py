"""The recording reader enforces recording-format.md; every rejection names the file,
the line and the column.  The writer is crash-safe."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from boomfmi.recording import RecordingError, read_recording, write_recording

GOOD = "t,u,p_a,p_b,alpha\n0.000,10,0,600000,0.634\n0.001,10,1.5,599000,0.634\n0.002,1.0,30000,580000,0.635\n"


def write(tmp_path, text, name="run.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_a_valid_recording_and_keeps_every_row(tmp_path):
    rec = read_recording(write(tmp_path, GOOD.replace("alpha\n", "alpha,operator\n", 1)
                               .replace("0.634\n", "0.634,ann\n").replace("0.635\n", "0.635,bob\n")))
    assert list(rec.data.columns) == ["t", "u", "p_a", "p_b", "alpha", "operator"]
    assert len(rec.data) == 3 and rec.data["u"].iloc[2] == 1.0
    assert rec.P_atm == 101325.0


def test_sidecar_overrides_the_rig(tmp_path):
    path = write(tmp_path, GOOD)
    path.with_suffix(".json").write_text(json.dumps({"rig": {"supply_pressure_gauge": 650000}, "notes": "cold day"}))
    rec = read_recording(path)
    assert rec.rig == {"supply_pressure_gauge": 650000} and rec.notes == "cold day"
    assert rec.rig_values() == {"P_s": 101325.0 + 650000}
    path.with_suffix(".json").write_text(json.dumps({"rig": {"suply_pressure": 6e5}}))
    with pytest.raises(RecordingError, match="run.json: unknown rig value 'suply_pressure'"):
        read_recording(path)


BAD = [
    ("missing column", "t,u,p_a,alpha\n0,5,0,0.6\n", 1, "p_b", "missing required column"),
    ("text in a number", GOOD.replace("1.5", "abc"), 3, "p_a", "'abc' is not a number"),
    ("NaN", GOOD.replace("599000", "nan"), 3, "p_b", "is not a finite number"),
    ("time going backwards", GOOD.replace("0.002,", "0.0005,"), 4, "t", "time does not increase"),
    ("empty file", "", 1, None, "empty file"),
    ("header only", "t,u,p_a,p_b,alpha\n", 2, None, "no samples"),
    ("command out of range", GOOD.replace("0.001,10,", "0.001,10.5,"), 3, "u", "outside 0 to 10 V"),
    ("wrong delimiter", GOOD.replace(",", ";"), 1, None, "separated by ';'"),
    ("pressure below vacuum", GOOD.replace("1.5", "-200000"), 3, "p_a", "below -P_atm"),
    ("short row", GOOD.replace("0.001,10,1.5,599000,0.634", "0.001,10,1.5,599000"), 3, None, "4 fields"),
]


@pytest.mark.parametrize("case, text, line, column, message", BAD, ids=[b[0] for b in BAD])
def test_rejections_name_file_line_and_column(tmp_path, case, text, line, column, message):
    path = write(tmp_path, text)
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    e = err.value
    assert e.path == path and e.row == line and e.column == column
    assert str(path) in str(e) and f"line {line}" in str(e) and message in str(e)
    if column:
        assert f"column '{column}'" in str(e)


def test_missing_file_and_bad_sidecar(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        read_recording(tmp_path / "none.csv")
    path = write(tmp_path, GOOD)
    path.with_suffix(".json").write_text("{not json")
    with pytest.raises(RecordingError, match="run.json: the sidecar is not valid JSON"):
        read_recording(path)


def test_write_then_read_round_trips(tmp_path):
    rec = read_recording(write(tmp_path, GOOD))
    out = write_recording(tmp_path / "copy.csv", rec.data, sidecar={"notes": "copy"})
    again = read_recording(out)
    np.testing.assert_array_equal(again.data.to_numpy(dtype=float), rec.data.to_numpy(dtype=float))
    assert again.notes == "copy"


def test_a_killed_writer_leaves_only_complete_rows(tmp_path):
    path = tmp_path / "killed.csv"
    code = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(tmp_path)!r})
        from boomfmi.recording import RecordingWriter
        w = RecordingWriter({str(path)!r})
        k = 0
        while True:
            w.write([k * 1e-3, 5.0, 1000.0 * k, 2000.0, 0.634])
            k += 1
            if k == 200:
                print("ready", flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    text = path.read_text()
    complete = text[: text.rfind("\n") + 1]
    rec = read_recording(write(tmp_path, complete, "complete.csv"))
    assert len(rec.data) >= 200
    assert text.endswith("\n"), "each row goes out in one write: the kill leaves no half row"
