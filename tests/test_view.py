"""The virtual view: frames from the physics' geometry, the live feed, the video export,
and the page end to end in headless Chromium (Debian's chromium and chromium-driver,
installed by ``./test.sh``'s set-up; skipped with the reason where they are missing).

The run file is a teleoperation replay through the built FMUs: the virtual rig's bucket
meets soft soil (``examples/rig/contact_soft.json``) during the operator's digging cycle,
so the machine stops while the model, which knows no soil, goes on down.
"""
from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from boomfmi.physics import Geometry, alpha_from_x, cylinder_length, linkage_points, phi_from_x
from boomfmi.physics import reference_rig
from boomfmi.view.frames import live_frame, load_run

ROOT = Path(__file__).resolve().parents[1]
ARTIFACTS = ROOT / "build" / "test-artifacts"
KEY = b"view-test-key-0123456789abcdef"       # the link key that signs and checks the live stream


@pytest.fixture(scope="module")
def contact_run(ssp_path, tmp_path_factory) -> Path:
    from boomfmi.experiments import dig
    from boomfmi.recording import write_recording
    from boomfmi.rig.offline import run_offline
    from boomfmi.simulate import replay_parameters, run_experiment
    tmp = tmp_path_factory.mktemp("view")
    cfg = json.loads((ROOT / "examples" / "rig" / "contact_soft.json").read_text())
    rec = write_recording(tmp / "reference_rig.csv", run_offline(cfg, dig(), 4.0))
    out = run_experiment(ssp_path.parent / "teleoperation.ssp", str(rec), parameters=[replay_parameters(rec)])
    path = tmp / "run.csv"
    out.to_csv(path, index=False, float_format="%.10g")
    return path


# -- frames: the drawing's geometry is Eq. 10 to 12 ---------------------------------------------
@pytest.mark.parametrize("x", [0.0, 0.017, 0.06])
def test_linkage_points_close_the_triangle_of_eq_10_to_12(x):
    geom = Geometry()
    C, R = linkage_points(alpha_from_x(x, geom), geom)
    assert math.dist((0.0, 0.0), C) == pytest.approx(geom.a)
    assert math.dist((0.0, 0.0), R) == pytest.approx(geom.b)
    assert math.dist(C, R) == pytest.approx(cylinder_length(x, geom))                 # l, Eq. 11
    assert math.atan2(R[1] - C[1], R[0] - C[0]) == pytest.approx(phi_from_x(x, geom))  # phi, Eq. 10
    assert C[1] == pytest.approx(-geom.h)


def test_run_frames_are_the_recording_at_its_samples(contact_run):
    run = load_run(contact_run)
    assert run.model is not None and "f_ext" in run.forces
    data = np.genfromtxt(contact_run, delimiter=",", names=True)
    for k in (0, 777, len(data) - 1):
        f = run.frame(data["t"][k])
        assert f["machine"]["alpha"] == pytest.approx(data["alpha_measured"][k], abs=1e-12)
        assert f["model"]["alpha"] == pytest.approx(data["alpha"][k], abs=1e-12)
        assert f["f_est"] == pytest.approx(data["f_est"][k], abs=1e-9)
        T = f["machine"]["T"]
        assert math.atan2(T[1], T[0]) == pytest.approx(data["alpha_measured"][k] - math.asin(reference_rig.h / reference_rig.a))
    mid = run.frame(0.5 * (data["t"][10] + data["t"][11]))       # between samples: linear
    assert mid["machine"]["alpha"] == pytest.approx(0.5 * (data["alpha_measured"][10] + data["alpha_measured"][11]))


def test_a_recording_of_the_machine_alone_has_no_ghost(tmp_path):
    from boomfmi.experiments import held
    from boomfmi.recording import write_recording
    from boomfmi.rig.offline import run_offline
    path = write_recording(tmp_path / "rec.csv", run_offline({"seed": 1}, held([(0.2, 7.0)]), 0.2))
    f = load_run(path).frame(0.1)
    assert f["model"] is None and f["f_est"] is None and f["machine"]["R"] is not None


