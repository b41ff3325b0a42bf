"""The rig link protocol, version 3.

Every datagram of the boom is exactly ``DATAGRAM_SIZE`` = 112 bytes: an 80-byte payload and its
HMAC-SHA256 (32 bytes) under a shared key.  Integers and floats are little-endian.

Payload header (20 bytes), then the body, zero-padded to 80 bytes::

    magic  2s  b"BF"
    version u8  3
    kind    u8  1 command, 2 sample, 3 status request, 6 challenge
    seq     u32 the sender's sequence number, strictly increasing per sender
    flags   u32 samples: bit 0 fail-safe engaged, bit 1 rig in lockstep
    t       f64 commands: the sender's time [s]; samples: the rig's sample time [s]

    command body:  u f64 (valve command [V]), dt f64 (the step it is for [s]: a lockstep
                   rig advances by dt, once per distinct t, after stepping through the
                   steps whose commands it never got), session u32
    status body:   session u32 (asks for the current sample without stepping a lockstep
                   rig; session 0 opens a new session), nonce u64, cookie u64 (both 0
                   except in the opening handshake)
    challenge body: echo u32 (the seq of the status request this answers), nonce u64 (that
                   request's), cookie u64 (the rig's challenge for that nonce)
    sample body:   u_applied, p_a, p_b, alpha, f_ext, x (f64 each: V, Pa gauge, Pa gauge,
                   rad, N, m), echo u32 (the seq of the command or status request this
                   answers), rejected u32 (datagrams the rig has ignored so far), session
                   u32 (the session the answer belongs to)

Sessions.  A client opens a session in two exchanges.  Its *hello* (a status request of
session 0 and cookie 0) carries a fresh random nonce; the rig answers with a
*challenge* (kind 6), a cookie it derives from the nonce, its own secret and the
current :data:`OPEN_WINDOW` (so it keeps nothing for a hello).  The client's *open*
(session 0, the same nonce, that cookie) makes the rig draw a random session number
and answer with it, once: a cookie opens one session, and only within one to two
windows of being issued.  So a captured open replayed later, or again, opens nothing
and is counted (``stale opens``); a replayed hello costs an answer and nothing kept.
From then on the rig accepts from that session only sequence numbers above the last it
accepted in it, whatever address or port they come from.  A command of session 0, or
of a session the rig does not know, is refused.  So a captured datagram replayed from
another port is refused as a replay, and one replayed after its session has been
forgotten as of an unknown session; forging a datagram of a new session needs the key.
A rig keeps at most :data:`MAX_SESSIONS` sessions; to open one more it forgets the
least recently used one only if that has been idle for :data:`SESSION_IDLE` seconds,
and otherwise refuses the open (``opens refused``): an active session is never evicted.

The excavator (``shared/spec/excavator.md``: four valves, eight pressures, four angles)
adds two kinds, of the same version, header, sessions and MAC::

    kind 4, excavator command (112 bytes, as the boom's):  u_swing, u_boom, u_arm,
                   u_bucket f64 [V], dt f64 [s], session u32
    kind 5, excavator sample (``EXCAVATOR_DATAGRAM_SIZE`` = 224 bytes: a 192-byte
                   payload and its MAC): u_applied x 4, p_a x 4, p_b x 4 (Pa gauge),
                   angle x 4 (rad), f_tip x 3 (N, world frame), f64 each in joint order
                   swing, boom, arm, bucket; echo u32, rejected u32, session u32

An excavator rig answers a status request with an excavator sample.  The size says
which payload a datagram carries; a kind in a datagram of the other size is malformed.

Version 2 opened a session with a single status request of session 0, which a
replayed capture could repeat at will; a version-3 receiver drops a version-2 datagram
as malformed.

A receiver drops, and counts, a datagram of the wrong size, magic or version
(malformed), one whose MAC does not verify (authentication), and one whose sequence
number is not above the last accepted in its session (replay) or whose session is
unknown.
"""
from __future__ import annotations

import hashlib
import hmac
import math
import os
import struct
import time
from pathlib import Path
from typing import NamedTuple

