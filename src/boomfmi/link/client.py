"""The bridge's side of the link: one request, one authenticated answer, bounded wait.

``RigClient.exchange`` sends a command (or a status request) and waits at most
``timeout`` seconds for the sample that answers it; the first opens a session (the
handshake of ``protocol.py``: a hello with a fresh nonce, the rig's challenge, the
open with its cookie) within the same deadline.  Datagrams that are malformed,
fail authentication, answer an older request or repeat an old rig sequence number are
dropped and counted; a missing answer returns ``None``.  Nothing here ever blocks
past its deadline.
"""
from __future__ import annotations

import secrets
import select
import socket
import time

from .protocol import (BadMac, Challenge, ExcavatorSampleDatagram, LinkError, Malformed, SampleDatagram,
                       SequenceGuard, decode, encode_command, encode_excavator_command, encode_status)


def parse_address(url: str) -> tuple[str, int]:
    """``udp://HOST:PORT`` (or ``HOST:PORT``) -> (host, port); raises LinkError."""
    rest = url[len("udp://"):] if url.startswith("udp://") else url
    host, sep, port = rest.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise LinkError(f"{url!r} is not a rig address of the form udp://HOST:PORT")
    return host, int(port)


def wait_until(deadline: float) -> None:
    """Sleep to just short of ``deadline`` (``time.perf_counter`` seconds), then spin:
    a plain sleep overshoots by up to a few hundred microseconds."""
    pause = deadline - time.perf_counter() - 3e-4
    if pause > 0:
        time.sleep(pause)
    while time.perf_counter() < deadline:
        pass


class RigClient:
    def __init__(self, host: str, port: int, key: bytes, timeout: float = 0.02):
        if not timeout > 0:
            raise LinkError(f"the reply timeout must be > 0 s, not {timeout!r}")
        try:
            self.address = (socket.gethostbyname(host), int(port))
        except OSError as e:
            raise LinkError(f"cannot resolve rig host {host!r}: {e}") from None
        self.key = key
        self.timeout = timeout
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.seq = int(time.time() * 1000) & 0x3FFFFFFF     # fresh start above old sessions
        self.guard = SequenceGuard()
        self.session = 0          #: the rig's session number, from the first answer
        self._nonce = 0           # the opening handshake's, until its open is sent
        self._opens = ()          # the seqs of the opens sent: a late answer to one still serves
        self.dropped = {"malformed": 0, "auth": 0, "stale": 0, "replay": 0}

    def _send(self, datagram: bytes) -> None:
        try:
            self.sock.sendto(datagram, self.address)
        except OSError:
            pass            # a refused or unreachable rig shows as a missing answer

    def exchange(self, u, t: float, dt: float = 1e-3) -> SampleDatagram | ExcavatorSampleDatagram | None:
        """Send a command (``u`` for the step from ``t`` to ``t + dt``: a number for the
        boom, four for the excavator's valves) or, with ``u=None``, a status request; return the rig's answer, or None when none arrives
        within the timeout.  The first exchange opens a session (a hello of a fresh
        nonce, then the open with the rig's cookie) before a command can be sent."""
        deadline = time.perf_counter() + self.timeout
        if not self.session:
            opened = self._open(t, deadline)
            if opened is None:
                return None
            self.session = opened.session
            if u is None:
                return opened
        self.seq += 1
        seq = self.seq
        if u is None:
            self._send(encode_status(seq, t, self.key, self.session))
        elif isinstance(u, (int, float)):
            self._send(encode_command(seq, t, u, self.key, dt, self.session))
        else:
            self._send(encode_excavator_command(seq, t, tuple(u), self.key, dt, self.session))
        return self._answer(seq, deadline)

    def _open(self, t: float, deadline: float):
        """The handshake (``protocol.py``): a hello, the rig's challenge, the open with its
        cookie; the rig's answer to the open (with the new session), or None at
        ``deadline``.  An answer that comes late, a challenge or an open's sample, serves
        the next attempt."""
        if not self._nonce:           # one nonce until its open is sent
            self._nonce = secrets.randbits(64) or 1
        self.seq += 1
        self._send(encode_status(self.seq, t, self.key, 0, self._nonce))
        msg = self._answer(self._opens, deadline, self._nonce)
        if isinstance(msg, Challenge):
            self.seq += 1
            self._send(encode_status(self.seq, t, self.key, 0, self._nonce, msg.cookie))
            self._nonce = 0           # its cookie is spent: another open needs another hello
            self._opens = (*self._opens[-7:], self.seq)
            msg = self._answer(self._opens, deadline)
        if msg is None or not msg.session:
            return None
        self._opens = ()
        return msg

    def _answer(self, seq, deadline: float, nonce: int | None = None):
        """The rig's answer to ``seq`` (authentic, of this session, not a replay; ``seq``
        may be a tuple of them), or None at ``deadline``; with ``nonce``, also the
        challenge to a hello of that nonce (this one or an earlier one's, late)."""
        seqs = seq if isinstance(seq, tuple) else (seq,)
        while True:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                return None
            ready, _, _ = select.select([self.sock], [], [], remaining)
            if not ready:
                return None
            try:
                data, _ = self.sock.recvfrom(2048)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:          # ICMP port unreachable: the rig is gone
                time.sleep(min(remaining, 0.001))
                continue
            try:
                msg = decode(data, self.key)
            except Malformed:
                self.dropped["malformed"] += 1
                continue
            except BadMac:
                self.dropped["auth"] += 1
                continue
            if isinstance(msg, Challenge):       # ours: to a hello of this nonce, with a cookie
                ours = nonce is not None and msg.nonce == nonce and bool(msg.cookie)
            elif isinstance(msg, (SampleDatagram, ExcavatorSampleDatagram)):
                ours = msg.echo in seqs and not (self.session and msg.session != self.session)
            else:
                self.dropped["malformed"] += 1
                continue
            if not ours:                            # another request's, or late
                self.dropped["stale"] += 1
                continue
            if not self.guard.accept(msg.seq):
                self.dropped["replay"] += 1
                continue
            return msg

    def close(self) -> None:
        self.sock.close()


__all__ = ["parse_address", "wait_until", "RigClient"]
