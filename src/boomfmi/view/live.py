"""The live feed: a running co-simulation sends its samples to ``boomfmi view --live``.

An excavator's sample has, instead of the boom's values, each joint's (``swing``,
``boom``, ``arm``, ``bucket``) ``angle_<joint>``, ``p_a_<joint>``, ``p_b_<joint>`` (the
model's) and ``..._measured`` (the machine's), and the tip forces ``f_tip_<a>`` (the
rig's truth), ``f_tip_est_<a>`` and ``f_reflect_<a>`` for a = x, y, z (``frames.py``);
it needs every joint's angle of the model or of the machine.

Each datagram is ``MAGIC`` (``b"BFV1"``), one UTF-8 JSON object, and the HMAC-SHA256
(32 bytes) of the two under the rig link's shared key (``link.protocol.load_key``: a key
file or ``$BOOMFMI_LINK_KEY``; the feed never runs unauthenticated).  The object is a
flat sample in the run's column names (``t``; the model's ``alpha, x, p_a, p_b``; the
machine's ``alpha_measured, x_measured, p_a_measured, p_b_measured``; ``f_est, f_ext,
f_reflect``; gauge pressures [Pa]; null where the value is not a finite number) with the
boom's geometry ``geom`` = [a, b, h, l_min] [m] (an excavator's sample has none) and the
feed's own fields: ``session`` (16 hex digits the sender draws at random), ``seq``
(strictly increasing within the session) and ``sent`` (the sender's wall clock, Unix
time [s]).

The sender keeps to ``rate`` datagrams per second of wall time, whatever the
simulation's pace, and never blocks: a view that is not running loses the datagrams,
not the simulation's time.

The receiver (:class:`FeedGuard` and :func:`open_datagram`) drops, and counts by
reason, a datagram that is too long (``malformed``), that lacks the magic or whose MAC
does not verify under its key (``unauthenticated``), whose JSON or fields break the schema
below, or whose geometry is not a linkage (``invalid``), one sent more than
``FRESHNESS`` seconds from the receiver's clock (``stale``: so the two machines' clocks
must agree to within that), and one whose ``seq`` is not above the last accepted in its
session (``replayed``).  A datagram's JSON is parsed only after its MAC verifies.
"""
from __future__ import annotations

import collections
import json
import math
import re
import secrets
import socket
import time

from ..link.client import parse_address
from ..link.protocol import MAC_SIZE, load_key, mac, verifies
from ..physics import Geometry, ParameterError, check_geometry
from ..physics import linkage

#: the view's frame rate is capped by what the sender sends
DEFAULT_RATE = 60.0
MAGIC = b"BFV1"
#: the longest datagram accepted [bytes] (a sample is about 500)
MAX_DATAGRAM = 2048
#: the largest difference between the sender's clock and the receiver's [s]
FRESHNESS = 30.0
#: sessions a receiver remembers (the latest); an older one's datagrams are new again,
#: but only within FRESHNESS of their sending
MAX_SESSIONS = 64
#: a sample's value fields and their bounds (|value| <= bound); null allowed
BOUNDS = {
    "alpha": 2 * math.pi, "alpha_measured": 2 * math.pi,
    "x": 10.0, "x_measured": 10.0,                          # m
    "p_a": 1e8, "p_b": 1e8, "p_a_measured": 1e8, "p_b_measured": 1e8,   # Pa gauge
    "f_est": 1e8, "f_ext": 1e8, "f_reflect": 1e8,           # N
}
#: the excavator's joints (the linkage's ``physics.linkage.JOINTS``) and its sample's fields
EXCAVATOR_JOINTS = linkage.JOINTS
BOUNDS.update({f"{q}_{j}{s}": bound for j in EXCAVATOR_JOINTS for s in ("", "_measured")
               for q, bound in (("angle", 2 * math.pi), ("p_a", 1e8), ("p_b", 1e8))})
BOUNDS.update({f"{f}_{a}": 1e8 for f in ("f_tip", "f_tip_est", "f_reflect") for a in "xyz"})
MAX_TIME = 1e9                  # |t| [s]
MAX_LENGTH = 10.0               # the longest linkage length accepted [m]
REASONS = ("malformed", "unauthenticated", "invalid", "stale", "replayed")


