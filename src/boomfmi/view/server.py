"""The virtual view's server: a page on 127.0.0.1 and the frames over a WebSocket.

``GET /`` is the page (``web/index.html``, ``app.js``, ``style.css``); ``/vendor/...``
serves the exact files of three.js and uPlot that the page loads (:data:`VENDOR_FILES`,
from the ``node_modules`` that the set-up installed with npm), so the page needs nothing
from outside the machine (its Content-Security-Policy forbids it).  Nothing else is
served: any other path is a 404, a malformed one (NUL, ``..``, a backslash, any
percent-encoding) a 400.  ``GET /ws`` is the WebSocket; messages are JSON:

server -> page
    ``{"type": "hello", "mode": "replay" | "live", "source": str, "t0": s,
    "duration": s or null, "scene": the run's mechanism's (``frames.BoomMechanism.scene``, or
    ``frames.LinkageMechanism.scene`` with ``"kind": "excavator"``), "has_model": bool,
    "has_truth": bool, "rate": frames per second}``, then
    ``{"type": "history", "frames": [...]}`` (the last 10 s, for the plots), then
    ``{"type": "frame", ...}`` (``frames.py``) at ``rate`` per second while playing,
    and one after each seek or pause; ``{"type": "error", "message": str}`` for a
    message the server refuses.
page -> server (replay)
    ``{"cmd": "play"}``, ``{"cmd": "pause"}``, ``{"cmd": "seek", "t": s}``,
    ``{"cmd": "speed", "value": factor}``: exactly these fields, numbers finite, ``t``
    within +-MAX_TIME, ``value`` in (0, 100]; at most MAX_MESSAGE bytes, no nesting
    (:func:`parse_command`).  Anything else is answered with an error message and the
    connection goes on; MAX_BAD_MESSAGES of them close it (1008, policy violation); a
    message longer than WS_MAX_MESSAGE closes it at once (1009, too big).

Trust.  Every request, the WebSocket's upgrade included, must name the server by a
loopback name (``Host``: 127.0.0.1, localhost or [::1], with the server's port) and,
when it has an ``Origin``, come from a page of one (``http://`` one of those names and
the port), unless that origin is configured (``allowed_origins``, ``boomfmi view
--allow-origin``); else it is refused with 403 and the reason.  So a web page of another
site in the user's browser can neither read the frames (Origin) nor reach the server by
a name of its own that resolves to 127.0.0.1 (Host, DNS rebinding).  Every response
carries :data:`SECURITY_HEADERS` (the page's own CSP, with ``frame-ancestors 'none'``);
responses to requests that the HTTP parser itself cannot read (aiohttp's 400 before any
routing) are aiohttp's plain text and carry none of them.  At most MAX_PAGES pages are
served at once (503 beyond).

In replay each connection has its own player.  In live mode every page gets the
frames of the samples arriving on the UDP address (``live.py``: signed with the link's
key, checked, and dropped and counted by reason otherwise), at the pace they come.  A
page that loses its connection reconnects and is sent hello and history again.
"""
from __future__ import annotations

import asyncio
import base64
import collections
import hashlib
import json
import logging
import math
import re
import signal
import sys
import time
from pathlib import Path

from aiohttp import WSCloseCode, WSMsgType, web
from aiohttp.http_exceptions import HttpProcessingError

from ..link.client import parse_address
from ..link.protocol import load_key
from ..physics import Geometry
from ..physics import reference_rig
from .frames import BoomMechanism, LinkageMechanism, Run, live_frame, load_run
from .live import FeedGuard, Refused, json_depth, open_datagram, strict_loads

WEB = Path(__file__).resolve().parent / "web"
MODULES = WEB / "node_modules"
#: the page's own files: URL path -> (file, content type, Cache-Control)
PAGE_FILES = {"/app.js": (WEB / "app.js", "text/javascript", "no-store"),
              "/style.css": (WEB / "style.css", "text/css", "no-store")}
