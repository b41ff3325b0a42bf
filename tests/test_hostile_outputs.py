"""Nothing overwritten, nothing half-written (issue 31, cases 5 to 8): an output that is
an input is refused; ``record``'s step and stop are checked before anything is opened
and a failed run never replaces an existing recording; every file being written is
locked against a second writer (by its name or through a link); an output set is all
new or all old in every failure, and a killed run's ``.partial-PID`` files are removed
by the next run.  docs/reliability.md lists them with their outcomes (R2-5 to R2-8)."""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from boomfmi import outputs
from boomfmi.diagnose import report as diagnosis_report
from boomfmi.outputs import OutputError, OutputSet
from boomfmi.recording import RecordingWriter, read_recording, write_recording

KEY = "a shared key of more than sixteen bytes"


def cli(*args, cwd=None, timeout=120):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=dict(os.environ, BOOMFMI_LINK_KEY=KEY))


def snapshot(folder: Path) -> dict:
    """Every entry of ``folder`` (recursively): a file's bytes, a link's target, a folder."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        out[rel] = ("link", os.readlink(p)) if p.is_symlink() else ("dir",) if p.is_dir() else p.read_bytes()
    return out


@pytest.fixture(scope="module")
def motion():
    """Two seconds of the virtual rig's steps: enough motion to identify on."""
    from boomfmi.experiments import random_steps
    from boomfmi.rig.offline import run_offline
    return run_offline({"seed": 1}, random_steps(1, duration=2.0), 2.0)


@pytest.fixture
def recording(tmp_path, motion) -> Path:
    """A valid recording (that identify would get through) with a sidecar."""
    return write_recording(tmp_path / "r.csv", motion, sidecar={"notes": "the good run"})


