"""The virtual view's server trusts nobody (issue 15): other web pages, other host names,
malformed paths, hostile WebSocket messages and forged, replayed or absurd live
datagrams are refused with a clear reason, counted where they are datagrams, and the
connection, the server and the next good frame carry on.  Every test runs on 127.0.0.1
(an aiohttp test server on port 0, or ``boomfmi view`` in a subprocess), bounded in
time, and no test leaves a traceback in the log.  /tmp/reliability_view.md lists the
cases with what happened before and what happens now."""
from __future__ import annotations

import asyncio
import contextlib
import hashlib
import hmac
import json
import logging
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import aiohttp
import pytest
from aiohttp.test_utils import TestServer

from boomfmi.link import protocol
from boomfmi.physics import Geometry, reference_rig
from boomfmi.view import live, server
from boomfmi.view.frames import live_frame, load_run
from boomfmi.view.live import FeedGuard, LiveSender, seal
from boomfmi.view.server import LiveHub, make_app

KEY = b"hostile-view-key-0123456789abcdef"
GEOM = [reference_rig.a, reference_rig.b, reference_rig.h, reference_rig.l_min]
FROM = ("127.0.0.1", 40000)
TIMEOUT = 30.0


# -- harness --------------------------------------------------------------------------------------
@pytest.fixture(autouse=True)
def no_traceback(caplog, capfd):
    """Whatever a test throws at the server, the log holds no traceback."""
    caplog.set_level(logging.WARNING)
    yield
    out, err = capfd.readouterr()
    assert "Traceback" not in caplog.text and "Traceback" not in err, caplog.text + err
    assert not [r for r in caplog.records if r.exc_info], caplog.text
    sys.stderr.write(err)


@pytest.fixture(scope="module")
def run_file(tmp_path_factory) -> Path:
    from boomfmi.experiments import held
    from boomfmi.recording import write_recording
    from boomfmi.rig.offline import run_offline
    return write_recording(tmp_path_factory.mktemp("hostile_view") / "run.csv",
                           run_offline({"seed": 1}, held([(0.5, 7.0), (0.5, 3.0)]), 1.0))


def go(coro):
    return asyncio.run(asyncio.wait_for(coro, TIMEOUT))


@contextlib.asynccontextmanager
async def served(app):
    """(port, client session) of ``app`` on 127.0.0.1, any free port."""
    srv = TestServer(app, host="127.0.0.1", port=0)
    await srv.start_server()
    try:
        async with aiohttp.ClientSession() as session:
            yield srv.port, session
    finally:
        await srv.close()


async def raw(port: int, target: bytes, headers: dict | None = None, method: bytes = b"GET",
              host: bytes | None = None, version: bytes = b"HTTP/1.1"):
    """One request written byte for byte (no client normalises its path): (status,
    headers with lower-case names, body)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    lines = [method + b" " + target + b" " + version]
    if host is not False:
        lines.append(b"Host: " + (host if host is not None else b"127.0.0.1:%d" % port))
    lines += [f"{k}: {v}".encode() for k, v in (headers or {}).items()]
    if not any(k.lower() == "upgrade" for k in headers or {}):
        lines.append(b"Connection: close")
    writer.write(b"\r\n".join(lines) + b"\r\n\r\n")
    await writer.drain()
    head = await reader.readuntil(b"\r\n\r\n")
    status_line, *header_lines = head.decode("latin-1").split("\r\n")
    out = {}
    for line in header_lines:
        if ":" in line:
            k, _, v = line.partition(":")
            out[k.strip().lower()] = v.strip()
    n = int(out.get("content-length", "0")) if method != b"HEAD" else 0
    body = await reader.readexactly(n) if n else b""
    writer.close()
    return int(status_line.split()[1]), out, body


async def next_of(ws, kind: str, pred=lambda m: True, timeout: float = 5.0) -> dict:
    """The next message of ``type`` kind (and ``pred``) from the server, skipping others."""
    end = time.monotonic() + timeout
    while True:
        msg = await ws.receive(timeout=max(0.01, end - time.monotonic()))
        assert msg.type == aiohttp.WSMsgType.TEXT, (msg.type, msg.data, msg.extra)
        data = json.loads(msg.data)
        if data["type"] == kind and pred(data):
            return data


async def still_serves(ws, run, t: float = 0.25) -> None:
    """The connection carries on: a pause and a seek give the frame at ``t``, the run's."""
    await ws.send_str(json.dumps({"cmd": "pause"}))
    await ws.send_str(json.dumps({"cmd": "seek", "t": t}))
    f = await next_of(ws, "frame", lambda f: not f["playing"] and abs(f["t"] - t) < 1e-12)
    assert f["machine"]["alpha"] == pytest.approx(run.frame(t)["machine"]["alpha"], abs=1e-12)


