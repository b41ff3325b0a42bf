"""Hostile traffic on the rig link (issue 31, cases 2 to 4): a captured open replayed, a
flood of junk, a blackout of every datagram, a watchdog too long to be a fail-safe.

Each attack runs during a short lockstep record through the hardware bridge (the rig in
its own process, ``boomfmi rig serve``) and checks that the record completes with every
row, that the rig's own recording has every step, and that the rig counted what it
ignored."""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from boomfmi.link import protocol as p
from boomfmi.link.client import RigClient
from boomfmi.record import record_experiment
from boomfmi.recording import read_recording
from boomfmi.rig import make_rig
from boomfmi.rig import server as rig_server
from chaos import ChaosProxy
from test_rig_link import KEY, Rig, key_env, rig  # noqa: F401  (the rig fixture and the key it needs)


def when_recording(out, action, delay=0.0):
    """Run ``action`` on a thread once the record has begun (``out`` exists: the bridge
    has its session) and ``delay`` seconds more."""
    def run():
        end = time.monotonic() + 30
        while not out.exists() and time.monotonic() < end:
            time.sleep(0.002)
        time.sleep(delay)
        action()
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def assert_nothing_lost(r, out, steps):
    """Every row of the bridge's record and every step of the rig's own recording; the
    rig on the bridge's clock wherever the link was up."""
    rec = read_recording(out)
    assert len(rec.data) == steps + 1 and not rec.incomplete
    ok = rec.data["link_ok"] == 1
    np.testing.assert_allclose(rec.data["t_rig"][ok], rec.data["t"][ok], atol=1e-9)
    rig_rows = read_recording(r.record).data
    # (a status client that opens a session on the idle lockstep rig after the run
    # restarts its plant: the rows after the run's end are that restart's)
    assert len(rig_rows[rig_rows["t"] <= rec.data["t"].iloc[-1] + 1e-9]) == steps + 1
    return rec


# ------------------------------------------------------------------ case 2: replayed opens

def test_a_captured_open_replayed_100_times_during_a_record_costs_it_nothing(fmu, rig, tmp_path):
    r = rig()
    client = RigClient("127.0.0.1", r.port, KEY.encode(), timeout=0.5)
    sent = []
    send = client._send
    client._send = lambda datagram: (sent.append(datagram), send(datagram))
    assert client.exchange(None, 0.0) is not None                     # an earlier run's session
    client.close()
    opening = [d for d in sent if p.decode(d, KEY.encode()).session == 0]
    assert opening, "the client opened its session with a datagram of session 0"

    def replay():
        attacker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for _ in range(100):
            for d in opening:
                attacker.sendto(d, ("127.0.0.1", r.port))
            time.sleep(0.0005)
        attacker.close()
    out = tmp_path / "run.csv"
    thread = when_recording(out, replay)
    stats = record_experiment(fmu("hardware_bridge"), r.url, out, stop_time=1.5)
    thread.join(10)
    r.stop()
    assert stats["lost_packets"] == 0
    rec = assert_nothing_lost(r, out, 1500)
    assert rec.data["link_ok"].all()
    assert r.count("stale opens") == 100                    # each replayed open refused and counted
    assert r.count("sessions") == 2                         # the earlier run's and the record's: no more


def test_the_rig_never_evicts_an_active_session_for_a_new_open(monkeypatch):
    """64 sessions in use: a 65th open is refused; once one has been idle for
    SESSION_IDLE, a new open takes its place."""
    monkeypatch.setattr(rig_server, "SESSION_IDLE", 0.3, raising=False)
    server = rig_server.RigServer(make_rig(), KEY.encode(), lockstep=True)
    thread = threading.Thread(target=server.serve, kwargs=dict(duration=20), daemon=True)
    thread.start()
    clients = [RigClient("127.0.0.1", server.port, KEY.encode(), timeout=0.5) for _ in range(p.MAX_SESSIONS + 1)]
    try:
        assert all(c.exchange(None, 0.0) is not None for c in clients[:-1])
        assert clients[-1].exchange(None, 0.0) is None                  # refused: every session active
        assert server.counters.refused_open == 1
        assert all(c.exchange(None, 0.0) is not None for c in clients[:-1])   # none was evicted
        time.sleep(0.4)
        assert all(c.exchange(None, 0.0) is not None for c in clients[1:-1])  # all but the first in use
        assert clients[-1].exchange(None, 0.0) is not None              # takes the idle first one's place
        assert clients[0].exchange(None, 0.0) is None                   # which is forgotten, and counted
        assert server.counters.rejected_session == 1 and len(server.counters.sessions) == p.MAX_SESSIONS
    finally:
        for c in clients:
            c.close()
        server.stop()
        thread.join(5)