MAGIC = b"BF"
VERSION = 3
PAYLOAD_SIZE = 80
MAC_SIZE = 32
DATAGRAM_SIZE = PAYLOAD_SIZE + MAC_SIZE
COMMAND, SAMPLE, STATUS = 1, 2, 3
EXCAVATOR_COMMAND, EXCAVATOR_SAMPLE = 4, 5
CHALLENGE = 6
EXCAVATOR_PAYLOAD_SIZE = 192
EXCAVATOR_DATAGRAM_SIZE = EXCAVATOR_PAYLOAD_SIZE + MAC_SIZE
FAILSAFE, LOCKSTEP = 1, 2
KEY_ENV = "BOOMFMI_LINK_KEY"
MIN_KEY_BYTES = 16
#: Sessions a rig keeps at most (one key, so also per key); a forgotten one's datagrams
#: are refused.
MAX_SESSIONS = 64
#: A session is forgotten for a new one only after this long without a datagram [s].
SESSION_IDLE = 10.0
#: A challenge's cookie opens a session within one to two of these windows [s].
OPEN_WINDOW = 2.0

_HEADER = struct.Struct("<2sBBIId")
_COMMAND = struct.Struct("<2sBBIIdddI")
_STATUS = struct.Struct("<2sBBIIdIQQ")
_CHALLENGE = struct.Struct("<2sBBIIdIQQ")
_SAMPLE = struct.Struct("<2sBBIId6dIII")
_EXCAVATOR_COMMAND = struct.Struct("<2sBBIId4ddI")
_EXCAVATOR_SAMPLE = struct.Struct("<2sBBIId19dIII")


class LinkError(Exception):
    """A link that cannot work (no key, bad address) or a datagram that is refused."""


class Malformed(LinkError):
    """Wrong size, magic, version or kind."""


class BadMac(LinkError):
    """The MAC does not verify under our key."""


class Command(NamedTuple):
    seq: int
    t: float
    u: float
    dt: float = 1e-3
    session: int = 0


class StatusRequest(NamedTuple):
    """A status request; of session 0, a hello (``cookie`` 0) or an open (the cookie of
    the rig's challenge to ``nonce``)."""
    seq: int
    t: float
    session: int = 0
    nonce: int = 0
    cookie: int = 0


class Challenge(NamedTuple):
    """The rig's answer to a hello: the cookie that opens a session for ``nonce``."""
    seq: int
    t: float
    echo: int
    nonce: int
    cookie: int


class SampleDatagram(NamedTuple):
    """A sample as the link carries it (the rig's ``rig.plant.Sample`` with the link's
    sequence number, flags, the command it echoes and the rejected-datagram count)."""
    seq: int
    flags: int
    t: float
    u_applied: float
    p_a: float
    p_b: float
    alpha: float
    f_ext: float
    x: float
    echo: int
    rejected: int
    session: int = 0

    @property
    def failsafe(self) -> bool:
        return bool(self.flags & FAILSAFE)

    @property
    def lockstep(self) -> bool:
        return bool(self.flags & LOCKSTEP)


class ExcavatorCommand(NamedTuple):
    """The four valve commands [V] (swing, boom, arm, bucket) for the step from ``t``."""
    seq: int
    t: float
    u: tuple
    dt: float = 1e-3
    session: int = 0


class ExcavatorSampleDatagram(NamedTuple):
    """An excavator rig's sample as the link carries it: per joint (swing, boom, arm,
    bucket) the command applied, the gauge pressures and the angle, and the true tip
    force (world frame), with the link's fields as :class:`SampleDatagram`'s."""
    seq: int
    flags: int
    t: float
    u_applied: tuple
    p_a: tuple
    p_b: tuple
    angle: tuple
    f_tip: tuple
    echo: int
    rejected: int
    session: int = 0

    @property
    def failsafe(self) -> bool:
        return bool(self.flags & FAILSAFE)

    @property
    def lockstep(self) -> bool:
        return bool(self.flags & LOCKSTEP)


def load_key(key_file: str | os.PathLike | None = None, env: dict | None = None) -> bytes:
    """The shared key: the contents of ``key_file``, else ``$BOOMFMI_LINK_KEY``.

    Raises :class:`LinkError` when neither gives one of at least 16 bytes: the link
    never runs unauthenticated.
    """
    env = os.environ if env is None else env
    if key_file:
        path = Path(key_file)
        try:
            key = path.read_bytes().strip()
        except OSError as e:
            raise LinkError(f"cannot read the link key file {path}: {e.strerror}") from None
        source = f"key file {path}"
    elif env.get(KEY_ENV):
        key = env[KEY_ENV].encode("utf-8")
        source = f"${KEY_ENV}"
    else:
        raise LinkError(f"no link key: give a key file or set {KEY_ENV}; "
                        f"the link does not run unauthenticated")
    if len(key) < MIN_KEY_BYTES:
        raise LinkError(f"the link key from {source} has {len(key)} bytes; it needs at least {MIN_KEY_BYTES}")
    return key


