"""The virtual view's server: a page on 127.0.0.1 and the frames over a WebSocket.

``GET /`` is the page (``web/index.html``, ``app.js``, ``style.css``); ``/vendor/three``
and ``/vendor/uplot`` serve three.js and uPlot from the ``node_modules`` that the
set-up installed with npm, so the page needs nothing from outside the machine (its
Content-Security-Policy forbids it).  ``GET /ws`` is the WebSocket; messages are JSON:

server -> page
    ``{"type": "hello", "mode": "replay" | "live", "source": str, "t0": s,
    "duration": s or null, "scene": frames.scene(), "has_model": bool,
    "has_truth": bool, "rate": frames per second}``, then
    ``{"type": "history", "frames": [...]}`` (the last 10 s, for the plots), then
    ``{"type": "frame", ...}`` (``frames.py``) at ``rate`` per second while playing,
    and one after each seek or pause.
page -> server (replay)
    ``{"cmd": "play"}``, ``{"cmd": "pause"}``, ``{"cmd": "seek", "t": s}``,
    ``{"cmd": "speed", "value": factor}``.

In replay each connection has its own player.  In live mode every page gets the
frames of the samples arriving on the UDP address (``live.py``), at the pace they
come.  A page that loses its connection reconnects and is sent hello and history
again.
"""
from __future__ import annotations

import asyncio
import base64
import collections
import hashlib
import json
import re
import signal
import sys
import time
from pathlib import Path

from aiohttp import WSMsgType, web

from ..link.client import parse_address
from ..physics import Geometry
from ..physics import reference_rig
from .frames import Run, live_frame, load_run, scene

WEB = Path(__file__).resolve().parent / "web"
MODULES = WEB / "node_modules"
#: what the page may load from node_modules: three.js's build and add-ons, uPlot's dist
VENDOR = {"three": ("build", "examples/jsm"), "uplot": ("dist",)}
RATE = 50.0                   # replay frames per second
HISTORY = 10.0                # seconds of plot history sent on (re)connection and seek


class ViewError(RuntimeError):
    """The view cannot start (a library not installed, a bad address)."""


def check_modules() -> None:
    """Raise ViewError unless three.js and uPlot are installed beside the page."""
    for name, file in (("three", "build/three.module.js"), ("uplot", "dist/uPlot.esm.js")):
        if not (MODULES / name / file).is_file():
            raise ViewError(f"{name} is not installed in {MODULES}: run `npm ci --prefix {WEB}` "
                            f"(scripts/bootstrap.sh does this)")


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
           "object-src 'none'; base-uri 'none'; form-action 'none'")
    return html, csp


async def _index(request: web.Request) -> web.Response:
    html, csp = request.app["page"]
    return web.Response(body=html, content_type="text/html", charset="utf-8",
                        headers={"Content-Security-Policy": csp, "Cache-Control": "no-store"})


async def _vendor(request: web.Request) -> web.StreamResponse:
    package, rest = request.match_info["package"], request.match_info["path"]
    if package not in VENDOR or not any(rest.startswith(d + "/") for d in VENDOR[package]):
        raise web.HTTPNotFound()
    root = (MODULES / package).resolve()
    path = (root / rest).resolve()
    if root not in path.parents or not path.is_file():
        raise web.HTTPNotFound()
    return web.FileResponse(path, headers={"Cache-Control": "max-age=3600"})


def _hello(mode: str, source: str, t0: float, duration, geom: Geometry, L: float,
           has_model: bool, has_truth: bool) -> str:
    return json.dumps({"type": "hello", "mode": mode, "source": source, "t0": t0,
                       "duration": duration, "scene": scene(geom, L), "has_model": has_model,
                       "has_truth": has_truth, "rate": RATE})


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
        """Apply a page's command; True when the plots need the history again."""
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
            self.t = min(max(float(msg["t"]), float(self.run.t[0])), float(self.run.t[-1]))
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


async def _replay_ws(request: web.Request) -> web.WebSocketResponse:
    run: Run = request.app["run"]
    ws = web.WebSocketResponse(heartbeat=5.0)
    await ws.prepare(request)
    player = Player(run)
    await ws.send_str(_hello("replay", str(run.path), float(run.t[0]), run.duration, run.geom, run.L,
                             run.model is not None, "f_ext" in run.forces))
    await ws.send_str(player.history())
    player.advance(time.perf_counter())
    await ws.send_str(player.frame())

    async def tick():
        period = 1.0 / RATE
        next_at = time.perf_counter()
        while not ws.closed:
            next_at += period
            await asyncio.sleep(max(0.0, next_at - time.perf_counter()))
            was = player.playing
            player.advance(time.perf_counter())
            if was:                      # the frame that shows a stop at the end goes too
                await ws.send_str(player.frame())

    ticker = asyncio.create_task(tick())
    try:
        async for msg in ws:
            if msg.type != WSMsgType.TEXT:
                continue
            try:
                player.advance(time.perf_counter())
                again = player.command(json.loads(msg.data))
            except (ValueError, KeyError, TypeError) as e:
                await ws.send_str(json.dumps({"type": "error", "message": str(e)}))
                continue
            if again:
                await ws.send_str(player.history())
            await ws.send_str(player.frame())
    except (ConnectionResetError, asyncio.CancelledError):
        pass
    finally:
        ticker.cancel()
    return ws


