"""Numbers from users, checked before use (issue 31, cases 12, 15, 16, 17 and 21): a
WebSocket number no float holds, a sidecar's rig values outside the physics' bounds, a
``--set`` value outside the FMU's declared range, a ``--stop`` no run can hold, and
``$BOOMFMI_MAX_RECORDING_MB`` that is not a size.  Each gets a clear error naming the
key, parameter, option or variable, no traceback, and nothing already written is
touched.  docs/reliability.md lists them (R2-12, R2-15, R2-16, R2-17, R2-21)."""
from __future__ import annotations

import asyncio
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import aiohttp
import pytest
from aiohttp.test_utils import TestServer

from boomfmi.recording import RecordingError, max_bytes, read_recording, read_sidecar, write_recording
from boomfmi.simulate import run_experiment
from boomfmi.system import FmuError
from boomfmi.system.master import MAX_STEPS
from boomfmi.system.ssv import SspError
from boomfmi.view.server import BadMessage, make_app, parse_command

BIG = int("9" * 400)         # a JSON or command-line integer beyond any float


def cli(*args, cwd=None, env=None, timeout=120):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory) -> Path:
    """A short rig recording (1 s, two held commands) with no sidecar."""
    from boomfmi.experiments import held
    from boomfmi.rig.offline import run_offline
    return write_recording(tmp_path_factory.mktemp("hostile_values") / "run.csv",
                           run_offline({"seed": 1}, held([(0.5, 7.0), (0.5, 3.0)]), 1.0))


# -- R2-12: the view's WebSocket ------------------------------------------------------------------
def test_r2_12_a_seek_or_speed_beyond_any_float_gets_an_error_and_the_connection_goes_on(run_csv, caplog):
    for cmd, field in (("seek", "t"), ("speed", "value")):
        for v in (BIG, -BIG):
            with pytest.raises(BadMessage, match=rf"{cmd}: {field} must be finite, not an integer of 400 digits"):
                parse_command(json.dumps({"cmd": cmd, field: v}))
    assert parse_command('{"cmd": "seek", "t": 2}') == {"cmd": "seek", "t": 2.0}

    from boomfmi.view.frames import load_run
    run = load_run(run_csv)

    async def main():
        srv = TestServer(make_app(run), host="127.0.0.1", port=0)
        await srv.start_server()
        try:
            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(f"http://127.0.0.1:{srv.port}/ws") as ws:
                    errors = []
                    for text in (json.dumps({"cmd": "seek", "t": BIG}), json.dumps({"cmd": "speed", "value": BIG})):
                        await ws.send_str(text)
                        while True:
                            msg = json.loads((await ws.receive(timeout=5)).data)
                            if msg["type"] == "error":
                                errors.append(msg["message"])
                                break
                    assert "seek: t must be finite" in errors[0] and "speed: value must be finite" in errors[1]
                    await ws.send_str('{"cmd": "pause"}')          # the connection goes on: the run's frame
                    await ws.send_str('{"cmd": "seek", "t": 0.25}')
                    while True:
                        msg = json.loads((await ws.receive(timeout=5)).data)
                        if msg["type"] == "frame" and not msg["playing"] and abs(msg["t"] - 0.25) < 1e-12:
                            break
                    assert not ws.closed
        finally:
            await srv.close()
    asyncio.run(asyncio.wait_for(main(), 30))
    assert "Traceback" not in caplog.text and not [r for r in caplog.records if r.exc_info]


# -- R2-15: a sidecar's rig values ----------------------------------------------------------------
@pytest.mark.parametrize("rig, key, why", [
    ({"A_max": 0}, "A_max", "must be > 0: at 0 the valve passes no air"),
    ({"T": 0}, "T", "must be > 0"),
    ({"a": 0, "b": 0}, "a", "must be > 0"),
    ({"M": -5}, "M", "must be > 0"),
    ({"L": 1.0}, "L", "must be at most 0.5 m"),
    ({"P_atm": 0}, "P_atm", "must be > 0"),
    ({"supply_pressure_gauge": -1e4}, "supply_pressure_gauge", "the supply must be above the exhaust"),
    ({"k": 1.0}, "k", "the ratio of specific heats must be > 1"),
    ({"h": 0.2}, "h", "must not exceed a = 0.15 m"),
])
def test_r2_15_a_sidecar_value_outside_the_physics_bounds_is_refused_naming_its_key(tmp_path, run_csv, rig, key, why):
    (tmp_path / "r.csv").write_bytes(run_csv.read_bytes())
    (tmp_path / "r.json").write_text(json.dumps({"rig": rig}))
    with pytest.raises(RecordingError, match=rf"r\.json: rig value '{key}' = .* is outside the physics' bounds: "
                                             rf".*{why}"):
        read_recording(tmp_path / "r.csv")
    with pytest.raises(RecordingError, match=rf"rig value '{key}'"):
        read_sidecar(tmp_path / "r.json")          # the campaign manifest's check of a sidecar: the same


def test_r2_15_a_partner_of_a_sidecar_value_is_named_and_identify_writes_nothing(tmp_path, run_csv):
    (tmp_path / "r.csv").write_bytes(run_csv.read_bytes())
    (tmp_path / "r.json").write_text(json.dumps({"rig": {"P_e": 8e5}}))       # above the reference supply
    with pytest.raises(RecordingError, match=r"the rig values \(P_e = 800000.0\) leave the reference rig's P_s "
                                             r"outside the physics' bounds: .*above the exhaust pressure P_e = 800000"):
        read_recording(tmp_path / "r.csv")
    # the command line: exit 1, the key named, no traceback, the previous parameter set untouched
    (tmp_path / "r.json").write_text(json.dumps({"rig": {"M": -5}}))
    out = tmp_path / "p"
    out.mkdir()
    (out / "params.json").write_text('{"old": true}')
    proc = cli("identify", tmp_path / "r.csv", "--out", out / "params.json")
    assert proc.returncode == 1, proc.stderr
    assert "r.json: rig value 'M' = -5 is outside the physics' bounds" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert (out / "params.json").read_text() == '{"old": true}' and sorted(p.name for p in out.iterdir()) == \
        ["params.json"]