def mac(payload: bytes, key: bytes) -> bytes:
    """The HMAC-SHA256 of ``payload`` under ``key`` (MAC_SIZE bytes): what every signed
    datagram of boomfmi carries, the link's and the live view's."""
    return hmac.new(key, payload, hashlib.sha256).digest()


def verifies(payload: bytes, tag: bytes, key: bytes) -> bool:
    """Whether ``tag`` is ``payload``'s :func:`mac` under ``key`` (in constant time)."""
    return hmac.compare_digest(tag, mac(payload, key))


def _seal(payload: bytes, key: bytes, size: int = PAYLOAD_SIZE) -> bytes:
    payload = payload.ljust(size, b"\0")
    return payload + mac(payload, key)


def encode_command(seq: int, t: float, u: float, key: bytes, dt: float = 1e-3, session: int = 0) -> bytes:
    return _seal(_COMMAND.pack(MAGIC, VERSION, COMMAND, seq, 0, t, u, dt, session), key)


def encode_status(seq: int, t: float, key: bytes, session: int = 0, nonce: int = 0, cookie: int = 0) -> bytes:
    return _seal(_STATUS.pack(MAGIC, VERSION, STATUS, seq, 0, t, session, nonce, cookie), key)


def encode_challenge(seq: int, t: float, echo: int, nonce: int, cookie: int, key: bytes) -> bytes:
    """The rig's challenge: ``cookie`` opens one session for the hello ``echo`` of ``nonce``."""
    return _seal(_CHALLENGE.pack(MAGIC, VERSION, CHALLENGE, seq, 0, t, echo & 0xFFFFFFFF, nonce, cookie), key)


def encode_sample(seq: int, flags: int, t: float, u_applied: float, p_a: float, p_b: float,
                  alpha: float, f_ext: float, x: float, echo: int, rejected: int, key: bytes,
                  session: int = 0) -> bytes:
    return _seal(_SAMPLE.pack(MAGIC, VERSION, SAMPLE, seq, flags, t, u_applied, p_a, p_b,
                              alpha, f_ext, x, echo & 0xFFFFFFFF, rejected & 0xFFFFFFFF, session), key)


def encode_excavator_command(seq: int, t: float, u, key: bytes, dt: float = 1e-3, session: int = 0) -> bytes:
    """An excavator command: ``u`` the four valve commands [V] (swing, boom, arm, bucket)."""
    return _seal(_EXCAVATOR_COMMAND.pack(MAGIC, VERSION, EXCAVATOR_COMMAND, seq, 0, t, *u, dt, session), key)


def encode_excavator_sample(seq: int, flags: int, t: float, u_applied, p_a, p_b, angle, f_tip,
                            echo: int, rejected: int, key: bytes, session: int = 0) -> bytes:
    """An excavator sample: four each of u_applied, p_a, p_b, angle, and three of f_tip."""
    return _seal(_EXCAVATOR_SAMPLE.pack(MAGIC, VERSION, EXCAVATOR_SAMPLE, seq, flags, t, *u_applied, *p_a, *p_b,
                                        *angle, *f_tip, echo & 0xFFFFFFFF, rejected & 0xFFFFFFFF, session),
                 key, EXCAVATOR_PAYLOAD_SIZE)


