"""The virtual rig behind its UDP link, the hardware bridge, and the faults a link meets.

The rig runs as its own process (``boomfmi rig serve``); the bridge FMU talks to it
through fmpy, directly or through a proxy that drops, duplicates, reorders or corrupts
datagrams."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from boomfmi.link.client import RigClient
from boomfmi.link.protocol import encode_command
from boomfmi.record import record_experiment
from boomfmi.recording import read_recording
from boomfmi.simulate import run_experiment
from boomfmi.system import FmuError, FmuInstance
from boomfmi.system.ssv import write_ssv
from chaos import ChaosProxy

KEY = "a shared key of more than sixteen bytes"


class Rig:
    """``boomfmi rig serve`` in a subprocess, on a free loopback port."""

    def __init__(self, tmp: Path, lockstep=True, record=True, key=KEY, config=None, watchdog=0.05):
        self.record = tmp / "rig.csv" if record else None
        args = [sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0", "--watchdog", str(watchdog)]
        args += ["--lockstep"] if lockstep else []
        args += ["--record", str(self.record)] if record else []
        args += ["--config", str(config)] if config else []
        self.proc = subprocess.Popen(args, env=dict(os.environ, BOOMFMI_LINK_KEY=key),
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        match = re.search(r"udp://127\.0\.0\.1:(\d+)", line)
        assert match, line + self.proc.stderr.read()
        self.port = int(match.group(1))
        self.url = f"udp://127.0.0.1:{self.port}"
        self.summary = ""

    def stop(self) -> str:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        out, _ = self.proc.communicate(timeout=10)
        self.summary = out
        return out

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait()

    def count(self, what: str) -> int:
        return int(re.search(rf"(\d+) {what}", self.summary).group(1))


@pytest.fixture
def key_env(monkeypatch):
    monkeypatch.setenv("BOOMFMI_LINK_KEY", KEY)


@pytest.fixture
def rig(tmp_path, key_env):
    rigs = []

    def start(**kw):
        r = Rig(tmp_path, **kw)
        rigs.append(r)
        return r
    yield start
    for r in rigs:
        if r.proc.poll() is None:
            r.stop()


def test_rig_refuses_to_start_without_a_key(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "BOOMFMI_LINK_KEY"}
    proc = subprocess.run([sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0"],
                          env=env, capture_output=True, text=True, timeout=30)
    assert proc.returncode == 1
    assert "no link key: give a key file or set BOOMFMI_LINK_KEY" in proc.stderr


def test_record_through_the_bridge_on_a_lockstep_rig(fmu, rig, tmp_path):
    r = rig()
    out = tmp_path / "run.csv"
    stats = record_experiment(fmu("hardware_bridge"), r.url, out, stop_time=2.0)
    r.stop()
    rec = read_recording(out)
    assert len(rec.data) == 2001 and stats["lost_packets"] == 0
    assert rec.data["link_ok"].all()
    np.testing.assert_allclose(rec.data["t_rig"], rec.data["t"], atol=1e-9)   # lockstep: one sample a step
    assert rec.data["x_alpha"].max() > 0.05                                    # the boom moved
    rig_rec = read_recording(r.record)                                         # the rig's own recording
    assert "f_ext" in rig_rec.data and len(rig_rec.data) == 2001
    assert r.count("commands") == 2000


def test_teleoperation_ssp_model_tracks_the_rig(ssp_path, rig, tmp_path):
    r = rig()
    link = write_ssv(tmp_path / "link.ssv", "link", {"hardware_bridge.rig": (r.url, None)})
    result = run_experiment(ssp_path.parent / "teleoperation.ssp", "paper_multistep", parameters=link)
    r.stop()
    assert {"x", "x_measured", "p_a", "p_a_measured", "u_applied", "link_ok", "lost_packets"} <= set(result.columns)
    assert result["link_ok"].all() and (result["lost_packets"] == 0).all()
    span = result["x_measured"].max() - result["x_measured"].min()
    nrmse_x = np.sqrt(np.mean((result["x"] - result["x_measured"]) ** 2)) / span
    assert span > 0.05 and nrmse_x < 0.02
    nrmse_p = np.sqrt(np.mean((result["p_a"] - result["p_a_measured"]) ** 2)) / result["p_a_measured"].max()
    assert nrmse_p < 0.03
    rig_rec = read_recording(r.record)
    assert len(rig_rec.data) == len(result)


@pytest.mark.parametrize("faults", [dict(drop=0.05), dict(duplicate=0.2), dict(reorder=0.1),
                                    dict(corrupt=0.05)], ids=["5%-loss", "duplicates", "reordering", "corruption"])
def test_a_damaged_link_keeps_the_recording_valid_and_aligned(fmu, rig, tmp_path, faults):
    r = rig()
    proxy = ChaosProxy(r.port, seed=7, **faults)
    out = tmp_path / "run.csv"
    try:
        stats = record_experiment(fmu("hardware_bridge"), proxy.url, out, stop_time=1.5, timeout=0.03)
    finally:
        proxy.close()
    r.stop()
    rec = read_recording(out)
    assert len(rec.data) == 1501
    ok = rec.data["link_ok"] == 1
    assert ok.mean() > 0.97
    # retries within the timeout keep the lockstep rig on the bridge's clock
    np.testing.assert_allclose(rec.data["t_rig"][ok], rec.data["t"][ok], atol=1e-9)
    rig_rec = read_recording(r.record).data
    assert (rig_rec["failsafe"].iloc[:-1] == 0).all(), "no fail-safe while commands keep coming"
    if "duplicate" in faults:
        assert r.count("replayed") > 0
    if "corrupt" in faults:
        assert r.count("unauthenticated") + r.count("malformed") > 0
    assert stats["lost_packets"] == (~ok).sum()


def test_a_200_ms_stall_engages_the_fail_safe_exactly_then(fmu, rig, tmp_path):
    r = rig(lockstep=False)
    with FmuInstance(fmu("hardware_bridge")) as b:
        b.initialize(dict(mode="udp", rig=r.url), inputs={"u": 1.0})
        t, dt = 0.0, 1e-3
        for _ in range(300):
            b.set(u=1.0)
            b.step_to(t, dt)
            t += dt
        last = b.get("t_rig")["t_rig"]
        time.sleep(0.2)                                   # the operator's side stalls
        for _ in range(200):
            b.set(u=1.0)
            b.step_to(t, dt)
            t += dt
        assert not b.get("failsafe")["failsafe"]
    r.stop()
    rec = read_recording(r.record).data
    after = rec[rec["t"] > last]
    fs = after[after["failsafe"] == 1]
    assert len(fs) > 0
    assert (fs["u"] == 5.0).all()                              # valve centred while in fail-safe
    # the stall's episode: the first run of fail-safe samples (the free-running rig's
    # watchdog also engages wherever this test's own process stalls 50 ms on a busy host)
    flags = after["failsafe"].to_numpy()
    first = int(np.argmax(flags == 1))
    n = int(np.argmax(flags[first:] == 0))
    assert n > 0, "commands resumed and the fail-safe was never released"
    assert 0.045 <= after["t"].iloc[first] - last <= 0.056    # watchdog: 50 ms after the last command
    assert 0.13 <= n * 1e-3 <= 0.17                            # until commands resume, ~150 ms


def test_a_real_time_bridge_paces_to_the_wall_clock_with_one_exchange_per_step(fmu, rig):
    r = rig(lockstep=False, record=False)
    n, dt = 300, 1e-3
    with FmuInstance(fmu("hardware_bridge")) as b:
        b.initialize(dict(mode="udp", rig=r.url), inputs={"u": 6.0})
        t, t_rig, late = 0.0, [], []
        wall0 = time.perf_counter()
        for _ in range(n):
            b.set(u=6.0)
            b.step_to(t, dt)
            t += dt
            got = b.get("t_rig", "lateness")
            t_rig.append(got["t_rig"])
            late.append(got["lateness"])
        wall = time.perf_counter() - wall0
    r.stop()
    assert n * dt <= wall < n * dt + 0.1                        # paced: never ahead of the clock
    assert r.count("commands") == n and r.count("status requests") == 1   # the set-up's only
    rig_dt = np.diff(t_rig)
    assert np.median(rig_dt) == pytest.approx(dt, abs=1e-9)     # each step, the rig's next tick
    assert 0.0 <= np.median(late) < dt                          # steps begin inside their slot


def test_rig_killed_mid_run_ends_with_a_clear_error_and_keeps_every_row(fmu, rig, tmp_path):
    r = rig()
    out = tmp_path / "run.csv"
    proc = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "record", "--rig", r.url, "--out", str(out),
                             "--fmu", str(fmu("hardware_bridge")), "--stop", "5", "--timeout", "0.02",
                             "--loss-budget", "10"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not out.exists() or out.read_text().count("\n") < 500:
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read() if proc.poll() else "slow"
        time.sleep(0.01)
    r.kill()
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert "lost: 11 answers in a row missing (loss budget 10)" in err and "Traceback" not in err
    rec = read_recording(out).data                     # valid: nothing written before the fault is lost
    assert len(rec) >= 500
    assert (rec["link_ok"].iloc[-10:] == 0).all()      # the held samples, flagged
    assert read_recording(r.record).data["t"].iloc[-1] > 0.4   # the killed rig's own file is valid too


def test_a_wrong_key_gets_no_answer_and_is_counted(fmu, rig, monkeypatch):
    r = rig()
    monkeypatch.setenv("BOOMFMI_LINK_KEY", "not the key the rig holds, surely")
    with FmuInstance(fmu("hardware_bridge")) as b:
        with pytest.raises(FmuError, match="no authenticated answer from the rig"):
            b.initialize(dict(mode="udp", rig=r.url, timeout=0.05))
    r.stop()
    assert r.count("unauthenticated") >= 1 and r.count("commands") == 0


def test_a_lockstep_rig_serves_a_second_run_and_any_step(fmu, rig, tmp_path):
    """A second session starts its clock at 0 again; a 2 ms step advances 2 ms."""
    r = rig()
    first = record_experiment(fmu("hardware_bridge"), r.url, tmp_path / "one.csv", stop_time=0.5)
    second = record_experiment(fmu("hardware_bridge"), r.url, tmp_path / "two.csv", stop_time=2.0, step=2e-3)
    r.stop()
    assert first["lost_packets"] == second["lost_packets"] == 0
    two = read_recording(tmp_path / "two.csv").data
    assert len(two) == 1001
    np.testing.assert_allclose(np.diff(two["t_rig"]), 2e-3, atol=1e-9)   # the rig stepped with the bridge
    assert two["x_alpha"].max() > 0.05                                      # and moved the boom


def test_a_replayed_datagram_is_ignored(rig):
    r = rig()
    client = RigClient("127.0.0.1", r.port, KEY.encode(), timeout=0.2)
    first = client.exchange(1.0, 0.0)
    assert first is not None and first.t == pytest.approx(1e-3)
    replay = encode_command(client.seq, 0.0, 1.0, KEY.encode(), session=client.session)   # the same bytes
    client.sock.sendto(replay, ("127.0.0.1", r.port))
    time.sleep(0.05)
    status = client.exchange(None, 0.0)
    assert status.t == pytest.approx(1e-3)                           # the rig did not step again
    client.close()
    r.stop()
    assert r.count("replayed") == 1


def test_a_command_replayed_from_another_port_is_refused(rig):
    """Replay protection is per session, not per sender port (issue 15)."""
    import socket
    r = rig()
    client = RigClient("127.0.0.1", r.port, KEY.encode(), timeout=0.2)
    assert client.exchange(1.0, 0.0).t == pytest.approx(1e-3)
    captured = encode_command(client.seq, 0.0, 1.0, KEY.encode(), session=client.session)
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)        # an attacker's new port
    other.sendto(captured, ("127.0.0.1", r.port))
    other.sendto(encode_command(client.seq + 5, 7.0, 9.0, KEY.encode()), ("127.0.0.1", r.port))  # no session
    other.close()
    time.sleep(0.05)
    assert client.exchange(None, 0.0).t == pytest.approx(1e-3)     # the rig did not step again
    client.close()
    r.stop()
    assert r.count("replayed") == 1 and r.count("of no open session") == 1


def test_a_rig_killed_mid_record_leaves_its_rows_marked_incomplete(fmu, rig, tmp_path):
    import json
    import threading
    from boomfmi.identify import identify_recordings
    r = rig()
    out = tmp_path / "run.csv"
    threading.Timer(0.5, r.kill).start()
    with pytest.raises(FmuError, match="lost"):
        record_experiment(fmu("hardware_bridge"), r.url, out, timeout=0.02, loss_budget=5)
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["incomplete"].startswith("the link failed at t = ")
    rec = read_recording(out)
    assert len(rec.data) > 10 and rec.incomplete
    with pytest.raises(ValueError, match="marked incomplete"):
        identify_recordings([out])