class Refused(ValueError):
    """A datagram the view drops: ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


def _number(name: str, v, bound: float, null: bool = False):
    if v is None and null:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise Refused("invalid", f"{name} must be a number, not {type(v).__name__}")
    v = float(v)
    if not math.isfinite(v) or abs(v) > bound:
        raise Refused("invalid", f"{name} = {v!r} is not a finite number within +-{bound:g}")
    return v


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def _no_duplicates(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"the key {k[:40]!r} appears twice")
        out[k] = v
    return out


def strict_loads(text):
    """``json.loads`` that refuses what JSON is not (NaN, Infinity) and a key given twice:
    raises ``ValueError``.  Count the nesting first (:func:`json_depth`)."""
    return json.loads(text, parse_constant=_no_constant, object_pairs_hook=_no_duplicates)


def geometry(value) -> Geometry:
    """The sample's ``geom`` as a :class:`Geometry`, or :class:`Refused` unless it is four
    finite positive lengths (h >= 0) of at most MAX_LENGTH that make the linkage's
    triangle (``physics.check_geometry``)."""
    if not isinstance(value, list) or len(value) != 4:
        raise Refused("invalid", "geom must be a list of four numbers [a, b, h, l_min]")
    geom = Geometry(*(_number(f"geom.{k}", v, MAX_LENGTH) for k, v in zip(Geometry._fields, value)))
    try:
        check_geometry(geom, 0.0)
    except ParameterError as e:
        raise Refused("invalid", f"geom: {e}") from None
    return geom


def check_sample(obj) -> dict:
    """The sample with its numbers as floats (and ``geom`` a :class:`Geometry`), or
    :class:`Refused` (reason ``invalid``) unless it keeps to the module's schema."""
    if not isinstance(obj, dict):
        raise Refused("invalid", f"a sample must be a JSON object, not {type(obj).__name__}")
    unknown = set(obj) - set(BOUNDS) - {"t", "geom", "session", "seq", "sent"}
    if unknown:
        raise Refused("invalid", f"unknown fields {sorted(k[:40] for k in unknown)[:5]}")
    session = obj.get("session")
    if not (isinstance(session, str) and re.fullmatch(r"[0-9a-f]{16}", session)):
        raise Refused("invalid", "session must be 16 lower-case hex digits")
    seq = obj.get("seq")
    if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < 2 ** 63:
        raise Refused("invalid", "seq must be an integer in [0, 2**63)")
    out = {"session": session, "seq": seq, "sent": _number("sent", obj.get("sent"), 1e12),
           "t": _number("t", obj.get("t"), MAX_TIME)}
    if "geom" in obj:
        out["geom"] = geometry(obj["geom"])
    for k, bound in BOUNDS.items():
        if k in obj:
            out[k] = _number(k, obj[k], bound, null=True)
    if any(f"angle_{j}{s}" in obj for j in EXCAVATOR_JOINTS for s in ("", "_measured")):
        if not any(all(out.get(f"angle_{j}{s}") is not None for j in EXCAVATOR_JOINTS) for s in ("", "_measured")):
            raise Refused("invalid", "an excavator's sample needs every joint's angle_<joint> or angle_<joint>_measured")
    elif out.get("alpha") is None and out.get("alpha_measured") is None:
        raise Refused("invalid", "a sample needs alpha or alpha_measured")
    return out


def seal(obj: dict, key: bytes) -> bytes:
    """One datagram: MAGIC, the JSON of ``obj`` and their HMAC-SHA256 under ``key``."""
    payload = MAGIC + json.dumps(obj, allow_nan=False, separators=(",", ":")).encode()
    return payload + mac(payload, key)


def open_datagram(data: bytes, key: bytes) -> dict:
    """The checked sample of a datagram (see :func:`check_sample`), or :class:`Refused`
    (malformed, unauthenticated or invalid; freshness and replay are :class:`FeedGuard`'s)."""
    if len(data) > MAX_DATAGRAM:
        raise Refused("malformed", f"{len(data)} bytes, more than {MAX_DATAGRAM}")
    if len(data) < len(MAGIC) + MAC_SIZE or not data.startswith(MAGIC):
        raise Refused("unauthenticated", "not signed: no BFV1 magic, or too short to hold a MAC")
    payload, tag = data[:-MAC_SIZE], data[-MAC_SIZE:]
    if not verifies(payload, tag, key):
        raise Refused("unauthenticated", "the MAC does not verify under the view's key")
    body = payload[len(MAGIC):]
    if json_depth(body) > 2:
        raise Refused("invalid", "the sample nests deeper than its geom list")
    try:
        obj = strict_loads(body.decode("utf-8"))
    except (ValueError, RecursionError) as e:          # UnicodeDecodeError is a ValueError
        raise Refused("invalid", f"not a JSON sample: {str(e)[:120]}") from None
    return check_sample(obj)