def decode(datagram: bytes, key: bytes):
    """A :class:`Command`, :class:`StatusRequest`, :class:`Challenge`, :class:`SampleDatagram`,
    :class:`ExcavatorCommand` or :class:`ExcavatorSampleDatagram`; raises
    :class:`Malformed` or :class:`BadMac`."""
    if len(datagram) == EXCAVATOR_DATAGRAM_SIZE:
        size = EXCAVATOR_PAYLOAD_SIZE
    elif len(datagram) == DATAGRAM_SIZE:
        size = PAYLOAD_SIZE
    else:
        raise Malformed(f"{len(datagram)} bytes, not {DATAGRAM_SIZE} (or {EXCAVATOR_DATAGRAM_SIZE}: an excavator sample)")
    payload, tag = datagram[:size], datagram[size:]
    if not verifies(payload, tag, key):
        raise BadMac("the MAC does not verify")
    magic, version, kind, seq, flags, t = _HEADER.unpack_from(payload)
    if magic != MAGIC or version != VERSION:
        raise Malformed(f"magic {magic!r} version {version}")
    if kind == COMMAND:
        u, dt, session = _COMMAND.unpack_from(payload)[6:9]
        if not (math.isfinite(u) and math.isfinite(dt) and 0.0 < dt <= 1.0):
            raise Malformed("a command whose u or dt is not a finite number (dt in (0, 1] s)")
        return Command(seq, t, u, dt, session)
    if kind == STATUS:
        return StatusRequest(seq, t, *_STATUS.unpack_from(payload)[6:9])
    if (kind == EXCAVATOR_SAMPLE) != (size == EXCAVATOR_PAYLOAD_SIZE):
        raise Malformed(f"kind {kind} in a datagram of {len(datagram)} bytes")
    if kind == CHALLENGE:
        return Challenge(seq, t, *_CHALLENGE.unpack_from(payload)[6:9])
    if kind == SAMPLE:
        f = _SAMPLE.unpack_from(payload)
        return SampleDatagram(seq, flags, *f[5:])
    if kind == EXCAVATOR_COMMAND:
        f = _EXCAVATOR_COMMAND.unpack_from(payload)
        u, dt, session = tuple(f[6:10]), f[10], f[11]
        if not (all(math.isfinite(c) for c in u) and math.isfinite(dt) and 0.0 < dt <= 1.0):
            raise Malformed("an excavator command whose u or dt is not a finite number (dt in (0, 1] s)")
        return ExcavatorCommand(seq, t, u, dt, session)
    if kind == EXCAVATOR_SAMPLE:
        f = _EXCAVATOR_SAMPLE.unpack_from(payload)
        v = f[6:25]
        return ExcavatorSampleDatagram(seq, flags, t, tuple(v[0:4]), tuple(v[4:8]), tuple(v[8:12]),
                                       tuple(v[12:16]), tuple(v[16:19]), *f[25:28])
    raise Malformed(f"unknown kind {kind}")


class OpenGuard:
    """The rig's side of the opening handshake: a cookie for a hello's nonce (derived from
    a secret of this guard's and the current :data:`OPEN_WINDOW`, so a hello costs no
    memory), and each cookie accepted once, within one to two windows of its issue.
    Keeps only the cookies used in the last two windows."""

    def __init__(self, window: float = OPEN_WINDOW, clock=time.monotonic):
        self.secret = os.urandom(32)
        self.window, self.clock = window, clock
        self.used: dict = {}            # cookie -> the window it was issued in

    def _cookie(self, nonce: int, window: int) -> int:
        return int.from_bytes(mac(struct.pack("<QQ", nonce, window), self.secret)[:8], "little") or 1

    def challenge(self, nonce: int) -> int:
        """The cookie that opens one session for ``nonce``."""
        return self._cookie(nonce, int(self.clock() // self.window))

    def accept(self, nonce: int, cookie: int) -> bool:
        """Whether an open of ``nonce`` with ``cookie`` opens a session: the cookie is this
        guard's for that nonce, of this window or the previous one, and not used yet."""
        now = int(self.clock() // self.window)
        self.used = {c: w for c, w in self.used.items() if w >= now - 1}
        for w in (now, now - 1):
            if cookie and hmac.compare_digest(cookie.to_bytes(8, "little"),
                                              self._cookie(nonce, w).to_bytes(8, "little")):
                if cookie in self.used:
                    return False
                self.used[cookie] = w
                return True
        return False


class SequenceGuard:
    """Accepts strictly increasing sequence numbers (of one session); counts what it
    refuses."""

    def __init__(self):
        self.last = -1
        self.replayed = 0

    def accept(self, seq: int) -> bool:
        if seq <= self.last:
            self.replayed += 1
            return False
        self.last = seq
        return True


__all__ = ["MAGIC", "VERSION", "PAYLOAD_SIZE", "MAC_SIZE", "DATAGRAM_SIZE", "COMMAND", "SAMPLE", "STATUS",
           "EXCAVATOR_COMMAND", "EXCAVATOR_SAMPLE", "CHALLENGE", "EXCAVATOR_PAYLOAD_SIZE", "EXCAVATOR_DATAGRAM_SIZE",
           "FAILSAFE", "LOCKSTEP", "KEY_ENV", "MIN_KEY_BYTES", "MAX_SESSIONS", "SESSION_IDLE", "OPEN_WINDOW",
           "LinkError", "Malformed", "BadMac", "Command", "StatusRequest", "Challenge", "SampleDatagram",
           "ExcavatorCommand", "ExcavatorSampleDatagram", "load_key", "mac", "verifies", "encode_command",
           "encode_status", "encode_challenge", "encode_sample", "encode_excavator_command", "encode_excavator_sample",
           "decode", "OpenGuard", "SequenceGuard"]