#: the files of node_modules the page loads (its import map, three.js's own import of
#: its core, uPlot's style sheet), served at /vendor/<file>
VENDOR_FILES = ("three/build/three.module.js", "three/build/three.core.js",
                "three/examples/jsm/controls/OrbitControls.js",
                "uplot/dist/uPlot.esm.js", "uplot/dist/uPlot.min.css")
_TYPES = {".js": "text/javascript", ".css": "text/css"}
RATE = 50.0                   # replay frames per second
HISTORY = 10.0                # seconds of plot history sent on (re)connection and seek
LOOPBACK = ("127.0.0.1", "localhost", "[::1]")
MAX_MESSAGE = 1024            # bytes of one page message (they are some 40)
WS_MAX_MESSAGE = 64 * 1024    # beyond this aiohttp closes the connection (1009)
MAX_BAD_MESSAGES = 20         # refused messages on one connection before it is closed (1008)
MAX_PAGES = 16                # WebSocket connections at once
MAX_TIME = 1e9                # |t| of a seek [s]
SECURITY_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Resource-Policy": "same-origin",
    "Content-Security-Policy": "default-src 'none'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'",
}
PAGE = web.AppKey("page", tuple)
RUN = web.AppKey("run", object)
HUB = web.AppKey("hub", object)
ORIGINS = web.AppKey("origins", frozenset)
PAGES = web.AppKey("pages", list)             # [the WebSocket connections open]
SOCKETS = web.AppKey("sockets", set)          # the open WebSockets, closed at shutdown


class ViewError(RuntimeError):
    """The view cannot start (a library not installed, a bad address)."""


class BadMessage(ValueError):
    """A page's message the server refuses."""


def check_modules() -> None:
    """Raise ViewError unless the three.js and uPlot files the page loads are installed."""
    for file in VENDOR_FILES:
        if not (MODULES / file).is_file():
            raise ViewError(f"{file.partition('/')[0]} is not installed in {MODULES} (no {file}): "
                            f"run `npm ci --prefix {WEB}` (scripts/bootstrap.sh does this)")