class Rig:
    """``boomfmi rig serve --lockstep`` in a subprocess on a free loopback port."""

    def __init__(self, record: Path | None = None):
        args = [sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0", "--lockstep"]
        args += ["--record", str(record)] if record else []
        self.proc = subprocess.Popen(args, env=dict(os.environ, BOOMFMI_LINK_KEY=KEY), stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        match = re.search(r"udp://127\.0\.0\.1:(\d+)", line)
        assert match, line + self.proc.stderr.read()
        self.url = f"udp://127.0.0.1:{match.group(1)}"

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        self.proc.communicate(timeout=10)

    def kill_once(self, folder: Path, pattern: str) -> threading.Thread:
        """Kill the rig (mid-run) once a file matching ``pattern`` is in ``folder``: the
        recorder has had the rig's answer and writes rows."""
        def watch():
            end = time.monotonic() + 30
            while not list(folder.glob(pattern)) and time.monotonic() < end:
                time.sleep(0.01)
            time.sleep(0.2)
            self.proc.kill()
        thread = threading.Thread(target=watch, daemon=True)
        thread.start()
        return thread


# ---------------------------------------------------------------- R2-5: an output that is an input
def test_an_output_that_is_an_input_or_its_sidecar_is_refused_and_the_input_kept(tmp_path, recording, ssp_path):
    (tmp_path / "link.csv").symlink_to("r.csv")
    os.link(recording, tmp_path / "hard.csv")
    (tmp_path / "f.txt").write_text("0\t5\t3\t2\t0.8\n" * 200)
    before = snapshot(tmp_path)
    cases = [
        (("identify", recording, "--out", recording), "r.csv: this output is the input recording"),
        (("identify", recording, "--out", tmp_path / "r.json"), "r.json: this output is the sidecar of the input"),
        (("identify", recording, "--out", tmp_path / "link.csv"), r"link.csv: this output is the input recording "
                                                                   r".*r\.csv \(through a link: both are "),
        (("identify", recording, "--out", tmp_path / "hard.csv"), r"hard.csv: this output is the input recording "
                                                                   r".*r\.csv \(a hard link to it\)"),
        (("simulate", ssp_path, "--experiment", recording, "--out", recording), "r.csv: this output is the input"),
        (("simulate", ssp_path, "--experiment", recording, "--out", tmp_path / "hard.csv"), "hard.csv: this output is"),
        (("simulate", ssp_path, "--experiment", recording, "--out", tmp_path / "r.json"), "sidecar of the input"),
        (("recording", "import", tmp_path / "f.txt", "--map", "t=1:s,u=2:V,p_a_gauge=3:bar,p_b_gauge=4:bar,alpha=5:rad",
          "--out", tmp_path / "f.txt"), "f.txt: this output is the input"),
    ]
    for args, message in cases:
        proc = cli(*args, timeout=60)
        assert proc.returncode == 1, (args, proc.stdout, proc.stderr)
        assert re.search(message, proc.stderr), (args, proc.stderr)
        assert "Traceback" not in proc.stderr
        assert snapshot(tmp_path) == before, args              # nothing lost, nothing new


def test_an_output_set_refuses_a_file_that_is_an_input(tmp_path, recording):
    from boomfmi.foreign import import_recording, read_options
    from boomfmi.recording import recording_inputs
    before = snapshot(tmp_path)
    with pytest.raises(OutputError, match=r"r\.json: this output is the sidecar of the input recording"):
        with OutputSet(tmp_path, inputs=recording_inputs([recording])) as files:
            files.path("params.ssv").write_text("new")
            files.path("r.json").write_text("new")
    (tmp_path / "f.txt").write_text("0\t5\t3\t2\t0.8\n" * 200)
    (tmp_path / "f_link.txt").symlink_to("f.txt")
    opts = read_options(None, map="t=1:s,u=2:V,p_a_gauge=3:bar,p_b_gauge=4:bar,alpha=5:rad")
    with pytest.raises(OutputError, match=r"f_link\.txt: this output is the input .*f\.txt"):
        import_recording(tmp_path / "f.txt", tmp_path / "f_link.txt", opts)
    assert {k: v for k, v in snapshot(tmp_path).items() if not k.startswith("f")} == before
    assert (tmp_path / "f.txt").read_text() == "0\t5\t3\t2\t0.8\n" * 200


# ---------------------------------------------------- R2-6: record's step and stop, failed runs
@pytest.mark.parametrize("option", [("--step", "-0.001"), ("--stop", "-1"), ("--step", "0"), ("--step", "1e-9"),
                                    ("--step", "nan"), ("--stop", "inf"), ("--step", "2", "--stop", "1")])
def test_record_refuses_a_bad_step_or_stop_before_opening_anything(tmp_path, recording, option):
    before = snapshot(tmp_path)
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)      # no rig needed: nothing is opened
    silent.bind(("127.0.0.1", 0))
    try:
        t0 = time.monotonic()
        proc = cli("record", "--rig", f"udp://127.0.0.1:{silent.getsockname()[1]}", "--out", recording, *option,
                   timeout=30)
    finally:
        silent.close()
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert re.search(r"boomfmi record: --(step|stop) .*(finite number of seconds > 0|longer than --stop|at most "
                     r"3600000)", proc.stderr), proc.stderr
    assert "Traceback" not in proc.stderr and "wrote" not in proc.stdout
    assert time.monotonic() - t0 < 15
    assert snapshot(tmp_path) == before


def test_a_failed_record_never_replaces_an_existing_recording(tmp_path, recording, fmu, monkeypatch):
    from boomfmi.record import record_experiment
    from boomfmi.system import FmuError
    monkeypatch.setenv("BOOMFMI_LINK_KEY", KEY)
    before = snapshot(tmp_path)
    rig = Rig()
    try:
        rig.kill_once(tmp_path, ".r.csv.partial-*")
        with pytest.raises(FmuError, match=r"r\.csv is left as it was \(this run's \d+ rows are kept in "
                                           r".*r\.incomplete-[0-9T]+-\d+\.csv, marked incomplete\)"):
            record_experiment(fmu("hardware_bridge"), rig.url, recording, key_file=None, timeout=0.02,
                              loss_budget=5)
    finally:
        rig.stop()
    after = snapshot(tmp_path)
    kept = sorted(k for k in after if ".incomplete-" in k)    # nothing recorded lost: the failed run's rows beside
    assert [Path(k).suffix for k in kept] == [".csv", ".json"], kept
    assert "incomplete" in json.loads(after.pop(kept[1]))
    assert after.pop(kept[0]).startswith(b"t,")
    assert after == before                                    # the recording, its sidecar; no partial file
    new = tmp_path / "new.csv"                                # with nothing there, the rows are kept, marked
    rig = Rig()
    try:
        rig.kill_once(tmp_path, "new.csv")
        with pytest.raises(FmuError):
            record_experiment(fmu("hardware_bridge"), rig.url, new, timeout=0.02, loss_budget=5)
    finally:
        rig.stop()
    assert read_recording(new).incomplete and len(read_recording(new).data) > 10


# --------------------------------------------------------------- R2-7: one writer per file
def test_a_second_writer_of_a_recording_is_refused_by_name_or_through_a_link(tmp_path, fmu):
    rig_file = tmp_path / "s.csv"
    (tmp_path / "link.csv").symlink_to("s.csv")
    rig = Rig(record=rig_file)
    try:
        for out in (rig_file, tmp_path / "link.csv"):
            proc = cli("record", "--rig", rig.url, "--out", out, "--stop", "0.05", timeout=60)
            assert proc.returncode == 1, proc.stdout + proc.stderr
            assert f"{out}: another writer" in proc.stderr and "Traceback" not in proc.stderr
        os.link(rig_file, tmp_path / "hard.csv")
        with pytest.raises(OutputError, match=r"hard\.csv: another writer"):
            RecordingWriter(tmp_path / "hard.csv")
        # a second rig recording to the same file
        proc = cli("rig", "serve", "--port", "0", "--lockstep", "--record", rig_file, timeout=30)
        assert proc.returncode == 1 and f"{rig_file}: another writer" in proc.stderr, proc.stderr
    finally:
        rig.stop()
    lines = rig_file.read_text().splitlines()               # the rig's own file: its header and rows only
    assert lines[0] == "t,u,p_a,p_b,alpha,f_ext,x,failsafe" and all(len(r.split(",")) == 8 for r in lines)
    assert (tmp_path / "link.csv").is_symlink() and not list(tmp_path.glob(".*"))


def test_record_through_a_link_replaces_the_link_and_never_writes_its_target(tmp_path, fmu, monkeypatch):
    from boomfmi.record import record_experiment
    monkeypatch.setenv("BOOMFMI_LINK_KEY", KEY)
    target = tmp_path / "precious.csv"
    target.write_text("not to be overwritten\n")
    (tmp_path / "out.csv").symlink_to(target)
    rig = Rig()
    try:
        stats = record_experiment(fmu("hardware_bridge"), rig.url, tmp_path / "out.csv", stop_time=0.1)
    finally:
        rig.stop()
    assert target.read_text() == "not to be overwritten\n"
    assert not (tmp_path / "out.csv").is_symlink() and len(read_recording(tmp_path / "out.csv").data) == stats["rows"]


def test_a_second_writer_of_an_output_set_is_refused(tmp_path):
    (tmp_path / "params.json").write_text("old")
    with OutputSet(tmp_path) as first:
        first.path("params.json").write_text("first")
        with pytest.raises(OutputError, match=r"params\.json: another writer"):
            with OutputSet(tmp_path) as second:
                second.path("params.json").write_text("second")
        assert (tmp_path / "params.json").read_text() == "old"
    assert (tmp_path / "params.json").read_text() == "first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["params.json"]          # no lock or partial left


# ------------------------------------------------------- R2-8: all new or all old, leftovers
def test_identify_into_an_existing_folder_is_refused_and_nothing_moves(tmp_path, recording):
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "keep.txt").write_text("mine")
    before = snapshot(tmp_path)
    proc = cli("identify", recording, "--out", tmp_path / "data", timeout=60)
    assert proc.returncode == 1 and "data: is a folder" in proc.stderr and "Traceback" not in proc.stderr
    assert snapshot(tmp_path) == before                     # no data.ssv, data.png or .partial beside it


