"""The virtual rig's process: the plant behind an authenticated UDP link.

``RigServer`` binds to loopback (unless told otherwise) and answers the bridge:

* a **command** (valve voltage) is applied from its arrival; in lockstep the rig then
  advances by the command's step ``dt``, unless the command repeats the time of that
  sender's previous one (a retry after a lost answer, which must not step twice), and
  answers with the new sample; a sender whose time goes back (a new run) is stepped
  too.  In real time the rig advances on its own clock at 1 kHz and answers with its
  latest sample at once;
* a **status request** is answered with the current sample without stepping.

A lockstep rig keeps each session's clock on its sender's: when the commands of some
steps were lost (a blackout, a flooded receive buffer), the next command's time says
so, and the rig first steps through the missed steps with the valve holding its last
command (or centred, once the watchdog has engaged), then the commanded step (up to
:data:`MAX_HELD_STEPS`; beyond, one step, and the bridge sees the gap).  So lost
datagrams never put the rig behind its driver.

The plant is the boom's :class:`~boomfmi.rig.plant.VirtualRig` or the excavator's
:class:`~boomfmi.rig.plant.ExcavatorRig`: the latter takes excavator commands (four
valve voltages) and answers with excavator samples (``link/protocol.py``, kinds 4 and
5); a command of the other machine is ignored and counted as malformed.  The
excavator's recording has its own columns (``rig.offline.COLUMNS`` and failsafe).

Datagrams that are malformed, fail authentication, belong to no open session or repeat
an old sequence number of their session (replay protection per session, whatever port
a datagram comes from), and opens whose challenge is stale or used (link protocol
version 3) are ignored and counted; so are the datagrams the kernel dropped because the
receive buffer was full (``SO_RXQ_OVFL``, Linux).  No unauthenticated datagram opens,
keeps or evicts a session or steps the rig.  **Watchdog**:
when no valid command has arrived for ``watchdog`` seconds (50 ms by default, wall
clock) the rig centres the valve (5 V) and reports the fail-safe state in every sample
until commands resume; it engages only after a command (an idle rig is not in
fail-safe), so a clean run enters it once, after its last command.  A session opened
on an idle lockstep rig starts the plant from its initial state (``_restart``).

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
import sys
import time
from collections import OrderedDict
from dataclasses import dataclass, field

from ..link.protocol import (FAILSAFE, LOCKSTEP, MAX_SESSIONS, SESSION_IDLE, BadMac, Command, ExcavatorCommand,
                             Malformed, OpenGuard, SequenceGuard, StatusRequest, decode, encode_challenge,
                             encode_excavator_sample, encode_sample)
from ..physics import reference_rig
from ..recording import RecordingWriter

MCL_CURRENT, MCL_FUTURE = 1, 2          # <sys/mman.h> on Linux
COLUMNS = ("t", "u", "p_a", "p_b", "alpha", "f_ext", "x", "failsafe")
#: The longest watchdog a rig accepts [s]: beyond, its fail-safe would in effect be off.
MAX_WATCHDOG = 10.0
#: A lockstep rig steps through at most this many steps whose commands were lost.
MAX_HELD_STEPS = 1000
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40)        # <asm-generic/socket.h>


@dataclass
class Counters:
    commands: int = 0
    status: int = 0
    hellos: int = 0                 #: handshakes' hellos (answered with a challenge)
    rejected_malformed: int = 0
    rejected_auth: int = 0
    rejected_replay: int = 0
    rejected_session: int = 0
    rejected_open: int = 0          #: opens whose challenge is stale, used or not the rig's
    refused_open: int = 0           #: opens refused because every session was active
    overflowed: int = 0             #: datagrams the kernel dropped, the receive buffer full
    held_steps: int = 0             #: lockstep steps taken for lost commands
    failsafe_entries: int = 0
    restarts: int = 0               #: lockstep runs that restarted the plant from its initial state
    missed_ticks: int = 0
    #: session number -> its SequenceGuard, at most MAX_SESSIONS, least recently used first
    sessions: OrderedDict = field(default_factory=OrderedDict)

    @property
    def rejected(self) -> int:
        return (self.rejected_malformed + self.rejected_auth + self.rejected_replay + self.rejected_session
                + self.rejected_open)

    def summary(self) -> str:
        return (f"{self.commands} commands, {self.status} status requests, {self.hellos} hellos, "
                f"{len(self.sessions)} sessions; "
                f"ignored {self.rejected_malformed} malformed, {self.rejected_auth} unauthenticated, "
                f"{self.rejected_replay} replayed, {self.rejected_session} of no open session, "
                f"{self.rejected_open} stale opens; {self.refused_open} opens refused (every session active); "
                f"{self.overflowed} lost in a full receive buffer; "
                f"{self.held_steps} lockstep steps held for lost commands; "
                f"{self.restarts} lockstep runs started from the initial state; "
                f"fail-safe entered {self.failsafe_entries} times (once after each run's last command: "
                f"its driver stopped, the valve centred); {self.missed_ticks} ticks missed")


class RigServer:
    def __init__(self, plant, key: bytes, port: int = 0, host: str = "127.0.0.1",
                 lockstep: bool = False, record=None, watchdog: float = 0.05, dt: float = 1e-3):
        if not 0.0 < watchdog <= MAX_WATCHDOG:      # also refuses nan
            raise ValueError(f"watchdog {watchdog!r} s: it must be > 0 and at most {MAX_WATCHDOG:g} s, "
                             f"or the fail-safe is in effect off")
        self.plant, self.key = plant, key
        self.lockstep, self.watchdog, self.dt = lockstep, watchdog, dt
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        try:                      # the kernel's count of datagrams dropped on a full buffer
            self.sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            self._ancillary = socket.CMSG_SPACE(4)
        except (OSError, AttributeError):
            self._ancillary = 0
        self.port = self.sock.getsockname()[1]
        self.counters = Counters()
        #: an excavator's rig (four valves) rather than the boom's
        self.excavator = getattr(plant, "JOINTS", None) is not None
        self.centre = (reference_rig.u_centre,) * len(plant.JOINTS) if self.excavator else reference_rig.u_centre
        self.u_cmd = self.centre
        self.last_command_wall = time.perf_counter()
        self.last_command_t: dict = {}           # per session: (t, dt) of its last command that stepped
        self.session_wall: dict = {}             # per session: when it last had a datagram accepted
        self.opens = OpenGuard()
        self.failsafe = False
        #: a command has come since the rig started or its watchdog last engaged: only
        #: then is there a driver whose silence the watchdog answers (an idle rig, its
        #: valve centred, is not in fail-safe)
        self.driven = False
        #: added to the plant's time in the rig's own recording: a lockstep run that
        #: restarts the plant (``_restart``) continues the file's time
        self.t_offset = 0.0
        self.seq = 0
        self.sample = plant.measure()
        if self.excavator:
            from .offline import COLUMNS as EXCAVATOR_COLUMNS
            columns = (*EXCAVATOR_COLUMNS, "failsafe")
        else:
            columns = COLUMNS
        try:        # locked while the rig runs: a second writer of the file is refused
            self.writer = RecordingWriter(record, columns) if record else None
        except BaseException:
            self.sock.close()
            raise
        self._stop = False

    # -- the plant ---------------------------------------------------------------------------
    def _record(self, s, u: float) -> None:
        if self.writer:
            if self.excavator:
                from .offline import sample_row
                row = [*sample_row(s, u), float(self.failsafe)]
            else:
                row = [s.t, u, s.p_a, s.p_b, s.alpha, s.f_ext, s.x, float(self.failsafe)]
            row[0] += self.t_offset
            self.writer.write(row)

    def _watchdog(self, now: float) -> None:
        if self.driven and not self.failsafe and now - self.last_command_wall > self.watchdog:
            self.failsafe = True
            self.driven = False
            self.counters.failsafe_entries += 1

    def _advance(self, dt: float | None = None) -> None:
        """Record the current sample with the command applied from now, then step."""
        u = self.centre if self.failsafe else self.u_cmd
        self._record(self.sample, u)
        self.sample = self.plant.step(u, dt or self.dt)

    # -- the link ----------------------------------------------------------------------------
    def _challenge(self, addr, echo: int, nonce: int) -> None:
        self.seq += 1
        try:
            self.sock.sendto(encode_challenge(self.seq, self.sample.t, echo, nonce, self.opens.challenge(nonce),
                                              self.key), addr)
        except OSError:
            pass

    def _open(self) -> int:
        """A new session, or 0 when all MAX_SESSIONS are in use and none has been idle
        for SESSION_IDLE (an active session is never evicted)."""
        c = self.counters
        if len(c.sessions) >= MAX_SESSIONS:
            oldest = next(iter(c.sessions))
            if time.perf_counter() - self.session_wall[oldest] < SESSION_IDLE:
                c.refused_open += 1
                return 0
            del c.sessions[oldest]
            self.session_wall.pop(oldest, None)
            self.last_command_t.pop(oldest, None)
        session = secrets.randbits(32) or 1
        while session in c.sessions:
            session = secrets.randbits(32) or 1
        c.sessions[session] = SequenceGuard()
        return session

    def _steps(self, session: int, msg) -> tuple[int, int]:
        """(held, stepped): the steps a lockstep command asks for, those of its session's
        lost commands first, then its own (0 for a retry of the last one)."""
        last = self.last_command_t.get(session)
        if last is None or msg.t < last[0] - 0.5 * msg.dt:       # a first command, or time went back
            return 0, 1
        if abs(msg.t - last[0]) <= 0.5 * msg.dt:                 # a retry: already stepped
            return 0, 0
        missed = round((msg.t - last[0] - last[1]) / msg.dt)
        return (missed if 0 < missed <= MAX_HELD_STEPS else 0), 1

    def _restart(self) -> None:
        """A session opened on an idle lockstep rig (no command since it started or its
        watchdog engaged) starts the plant from its initial state at rig time 0, out of
        fail-safe, as a run of the model would: a second ``record`` does not continue
        where the first left off.  A session opened while another drives the rig (a
        monitor) changes nothing.  The rig's own recording goes on in time
        (``t_offset``)."""
        self.failsafe = False
        if self.plant.t == 0.0:
            return
        self._record(self.sample, self.centre)                   # the last state, before the restart
        self.t_offset += self.plant.t + self.dt
        self.plant.reset()
        self.sample = self.plant.measure()
        self.u_cmd = self.centre
        self.counters.restarts += 1

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
        if isinstance(msg, StatusRequest) and session == 0:
            if not msg.cookie:                                     # a hello: challenge it, keep nothing
                c.hellos += 1
                self._challenge(addr, msg.seq, msg.nonce)
                return
            if not self.opens.accept(msg.nonce, msg.cookie):       # a stale or replayed open
                c.rejected_open += 1
                return
            session = self._open()
            if not session:
                return
            if self.lockstep and not self.driven:
                self._restart()
            self.session_wall[session] = time.perf_counter()
        guard = c.sessions.get(session)
        if guard is None:
            c.rejected_session += 1
            return
        if not guard.accept(msg.seq):
            c.rejected_replay += 1
            return
        c.sessions.move_to_end(session)                            # least recently used first
        self.session_wall[session] = time.perf_counter()
        if isinstance(msg, StatusRequest):
            c.status += 1
            self._reply(addr, msg.seq, session)
            return
        c.commands += 1
        held, stepped = self._steps(session, msg) if self.lockstep else (0, 0)
        for _ in range(held):            # the lost commands' steps: the valve holds its last command
            self._advance(msg.dt)
        c.held_steps += held
        if self.excavator:
            self.u_cmd = tuple(min(max(u, reference_rig.u_min), reference_rig.u_max) for u in msg.u)
        else:
            self.u_cmd = min(max(msg.u, reference_rig.u_min), reference_rig.u_max)
        self.last_command_wall = time.perf_counter()
        self.failsafe = False
        self.driven = True
        if stepped:
            self._advance(msg.dt)
            self.last_command_t[session] = (msg.t, msg.dt)
        self._reply(addr, msg.seq, session)

    def _drain(self) -> None:
        while True:
            try:
                if self._ancillary:
                    data, ancillary, _, addr = self.sock.recvmsg(2048, self._ancillary)
                    for level, kind, value in ancillary:
                        if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(value) >= 4:
                            self.counters.overflowed = int.from_bytes(value[:4], sys.byteorder)   # cumulative
                else:
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


__all__ = ["MCL_CURRENT", "MCL_FUTURE", "COLUMNS", "MAX_WATCHDOG", "MAX_HELD_STEPS", "SO_RXQ_OVFL", "Counters",
           "RigServer", "realtime_priority", "lock_memory", "serve"]