def _page() -> tuple[bytes, str]:
    """index.html and its Content-Security-Policy (the inline import map by hash)."""
    html = (WEB / "index.html").read_bytes()
    digests = [base64.b64encode(hashlib.sha256(m.group(1)).digest()).decode()
               for m in re.finditer(rb"<script[^>]*>(.*?)</script>", html, re.S) if m.group(1).strip()]
    scripts = " ".join(f"'sha256-{d}'" for d in digests)
    csp = ("default-src 'self'; "
           f"script-src 'self' {scripts}; "
           "style-src 'self' 'unsafe-inline'; "
           "img-src 'self' data: blob:; "
           "connect-src 'self' ws://127.0.0.1:* ws://localhost:*; "
           "object-src 'none'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
    return html, csp


# -- trust: Host, Origin, path, headers ---------------------------------------------------------
_NAME = r"(\[[0-9a-f:.]+\]|[a-z0-9](?:[a-z0-9.-]*[a-z0-9])?)"
_HOST = re.compile(_NAME + r"(?::([0-9]{1,5}))?")
_ORIGIN = re.compile(r"(https?)://" + _NAME + r"(?::([0-9]{1,5}))?")


def parse_origin(text: str) -> tuple[str, str, int] | None:
    """``scheme://host[:port]`` -> (scheme, host, port), lower case, the scheme's port
    by default; None unless it is one."""
    m = _ORIGIN.fullmatch(text.strip().lower())
    if not m:
        return None
    port = int(m.group(3)) if m.group(3) else {"http": 80, "https": 443}[m.group(1)]
    return (m.group(1), m.group(2), port) if 0 < port < 65536 else None


def _parse_host(text: str) -> tuple[str, int] | None:
    m = _HOST.fullmatch(text.strip().lower())
    if not m:
        return None
    port = int(m.group(2)) if m.group(2) else 80
    return (m.group(1), port) if 0 < port < 65536 else None


def allowed_origins(origins) -> frozenset:
    """The configured origins, parsed; ViewError naming one that is not
    ``http(s)://HOST[:PORT]``."""
    out = set()
    for o in origins or ():
        parsed = parse_origin(o)
        if parsed is None:
            raise ViewError(f"{o!r} is not an origin of the form http://HOST[:PORT] (no path, no wildcard)")
        out.add(parsed)
    return frozenset(out)


def _refuse(status: int, reason: str) -> web.Response:
    title = {400: "Bad Request", 403: "Forbidden", 503: "Service Unavailable"}[status]
    return web.Response(status=status, text=f"{status} {title}: {reason}\n")


def _shown(text: str) -> str:
    return repr(text[:80] + ("..." if len(text) > 80 else ""))


def trust_problem(request: web.Request) -> tuple[int, str] | None:
    """(status, reason) when the request's Host, Origin or path is refused, else None."""
    sock = request.transport.get_extra_info("sockname") if request.transport else None
    if not sock:
        return 403, "the connection is gone"
    port = sock[1]
    extra = request.app[ORIGINS]
    hosts = request.headers.getall("Host", [])
    if len(hosts) != 1:
        return 403, f"a request needs exactly one Host header, not {len(hosts)}"
    host = _parse_host(hosts[0])
    if host is None or not ((host[0] in LOOPBACK and host[1] == port) or any(host == (h, p) for _, h, p in extra)):
        return 403, (f"Host {_shown(hosts[0])} is not this server's: the view answers to 127.0.0.1, "
                     f"localhost or [::1] with port {port} only (--allow-origin adds a name)")
    origins = request.headers.getall("Origin", [])
    if len(origins) > 1:
        return 403, "a request may have one Origin header, not several"
    if origins:
        origin = parse_origin(origins[0])
        if origin is None or not (origin in {("http", h, port) for h in LOOPBACK} or origin in extra):
            return 403, (f"Origin {_shown(origins[0])} is not allowed: the view's pages are "
                         f"http://127.0.0.1:{port}, http://localhost:{port} and http://[::1]:{port} "
                         f"(--allow-origin adds one)")
    path = request.raw_path.partition("?")[0]
    if ("\0" in path or "%" in path or "\\" in path or not path.startswith("/")
            or any(seg in (".", "..") for seg in path.split("/"))):
        return 400, f"malformed path {_shown(path)} (NUL, a backslash, '.' or '..' segments or percent-encoding)"
    return None


@web.middleware
async def _guard(request: web.Request, handler):
    problem = trust_problem(request)
    if problem is not None:
        return _refuse(*problem)
    return await handler(request)


async def _security_headers(request: web.Request, response: web.StreamResponse) -> None:
    for name, value in SECURITY_HEADERS.items():
        if name not in response.headers:
            response.headers[name] = value
    csp = response.headers["Content-Security-Policy"]
    if "frame-ancestors" not in csp:
        response.headers["Content-Security-Policy"] = csp.rstrip("; ") + "; frame-ancestors 'none'"


class _ServerLog(logging.LoggerAdapter):
    """aiohttp's server log, with a client's malformed request (and a dropped
    connection) as one line instead of a traceback; the server's own faults keep theirs."""

    def exception(self, msg, *args, exc_info=True, **kwargs):
        exc = exc_info if isinstance(exc_info, BaseException) else sys.exc_info()[1]
        if isinstance(exc, (HttpProcessingError, ConnectionError)):
            self.warning(f"{msg} (refused): %s", *args, f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:240])
        else:
            super().exception(msg, *args, exc_info=exc_info, **kwargs)


# -- the page and its files ---------------------------------------------------------------------
async def _index(request: web.Request) -> web.Response:
    html, csp = request.app[PAGE]
    return web.Response(body=html, content_type="text/html", charset="utf-8",
                        headers={"Content-Security-Policy": csp, "Cache-Control": "no-store"})


def _file(path: Path, content_type: str, cache: str):
    async def handler(request: web.Request) -> web.FileResponse:
        return web.FileResponse(path, headers={"Content-Type": content_type, "Cache-Control": cache})
    return handler


