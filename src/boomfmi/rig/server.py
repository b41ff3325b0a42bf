"""The virtual rig's process: the plant behind an authenticated UDP link.

``RigServer`` binds to loopback (unless told otherwise) and answers the bridge:

* a **command** (valve voltage) is applied from its arrival; in lockstep the rig then
  advances by the command's step ``dt``, unless the command repeats the time of that
  sender's previous one (a retry after a lost answer, which must not step twice), and
  answers with the new sample; a sender whose time goes back (a new run) is stepped
  too.  In real time the rig advances on its own clock at 1 kHz and answers with its
  latest sample at once;
* a **status request** is answered with the current sample without stepping.

The plant is the boom's :class:`~boomfmi.rig.plant.VirtualRig` or the excavator's
:class:`~boomfmi.rig.excavator.ExcavatorRig`: the latter takes excavator commands (four
valve voltages) and answers with excavator samples (``link/protocol.py``, kinds 4 and
5); a command of the other machine is ignored and counted as malformed.  The
excavator's recording has its own columns (``rig.excavator.COLUMNS`` and failsafe).

Datagrams that are malformed, fail authentication, belong to no open session or repeat
an old sequence number of their session (link protocol version 2: replay protection per
session, whatever port a datagram comes from) are ignored and counted.  **Watchdog**:
when no valid command has arrived for ``watchdog`` seconds (50 ms by default, wall
clock) the rig centres the valve (5 V) and reports the fail-safe state in every sample
until commands resume.

With ``record`` the rig writes every sample it measures in the recording format, plus
``f_ext`` (the true external force), ``x`` (the true position) and ``failsafe``, row by
row and crash-safe.  A row holds the sample measured at its time ``t`` and the
command the valve gets from ``t`` on (until the next row), as a DAQ loop reads its
sensors and writes its output at each tick.
"""
from __future__ import annotations

import ctypes
import gc
import os
import secrets
import select
import signal
import socket
import time
from collections import OrderedDict
from dataclasses import dataclass, field

from ..link.protocol import (FAILSAFE, LOCKSTEP, MAX_SESSIONS, BadMac, Command, ExcavatorCommand, Malformed,
                             SequenceGuard, StatusRequest, decode, encode_excavator_sample, encode_sample)
from ..physics import reference_rig
from ..recording import RecordingWriter

MCL_CURRENT, MCL_FUTURE = 1, 2          # <sys/mman.h> on Linux
COLUMNS = ("t", "u", "p_a", "p_b", "alpha", "f_ext", "x", "failsafe")


@dataclass
class Counters:
    commands: int = 0
    status: int = 0
    rejected_malformed: int = 0
    rejected_auth: int = 0
    rejected_replay: int = 0
    rejected_session: int = 0
    failsafe_entries: int = 0
    missed_ticks: int = 0
    #: session number -> its SequenceGuard, the latest MAX_SESSIONS opened
    sessions: OrderedDict = field(default_factory=OrderedDict)

    @property
    def rejected(self) -> int:
        return self.rejected_malformed + self.rejected_auth + self.rejected_replay + self.rejected_session

    def summary(self) -> str:
        return (f"{self.commands} commands, {self.status} status requests, {len(self.sessions)} sessions; "
                f"ignored {self.rejected_malformed} malformed, {self.rejected_auth} unauthenticated, "
                f"{self.rejected_replay} replayed, {self.rejected_session} of no open session; "
                f"fail-safe entered {self.failsafe_entries} times; {self.missed_ticks} ticks missed")


