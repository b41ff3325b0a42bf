"""The rig link protocol: fixed-size authenticated datagrams, replay guard, keys."""
from __future__ import annotations

import pytest

from boomfmi.link import protocol as p

KEY = b"0123456789abcdef0123456789abcdef"


def test_every_kind_round_trips_at_the_fixed_size():
    cmd = p.encode_command(7, 1.25, 3.5, KEY)
    status = p.encode_status(8, 1.5, KEY)
    sample = p.encode_sample(9, p.FAILSAFE | p.LOCKSTEP, 2.0, 5.0, 6e5, 1e3, 0.7, -12.5, 0.03, 7, 4, KEY)
    assert len(cmd) == len(status) == len(sample) == p.DATAGRAM_SIZE == 112
    assert p.decode(cmd, KEY) == p.Command(7, 1.25, 3.5)
    assert p.decode(status, KEY) == p.StatusRequest(8, 1.5)
    assert p.decode(p.encode_command(7, 1.25, 3.5, KEY, session=0xDEADBEEF), KEY).session == 0xDEADBEEF
    assert p.decode(p.encode_status(8, 1.5, KEY, session=5), KEY).session == 5
    assert p.decode(p.encode_sample(9, 0, 2.0, 5, 0, 0, 0, 0, 0, 7, 4, KEY, session=6), KEY).session == 6
    s = p.decode(sample, KEY)
    assert (s.seq, s.t, s.p_a, s.f_ext, s.echo, s.rejected) == (9, 2.0, 6e5, -12.5, 7, 4)
    assert s.failsafe and s.lockstep


@pytest.mark.parametrize("mangle, error", [
    (lambda d: d[:-1], p.Malformed),                       # short
    (lambda d: d + b"\0", p.Malformed),                    # long
    (lambda d: bytes([d[0] ^ 1]) + d[1:], p.BadMac),      # a flipped payload byte
    (lambda d: d[:-1] + bytes([d[-1] ^ 0x80]), p.BadMac),  # a flipped MAC byte
])
def test_damaged_datagrams_are_refused(mangle, error):
    with pytest.raises(error):
        p.decode(mangle(p.encode_command(1, 0.0, 5.0, KEY)), KEY)


def test_wrong_key_is_refused():
    with pytest.raises(p.BadMac):
        p.decode(p.encode_command(1, 0.0, 5.0, KEY), b"another key of 32 bytes........!")


def test_wrong_version_is_malformed_even_when_authenticated():
    import hashlib
    import hmac
    payload = bytearray(p.encode_command(1, 0.0, 5.0, KEY)[:p.PAYLOAD_SIZE])
    payload[2] = 1                                        # version 1: no sessions
    forged = bytes(payload) + hmac.new(KEY, bytes(payload), hashlib.sha256).digest()
    with pytest.raises(p.Malformed, match="version 1"):
        p.decode(forged, KEY)


def test_non_finite_command_is_malformed():
    with pytest.raises(p.Malformed):
        p.decode(p.encode_command(1, 0.0, float("nan"), KEY), KEY)


def test_sequence_guard_refuses_replays_and_old_numbers():
    g = p.SequenceGuard()
    assert [g.accept(s) for s in (1, 2, 2, 5, 3, 6)] == [True, True, False, True, False, True]
    assert g.replayed == 2


def test_keys(tmp_path):
    assert p.load_key(env={p.KEY_ENV: "x" * 20}) == b"x" * 20
    f = tmp_path / "key"
    f.write_bytes(KEY + b"\n")
    assert p.load_key(f, env={}) == KEY
    with pytest.raises(p.LinkError, match="no link key: give a key file or set BOOMFMI_LINK_KEY"):
        p.load_key(None, env={})
    with pytest.raises(p.LinkError, match="at least 16"):
        p.load_key(None, env={p.KEY_ENV: "short"})
    with pytest.raises(p.LinkError, match="cannot read the link key file"):
        p.load_key(tmp_path / "missing", env={})