# -- live ------------------------------------------------------------------------------------
class LiveHub(asyncio.DatagramProtocol):
    """Receives the co-simulation's samples and hands their frames to every page."""

    def __init__(self, source: str):
        self.source = source
        self.geom = Geometry()
        self.pages: set[asyncio.Queue] = set()
        self.history: collections.deque = collections.deque()
        self.received = 0
        self.rejected = 0

    def datagram_received(self, data: bytes, addr) -> None:
        try:
            sample = json.loads(data)
            if "geom" in sample:
                self.geom = Geometry(*map(float, sample["geom"]))
            frame = live_frame(sample, self.geom)
        except (ValueError, TypeError, KeyError) as e:
            self.rejected += 1
            if self.rejected in (1, 10, 100, 1000):
                print(f"view: ignored a malformed sample from {addr[0]}:{addr[1]} "
                      f"({self.rejected} so far): {e}", file=sys.stderr, flush=True)
            return
        self.received += 1
        if self.history and frame["t"] < self.history[-1]["t"]:
            self.history.clear()                     # a new run: start the plots afresh
        self.history.append(frame)
        while frame["t"] - self.history[0]["t"] > HISTORY:
            self.history.popleft()
        text = json.dumps(dict(frame, playing=True))
        for q in self.pages:
            if q.full():
                q.get_nowait()                       # a slow page skips, it never stalls the rest
            q.put_nowait(text)

    def hello(self) -> str:
        last = self.history[-1] if self.history else None
        return _hello("live", self.source, last["t"] if last else 0.0, None, self.geom, reference_rig.L,
                      bool(last and last["model"] is not None), bool(last and last["f_ext"] is not None))


async def _live_ws(request: web.Request) -> web.WebSocketResponse:
    hub: LiveHub = request.app["hub"]
    ws = web.WebSocketResponse(heartbeat=5.0)
    await ws.prepare(request)
    queue: asyncio.Queue = asyncio.Queue(maxsize=8)
    hub.pages.add(queue)
    try:
        await ws.send_str(hub.hello())
        await ws.send_str(json.dumps({"type": "history", "frames": list(hub.history)}))

        async def pump():
            while not ws.closed:
                await ws.send_str(await queue.get())

        pumping = asyncio.create_task(pump())
        try:
            async for msg in ws:         # a live page's commands have nothing to do
                pass
        finally:
            pumping.cancel()
    except (ConnectionResetError, asyncio.CancelledError):
        pass
    finally:
        hub.pages.discard(queue)
    return ws


# -- the app ---------------------------------------------------------------------------------
def make_app(run: Run | None = None, hub: LiveHub | None = None) -> web.Application:
    """The page, the vendored libraries and the WebSocket, for a replay or live hub."""
    check_modules()
    app = web.Application()
    app["page"] = _page()
    app["run"], app["hub"] = run, hub
    app.router.add_get("/", _index)
    app.router.add_get("/app.js", lambda r: web.FileResponse(WEB / "app.js", headers={"Cache-Control": "no-store"}))
    app.router.add_get("/style.css", lambda r: web.FileResponse(WEB / "style.css", headers={"Cache-Control": "no-store"}))
    app.router.add_get("/vendor/{package}/{path:.+}", _vendor)
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
        await runner.cleanup()


def serve(replay=None, live: str | None = None, host: str = "127.0.0.1", port: int = 0, ready=None) -> None:
    """Serve the view of a run file (``replay``) or of a live feed (``live``,
    udp://HOST:PORT to listen on) until SIGINT or SIGTERM; ``ready(url)`` once serving."""
    if (replay is None) == (live is None):
        raise ViewError("give a run to replay or a live address, not both or neither")
    run = load_run(replay) if replay is not None else None
    udp = parse_address(live) if live is not None else None
    hub = LiveHub(live) if live is not None else None
    app = make_app(run, hub)
    asyncio.run(_serve(app, host, port, hub, udp, ready))