async def errors_for(ws, messages) -> list[str]:
    out = []
    for m in messages:
        if isinstance(m, bytes):
            await ws.send_bytes(m)
        else:
            await ws.send_str(m)
        out.append((await next_of(ws, "error"))["message"])
    return out


def sample(seq: int, session: str = "0123456789abcdef", **over) -> dict:
    s = {"session": session, "seq": seq, "sent": time.time(), "t": 1.0 + 0.01 * seq, "geom": GEOM,
         "alpha": 0.8, "x": 0.03, "p_a": 2e5, "p_b": 1e5, "alpha_measured": 0.75 + 0.001 * seq,
         "p_a_measured": 1.5e5, "f_est": -320.0}
    s.update(over)
    return s


def expected(s: dict) -> dict:
    keys = ("t", "alpha", "x", "p_a", "p_b", "alpha_measured", "x_measured", "p_a_measured", "p_b_measured",
            "f_est", "f_ext", "f_reflect")
    return live_frame({k: s[k] for k in keys if k in s}, Geometry(*s.get("geom", GEOM)))


def signed_body(body: bytes, key: bytes = KEY) -> bytes:
    payload = live.MAGIC + body
    return payload + hmac.new(key, payload, hashlib.sha256).digest()


def hub_with_page():
    hub = LiveHub("udp://127.0.0.1:0", KEY)
    page = asyncio.Queue(maxsize=1000)
    hub.pages.add(page)
    return hub, page


def assert_dropped_then_next_frame_right(hub, page, datagram: bytes, reason: str, seq: int) -> None:
    before, shown = hub.dropped[reason], hub.received
    while not page.empty():
        page.get_nowait()
    hub.datagram_received(datagram, FROM)
    assert hub.dropped[reason] == before + 1, dict(hub.dropped)
    assert hub.received == shown and page.empty()             # it reached no frame, no page
    good = sample(seq)
    hub.datagram_received(seal(good, KEY), FROM)
    assert hub.received == shown + 1
    assert hub.history[-1] == expected(good)
    assert json.loads(page.get_nowait()) == json.loads(json.dumps(dict(expected(good), playing=True)))


# -- 1. Origin ------------------------------------------------------------------------------------
def test_1_a_websocket_from_another_origin_is_refused_with_403(run_file):
    async def main():
        async with served(make_app(load_run(run_file))) as (port, session):
            for origin in ("http://evil.example", "null", f"http://127.0.0.1.evil.example:{port}",
                           f"https://127.0.0.1:{port}", f"http://127.0.0.1:{port + 1}", "not an origin"):
                with pytest.raises(aiohttp.WSServerHandshakeError) as e:
                    await session.ws_connect(f"http://127.0.0.1:{port}/ws", origin=origin)
                assert e.value.status == 403, origin
                status, _, body = await raw(port, b"/ws", {"Origin": origin, "Upgrade": "websocket",
                                                           "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
                                                           "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="})
                assert status == 403 and b"Origin" in body and b"is not allowed" in body, body
            status, _, body = await raw(port, b"/", {"Origin": "http://evil.example"})
            assert status == 403 and b"Origin 'http://evil.example' is not allowed" in body
            for name in ("127.0.0.1", "localhost", "[::1]"):              # the loopback pages are served
                async with session.ws_connect(f"http://127.0.0.1:{port}/ws", origin=f"http://{name}:{port}",
                                              headers={"Host": f"{name}:{port}"}) as ws:
                    assert (await next_of(ws, "hello"))["mode"] == "replay"
    go(main())


# -- 2. the zero geometry -------------------------------------------------------------------------
def test_2_a_zero_geometry_datagram_is_dropped_and_later_frames_are_right():
    hub, page = hub_with_page()
    hub.datagram_received(seal(sample(1), KEY), FROM)
    # the hostile test's datagram: unauthenticated JSON with a zero geometry
    unsigned = json.dumps(dict(sample(2), geom=[0, 0, 0, 0])).encode()
    assert_dropped_then_next_frame_right(hub, page, unsigned, "unauthenticated", 3)
    # the same, signed by a sender that holds the key: the geometry is refused
    assert_dropped_then_next_frame_right(hub, page, seal(sample(4, geom=[0, 0, 0, 0]), KEY), "invalid", 5)
    assert hub.geom == Geometry(*GEOM)
    hello = json.loads(hub.hello())
    assert hello["scene"]["a"] == reference_rig.a and hello["scene"]["C"][1] == pytest.approx(-reference_rig.h)