def test_r2_15_a_stroke_the_recorded_angles_do_not_fit_is_refused_naming_the_geometry(tmp_path, run_csv):
    """L = 1e-9 is within the physics' bounds (L > 0): a recording of a boom that moves
    cannot come from it, which the recording's angle range tells (Eq. 12)."""
    (tmp_path / "r.csv").write_bytes(run_csv.read_bytes())
    (tmp_path / "r.json").write_text(json.dumps({"rig": {"L": 1e-9}}))
    from boomfmi.recording import read_checked
    with pytest.raises(ValueError, match=r"r\.csv.*column 'alpha'.*outside its physical range.*\bL\b"):
        read_checked([tmp_path / "r.csv"])


# -- R2-16: --set values --------------------------------------------------------------------------
def test_r2_16_a_set_value_that_is_infinite_or_out_of_range_is_refused_naming_the_parameter(ssp_path, tmp_path):
    cases = [({"boom_load.M": math.inf}, SspError, r"parameter boom_load\.M = inf: must be a finite number"),
             ({"boom_load.M": math.nan}, SspError, r"parameter boom_load\.M = nan: must be a finite number"),
             ({"boom_load.M": BIG}, SspError, r"boom_load\.M = an integer of 400 digits: must be a finite number"),
             # a range is the FMU's own to judge (its declared min and max, its reasons) ...
             ({"valve.P_s": 2e6}, FmuError, r"valve: fmi2ExitInitializationMode returned fmi2Error: parameter P_s = "
                                            r"2000000\.0 is invalid: must be <= 1\.10132e\+06 Pa"),
             # ... but what the stable step divides by is named before it divides
             ({"boom_load.M": -1.0}, ValueError, r"boom_load\.M: parameter M = -1\.0 is invalid: must be > 0"),
             ({"valve.P_s": math.inf}, SspError, r"valve\.P_s = inf: must be a finite number"),
             # within the declared range (min 0), yet no mass
             ({"boom_load.M": 0.0}, ValueError, r"boom_load\.M: parameter M = 0\.0 is invalid: must be > 0")]
    for given, error, message in cases:
        with pytest.raises(error, match=message):
            run_experiment(ssp_path, "paper_multistep", parameters=[given], stop_time=0.01)
    out = tmp_path / "x.csv"
    out.write_text("old\n")
    proc = cli("simulate", ssp_path, "--set", "boom_load.M=inf", "--stop", "0.01", "--out", out)
    assert proc.returncode == 1 and "parameter boom_load.M = inf: must be a finite number" in proc.stderr
    assert "Traceback" not in proc.stderr and out.read_text() == "old\n"


# -- R2-17: --stop --------------------------------------------------------------------------------
def test_r2_17_a_stop_no_run_can_hold_is_refused_naming_the_bound(ssp_path, tmp_path):
    for stop in (1e7, 1e12):
        with pytest.raises(ValueError, match=rf"stop time {re.escape(f'{stop:g}')} s is .* steps of 0\.001 s; a run may have at most "
                                             rf"{MAX_STEPS:,} \(MAX_STEPS: 2\.78 h at this step"):
            run_experiment(ssp_path, "paper_multistep", stop_time=stop)
    with pytest.raises(ValueError, match=r"the stop time must be a finite number of seconds, not nan"):
        run_experiment(ssp_path, "paper_multistep", stop_time=math.nan)
    out = tmp_path / "x.csv"
    out.write_text("old\n")
    proc = cli("simulate", ssp_path, "--stop", "1e7", "--out", out)
    assert proc.returncode == 1 and "a run may have at most 10,000,000 (MAX_STEPS" in proc.stderr
    assert "Traceback" not in proc.stderr and out.read_text() == "old\n"
    for stop in ("nan", "-1", "inf"):
        proc = cli("simulate", ssp_path, "--stop", stop, "--out", out)
        assert proc.returncode == 2 and f"argument --stop: {stop} must be a finite number > 0" in proc.stderr
        assert "Traceback" not in proc.stderr and out.read_text() == "old\n"


# -- R2-21: $BOOMFMI_MAX_RECORDING_MB -------------------------------------------------------------
def test_r2_21_a_recording_size_limit_that_is_not_a_size_is_refused_naming_the_variable(run_csv, monkeypatch,
                                                                                      tmp_path):
    for bad in ("1e400", "-5", "0", "nan", "inf", "-inf"):
        monkeypatch.setenv("BOOMFMI_MAX_RECORDING_MB", bad)
        with pytest.raises(ValueError, match=rf"\$BOOMFMI_MAX_RECORDING_MB must be a finite number of MiB > 0, "
                                             rf"not '{bad}' \(unset, the limit is 256 MiB\)"):
            max_bytes()
    monkeypatch.setenv("BOOMFMI_MAX_RECORDING_MB", "300")
    assert max_bytes() == 300 * 2**20 and len(read_recording(run_csv).data) == 1001
    out = tmp_path / "p"
    proc = cli("identify", run_csv, "--out", out / "params.json",
               env={**os.environ, "BOOMFMI_MAX_RECORDING_MB": "1e400"})
    assert proc.returncode == 1 and "$BOOMFMI_MAX_RECORDING_MB must be a finite number of MiB > 0, not '1e400'" \
        in proc.stderr
    assert "Traceback" not in proc.stderr and not out.exists()