def test_an_open_cookie_opens_once_and_only_within_two_windows():
    now = [100.0]
    guard = p.OpenGuard(window=2.0, clock=lambda: now[0])
    cookie = guard.challenge(7)
    assert not guard.accept(8, cookie)                  # another nonce's
    assert guard.accept(7, cookie)
    assert not guard.accept(7, cookie)                  # used
    late = guard.challenge(9)
    now[0] += 2.0                                       # the next window: still good
    assert guard.accept(9, late)
    stale = guard.challenge(10)
    now[0] += 4.0                                       # two windows on: stale
    assert not guard.accept(10, stale)
    assert not guard.accept(11, 0)
    key = KEY.encode()                                  # the handshake's datagrams, 112 bytes each
    hello, challenge = p.encode_status(5, 0.0, key, 0, 7), p.encode_challenge(9, 1.0, 5, 7, cookie, key)
    assert len(hello) == len(challenge) == p.DATAGRAM_SIZE
    assert p.decode(hello, key) == p.StatusRequest(5, 0.0, 0, 7, 0)
    assert p.decode(challenge, key) == p.Challenge(9, 1.0, 5, 7, cookie)
    assert p.decode(p.encode_status(6, 0.0, key, 0, 7, cookie), key).cookie == cookie


# ------------------------------------------------------------------ case 3: junk and blackouts

def test_a_blackout_longer_than_the_timeout_does_not_put_the_lockstep_rig_behind(fmu, rig, tmp_path):
    """Every datagram of several steps lost (what a flood's full receive buffer does):
    the rig steps through them with the valve held, the record goes on."""
    r = rig()
    proxy = ChaosProxy(r.port)
    out = tmp_path / "run.csv"
    thread = when_recording(out, lambda: proxy.stall(0.15), delay=0.1)
    try:
        stats = record_experiment(fmu("hardware_bridge"), proxy.url, out, stop_time=3.0)
    finally:
        thread.join(10)
        proxy.close()
    r.stop()
    rec = assert_nothing_lost(r, out, 3000)
    lost = (rec.data["link_ok"] == 0).sum()
    assert stats["lost_packets"] == lost > 0
    assert r.count("lockstep steps held for lost commands") > 0
    assert rec.data["link_ok"].iloc[-100:].all()             # and back on the bridge's clock after


FLOOD = """
import os, socket, sys
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
junk = os.urandom(112)
for _ in range(70000):
    s.sendto(junk, ("127.0.0.1", int(sys.argv[1])))
"""


def test_70000_junk_datagrams_during_a_record_are_counted_and_change_nothing(fmu, rig, tmp_path):
    r = rig()
    out = tmp_path / "run.csv"
    flood = []
    thread = when_recording(out, lambda: flood.append(subprocess.Popen([sys.executable, "-c", FLOOD, str(r.port)])))
    stats = record_experiment(fmu("hardware_bridge"), r.url, out, stop_time=3.0)
    thread.join(10)
    assert flood and flood[0].wait(30) == 0
    time.sleep(0.2)                                          # the rig drains what is left
    RigClient("127.0.0.1", r.port, KEY.encode(), timeout=0.5).exchange(None, 0.0)   # and reads the count
    r.stop()
    rec = assert_nothing_lost(r, out, 3000)
    assert stats["lost_packets"] == (rec.data["link_ok"] == 0).sum()
    # every junk datagram counted: read and refused, or dropped by the kernel on a full
    # buffer (a count that also holds the few of the bridge's own it dropped)
    assert r.count("unauthenticated") <= 70000
    assert r.count("unauthenticated") + r.count("lost in a full receive buffer") >= 70000
    assert r.count("sessions") == 2 and r.count("stale opens") == 0


# ------------------------------------------------------------------ case 4: the watchdog's bound

def test_a_watchdog_beyond_10_s_is_refused_and_10_s_is_served(rig):
    for watchdog in ("1e308", "10.5"):
        proc = subprocess.run([sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0",
                               "--watchdog", watchdog], env={**os.environ, "BOOMFMI_LINK_KEY": KEY},
                              capture_output=True, text=True, timeout=10)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        assert f"argument --watchdog: {watchdog} s is beyond the longest watchdog, 10 s" in proc.stderr
        with pytest.raises(ValueError, match=r"at most 10 s"):
            rig_server.RigServer(make_rig(), KEY.encode(), watchdog=float(watchdog))
    r = rig(watchdog=10, record=False)                      # the longest is served
    r.stop()
    assert "rig stopped" in r.summary