# -- 3. a message that is not an object -----------------------------------------------------------
def test_3_a_list_number_string_or_null_message_gets_an_error_and_the_connection_goes_on(run_file):
    run = load_run(run_file)

    async def main():
        async with served(make_app(run)) as (port, session):
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
                errors = await errors_for(ws, ["[]", "[1, 2]", "42", "-1.5", "null", '"play"', "true"])
                assert all("must be a JSON object" in e for e in errors), errors
                await still_serves(ws, run)
    go(main())


# -- 4. NaN seek, nesting -------------------------------------------------------------------------
def test_4_a_nan_seek_or_deeply_nested_message_gets_an_error_and_the_connection_goes_on(run_file):
    run = load_run(run_file)

    async def main():
        async with served(make_app(run)) as (port, session):
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
                errors = await errors_for(ws, ['{"cmd": "seek", "t": NaN}', '{"cmd": "seek", "t": Infinity}',
                                               '{"cmd": "seek", "t": -Infinity}', '{"cmd": "seek", "t": 1e400}',
                                               '{"cmd": "speed", "value": NaN}'])
                assert "NaN is not a JSON number" in errors[0] and "Infinity is not a JSON number" in errors[1]
                assert "-Infinity is not a JSON number" in errors[2]
                assert "t must be finite" in errors[3] and "NaN is not a JSON number" in errors[4]
                errors = await errors_for(ws, ["[" * 500 + "]" * 500, '{"cmd": "seek", "t": {"t": 1}}',
                                               "[" * 50_000])
                assert "nothing nested" in errors[0] and "nothing nested" in errors[1]
                assert "at most 1024 bytes" in errors[2]
                await still_serves(ws, run)
    go(main())


# -- 5. NUL in a path -----------------------------------------------------------------------------
def test_5_a_nul_in_a_vendor_path_is_a_400_not_a_500(run_file):
    async def main():
        async with served(make_app(load_run(run_file))) as (port, session):
            status, headers, body = await raw(port, b"/vendor/three/build/%00")
            assert status == 400 and b"malformed path" in body, body
            assert headers["x-content-type-options"] == "nosniff"
            status, _, body = await raw(port, b"/vendor/three/build/three.module.js%00.map")
            assert status == 400
            status, _, body = await raw(port, b"/vendor/three/build/\x00")    # the HTTP parser's own 400
            assert status == 400
            async with session.get(f"http://127.0.0.1:{port}/") as r:        # and the server goes on
                assert r.status == 200
    go(main())


# -- 6. .. in a path ------------------------------------------------------------------------------
@pytest.mark.parametrize("target", [b"/vendor/three/build/../package.json", b"/vendor/three/build/%2e%2e/package.json",
                                    b"/vendor/three/build/%2E%2E/package.json", b"/vendor/three/build/..%2fpackage.json",
                                    b"/vendor/three/build/..\\package.json", b"/vendor/../../web/index.html",
                                    b"/./app.js", b"/vendor/three/build/%252e%252e/package.json"])
def test_6_dot_dot_or_encoding_leaves_no_folder(run_file, target):
    async def main():
        async with served(make_app(load_run(run_file))) as (port, _):
            status, _, body = await raw(port, target)
            assert status == 400 and b"malformed path" in body, (status, body)
            assert b'"name"' not in body and b"<html" not in body
    go(main())


# -- Host -----------------------------------------------------------------------------------------
def test_a_request_naming_another_host_is_refused_with_403(run_file):
    """DNS rebinding: a page of evil.example whose name now resolves to 127.0.0.1 sends
    Host: evil.example:PORT and no Origin (it is its own origin)."""
    async def main():
        async with served(make_app(load_run(run_file))) as (port, session):
            for host in (b"evil.example:%d" % port, b"evil.example", b"127.0.0.1:%d" % (port + 1), b"127.0.0.1",
                         b"localhost.:%d" % port, b"127.0.0.2:%d" % port, b"0.0.0.0:%d" % port, b"", b"a b"):
                for target in (b"/", b"/app.js", b"/ws", b"/nothing"):
                    status, headers, body = await raw(port, target, host=host)
                    assert status == 403, (host, target, status)
                    assert b"is not this server's" in body and b"127.0.0.1, localhost or [::1]" in body, body
                    assert headers["x-frame-options"] == "DENY"
            status, _, body = await raw(port, b"/", host=False, version=b"HTTP/1.0")   # no Host at all
            assert status == 403 and b"exactly one Host header" in body
            for name in (b"127.0.0.1", b"localhost", b"LOCALHOST", b"[::1]"):
                status, _, _ = await raw(port, b"/", host=name + b":%d" % port)
                assert status == 200, name
    go(main())