class RigServer:
    def __init__(self, plant, key: bytes, port: int = 0, host: str = "127.0.0.1",
                 lockstep: bool = False, record=None, watchdog: float = 0.05, dt: float = 1e-3):
        self.plant, self.key = plant, key
        self.lockstep, self.watchdog, self.dt = lockstep, watchdog, dt
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.counters = Counters()
        #: an excavator's rig (four valves) rather than the boom's
        self.excavator = getattr(plant, "JOINTS", None) is not None
        self.centre = (reference_rig.u_centre,) * len(plant.JOINTS) if self.excavator else reference_rig.u_centre
        self.u_cmd = self.centre
        self.last_command_wall = time.perf_counter()
        self.last_command_t: dict = {}           # per session: the time of its last command
        self.failsafe = False
        self.seq = 0
        self.sample = plant.measure()
        if self.excavator:
            from .excavator import COLUMNS as EXCAVATOR_COLUMNS
            columns = (*EXCAVATOR_COLUMNS, "failsafe")
        else:
            columns = COLUMNS
        self.writer = RecordingWriter(record, columns) if record else None
        self._stop = False

    # -- the plant ---------------------------------------------------------------------------
    def _record(self, s, u: float) -> None:
        if self.writer:
            if self.excavator:
                from .excavator import sample_row
                self.writer.write((*sample_row(s, u), float(self.failsafe)))
            else:
                self.writer.write((s.t, u, s.p_a, s.p_b, s.alpha, s.f_ext, s.x, float(self.failsafe)))

    def _watchdog(self, now: float) -> None:
        if not self.failsafe and now - self.last_command_wall > self.watchdog:
            self.failsafe = True
            self.counters.failsafe_entries += 1

    def _advance(self, dt: float | None = None) -> None:
        """Record the current sample with the command applied from now, then step."""
        u = self.centre if self.failsafe else self.u_cmd
        self._record(self.sample, u)
        self.sample = self.plant.step(u, dt or self.dt)

    # -- the link ----------------------------------------------------------------------------
    def _reply(self, addr, echo: int, session: int) -> None:
        s = self.sample
        self.seq += 1
        flags = (FAILSAFE if self.failsafe else 0) | (LOCKSTEP if self.lockstep else 0)
        if self.excavator:
            datagram = encode_excavator_sample(self.seq, flags, s.t, s.u_applied, s.p_a, s.p_b, s.angle, s.f_tip,
                                               echo, self.counters.rejected, self.key, session)
        else:
            datagram = encode_sample(self.seq, flags, s.t, s.u_applied, s.p_a, s.p_b, s.alpha,
                                     s.f_ext, s.x, echo, self.counters.rejected, self.key, session)
        try:
            self.sock.sendto(datagram, addr)
        except OSError:
            pass

    def _handle(self, data: bytes, addr) -> None:
        c = self.counters
        try:
            msg = decode(data, self.key)
        except Malformed:
            c.rejected_malformed += 1
            return
        except BadMac:
            c.rejected_auth += 1
            return
        if not isinstance(msg, (ExcavatorCommand if self.excavator else Command, StatusRequest)):
            c.rejected_malformed += 1
            return
        session = msg.session
        if isinstance(msg, StatusRequest) and session == 0:       # opens a session
            session = secrets.randbits(32) or 1
            while session in c.sessions:
                session = secrets.randbits(32) or 1
            c.sessions[session] = SequenceGuard()
            while len(c.sessions) > MAX_SESSIONS:
                forgotten, _ = c.sessions.popitem(last=False)
                self.last_command_t.pop(forgotten, None)
        guard = c.sessions.get(session)
        if guard is None:
            c.rejected_session += 1
            return
        if not guard.accept(msg.seq):
            c.rejected_replay += 1
            return
        if isinstance(msg, StatusRequest):
            c.status += 1
            self._reply(addr, msg.seq, session)
            return
        c.commands += 1
        if self.excavator:
            self.u_cmd = tuple(min(max(u, reference_rig.u_min), reference_rig.u_max) for u in msg.u)
        else:
            self.u_cmd = min(max(msg.u, reference_rig.u_min), reference_rig.u_max)
        self.last_command_wall = time.perf_counter()
        self.failsafe = False
        if self.lockstep:
            last = self.last_command_t.get(session)
            if last is None or abs(msg.t - last) > 0.5 * msg.dt:     # not a retry of the last one
                self._advance(msg.dt)
                self.last_command_t[session] = msg.t
        self._reply(addr, msg.seq, session)

    def _drain(self) -> None:
        while True:
            try:
                data, addr = self.sock.recvfrom(2048)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue
            self._handle(data, addr)

    # -- the loop ----------------------------------------------------------------------------
    def stop(self, *_) -> None:
        self._stop = True

    def serve(self, duration: float | None = None) -> Counters:
        """Serve until :meth:`stop` (SIGTERM, SIGINT) or for ``duration`` seconds of wall time."""
        end = None if duration is None else time.perf_counter() + duration
        next_tick = time.perf_counter() + self.dt
        gc.freeze()           # what exists now is never collected: shorter pauses in the loop
        try:
            while not self._stop:
                now = time.perf_counter()
                if end is not None and now >= end:
                    break
                if self.lockstep:
                    wait = 0.05 if self.failsafe else max(0.0, self.last_command_wall + self.watchdog - now)
                else:
                    wait = max(0.0, next_tick - now)
                if end is not None:
                    wait = min(wait, max(0.0, end - now))
                ready, _, _ = select.select([self.sock], [], [], min(wait, 0.05))
                if ready:
                    self._drain()
                now = time.perf_counter()
                self._watchdog(now)
                if not self.lockstep:
                    while now >= next_tick:
                        self._advance()
                        next_tick += self.dt
                        if now - next_tick > 50 * self.dt:          # hopelessly behind: resync
                            self.counters.missed_ticks += int((now - next_tick) / self.dt)
                            next_tick = now + self.dt
        finally:
            self.close()
        return self.counters

    def close(self) -> None:
        if self.writer:
            self._record(self.sample, self.centre if self.failsafe else self.u_cmd)
            self.writer.close()
            self.writer = None
        self.sock.close()


def realtime_priority(priority: int, pid: int = 0) -> str:
    """Put process ``pid`` (0: this one) under the real-time FIFO scheduler at
    ``priority`` (1 to 99), so that ordinary processes cannot delay its ticks; return a
    line saying what was done.  Without the right to (root or CAP_SYS_NICE) the process
    stays on the normal scheduler and the line says so: a rig still runs, with more
    jitter."""
    if not 1 <= priority <= 99:
        raise ValueError(f"real-time priority must be 1 to 99, not {priority}")
    if not hasattr(os, "sched_setscheduler"):
        return "real-time priority: not available on this system; normal scheduler"
    try:
        os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        return "real-time priority: not permitted (needs root or CAP_SYS_NICE); normal scheduler"
    return f"real-time priority: SCHED_FIFO {priority}; {lock_memory()}"


def lock_memory() -> str:
    """Lock this process's pages in RAM (``mlockall``), as real-time programs do: a page
    the kernel evicted (its code, a library) costs a fault of milliseconds when the loop
    next touches it.  Returns a line saying what was done."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
            return f"memory not locked ({os.strerror(ctypes.get_errno())})"
    except (OSError, AttributeError):
        return "memory not locked (no mlockall here)"
    return "memory locked"


def serve(plant, key: bytes, port: int, host: str = "127.0.0.1", lockstep: bool = False,
          record=None, watchdog: float = 0.05, ready=None) -> Counters:
    """Run a rig server until SIGTERM or SIGINT; ``ready(port)`` is called once bound."""
    server = RigServer(plant, key, port, host, lockstep, record, watchdog)
    signal.signal(signal.SIGTERM, server.stop)
    signal.signal(signal.SIGINT, server.stop)
    if ready:
        ready(server.port)
    return server.serve()
