"""The excavator's virtual view: frames of the whole machine from the linkage's
kinematics, the live feed, and the page in headless Chromium (Debian's chromium and
chromium-driver; skipped with the reason where they are missing): all four joint angles
drawn equal the recording's, the model's ghost, the estimated tip force's arrow beside
the true one, and no request leaves the machine; the video export of an excavator run;
and the page live beside ``boomfmi simulate build/excavator.ssp --view``.

The run file is, for now, a *kinematic* trajectory: each piston driven at a speed in
proportion to its valve's opening in the digging cycle (``experiments.digging_cycle``),
its joint angles from ``physics.linkage.joint_angles``, the pressures constant, the
soft soil's force (``experiments.contact("soft_soil")``) at the tip as the truth and a
scaled, lagging copy as the estimate; the model's ghost is the same trajectory a little
slower.  It will switch to a recording of the excavator rig (through the excavator's
teleoperation system) once that exists.
"""
from __future__ import annotations

import asyncio
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi.experiments import contact, digging_cycle
from boomfmi.physics import linkage
from boomfmi.recording import write_recording
from boomfmi.view.frames import excavator_angle_map, live_frame, load_run

JOINTS = linkage.JOINTS
KEY = b"excavator-view-test-key-0123456789"
ROOT = Path(__file__).resolve().parents[1]
ARTIFACTS = ROOT / "build" / "test-artifacts"
DT = 2e-3


def kinematic_run(speed: float = 0.03, lag: int = 0) -> pd.DataFrame:
    """The digging cycle's kinematics: piston speeds ``speed * (5 V - u)`` [m/s] from
    mid-stroke, clipped to the strokes, every ``DT`` [s]."""
    p, ex = digging_cycle(), linkage.excavator_parameters()
    t = np.arange(0.0, p.duration, DT)
    x, xs, us = 0.5 * ex.strokes, [], []
    for s in t:
        u = p(s)
        us.append([u[f"u_{j}"] for j in JOINTS])
        x = np.clip(x + speed * np.array([5.0 - c for c in us[-1]]) * DT, 0.0, ex.strokes)
        xs.append(x)
    xs = np.array(xs)
    q = linkage.joint_angles(xs)
    d = {"t": t}
    for k, j in enumerate(JOINTS):
        d[f"u_{j}"] = np.array(us)[:, k]
        d[f"p_a_{j}"] = np.full(len(t), 2.0e5 + 1e4 * k)
        d[f"p_b_{j}"] = np.full(len(t), 3.0e5 - 1e4 * k)
        d[f"angle_{j}"] = q[:, k]
    tip = linkage.forward_kinematics(q)["tip"]
    vel = np.gradient(tip, DT, axis=0)
    soil = contact("soft_soil")
    f = np.array([soil.force(s, r, v) for s, r, v in zip(t, tip, vel)])
    for a, k in zip("xyz", range(3)):
        d[f"f_tip_{a}"] = f[:, k]
    return pd.DataFrame(d)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """``machine.csv``: the machine alone (a recording); ``run.csv``: the model (a
    little slower) beside the machine (``_measured``) with the estimated tip force."""
    tmp = tmp_path_factory.mktemp("excavator_view")
    machine = kinematic_run()
    rec = write_recording(tmp / "machine.csv", machine)
    model = kinematic_run(speed=0.027)
    run = model[[c for c in model.columns if not c.startswith("f_tip")]].copy()
    for j in JOINTS:
        for q in ("p_a", "p_b", "angle"):
            run[f"{q}_{j}_measured"] = machine[f"{q}_{j}"]
    for a in "xyz":
        run[f"f_tip_{a}"] = machine[f"f_tip_{a}"]
        run[f"f_tip_est_{a}"] = 0.9 * np.roll(machine[f"f_tip_{a}"].to_numpy(), 10)
    path = write_recording(tmp / "run.csv", run)
    return {"machine": rec, "run": path, "data": run}