def test_an_allowed_origin_is_served_and_a_malformed_one_is_refused(run_file, tmp_path):
    async def main():
        app = make_app(load_run(run_file), origins=["http://view.example:9000"])
        async with served(app) as (port, _):
            status, _, _ = await raw(port, b"/", {"Origin": "http://view.example:9000"}, host=b"view.example:9000")
            assert status == 200
            status, _, _ = await raw(port, b"/", {"Origin": "http://view.example:9001"}, host=b"view.example:9000")
            assert status == 403
            status, _, _ = await raw(port, b"/", host=b"view.example:9001")
            assert status == 403
    go(main())
    for bad in ("*", "http://view.example/path", "view.example:9000", "ftp://view.example"):
        with pytest.raises(server.ViewError, match="not an origin"):
            make_app(load_run(run_file), origins=[bad])
    out = subprocess.run([sys.executable, "-m", "boomfmi.cli", "view", "--replay", str(run_file), "--port", "0",
                          "--allow-origin", "http://x.example/page"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and "not an origin of the form http://HOST[:PORT]" in out.stderr, out.stderr


# -- security headers -----------------------------------------------------------------------------
def test_every_response_carries_the_security_headers(run_file):
    async def main():
        async with served(make_app(load_run(run_file))) as (port, _):
            cases = [(b"GET", b"/", {}, 200), (b"GET", b"/app.js", {}, 200), (b"GET", b"/style.css", {}, 200),
                     (b"GET", b"/vendor/three/build/three.core.js", {}, 200), (b"HEAD", b"/", {}, 200),
                     (b"GET", b"/nothing", {}, 404), (b"POST", b"/", {"Content-Length": "0"}, 405),
                     (b"GET", b"/a/../b", {}, 400), (b"GET", b"/", {"Origin": "http://evil.example"}, 403),
                     (b"GET", b"/ws", {}, 400),
                     (b"GET", b"/ws", {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
                                       "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}, 101)]
            for method, target, headers, want in cases:
                status, h, _ = await raw(port, target, headers, method=method)
                assert status == want, (method, target, status)
                assert h["x-content-type-options"] == "nosniff", target
                assert h["x-frame-options"] == "DENY" and h["referrer-policy"] == "no-referrer", target
                assert "frame-ancestors 'none'" in h["content-security-policy"], target
            _, h, _ = await raw(port, b"/")
            csp = h["content-security-policy"]                  # the page's strict CSP, merged
            assert re.search(r"script-src 'self' 'sha256-[A-Za-z0-9+/=]+'", csp) and "default-src 'self'" in csp
            assert "object-src 'none'" in csp and csp.count("frame-ancestors") == 1
    go(main())


# -- static allow-list ----------------------------------------------------------------------------
def test_only_the_pages_own_files_and_the_vendor_files_it_loads_are_served(run_file):
    async def main():
        async with served(make_app(load_run(run_file))) as (port, _):
            served_ok = {b"/app.js": "text/javascript", b"/style.css": "text/css",
                         **{b"/vendor/" + f.encode(): "text/" + ("css" if f.endswith(".css") else "javascript")
                            for f in server.VENDOR_FILES}}
            for target, ctype in served_ok.items():
                status, h, body = await raw(port, target)
                assert status == 200 and h["content-type"].startswith(ctype) and body, target
            for target in (b"/vendor/three/package.json", b"/vendor/three/build/three.cjs",
                           b"/vendor/three/build/three.webgpu.js", b"/vendor/three/src/Three.js",
                           b"/vendor/three/examples/jsm/controls/TrackballControls.js", b"/vendor/uplot/dist/uPlot.iife.js",
                           b"/vendor/uplot/package.json", b"/index.html", b"/package.json", b"/node_modules/three/package.json",
                           b"/vendor/three/build/", b"/vendor/", b"/app.js/", b"/APP.JS"):
                status, _, _ = await raw(port, target)
                assert status == 404, target
    go(main())


# -- the WebSocket's schema -----------------------------------------------------------------------
def test_every_websocket_message_is_checked_against_the_schema(run_file):
    run = load_run(run_file)

    async def main():
        async with served(make_app(run)) as (port, session):
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
                cases = {'{"cmd": "rm -rf"}': "unknown command 'rm -rf'", '{}': "unknown command None",
                         '{"cmd": 1}': "unknown command 1", '{"type": "seek", "t": 1}': "unknown command None",
                         '{"cmd": "seek"}': "t must be a number, not NoneType",
                         '{"cmd": "seek", "t": "1"}': "t must be a number, not str",
                         '{"cmd": "seek", "t": true}': "t must be a number, not bool",
                         '{"cmd": "seek", "t": 1e12}': "t must be within",
                         '{"cmd": "seek", "t": 1, "x": 2}': "seek takes t, not 'x'",
                         '{"cmd": "play", "t": 1}': "play takes no fields",
                         '{"cmd": "seek", "t": 1, "t": 2}': "appears twice",
                         '{"cmd": "speed", "value": 0}': "value must be in (0, 100]",
                         '{"cmd": "speed", "value": -3}': "value must be in (0, 100]",
                         '{"cmd": "speed", "value": 1000}': "value must be in (0, 100]",
                         '{"cmd": "pause"': "not JSON", "": "not JSON", "\ufeff{}": "not JSON",
                         '{"cmd": "seek", "t": 0.1, "pad": "' + "x" * 1100 + '"}': "at most 1024 bytes",
                         b'{"cmd": "play"}': "binary messages are not accepted"}
                errors = await errors_for(ws, list(cases))
                for (message, want), got in zip(cases.items(), errors):
                    assert want in got, (message, got)
                await still_serves(ws, run)
                await ws.send_str(json.dumps({"cmd": "speed", "value": 2}))   # the good ones still work
                await ws.send_str(json.dumps({"cmd": "play"}))
                await next_of(ws, "frame", lambda f: f["playing"])
    go(main())


def test_too_many_invalid_messages_close_the_connection_with_1008_and_the_server_goes_on(run_file):
    run = load_run(run_file)

    async def main():
        async with served(make_app(run)) as (port, session):
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
                for _ in range(server.MAX_BAD_MESSAGES):
                    await ws.send_str("null")
                while (msg := await ws.receive(timeout=5)).type == aiohttp.WSMsgType.TEXT:
                    pass
                assert msg.type == aiohttp.WSMsgType.CLOSE and msg.data == 1008, msg
                assert ws.close_code == 1008
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:  # a new page is served
                await still_serves(ws, run)
    go(main())


def test_an_oversized_message_closes_the_connection_with_1009_and_the_server_goes_on(run_file):
    run = load_run(run_file)

    async def main():
        async with served(make_app(run)) as (port, session):
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
                await ws.send_str('{"cmd": "play", "x": "' + "x" * (server.WS_MAX_MESSAGE + 10) + '"}')
                while (msg := await ws.receive(timeout=5)).type == aiohttp.WSMsgType.TEXT:
                    pass
                assert msg.type == aiohttp.WSMsgType.CLOSE and msg.data == 1009, msg
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
                await still_serves(ws, run)
    go(main())


def test_a_live_page_gets_an_error_for_any_command_and_goes_on():
    hub = LiveHub("udp://127.0.0.1:0", KEY)

    async def main():
        async with served(make_app(hub=hub)) as (port, session):
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
                assert (await next_of(ws, "hello"))["mode"] == "live"
                errors = await errors_for(ws, ['{"cmd": "seek", "t": NaN}', "[" * 500 + "]" * 500, "[]",
                                               '{"cmd": "pause"}'])
                assert "NaN" in errors[0] and "nothing nested" in errors[1] and "JSON object" in errors[2]
                assert "follows the feed" in errors[3]
                s = sample(1)
                hub.datagram_received(seal(s, KEY), FROM)
                f = await next_of(ws, "frame")
                assert f == json.loads(json.dumps(dict(expected(s), playing=True)))
    go(main())


def test_more_pages_than_the_limit_get_503(run_file, monkeypatch):
    monkeypatch.setattr(server, "MAX_PAGES", 2)
    run = load_run(run_file)
    app = make_app(run)

    async def main():
        async with served(app) as (port, session):
            url = f"http://127.0.0.1:{port}/ws"
            async with session.ws_connect(url) as a, session.ws_connect(url) as b:
                await next_of(a, "hello"), await next_of(b, "hello")
                with pytest.raises(aiohttp.WSServerHandshakeError) as e:
                    await session.ws_connect(url)
                assert e.value.status == 503
                status, _, body = await raw(port, b"/ws", {"Upgrade": "websocket", "Connection": "Upgrade",
                                                           "Sec-WebSocket-Version": "13",
                                                           "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="})
                assert status == 503 and b"2 pages are open already" in body
            for _ in range(200):                          # closed pages are uncounted
                if app[server.PAGES][0] == 0:
                    break
                await asyncio.sleep(0.01)
            assert app[server.PAGES][0] == 0
            async with session.ws_connect(url) as c:
                await still_serves(c, run)
    go(main())


# -- live datagrams: authentication ---------------------------------------------------------------
def test_unsigned_badly_signed_tampered_or_foreign_datagrams_are_dropped_and_counted():
    hub, page = hub_with_page()
    hub.datagram_received(seal(sample(1), KEY), FROM)
    good = seal(sample(2), KEY)
    cases = [
        (json.dumps(sample(2)).encode(), "unauthenticated"),                       # the old, unsigned format
        (seal(sample(2), b"another-key-0123456789abcdef"), "unauthenticated"),      # signed with another key
        (good[:20] + bytes([good[20] ^ 1]) + good[21:], "unauthenticated"),         # one bit of the payload flipped
        (good[:-1] + bytes([good[-1] ^ 1]), "unauthenticated"),                     # one bit of the MAC flipped
        (good[:-32], "unauthenticated"),                                            # the MAC cut off
        (live.MAGIC + json.dumps(sample(2)).encode() + b"\0" * 32, "unauthenticated"),
        (b"", "unauthenticated"), (b"BFV1", "unauthenticated"), (b"x" * 200, "unauthenticated"),
        (protocol.encode_sample(2, 0, 1.0, 5.0, 2e5, 1e5, 0.8, 0.0, 0.03, 1, 0, KEY), "unauthenticated"),  # the rig link's
        (signed_body(b" " * (live.MAX_DATAGRAM + 1)), "malformed"),                # too long, not even verified
    ]
    for seq, (datagram, reason) in enumerate(cases, start=3):
        assert_dropped_then_next_frame_right(hub, page, datagram, reason, 10 * seq)
    assert hub.rejected == len(cases)


def test_replayed_and_stale_datagrams_are_dropped_and_counted():
    hub, page = hub_with_page()
    first = seal(sample(1), KEY)
    hub.datagram_received(first, FROM)
    assert_dropped_then_next_frame_right(hub, page, first, "replayed", 2)                    # the same again
    assert_dropped_then_next_frame_right(hub, page, seal(sample(2), KEY), "replayed", 3)     # an old seq
    assert_dropped_then_next_frame_right(hub, page, seal(sample(100, sent=time.time() - 3600), KEY), "stale", 4)
    assert_dropped_then_next_frame_right(hub, page, seal(sample(101, sent=time.time() + 3600), KEY), "stale", 5)
    assert_dropped_then_next_frame_right(hub, page, seal(sample(1, session="fedcba9876543210",
                                                                sent=time.time() - 600), KEY), "stale", 6)
    other = sample(1, session="fedcba9876543210")                       # a second sender's session is its own
    hub.datagram_received(seal(other, KEY), FROM)
    assert hub.history[-1] == expected(other)
    assert dict(hub.dropped) == {"replayed": 2, "stale": 3}


def test_a_forgotten_session_is_new_again_only_while_fresh():
    now = [1000.0]
    guard = FeedGuard(window=30.0, max_sessions=2, clock=lambda: now[0])
    for session in ("a" * 16, "b" * 16, "c" * 16):          # the first is forgotten
        s = {"session": session, "seq": 5, "sent": now[0]}
        guard.check(s)
        guard.accept(s)
    guard.check({"session": "a" * 16, "seq": 5, "sent": now[0]})
    now[0] += 31
    with pytest.raises(live.Refused, match="sent 31.0 s ago, more than 30 s"):
        guard.check({"session": "a" * 16, "seq": 5, "sent": 1000.0})


# -- live datagrams: validation -------------------------------------------------------------------
@pytest.mark.parametrize("over, why", [
    ({"geom": [0, 0, 0, 0]}, "a"), ({"geom": [0.15, 0.3, 0.05, -0.2]}, "l_min"),
    ({"geom": [0.15, 0.3, 0.2, 0.2]}, "must not exceed a"), ({"geom": [0.15, 0.3, 0.05, 0.5]}, "longer than a + b"),
    ({"geom": [0.15, 0.3, 0.05, 0.1]}, "shorter than |a - b|"), ({"geom": [15.0, 30.0, 5.0, 20.0]}, "within +-10"),
    ({"geom": [0.15, 0.3, 0.05]}, "four numbers"), ({"geom": [0.15, 0.3, 0.05, "0.2"]}, "must be a number"),
    ({"geom": "0.15 0.3 0.05 0.2"}, "four numbers"), ({"geom": None}, "four numbers"),
    ({"alpha": 1e9}, "alpha"), ({"alpha_measured": "0.7"}, "must be a number"), ({"alpha": True}, "must be a number"),
    ({"p_a": 1e12}, "p_a"), ({"x": -50.0}, "x ="), ({"f_est": [1.0]}, "f_est must be a number"),
    ({"t": 1e300}, "t ="), ({"t": None}, "t must be a number"), ({"alpha": None, "alpha_measured": None}, "needs alpha"),
    ({"evil": 1}, "unknown fields"), ({"seq": -1}, "seq"), ({"seq": 1.5}, "seq"), ({"seq": 2 ** 64}, "seq"),
    ({"session": "../../etc"}, "session"), ({"session": None}, "session"), ({"sent": None}, "sent"),
])
def test_a_signed_datagram_outside_the_schema_or_physics_is_dropped_and_counted(over, why):
    hub, page = hub_with_page()
    hub.datagram_received(seal(sample(1), KEY), FROM)
    bad = sample(2)
    bad.update(over)
    with pytest.raises(live.Refused, match=re.escape(why)) as e:
        live.check_sample(json.loads(json.dumps(bad)))
    assert e.value.reason == "invalid"
    assert_dropped_then_next_frame_right(hub, page, seal(bad, KEY), "invalid", 3)


@pytest.mark.parametrize("body", [
    b'{"session": "0123456789abcdef", "seq": 2, "sent": %f, "t": NaN, "alpha": 0.8}',
    b'{"session": "0123456789abcdef", "seq": 2, "sent": %f, "t": 1, "alpha": Infinity}',
    b'{"session": "0123456789abcdef", "seq": 2, "sent": %f, "t": 1, "alpha": 1e999}',
    b'{"session": "0123456789abcdef", "seq": 2, "seq": 3, "sent": %f, "t": 1, "alpha": 0.8}',
    b'{"session": "0123456789abcdef", "seq": 2, "sent": %f, "t": 1, "alpha": 0.8, "geom": [[[[0.15]]]]}',
    b'[' * 1000 + b']' * 1000, b"\xff\xfe not utf-8 %f", b"[1, 2, 3] %f", b"null %f", b"%f",
])
def test_a_signed_datagram_that_is_not_a_finite_flat_json_sample_is_dropped(body):
    hub, page = hub_with_page()
    hub.datagram_received(seal(sample(1), KEY), FROM)
    if b"%f" in body:
        body = body.replace(b"%f", str(time.time()).encode())
    assert_dropped_then_next_frame_right(hub, page, signed_body(body), "invalid", 3)


def test_non_finite_values_the_sender_cannot_carry_go_as_null():
    hub, page = hub_with_page()
    s = sample(1, p_a=None, f_est=None, x=None)
    hub.datagram_received(seal(s, KEY), FROM)
    f = hub.history[-1]
    assert f["model"]["p_a"] is None and f["f_est"] is None
    assert f["model"]["x"] == pytest.approx(expected(s)["model"]["x"])         # x from alpha, at the geometry
    json.loads(page.get_nowait())                                               # the page's text is valid JSON


# -- end to end: sender, UDP, hub, page -------------------------------------------------------------
def test_the_page_sees_the_signed_senders_frames_and_none_of_a_forgers():
    hub = LiveHub("udp://127.0.0.1:0", KEY)

    async def main():
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(lambda: hub, local_addr=("127.0.0.1", 0))
        udp = transport.get_extra_info("sockname")[1]
        try:
            async with served(make_app(hub=hub)) as (port, session):
                async with session.ws_connect(f"http://127.0.0.1:{port}/ws") as ws:
                    await next_of(ws, "hello")
                    names = ["time", "boom_load.alpha", "hardware_bridge.alpha"]
                    cols = {"alpha": ("boom_load.alpha", 0.0), "alpha_measured": ("hardware_bridge.alpha", 0.0)}
                    forger = LiveSender(f"udp://127.0.0.1:{udp}", cols, [0, 0, 0, 0], rate=1e6,
                                        key=b"not-the-key-0123456789abcdef")
                    honest = LiveSender(f"udp://127.0.0.1:{udp}", cols, GEOM, rate=1e6, key=KEY)
                    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as plain:
                        for k in range(5):
                            forger(names, [9.0 + k, 0.1, 0.1])
                            plain.sendto(json.dumps({"t": 9.0, "alpha": 0.1, "geom": [0, 0, 0, 0]}).encode(),
                                         ("127.0.0.1", udp))
                            honest(names, [1.0 + k, 0.8, 0.75])
                            f = await next_of(ws, "frame")
                            assert f["t"] == 1.0 + k and f["machine"]["alpha"] == 0.75 and f["model"]["alpha"] == 0.8
                    forger.close(), honest.close()
                    for _ in range(100):
                        if hub.rejected == 10:
                            break
                        await asyncio.sleep(0.01)
            assert hub.received == 5 and dict(hub.dropped) == {"unauthenticated": 10}
        finally:
            transport.close()
    go(main())


# -- the command line ------------------------------------------------------------------------------
def _cli(*args, env=None, timeout=60):
    env = {k: v for k, v in os.environ.items() if k != protocol.KEY_ENV} if env is None else env
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=env)


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_live_mode_without_a_key_refuses_to_start_naming_the_options(tmp_path, run_file):
    udp = f"udp://127.0.0.1:{_free_udp_port()}"
    out = _cli("view", "--live", udp, "--port", "0")
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert "--key-file" in out.stderr and "$BOOMFMI_LINK_KEY" in out.stderr and "unauthenticated" in out.stderr
    out = _cli("simulate", tmp_path / "none.ssp", "--view", udp, "--out", tmp_path / "out.csv")
    assert out.returncode == 1 and "--key-file" in out.stderr and "$BOOMFMI_LINK_KEY" in out.stderr, out.stderr
    assert "none.ssp" not in out.stderr and not (tmp_path / "out.csv").exists()      # before anything runs
    short = tmp_path / "short.key"
    short.write_bytes(b"0123456789")
    out = _cli("view", "--live", udp, "--port", "0", "--key-file", short)
    assert out.returncode == 1 and "it needs at least 16" in out.stderr
    out = _cli("view", "--live", udp, "--port", "0", "--key-file", tmp_path / "missing.key")
    assert out.returncode == 1 and "cannot read the link key file" in out.stderr
    out = _cli("view", "--replay", run_file, "--port", "0", "--key-file", short)
    assert out.returncode == 1 and "--key-file checks the --live stream" in out.stderr
    out = _cli("simulate", tmp_path / "none.ssp", "--key-file", short, "--out", tmp_path / "out.csv")
    assert out.returncode == 1 and "--key-file signs the --view stream" in out.stderr


def test_boomfmi_view_live_with_a_key_file_shows_signed_samples_and_counts_the_rest(tmp_path):
    key_file = tmp_path / "link.key"
    key_file.write_bytes(KEY + b"\n")
    udp = _free_udp_port()
    env = {k: v for k, v in os.environ.items() if k != protocol.KEY_ENV}
    proc = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "view", "--live", f"udp://127.0.0.1:{udp}",
                             "--key-file", str(key_file), "--port", "0"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
        assert m, line

        async def main():
            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(f"http://127.0.0.1:{m.group(1)}/ws") as ws:
                    await next_of(ws, "hello")
                    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                        s.sendto(json.dumps(dict(sample(1), geom=[0, 0, 0, 0])).encode(), ("127.0.0.1", udp))
                        s.sendto(seal(sample(2, geom=[0, 0, 0, 0]), KEY), ("127.0.0.1", udp))
                        good = sample(3)
                        s.sendto(seal(good, KEY), ("127.0.0.1", udp))
                        s.sendto(seal(good, KEY), ("127.0.0.1", udp))
                    f = await next_of(ws, "frame")
                    assert f == json.loads(json.dumps(dict(expected(good), playing=True)))
                    await asyncio.sleep(0.2)
        go(main())
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert "samples shown: 1; datagrams dropped: invalid 1, replayed 1, unauthenticated 1" in err, err