def test_a_bad_run_file_is_named_in_the_error(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,u,p_a,p_b,alpha\n0,5,0,0,0.8\n0.001,5,zero,0,0.8\n")
    out = subprocess.run([sys.executable, "-m", "boomfmi.cli", "view", "--replay", str(bad), "--port", "0"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1
    assert "bad.csv" in out.stderr and "p_a" in out.stderr and "3" in out.stderr


def test_live_sender_reaches_the_hub_as_frames():
    """simulate's LiveSender -> UDP -> the view's LiveHub: the same frame as a run file's."""
    import asyncio
    from boomfmi.view.live import LiveSender
    from boomfmi.view.server import LiveHub

    async def go():
        hub = LiveHub("udp://127.0.0.1:0", KEY)
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(lambda: hub, local_addr=("127.0.0.1", 0))
        port = transport.get_extra_info("sockname")[1]
        names = ["time", "boom_load.alpha", "boom_load.x", "cylinder.p_a", "cylinder.p_b",
                 "hardware_bridge.alpha", "hardware_bridge.p_a", "force_estimator.f_est"]
        sender = LiveSender(f"udp://127.0.0.1:{port}",
                            {"alpha": ("boom_load.alpha", 0.0), "x": ("boom_load.x", 0.0),
                             "p_a": ("cylinder.p_a", -reference_rig.P_atm), "p_b": ("cylinder.p_b", -reference_rig.P_atm),
                             "alpha_measured": ("hardware_bridge.alpha", 0.0),
                             "p_a_measured": ("hardware_bridge.p_a", 0.0), "f_est": ("force_estimator.f_est", 0.0)},
                            [reference_rig.a, reference_rig.b, reference_rig.h, reference_rig.l_min], rate=1e6,
                            key=KEY)
        sender(names, np.array([1.25, 0.80, 0.03, reference_rig.P_atm + 2e5, reference_rig.P_atm + 1e5, 0.75, 1.5e5, -320.0]))
        for _ in range(100):
            if hub.history:
                break
            await asyncio.sleep(0.01)
        sender.close()
        transport.close()
        return hub

    hub = asyncio.run(go())
    assert hub.received == 1 and hub.rejected == 0
    f = hub.history[-1]
    assert f["t"] == 1.25 and f["f_est"] == -320.0
    assert f["model"]["p_a"] == pytest.approx(2e5) and f["model"]["x"] == 0.03
    assert f["machine"]["alpha"] == 0.75 and f["machine"]["p_a"] == 1.5e5
    assert f == live_frame({"t": 1.25, "alpha": 0.8, "x": 0.03, "p_a": 2e5, "p_b": 1e5, "alpha_measured": 0.75,
                            "p_a_measured": 1.5e5, "f_est": -320.0}, Geometry())


# -- export --------------------------------------------------------------------------------------
def test_export_renders_gif_and_mp4(contact_run, tmp_path):
    from PIL import Image
    import imageio_ffmpeg
    gif = tmp_path / "view.gif"
    out = subprocess.run([sys.executable, "-m", "boomfmi.cli", "view", "--replay", str(contact_run), "--export",
                          str(gif), "--start", "1.0", "--stop", "1.5", "--fps", "10", "--size", "640x360"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    with Image.open(gif) as im:
        assert im.size == (640, 360) and im.n_frames == 6
    mp4 = tmp_path / "view.mp4"
    out = subprocess.run([sys.executable, "-m", "boomfmi.cli", "view", "--replay", str(contact_run), "--export",
                          str(mp4), "--stop", "0.4", "--fps", "20", "--size", "640x360"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(mp4))
    assert frames == 9 and seconds == pytest.approx(0.45, abs=0.06)
    bad = subprocess.run([sys.executable, "-m", "boomfmi.cli", "view", "--replay", str(contact_run), "--export",
                          str(tmp_path / "view.avi")], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 1 and ".mp4 or .gif" in bad.stderr


# -- the page in headless Chromium ----------------------------------------------------------------
CHROMIUM, CHROMEDRIVER = shutil.which("chromium"), shutil.which("chromedriver")
browser = pytest.mark.skipif(not (CHROMIUM and CHROMEDRIVER),
                             reason="Debian's chromium and chromium-driver are not installed (./test.sh installs them as root)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class View:
    """``boomfmi view`` in a subprocess."""

    def __init__(self, *args: str, port: int = 0, env: dict | None = None):
        self.proc = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "view", *args, "--port", str(port)],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        line = self.proc.stdout.readline()
        m = re.search(r"(http://127\.0\.0\.1:(\d+)/)", line)
        assert m, line + self.proc.stderr.read()
        self.url, self.port = m.group(1), int(m.group(2))

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait(timeout=10)


@pytest.fixture
def driver():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
              "--disable-background-networking", "--disable-component-update", "--disable-sync",
              "--disable-default-apps", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
              "--window-size=1400,800"):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    d = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    yield d
    d.quit()


def _wait(d, script: str, timeout: float = 10.0):
    end = time.monotonic() + timeout
    while True:
        value = d.execute_script(script)
        if value:
            return value
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for: {script}")
        time.sleep(0.05)


def _seek(d, t: float) -> dict:
    d.execute_script(f"window.boomView.pause(); window.boomView.seek({t});")
    _wait(d, f"const s = window.boomView.state(); return s && !s.playing && Math.abs(s.t - {t}) < 1e-6")
    return d.execute_script("return window.boomView.state()")


def _severe(d) -> list:
    return [e for e in d.get_log("browser") if e["level"] == "SEVERE"]


@browser
def test_the_page_follows_the_recording_and_the_ghost_leaves_the_machine_in_contact(contact_run, driver):
    view = View("--replay", str(contact_run))
    try:
        driver.get(view.url)
        _wait(driver, "return window.boomView && window.boomView.framesReceived > 5")
        time.sleep(1.2)
        fps = driver.execute_script("return window.boomView.fps()")
        assert fps >= 30, f"{fps} frames in the last second"
        data = np.genfromtxt(contact_run, delimiter=",", names=True)
        at = lambda col, t: float(np.interp(t, data["t"], data[col]))
        early, contact = _seek(driver, 0.05), _seek(driver, 1.5)
        for s, t in ((early, 0.05), (contact, 1.5)):            # the drawn boom angle is the recording's
            assert s["machineAlpha"] == pytest.approx(at("alpha_measured", t), abs=1e-6)
            assert s["ghostAlpha"] == pytest.approx(at("alpha", t), abs=1e-6)
            assert s["machineVisible"] and s["ghostVisible"]
        assert math.degrees(contact["machineAlpha"] - early["machineAlpha"]) < -5     # the boom went down
        assert abs(math.degrees(early["ghostAlpha"] - early["machineAlpha"])) < 0.5  # together before contact
        assert abs(math.degrees(contact["ghostAlpha"] - contact["machineAlpha"])) > 4  # apart in the soil
        assert contact["fEst"] < -300 and contact["arrowLength"] > 0.05                 # the soil's push, drawn
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(ARTIFACTS / "view_contact.png"))
        assert (ARTIFACTS / "view_contact.png").stat().st_size > 10_000
        resources = driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
        assert resources and all(r.startswith(view.url) for r in resources), resources   # nothing leaves the machine
        assert any("three.module.js" in r for r in resources)
        assert _severe(driver) == []
    finally:
        view.stop()


@browser
def test_the_page_reconnects_after_its_websocket_drops(contact_run, driver):
    port = _free_port()
    view = View("--replay", str(contact_run), port=port)
    try:
        driver.get(view.url)
        _seek(driver, 2.0)
        view.stop()                                              # the server goes away...
        _wait(driver, "return !window.boomView.connected")
        assert "reconnecting" in driver.find_element("id", "status").text
        # the server closed the page's connection as it stopped (1001), not the page's timeout
        assert driver.execute_script("return window.boomView.closeCode") == 1001
        view = View("--replay", str(contact_run), port=port)     # ...and comes back
        _wait(driver, "return window.boomView.connected && window.boomView.connections === 2", timeout=15)
        s = _wait(driver, "const s = window.boomView.state(); return s && Math.abs(s.t - 2.0) < 1e-6 && s")
        assert not s["playing"]                                  # where it was, as it was
        driver.execute_script("window.boomView.play()")
        before = driver.execute_script("return window.boomView.framesReceived")
        time.sleep(0.5)
        assert driver.execute_script("return window.boomView.framesReceived") > before + 10
        assert [e for e in _severe(driver) if "/ws" not in e["message"]] == []   # only the refused reconnects
    finally:
        view.stop()


def live_view(driver, tmp_path) -> tuple["View", int]:
    """``boomfmi view --live`` on a free UDP port, checking with a key file, the page
    connected to it: ``(view, udp_port)``."""
    udp = _free_port()
    key_file = tmp_path / "link.key"                 # the view checks with a key file, simulate signs from the env
    key_file.write_bytes(KEY)
    view = View("--live", f"udp://127.0.0.1:{udp}", "--key-file", str(key_file),
                env={k: v for k, v in os.environ.items() if k != "BOOMFMI_LINK_KEY"})
    driver.get(view.url)
    _wait(driver, "return window.boomView.connected && window.boomView.mode === 'live'")
    return view, udp


def simulate_live(udp: int, *args) -> None:
    """``boomfmi simulate ARGS --view udp://127.0.0.1:UDP``, signed from the environment's key."""
    sim = subprocess.run([sys.executable, "-m", "boomfmi.cli", "simulate", *map(str, args),
                          "--view", f"udp://127.0.0.1:{udp}"], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "BOOMFMI_LINK_KEY": KEY.decode()})
    assert sim.returncode == 0, sim.stderr


@browser
def test_live_view_beside_a_running_teleoperation(contact_run, ssp_path, driver, tmp_path):
    rec = contact_run.parent / "reference_rig.csv"
    view, udp = live_view(driver, tmp_path)
    try:
        simulate_live(udp, ssp_path.parent / "teleoperation.ssp", "--experiment", rec, "--replay",
                      "--out", tmp_path / "live.csv")
        s = _wait(driver, "return window.boomView.framesReceived > 20 && window.boomView.state()")
        assert s["ghostVisible"] and s["machineVisible"]
        out = np.genfromtxt(tmp_path / "live.csv", delimiter=",", names=True)
        assert s["machineAlpha"] == pytest.approx(float(np.interp(s["t"], out["t"], out["alpha_measured"])), abs=2e-3)
        assert _severe(driver) == []
    finally:
        view.stop()