def contact_time(data) -> float:
    """A time in the soil, the estimated force well drawn."""
    f = np.hypot(np.hypot(data["f_tip_est_x"], data["f_tip_est_y"]), data["f_tip_est_z"]).to_numpy()
    return float(data["t"].iloc[int(np.argmax(f))])


# -- frames -----------------------------------------------------------------------------------
def test_frames_carry_the_recording_s_angles_and_the_linkage_s_points(runs):
    run = load_run(runs["run"])
    assert run.kind == "excavator" and run.model is not None and run.has_truth
    d = runs["data"]
    for k in (0, 1234, len(d) - 1):
        f = run.frame(d["t"][k])
        q = [d[f"angle_{j}_measured"][k] for j in JOINTS]
        assert f["kind"] == "excavator"
        assert [f["machine"]["angle"][j] for j in JOINTS] == pytest.approx(q, abs=1e-12)
        assert [f["model"]["angle"][j] for j in JOINTS] == pytest.approx([d[f"angle_{j}"][k] for j in JOINTS])
        assert f["machine"]["points"]["tip"] == pytest.approx(linkage.forward_kinematics(np.array(q))["tip"])
        assert f["f_tip_est"] == pytest.approx([d[f"f_tip_est_{a}"][k] for a in "xyz"], abs=1e-9)
        assert f["f_tip"] == pytest.approx([d[f"f_tip_{a}"][k] for a in "xyz"], abs=1e-9)
    mid = run.frame(0.5 * (d["t"][10] + d["t"][11]))
    assert mid["machine"]["angle"]["arm"] == pytest.approx(0.5 * (d["angle_arm_measured"][10] + d["angle_arm_measured"][11]))
    assert run.scene()["kind"] == "excavator" and run.scene()["joints"] == list(JOINTS)


def test_a_recording_of_the_machine_alone_has_no_ghost(runs):
    run = load_run(runs["machine"])
    f = run.frame(1.0)
    assert f["model"] is None and f["f_tip_est"] is None and f["f_tip"] is not None
    assert set(f["machine"]["points"]) >= {"swing_axis", "boom_pivot", "arm_pivot", "bucket_pivot", "tip",
                                           *(f"cyl_{j}_{e}" for j in JOINTS for e in ("base", "rod"))}


@pytest.mark.parametrize("q", [(0.0, 0.8, 1.2, 0.9), (0.4, 0.7, 1.8, 0.6), (-0.4, 1.0, 0.95, 1.5)])
def test_the_drawn_angles_map_to_the_recording_s(q):
    """The angle map the page reads its drawn angles back with is the kinematics'."""
    from boomfmi.view.frames import _angles_of_points, _wrap
    drawn = _angles_of_points(linkage.forward_kinematics(np.array(q)))
    back = [m["sign"] * float(_wrap(drawn[k] - m["offset"])) for k, m in enumerate(excavator_angle_map())]
    assert back == pytest.approx(q, abs=1e-9)


def test_a_run_missing_one_machine_column_is_named(runs, tmp_path):
    d = runs["data"].drop(columns=["p_b_bucket_measured"])
    path = write_recording(tmp_path / "bad.csv", d)
    from boomfmi.recording import RecordingError
    with pytest.raises(RecordingError, match=r"bad\.csv, line 1, column 'p_b_bucket_measured'"):
        load_run(path)
    d = runs["data"].drop(columns=["f_tip_est_y"])
    path = write_recording(tmp_path / "bad2.csv", d)
    with pytest.raises(RecordingError, match=r"bad2\.csv, line 1, column 'f_tip_est_y': a tip force needs all three"):
        load_run(path)