def test_a_diagnosis_whose_report_is_a_folder_leaves_the_old_set_whole(tmp_path, monkeypatch):
    old = {"diagnosis.json": b"{}", "overlay_x.png": b"old png"}
    for name, body in old.items():
        (tmp_path / name).write_bytes(body)
    (tmp_path / "report.html").mkdir()

    def plots(files, *args):
        files.path("overlay_x.png").write_bytes(b"new png")
        return ["overlay_x.png"]
    monkeypatch.setattr(diagnosis_report, "_plots", plots)
    before = snapshot(tmp_path)
    with pytest.raises(OutputError, match=r"report\.html: is a folder"):
        diagnosis_report._write(tmp_path, {"judgeable": False, "reason": "no motion", "verdict": []}, object(),
                                None, None)
    assert snapshot(tmp_path) == before


def test_a_move_that_fails_midway_puts_back_the_files_moved_before_it(tmp_path, monkeypatch):
    for name in ("a.json", "b.ssv"):
        (tmp_path / name).write_text(f"old {name}")
    real = os.replace
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(src, dst)
    monkeypatch.setattr(outputs.os, "replace", failing)
    with pytest.raises(OSError, match="No space"):
        with OutputSet(tmp_path) as files:
            files.path("a.json").write_text("new")
            files.path("b.ssv").write_text("new")
            files.path("c.png").write_text("new")
    monkeypatch.setattr(outputs.os, "replace", real)
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {"a.json": "old a.json", "b.ssv": "old b.ssv"}


def test_a_killed_runs_partial_files_are_removed_by_the_next_run(tmp_path):
    code = ("import os, sys\n"
            "from boomfmi.outputs import OutputSet\n"
            "from boomfmi.recording import RecordingWriter\n"
            f"w = RecordingWriter({str(tmp_path / 'run.csv')!r}, sidecar={{'notes': 'x'}})\n"
            f"s = OutputSet({str(tmp_path)!r}).__enter__()\n"
            "s.path('params.json').write_text('half')\n"
            "print('ready', flush=True)\n"
            "sys.stdin.read()\n")
    (tmp_path / "run.csv").write_text("t,u,p_a,p_b,alpha\n0,5,0,0,1\n")        # replaced: rows go to a partial
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    proc.kill()
    proc.wait()
    left = sorted(p.name for p in tmp_path.iterdir() if ".partial-" in p.name)
    assert left == [f".params.json.partial-{proc.pid}", f".run.csv.partial-{proc.pid}", f".run.json.partial-{proc.pid}"]
    assert (tmp_path / "run.csv").read_text() == "t,u,p_a,p_b,alpha\n0,5,0,0,1\n"  # the killed run replaced nothing
    with OutputSet(tmp_path) as files:
        files.path("params.json").write_text("{}")
    with RecordingWriter(tmp_path / "run.csv") as w:
        w.write([0, 5, 0, 0, 2])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["params.json", "run.csv"]
    assert json.loads((tmp_path / "params.json").read_text()) == {}