def _hello(mode: str, source: str, t0: float, duration, the_scene: dict,
           has_model: bool, has_truth: bool) -> str:
    return json.dumps({"type": "hello", "mode": mode, "source": source, "t0": t0,
                       "duration": duration, "scene": the_scene, "has_model": has_model,
                       "has_truth": has_truth, "rate": RATE})


# -- the page's messages ------------------------------------------------------------------------
def parse_command(data) -> dict:
    """A page's message (str or bytes) as a checked command, or BadMessage saying why:
    one JSON object of at most MAX_MESSAGE bytes, nothing nested, a known ``cmd`` and
    exactly its fields, finite and in their bounds (see the module's text)."""
    if not isinstance(data, str):
        raise BadMessage("binary messages are not accepted: send JSON text")
    if len(data) > MAX_MESSAGE or len(data.encode("utf-8", "replace")) > MAX_MESSAGE:
        raise BadMessage(f"a message may have at most {MAX_MESSAGE} bytes")
    if json_depth(data) > 1:
        raise BadMessage("a message is one flat JSON object: nothing nested")
    try:
        msg = strict_loads(data)
    except (ValueError, RecursionError) as e:
        raise BadMessage(f"not JSON: {str(e)[:120]}") from None
    if not isinstance(msg, dict):
        raise BadMessage(f"a message must be a JSON object, not {type(msg).__name__}")
    cmd = msg.get("cmd")
    fields = {"play": (), "pause": (), "seek": ("t",), "speed": ("value",)}
    if not isinstance(cmd, str) or cmd not in fields:
        shown = _shown(cmd) if isinstance(cmd, str) else repr(cmd)[:40]
        raise BadMessage(f"unknown command {shown}: give cmd play, pause, seek or speed")
    extra = set(msg) - {"cmd", *fields[cmd]}
    if extra:
        raise BadMessage(f"{cmd} takes {', '.join(fields[cmd]) or 'no fields'}, "
                         f"not {', '.join(sorted(_shown(k) for k in extra)[:5])}")
    for name in fields[cmd]:
        v = msg.get(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise BadMessage(f"{cmd}: {name} must be a number, not {type(v).__name__}")
        try:
            v = float(v)
        except OverflowError:                     # an integer beyond any float (400 digits)
            raise BadMessage(f"{cmd}: {name} must be finite, not an integer of "
                             f"{len(str(abs(v)))} digits") from None
        if not math.isfinite(v):
            raise BadMessage(f"{cmd}: {name} must be finite, not {v}")
        msg[name] = v
    if cmd == "seek" and abs(msg["t"]) > MAX_TIME:
        raise BadMessage(f"seek: t must be within +-{MAX_TIME:g} s")
    if cmd == "speed" and not 0 < msg["value"] <= 100:
        raise BadMessage(f"speed: value must be in (0, 100], not {msg['value']:g}")
    return msg


async def _send(ws: web.WebSocketResponse, text: str) -> bool:
    """Send unless the connection is gone; False when it is."""
    if ws.closed:
        return False
    try:
        await ws.send_str(text)
        return True
    except ConnectionError:
        return False


async def _commands(ws: web.WebSocketResponse, apply) -> None:
    """Read the page's messages, refusing the bad ones, until it goes; ``apply(cmd)``
    handles a good one."""
    bad = 0
    async for msg in ws:
        if msg.type == WSMsgType.ERROR:          # too long or not a WebSocket frame: aiohttp closes
            break
        if msg.type not in (WSMsgType.TEXT, WSMsgType.BINARY):
            continue
        try:
            cmd = parse_command(msg.data)
        except BadMessage as e:
            bad += 1
            await _send(ws, json.dumps({"type": "error", "message": str(e)}))
            if bad >= MAX_BAD_MESSAGES:
                await ws.close(code=WSCloseCode.POLICY_VIOLATION,
                               message=f"{bad} invalid messages".encode())
                break
            continue
        await apply(cmd)


def _open(request: web.Request) -> web.WebSocketResponse | web.Response:
    """A WebSocket for the page, counted in PAGES (the caller uncounts it when done), or
    a 503 when MAX_PAGES are open."""
    pages = request.app[PAGES]
    if pages[0] >= MAX_PAGES:
        return _refuse(503, f"{MAX_PAGES} pages are open already; close one")
    pages[0] += 1
    ws = web.WebSocketResponse(heartbeat=5.0, max_msg_size=WS_MAX_MESSAGE)
    request.app[SOCKETS].add(ws)
    return ws


async def _close_sockets(app: web.Application) -> None:
    """At shutdown (SIGINT, SIGTERM) every page is told the server is going (1001) at
    once; else aiohttp waits for each page's connection to end by itself."""
    for ws in list(app[SOCKETS]):
        await ws.close(code=WSCloseCode.GOING_AWAY, message=b"the view is stopping")


# -- replay ----------------------------------------------------------------------------------
class Player:
    """One page's replay: the time shown, playing or paused, and the speed."""

    def __init__(self, run: Run):
        self.run, self.t, self.playing, self.speed = run, float(run.t[0]), True, 1.0
        self._wall = None

    def advance(self, now: float) -> None:
        if self.playing and self._wall is not None:
            self.t += (now - self._wall) * self.speed
            if self.t >= self.run.t[-1]:
                self.t, self.playing = float(self.run.t[-1]), False
        self._wall = now

    def command(self, msg: dict) -> bool:
        """Apply a page's command (checked by :func:`parse_command`); True when the
        plots need the history again."""
        cmd = msg.get("cmd")
        if cmd == "play":
            again = self.t >= self.run.t[-1]          # at the end: from the start
            if again:
                self.t = float(self.run.t[0])
            self.playing = True
            return again
        elif cmd == "pause":
            self.playing = False
        elif cmd == "seek":
            t = float(msg["t"])
            if not math.isfinite(t):
                raise ValueError(f"seek: t must be finite, not {t}")
            self.t = min(max(t, float(self.run.t[0])), float(self.run.t[-1]))
            return True
        elif cmd == "speed":
            value = float(msg["value"])
            if not 0 < value <= 100:
                raise ValueError(f"speed must be in (0, 100], not {value}")
            self.speed = value
        else:
            raise ValueError(f"unknown command {cmd!r}")
        return False

    def frame(self) -> str:
        return json.dumps(dict(self.run.frame(self.t), playing=self.playing))

    def history(self) -> str:
        return json.dumps({"type": "history", "frames": self.run.history(self.t, HISTORY)})


async def _replay_ws(request: web.Request) -> web.StreamResponse:
    run: Run = request.app[RUN]
    ws = _open(request)
    if not isinstance(ws, web.WebSocketResponse):
        return ws
    player, ticker = Player(run), None

    async def tick():
        period = 1.0 / RATE
        next_at = time.perf_counter()
        while not ws.closed:
            next_at += period
            await asyncio.sleep(max(0.0, next_at - time.perf_counter()))
            was = player.playing
            player.advance(time.perf_counter())
            if was and not await _send(ws, player.frame()):   # the stop at the end goes too
                break

    async def apply(cmd: dict) -> None:
        player.advance(time.perf_counter())
        try:
            again = player.command(cmd)
        except ValueError as e:
            await _send(ws, json.dumps({"type": "error", "message": str(e)}))
            return
        if again:
            await _send(ws, player.history())
        await _send(ws, player.frame())

    try:
        await ws.prepare(request)
        await _send(ws, _hello("replay", str(run.path), float(run.t[0]), run.duration, run.scene(),
                               run.model is not None, run.has_truth))
        await _send(ws, player.history())
        player.advance(time.perf_counter())
        await _send(ws, player.frame())
        ticker = asyncio.create_task(tick())
        await _commands(ws, apply)
    except (ConnectionError, asyncio.CancelledError):
        pass
    finally:
        request.app[PAGES][0] -= 1
        request.app[SOCKETS].discard(ws)
        if ticker is not None:
            ticker.cancel()
    return ws


# -- live ------------------------------------------------------------------------------------
class LiveHub(asyncio.DatagramProtocol):
    """Receives the co-simulation's samples, signed with ``key`` (``live.py``), and
    hands their frames to every page; drops, and counts in ``dropped`` by reason, every
    datagram that is not an authentic, fresh, new and valid sample.  A sample of the
    other machine (the excavator's after the boom's, or back) starts afresh: the plots'
    history is cleared and every page is sent a new hello with that machine's scene."""

    def __init__(self, source: str, key: bytes, guard: FeedGuard | None = None):
        if not key:
            raise ViewError("the live view needs the link key: it does not run unauthenticated")
        self.source, self.key = source, key
        self.guard = guard or FeedGuard()
        self.geom = Geometry()
        self.kind = "boom"
        self.pages: set[asyncio.Queue] = set()
        self.history: collections.deque = collections.deque()
        self.received = 0
        self.dropped: collections.Counter = collections.Counter()

    @property
    def rejected(self) -> int:
        """Datagrams dropped, for whatever reason."""
        return sum(self.dropped.values())

    def _drop(self, reason: str, why: str, addr) -> None:
        self.dropped[reason] += 1
        n = self.rejected
        if n in (1, 10, 100, 1000) or n % 10000 == 0:
            where = f"{addr[0]}:{addr[1]}" if isinstance(addr, tuple) and len(addr) >= 2 else str(addr)
            print(f"view: dropped a live datagram from {where} ({reason}: {why}); dropped so far: "
                  + ", ".join(f"{k} {v}" for k, v in sorted(self.dropped.items())), file=sys.stderr, flush=True)

    def datagram_received(self, data: bytes, addr) -> None:
        try:
            sample = open_datagram(data, self.key)
            self.guard.check(sample)
            geom = sample.get("geom", self.geom)
            frame = live_frame(sample, geom)
            text = json.dumps(dict(frame, playing=True), allow_nan=False)
        except Refused as e:
            self._drop(e.reason, str(e), addr)
            return
        except (ValueError, ArithmeticError, TypeError, KeyError) as e:
            self._drop("invalid", f"{type(e).__name__}: {e}", addr)
            return
        self.guard.accept(sample)
        self.geom = geom
        self.received += 1
        kind = frame.get("kind", "boom")
        if kind != self.kind:                        # the other machine: its scene, afresh
            self.kind = kind
            self.history.clear()
            hello = self.hello()
            for q in self.pages:
                while not q.empty():
                    q.get_nowait()
                q.put_nowait(hello)
        if self.history and frame["t"] < self.history[-1]["t"]:
            self.history.clear()                     # a new run: start the plots afresh
        self.history.append(frame)
        while frame["t"] - self.history[0]["t"] > HISTORY:
            self.history.popleft()
        for q in self.pages:
            if q.full():
                q.get_nowait()                       # a slow page skips, it never stalls the rest
            q.put_nowait(text)

    def hello(self) -> str:
        last = self.history[-1] if self.history else None
        mech = LinkageMechanism() if self.kind == "excavator" else BoomMechanism(self.geom, reference_rig.L)
        the_scene, truth = mech.scene(), mech.truth
        return _hello("live", self.source, last["t"] if last else 0.0, None, the_scene,
                      bool(last and last["model"] is not None), bool(last and last.get(truth) is not None))

    def summary(self) -> str:
        dropped = ", ".join(f"{k} {v}" for k, v in sorted(self.dropped.items())) or "none"
        return f"samples shown: {self.received}; datagrams dropped: {dropped}"


async def _live_ws(request: web.Request) -> web.StreamResponse:
    hub: LiveHub = request.app[HUB]
    ws = _open(request)
    if not isinstance(ws, web.WebSocketResponse):
        return ws
    queue: asyncio.Queue = asyncio.Queue(maxsize=8)
    pumping = None

    async def pump():
        while await _send(ws, await queue.get()):
            pass

    async def apply(cmd: dict) -> None:
        await _send(ws, json.dumps({"type": "error", "message": f"the live view follows the feed: "
                                                                f"{cmd['cmd']} has nothing to do"}))

    try:
        await ws.prepare(request)
        hub.pages.add(queue)
        await _send(ws, hub.hello())
        await _send(ws, json.dumps({"type": "history", "frames": list(hub.history)}))
        pumping = asyncio.create_task(pump())
        await _commands(ws, apply)
    except (ConnectionError, asyncio.CancelledError):
        pass
    finally:
        request.app[PAGES][0] -= 1
        request.app[SOCKETS].discard(ws)
        hub.pages.discard(queue)
        if pumping is not None:
            pumping.cancel()
    return ws


# -- the app ---------------------------------------------------------------------------------
def make_app(run: Run | None = None, hub: LiveHub | None = None, origins=()) -> web.Application:
    """The page, the vendored libraries and the WebSocket, for a replay or live hub;
    ``origins``: pages of other origins (``http://HOST:PORT``) allowed besides the
    loopback names at the server's port."""
    check_modules()
    app = web.Application(middlewares=[_guard],
                          handler_args={"logger": _ServerLog(logging.getLogger("aiohttp.server"), {})})
    app[PAGE] = _page()
    app[RUN], app[HUB] = run, hub
    app[ORIGINS] = allowed_origins(origins)
    app[PAGES] = [0]
    app[SOCKETS] = set()
    app.on_shutdown.append(_close_sockets)
    app.on_response_prepare.append(_security_headers)
    app.router.add_get("/", _index)
    for url, (path, ctype, cache) in PAGE_FILES.items():
        app.router.add_get(url, _file(path, ctype, cache))
    for file in VENDOR_FILES:
        app.router.add_get(f"/vendor/{file}", _file(MODULES / file, _TYPES[Path(file).suffix], "max-age=3600"))
    app.router.add_get("/ws", _replay_ws if run is not None else _live_ws)
    return app


async def _serve(app: web.Application, host: str, port: int, hub: LiveHub | None, udp, ready) -> None:
    loop = asyncio.get_running_loop()
    transport = None
    if hub is not None:
        try:
            transport, _ = await loop.create_datagram_endpoint(lambda: hub, local_addr=udp)
        except OSError as e:
            raise ViewError(f"cannot listen for the live feed on {hub.source}: {e}") from None
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    try:
        await site.start()
    except OSError as e:
        await runner.cleanup()
        raise ViewError(f"cannot serve the view on {host}:{port}: {e}") from None
    bound = runner.addresses[0][1]
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    if ready:
        ready(f"http://{host}:{bound}/")
    try:
        await stop.wait()
    finally:
        if transport is not None:
            transport.close()
            print(f"view: live feed: {hub.summary()}", file=sys.stderr, flush=True)
        await runner.cleanup()


def serve(replay=None, live: str | None = None, host: str = "127.0.0.1", port: int = 0, ready=None,
          key: bytes | None = None, origins=()) -> None:
    """Serve the view of a run file (``replay``) or of a live feed (``live``,
    udp://HOST:PORT to listen on, its datagrams signed with ``key``: by default
    ``link.protocol.load_key()``'s) until SIGINT or SIGTERM; ``ready(url)`` once
    serving.  ``origins``: see :func:`make_app`."""
    if (replay is None) == (live is None):
        raise ViewError("give a run to replay or a live address, not both or neither")
    allowed_origins(origins)                  # a bad one before anything is read
    hub = None
    if live is not None:
        if not key:
            key = load_key()
        udp = parse_address(live)
        hub = LiveHub(live, key)
    else:
        udp = None
    run = load_run(replay) if replay is not None else None
    app = make_app(run, hub, origins)
    asyncio.run(_serve(app, host, port, hub, udp, ready))


__all__ = ["WEB", "MODULES", "PAGE_FILES", "VENDOR_FILES", "RATE", "HISTORY", "LOOPBACK", "MAX_MESSAGE",
           "WS_MAX_MESSAGE", "MAX_BAD_MESSAGES", "MAX_PAGES", "MAX_TIME", "SECURITY_HEADERS", "PAGE", "RUN", "HUB",
           "ORIGINS", "PAGES", "SOCKETS", "ViewError", "BadMessage", "check_modules", "parse_origin",
           "allowed_origins", "trust_problem", "parse_command", "Player", "LiveHub", "make_app", "serve"]