# -- export -----------------------------------------------------------------------------------
def test_export_renders_an_excavator_recording_to_gif(tmp_path):
    from PIL import Image
    from boomfmi.rig import run_excavator_offline
    rec = write_recording(tmp_path / "dig.csv", run_excavator_offline({"machine": "excavator"}, digging_cycle(), 1.0))
    gif = tmp_path / "dig.gif"
    out = subprocess.run([sys.executable, "-m", "boomfmi.cli", "view", "--replay", str(rec), "--export", str(gif),
                          "--fps", "4", "--size", "480x270"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    with Image.open(gif) as im:
        assert im.size == (480, 270) and im.n_frames == 5


def test_the_export_draws_the_recording_s_angles_and_the_tip_forces(runs):
    """The exported picture's links are the linkage's forward kinematics at the run's
    angles, in the side (x-z) and top (x-y) views, the ghost the model's; in the soil both
    tip forces are arrows whose heads are beside the tip."""
    import matplotlib.pyplot as plt
    from boomfmi.view.export import EXCAVATOR_LINKS, TIP_SIDE, Drawing
    run = load_run(runs["run"])
    d, tc = runs["data"], contact_time(runs["data"])
    drawing = Drawing.of(run, 640, 360)
    try:
        drawing.show(tc)
        at = lambda col: float(np.interp(tc, d["t"], d[col]))
        for lines, suffix in ((drawing.machine, "_measured"), (drawing.ghost, "")):
            fk = linkage.forward_kinematics(np.array([at(f"angle_{j}{suffix}") for j in JOINTS]))
            for (_, k), view in zip(drawing.views, lines):
                for name, a, b, _ in EXCAVATOR_LINKS:
                    xs, ys = view[name].get_data()
                    assert list(xs) == pytest.approx([fk[a][0], fk[b][0]], abs=1e-9)
                    assert list(ys) == pytest.approx([fk[a][k], fk[b][k]], abs=1e-9)
        tip = run.frame(tc)["machine"]["points"]["tip"]
        for key in ("f_tip_est", "f_tip"):
            for (_, k), arrow in zip(drawing.views, drawing.arrows[key]):
                assert arrow.get_visible()
                head = arrow._posA_posB[1]                 # (matplotlib has no getter)
                assert np.hypot(head[0] - tip[0], head[1] - tip[k]) <= TIP_SIDE + 1e-9
        drawing.show(10.0)                                               # out of the soil: none
        assert not any(a.get_visible() for arrows in drawing.arrows.values() for a in arrows)
    finally:
        plt.close(drawing.fig)


def test_live_excavator_samples_reach_the_hub_as_frames():
    """A LiveSender's excavator sample -> UDP -> the view's LiveHub: the hub switches to
    the excavator's scene and its frame is the same as the run file's would be."""
    from boomfmi.physics import reference_rig
    from boomfmi.view.live import LiveSender
    from boomfmi.view.server import LiveHub
    q = (0.2, 0.8, 1.3, 0.9)
    names = ["time", *(f"m.angle_{j}" for j in JOINTS), *(f"r.angle_{j}" for j in JOINTS),
             "f.x", "f.y", "f.z", "r.pa_arm"]
    row = np.array([2.5, *q, *(v + 0.01 for v in q), 3.0, -1.0, 20.0, reference_rig.P_atm + 2e5])
    columns = {**{f"angle_{j}": (f"m.angle_{j}", 0.0) for j in JOINTS},
               **{f"angle_{j}_measured": (f"r.angle_{j}", 0.0) for j in JOINTS},
               **{f"f_tip_est_{a}": (f"f.{a}", 0.0) for a in "xyz"},
               "p_a_arm_measured": ("r.pa_arm", -reference_rig.P_atm)}

    async def go():
        hub = LiveHub("udp://127.0.0.1:0", KEY)
        page: asyncio.Queue = asyncio.Queue(maxsize=8)
        hub.pages.add(page)
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(lambda: hub, local_addr=("127.0.0.1", 0))
        port = transport.get_extra_info("sockname")[1]
        sender = LiveSender(f"udp://127.0.0.1:{port}", columns,
                            [reference_rig.a, reference_rig.b, reference_rig.h, reference_rig.l_min], rate=1e6, key=KEY)
        sender(names, row)
        for _ in range(100):
            if hub.history:
                break
            await asyncio.sleep(0.01)
        sender.close()
        transport.close()
        return hub, [page.get_nowait() for _ in range(page.qsize())]

    hub, sent = asyncio.run(go())
    assert hub.received == 1 and hub.rejected == 0 and hub.kind == "excavator"
    assert '"type": "hello"' in sent[0] and '"kind": "excavator"' in sent[0] and '"type": "frame"' in sent[1]
    f = hub.history[-1]
    assert f["kind"] == "excavator" and f["t"] == 2.5
    assert [f["machine"]["angle"][j] for j in JOINTS] == pytest.approx([v + 0.01 for v in q])
    assert [f["model"]["angle"][j] for j in JOINTS] == pytest.approx(q)
    assert f["machine"]["p_a"]["arm"] == pytest.approx(2e5) and f["machine"]["p_a"]["boom"] is None
    assert f["f_tip_est"] == [3.0, -1.0, 20.0] and f["f_tip"] is None
    assert f["machine"]["points"]["tip"] == pytest.approx(
        linkage.forward_kinematics(np.array(q) + 0.01)["tip"])


def test_a_live_excavator_sample_missing_a_joint_is_refused():
    from boomfmi.view.live import Refused, check_sample
    base = {"session": "0123456789abcdef", "seq": 1, "sent": time.time(), "t": 0.0}
    with pytest.raises(Refused, match="needs every joint's angle"):
        check_sample({**base, "angle_swing": 0.1, "angle_boom": 0.8, "angle_arm": 1.0})
    with pytest.raises(Refused, match="angle_arm = 9.0 is not a finite number within"):
        check_sample({**base, **{f"angle_{j}": 0.5 for j in JOINTS}, "angle_arm": 9.0})
    assert live_frame(check_sample({**base, **{f"angle_{j}": 0.9 for j in JOINTS}}), None)["model"] is None


# -- the page in headless Chromium --------------------------------------------------------------
from test_view import CHROMIUM, CHROMEDRIVER, View, _severe, _wait, driver, live_view, simulate_live  # noqa: E402,F401  (one browser set-up)

browser = pytest.mark.skipif(not (CHROMIUM and CHROMEDRIVER),
                             reason="Debian's chromium and chromium-driver are not installed (./test.sh installs them as root)")


def _seek(d, t: float) -> dict:
    d.execute_script(f"window.boomView.pause(); window.boomView.seek({t});")
    _wait(d, f"const s = window.boomView.state(); return s && s.kind === 'excavator' && !s.playing "
             f"&& Math.abs(s.t - {t}) < 1e-6")
    return d.execute_script("return window.boomView.state()")


@browser
def test_the_page_draws_the_whole_machine_its_ghost_and_the_tip_forces(runs, driver):
    data = runs["data"]
    view = View("--replay", str(runs["run"]))
    try:
        driver.get(view.url)
        _wait(driver, "return window.boomView && window.boomView.framesReceived > 5")
        s0 = driver.execute_script("return window.boomView.state()")
        assert s0["kind"] == "excavator" and s0["webgl"]
        at = lambda col, t: float(np.interp(t, data["t"], data[col]))
        tc = contact_time(data)
        states = {t: _seek(driver, t) for t in (0.2, 2.2, tc, 8.0, 10.0)}
        for t, s in states.items():                    # every joint drawn at the recording's angle
            assert s["machineVisible"] and s["ghostVisible"]
            for j in JOINTS:
                assert s["machineAngles"][j] == pytest.approx(at(f"angle_{j}_measured", t), abs=1e-6), (t, j)
                assert s["ghostAngles"][j] == pytest.approx(at(f"angle_{j}", t), abs=1e-6), (t, j)
        moved = {j: max(abs(states[t]["machineAngles"][j] - states[0.2]["machineAngles"][j]) for t in states)
                 for j in JOINTS}
        assert all(m > 0.1 for m in moved.values()), moved                # the cycle moves every joint
        s = states[tc]                                                     # in the soil: both arrows
        f_est = np.array([at(f"f_tip_est_{a}", tc) for a in "xyz"])
        f_true = np.array([at(f"f_tip_{a}", tc) for a in "xyz"])
        scale = driver.execute_script("return window.boomView.hello.scene.force_scale")
        for arrow, f in ((s["arrowEst"], f_est), (s["arrowTruth"], f_true)):
            assert arrow["visible"]
            assert arrow["dir"] == pytest.approx(f / np.linalg.norm(f), abs=1e-6)
            assert arrow["length"] == pytest.approx(max(0.05, np.linalg.norm(f) * scale), rel=1e-6)
            assert np.linalg.norm(np.subtract(arrow["head"], s["tip"])) == pytest.approx(0.03, abs=1e-6)  # beside the tip
        assert f_est[2] > 5 and s["arrowEst"]["dir"][2] > 0.5                # the soil pushes the tip up
        assert not states[10.0]["arrowEst"]["visible"]                      # out of the soil: none
        _seek(driver, tc)                                                   # the picture: in the soil
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(ARTIFACTS / "excavator_view.png"))
        assert (ARTIFACTS / "excavator_view.png").stat().st_size > 10_000
        resources = driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
        assert resources and all(r.startswith(view.url) for r in resources), resources   # nothing leaves the machine
        assert any("three.module.js" in r for r in resources)
        assert _severe(driver) == []
    finally:
        view.stop()


@browser
def test_the_page_replays_a_machine_alone_without_ghost_or_estimate(runs, driver):
    view = View("--replay", str(runs["machine"]))
    try:
        driver.get(view.url)
        data = pd.read_csv(runs["machine"])
        s = _seek(driver, 4.0)
        assert s["machineVisible"] and not s["ghostVisible"] and not s["arrowEst"]["visible"]
        for j in JOINTS:
            assert s["machineAngles"][j] == pytest.approx(float(np.interp(4.0, data["t"], data[f"angle_{j}"])), abs=1e-6)
        assert _severe(driver) == []
    finally:
        view.stop()


EXCAVATOR_SSP = ROOT / "build" / "excavator.ssp"


@browser
@pytest.mark.skipif(not EXCAVATOR_SSP.is_file(), reason="build/excavator.ssp is not built (build_fmus.py linkage)")
def test_live_view_beside_a_running_excavator_cosimulation(driver, tmp_path):
    view, udp = live_view(driver, tmp_path)
    try:
        out = tmp_path / "live.csv"
        # the sender sends 60 samples per wall second: 5 s of the cycle run for about a second
        # at five times real time, long enough for the 20 frames awaited below
        simulate_live(udp, EXCAVATOR_SSP, "--experiment", "digging_cycle", "--stop", "5.0", "--out", out)
        s = _wait(driver, "const s = window.boomView.state(); return window.boomView.framesReceived > 20 "
                          "&& s && s.kind === 'excavator' && s")
        assert driver.execute_script("return window.boomView.hello.scene.kind") == "excavator"
        assert s["machineVisible"] and not s["ghostVisible"]               # the model alone: drawn as the machine
        data = pd.read_csv(out)
        assert 0.0 < s["t"] <= 5.0
        for j in JOINTS:
            assert s["machineAngles"][j] == pytest.approx(float(np.interp(s["t"], data["t"], data[f"angle_{j}"])),
                                                          abs=2e-3), j
        assert s["fTip"] == [0.0, 0.0, 0.0]                                 # the force the linkage was given
        assert _severe(driver) == []
    finally:
        view.stop()