def json_depth(text) -> int:
    """How deep JSON ``text`` (str or bytes) nests its arrays and objects, strings
    skipped; counted before parsing, so that depth never reaches the parser."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    depth = deepest = 0
    in_string = escaped = False
    for c in text:
        if in_string:
            if escaped:
                escaped = False
            elif c == "\\":
                escaped = True
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


class FeedGuard:
    """Freshness and replay: accepts a sample sent within ``window`` seconds of
    ``clock()`` whose ``seq`` is above the last accepted in its session (of the
    ``max_sessions`` latest)."""

    def __init__(self, window: float = FRESHNESS, max_sessions: int = MAX_SESSIONS, clock=time.time):
        self.window, self.max_sessions, self.clock = window, max_sessions, clock
        self.sessions: collections.OrderedDict[str, int] = collections.OrderedDict()

    def check(self, sample: dict) -> None:
        """Raise :class:`Refused` (stale or replayed) unless the sample is new."""
        late = self.clock() - sample["sent"]
        if abs(late) > self.window:
            when = f"{late:.1f} s ago" if late > 0 else f"{-late:.1f} s ahead of this clock"
            raise Refused("stale", f"sent {when}, more than {self.window:g} s (are the two clocks set?)")
        last = self.sessions.get(sample["session"])
        if last is not None and sample["seq"] <= last:
            raise Refused("replayed", f"seq {sample['seq']} of session {sample['session']} "
                                      f"is not above {last}")

    def accept(self, sample: dict) -> None:
        """Record the sample's seq as its session's last."""
        self.sessions[sample["session"]] = sample["seq"]
        self.sessions.move_to_end(sample["session"])
        while len(self.sessions) > self.max_sessions:
            self.sessions.popitem(last=False)


class LiveSender:
    """``monitor`` for :meth:`CoSimulation.simulate`: picks the sample's columns from
    each recorded row and sends it, signed with ``key``, to ``url`` (udp://HOST:PORT).

    ``columns`` maps a sample name to ``(column, offset)``: the value sent is
    ``row[column] + offset`` (the offset turns an absolute pressure into gauge).
    ``geom`` is the boom's [a, b, h, l_min]; None (the excavator's samples) sends none."""

    def __init__(self, url: str, columns: dict[str, tuple[str, float]], geom=None, rate: float = DEFAULT_RATE,
                 key: bytes | None = None):
        if not rate > 0:
            raise ValueError(f"the live view's rate must be > 0 per second, not {rate!r}")
        if not key:
            key = load_key()                 # $BOOMFMI_LINK_KEY, else LinkError
        self.address = parse_address(url)
        # only the fields a sample may carry (BOUNDS): the view refuses a sample with others
        self.columns = {k: c for k, c in columns.items() if k in BOUNDS}
        self.period = 1.0 / rate
        self.geom = None if geom is None else [float(v) for v in geom]
        self.key, self.session, self.seq = key, secrets.token_hex(8), 0
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self._index = None
        self._next = 0.0
        self.sent = 0

    def __call__(self, names: list[str], row) -> None:
        now = time.perf_counter()
        if now < self._next:
            return
        self._next = now + self.period
        if self._index is None:
            where = {n: i for i, n in enumerate(names)}
            self._index = {k: (where[c], off) for k, (c, off) in self.columns.items() if c in where}
        self.seq += 1
        sample = {"session": self.session, "seq": self.seq, "sent": time.time(), "t": float(row[0])}
        if self.geom is not None:
            sample["geom"] = self.geom
        for k, (i, off) in self._index.items():
            v = float(row[i]) + off
            sample[k] = v if math.isfinite(v) else None
        try:
            self.sock.sendto(seal(sample, self.key), self.address)
            self.sent += 1
        except (OSError, ValueError):    # no view listening (yet), or a geometry JSON cannot carry
            pass

    def close(self) -> None:
        self.sock.close()


__all__ = ["DEFAULT_RATE", "MAGIC", "MAX_DATAGRAM", "FRESHNESS", "MAX_SESSIONS", "BOUNDS", "EXCAVATOR_JOINTS",
           "MAX_TIME", "MAX_LENGTH", "REASONS", "Refused", "strict_loads", "geometry", "check_sample", "seal",
           "open_datagram", "json_depth", "FeedGuard", "LiveSender"]
