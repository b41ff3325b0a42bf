"""The excavator's virtual rig: four joints, effects per joint, the tip's contact, and the
link (server, excavator datagrams, the excavator bridge FMU through fmpy)."""
from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from boomfmi.experiments import held_joints
from boomfmi.link import protocol as p
from boomfmi.physics.linkage import Excavator, joint_angles, lever_arms, tip_jacobian, tip_position
from boomfmi.recording import read_recording, recording_kind
from boomfmi.rig import config_machine, make_rig
from boomfmi.rig.config import load_excavator_config
from boomfmi.rig import ExcavatorRig, run_excavator_offline
from boomfmi.rig.offline import run_offline

ROOT = Path(__file__).resolve().parents[1]
JOINTS = ("swing", "boom", "arm", "bucket")
QUIET = {"p_sigma": 0.0, "alpha_sigma": 0.0, "quantise": False}
KEY = "a shared key of more than sixteen bytes"
EX = Excavator()


def _run(config, segments, duration):
    return run_excavator_offline(config, held_joints(segments), duration)


# -- each joint ----------------------------------------------------------------------------
@pytest.mark.parametrize("joint", JOINTS)
def test_each_joint_moves_the_right_way_for_its_command(joint):
    """Below 5 V the valve feeds chamber A: that cylinder extends, its angle rises, its
    p_a rises; above 5 V it retracts.  The other joints, valves centred, move far less
    (the linkage's coupling jolts them as the driven one stops at its end)."""
    k = JOINTS.index(joint)
    for u, sign in ((3.0, +1), (7.0, -1)):
        rig = ExcavatorRig({"machine": "excavator", "noise": QUIET})
        s0 = rig.measure()
        cmd = [5.0] * 4
        cmd[k] = u
        for _ in range(250):
            s = rig.step(cmd)
        dx = np.subtract(s.x, s0.x)
        dq = np.subtract(s.angle, s0.angle)
        assert sign * dx[k] > 2e-3, (joint, u, dx)
        assert sign * dq[k] > 0.01, (joint, u, dq)
        others = [i for i in range(4) if i != k]
        assert np.abs(dx[others]).max() < 0.1 * abs(dx[k]), (joint, u, dx)
        if sign > 0:
            assert s.p_a[k] > s0.p_a[k] + 5e4
        else:
            assert s.p_b[k] > s0.p_b[k] + 5e4
        assert s.u_applied[k] == u


def test_the_machine_stands_still_at_its_start_and_its_angles_are_the_linkage_s():
    rig = ExcavatorRig({"machine": "excavator", "noise": QUIET})
    x0 = np.array(rig.measure().x)
    np.testing.assert_allclose(x0, EX.strokes / 2)
    for _ in range(200):
        s = rig.step([5.0] * 4)
    np.testing.assert_allclose(s.x, x0, atol=1e-5)          # held by the chambers' pressures
    np.testing.assert_allclose(s.angle, joint_angles(np.array(s.x)), atol=1e-12)


def test_an_effect_on_one_joint_changes_only_that_joint_beyond_noise():
    """piston_leakage on the arm, every joint moving then holding, same noise seed: the
    arm's pressures differ by tens of kPa, the other joints' channels by at most the
    noise (one ADC step where the linkage's coupling tips a reading over an LSB)."""
    cmd = [(0.4, {"swing": 3.5, "boom": 6.0, "arm": 5.0, "bucket": 4.0}), (0.6, {})]
    base = {"machine": "excavator", "seed": 3}
    a = _run(base, cmd, 1.0)
    b = _run({**base, "joints": {"arm": {"effects": {"piston_leakage": True}}}}, cmd, 1.0)
    p_sigma = 500.0
    for j in JOINTS:
        dp = max(np.abs(a[f"{q}_{j}"] - b[f"{q}_{j}"]).max() for q in ("p_a", "p_b"))
        dang = np.abs(a[f"angle_{j}"] - b[f"angle_{j}"]).max()
        if j == "arm":
            assert dp > 40 * p_sigma and np.abs(a["x_arm"] - b["x_arm"]).max() > 3e-5
        else:
            assert dp < 2 * p_sigma and dang < 2 * math.pi / 4096, (j, dp, dang)


def test_a_friction_effect_on_the_bucket_is_felt_by_the_bucket():
    """stribeck_friction on the bucket: its breakaway needs more pressure (the default
    F_brk scaled to its 20 mm bore), so it starts later than without."""
    cfg = {"machine": "excavator", "noise": QUIET}
    cmd = [(0.3, {"bucket": 4.2})]
    a = _run(cfg, cmd, 0.3)
    b = _run({**cfg, "joints": {"bucket": {"effects": {"stribeck_friction": True}}}}, cmd, 0.3)
    assert load_excavator_config({"joints": {"bucket": {"effects": {"stribeck_friction": True}}}}) \
        .joints["bucket"]["effects"]["stribeck_friction"]["F_brk"] == pytest.approx(140.0 * (20 / 32) ** 2)
    start = lambda df: df["t"][np.argmax(df["x_bucket"].to_numpy() > df["x_bucket"][0] + 1e-4)]
    assert start(b) > start(a) + 1e-3
    np.testing.assert_array_equal(a["x_boom"], b["x_boom"])


# -- the tip's contact -----------------------------------------------------------------------
def _ground_law(row, c):
    """The ground's force on the tip [N], written out here from the rig's documented law."""
    x = np.array([row[f"x_{j}"] for j in JOINTS])
    v = np.array([row[f"v_{j}"] for j in JOINTS])
    q = joint_angles(x)
    tip = tip_position(q)
    vt = tip_jacobian(q) @ (v / lever_arms(x))
    depth = c["ground_z"] - tip[2]
    if depth <= 0:
        return np.zeros(3), tip
    fz = c["stiffness"] * depth + c["damping"] * max(-vt[2], 0.0)
    drag = -c["friction"] * fz * vt[:2] / max(math.hypot(vt[0], vt[1]), c["v_slip"])
    return np.array([drag[0], drag[1], fz]), tip


def test_the_ground_contact_records_the_tip_force_of_its_law_and_stops_the_tip():
    contact = json.loads((ROOT / "examples/rig/excavator_contact_hard.json").read_text())["contact"]
    # the tip 1 cm above the ground, the boom driven down and the arm in while swinging
    start = {"boom": {"x0": 0.012}}
    cfg = {"machine": "excavator", "noise": QUIET, "joints": start, "contact": contact}
    cmd = [(0.8, {"boom": 7.0, "arm": 4.0, "swing": 4.0})]
    df = _run(cfg, cmd, 0.8)
    free = _run({**cfg, "contact": None}, cmd, 0.8)
    f = df[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy()
    assert f[:, 2].max() > 30.0 and (f[:, 2] > 0).sum() > 100        # in the ground for a while
    rows = df.iloc[::10]
    depth_hard, depth_free = [], []
    for (_, row), (_, row_free) in zip(rows.iterrows(), free.iloc[::10].iterrows()):
        law, tip = _ground_law(row, contact)
        np.testing.assert_allclose([row.f_tip_x, row.f_tip_y, row.f_tip_z], law, rtol=1e-9, atol=1e-9)
        depth_hard.append(-tip[2])
        depth_free.append(-tip_position(joint_angles(np.array([row_free[f"x_{j}"] for j in JOINTS])))[2])
    assert max(depth_free) > 0.02 and max(depth_hard) < 0.5 * max(depth_free)   # the ground holds the tip up
    assert np.abs(f[:, :2]).max() > 1.0                                       # and drags it


def test_a_prescribed_tip_force_is_recorded_and_pushes_the_machine():
    push = {"type": "prescribed", "force": [0.0, 0.0, 60.0], "start": 0.1, "stop": 0.5, "ramp": 0.05}
    cfg = {"machine": "excavator", "noise": QUIET, "contact": push}
    df = _run(cfg, [(0.5, {})], 0.5)
    t = df["t"].to_numpy()
    w = np.clip(np.minimum((t - 0.1) / 0.05, (0.5 - t) / 0.05), 0.0, 1.0) * ((t >= 0.1) & (t <= 0.5))
    np.testing.assert_allclose(df["f_tip_z"], 60.0 * w, atol=1e-9)
    np.testing.assert_allclose(df[["f_tip_x", "f_tip_y"]].to_numpy(), 0.0)
    quiet = _run({**cfg, "contact": None}, [(0.5, {})], 0.5)
    assert np.abs(df["x_bucket"] - quiet["x_bucket"]).max() > 1e-4 or np.abs(df["x_arm"] - quiet["x_arm"]).max() > 1e-4


# -- the configuration ---------------------------------------------------------------------------
@pytest.mark.parametrize("bad, named", [
    ({"jonts": {}}, "jonts"),
    ({"joints": {"stick": {}}}, "joints.stick"),
    ({"joints": {"arm": {"effect": {}}}}, "joints.arm.effect"),
    ({"joints": {"arm": {"effects": {"piston_leak": True}}}}, "joints.arm.effects.piston_leak"),
    ({"joints": {"arm": {"effects": {"piston_leakage": {"A_lek": 1e-8}}}}}, "joints.arm.effects.piston_leakage.A_lek"),
    ({"joints": {"boom": {"effects": {"valve_deadband": {"overlap": 5.0}}}}}, "joints.boom.effects.valve_deadband.overlap"),
    ({"joints": {"swing": {"params": {"K_v": -1.0}}}}, "joints.swing.params.K_v"),
    ({"joints": {"swing": {"params": {"bore": 0.03}}}}, "joints.swing.params.bore"),
    ({"joints": {"bucket": {"x0": 0.2}}}, "joints.bucket.x0"),
    ({"joints": {"bucket": {"noise": {"p_sigm": 1.0}}}}, "joints.bucket.noise.p_sigm"),
    ({"contact": {"type": "spring", "x_contact": 0.01, "stiffness": 1.0}}, "contact.type"),
    ({"contact": {"type": "ground"}}, "contact.stiffness"),
    ({"contact": {"type": "ground", "stiffness": 1e3, "mu": 0.3}}, "contact.mu"),
    ({"contact": {"type": "prescribed", "force": [1.0, 2.0]}}, "contact.force"),
    ({"payload": -1.0}, "payload"),
    ({"params": {"A_max": 1e-6}}, "params.A_max"),
])
def test_a_bad_key_is_named_in_the_error(bad, named):
    with pytest.raises(ValueError, match=re.escape(f"rig config: {named}:")):
        ExcavatorRig({"machine": "excavator", **bad})


def test_the_example_configs_load_and_say_they_are_an_excavator_s():
    paths = sorted((ROOT / "examples/rig").glob("excavator_*.json"))
    assert len(paths) >= 4
    for path in paths:
        assert config_machine(path) == "excavator"
        assert isinstance(make_rig(path), ExcavatorRig)
    assert config_machine(ROOT / "examples/rig/none.json") == "boom"
    df = run_offline(ROOT / "examples/rig/excavator_none.json", lambda t: {f"u_{j}": 5.0 for j in JOINTS}, 0.1)
    assert recording_kind(df.columns) == "excavator" and len(df) == 101


# -- the link ----------------------------------------------------------------------------------
def test_excavator_datagrams_round_trip_and_keep_to_their_size():
    key = KEY.encode()
    cmd = p.encode_excavator_command(3, 0.5, (1.0, 2.0, 8.0, 9.5), key, 1e-3, session=7)
    assert len(cmd) == p.DATAGRAM_SIZE
    assert p.decode(cmd, key) == p.ExcavatorCommand(3, 0.5, (1.0, 2.0, 8.0, 9.5), 1e-3, 7)
    s = p.encode_excavator_sample(4, p.LOCKSTEP, 0.75, (5, 5, 4, 6), (1e5, 2e5, 3e5, 4e5), (5e5, 6e5, 7e5, 8e5),
                                  (0.1, 0.8, 1.5, 1.0), (-1.0, 2.0, 30.0), 3, 2, key, session=7)
    assert len(s) == p.EXCAVATOR_DATAGRAM_SIZE
    d = p.decode(s, key)
    assert (d.t, d.u_applied, d.p_b, d.angle, d.f_tip, d.echo, d.rejected, d.session) == \
        (0.75, (5, 5, 4, 6), (5e5, 6e5, 7e5, 8e5), (0.1, 0.8, 1.5, 1.0), (-1.0, 2.0, 30.0), 3, 2, 7)
    assert d.lockstep and not d.failsafe
    with pytest.raises(p.BadMac):
        p.decode(s[:-1] + bytes([s[-1] ^ 1]), key)
    with pytest.raises(p.Malformed):          # an excavator sample's kind in a boom-sized datagram
        payload = s[:p.PAYLOAD_SIZE]
        p.decode(payload + p.mac(payload, key), key)
    with pytest.raises(p.Malformed):
        p.decode(s + b"\0", key)


@pytest.fixture(scope="module")
def bridge_fmu() -> Path:
    """build/fmus/excavator_bridge.fmu, rebuilt (alone) when its sources are newer."""
    path = ROOT / "build" / "fmus" / "excavator_bridge.fmu"
    src = ROOT / "src" / "boomfmi"
    sources = [*ROOT.joinpath("fmus", "excavator_bridge").iterdir(), *src.joinpath("link").glob("*.py"),
               *src.joinpath("physics").glob("*.py"), src / "recording.py", src / "fmislave.py", src / "rigbridge.py"]
    if not path.is_file() or any(s.stat().st_mtime > path.stat().st_mtime for s in sources):
        subprocess.run([sys.executable, str(ROOT / "build_fmus.py"), "excavator_bridge"], check=True, cwd=ROOT)
    return path


@pytest.fixture
def excavator_rig(tmp_path, monkeypatch):
    monkeypatch.setenv("BOOMFMI_LINK_KEY", KEY)
    procs = []

    def start(config: Path):
        record = tmp_path / "rig.csv"
        proc = subprocess.Popen([sys.executable, "-m", "boomfmi.cli", "rig", "serve", "--port", "0", "--lockstep",
                                 "--record", str(record), "--config", str(config)],
                                env=dict(os.environ, BOOMFMI_LINK_KEY=KEY), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        procs.append(proc)
        line = proc.stdout.readline()
        match = re.search(r"udp://127\.0\.0\.1:(\d+)", line)
        assert match, line + proc.stderr.read()
        return proc, f"udp://127.0.0.1:{match.group(1)}", record
    yield start
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=20)


def test_recording_the_digging_cycle_through_the_bridge_on_a_lockstep_excavator_rig(bridge_fmu, excavator_rig,
                                                                                  tmp_path):
    from fmpy.validation import validate_fmu

    from boomfmi.record import record_experiment
    assert validate_fmu(str(bridge_fmu)) == []
    config = tmp_path / "excavator_config.json"
    config.write_text(json.dumps({"machine": "excavator", "seed": 9, "contact": {
        "type": "prescribed", "force": [-5.0, 2.0, 12.0], "start": 0.2, "stop": 10.0, "ramp": 0.1}}))
    proc, url, rig_record = excavator_rig(config)
    out = tmp_path / "run.csv"
    stats = record_experiment(None, url, out, "digging_cycle", stop_time=1.0)
    proc.send_signal(signal.SIGTERM)
    summary, _ = proc.communicate(timeout=20)
    assert stats == {"rows": 1001, "lost_packets": 0}
    assert int(re.search(r"(\d+) commands", summary).group(1)) >= 1000     # (a retry is not stepped twice)
    rec = read_recording(out)
    assert rec.kind == "excavator" and len(rec.data) == 1001
    d = rec.data
    assert d["link_ok"].all()
    np.testing.assert_allclose(d["t_rig"], d["t"], atol=1e-9)               # lockstep: one sample a step
    # the cycle's first phases: rest, then the swing cylinder extends (u_swing 3 V)
    np.testing.assert_array_equal(d["u_swing"], np.where(d["t"] < 0.5 - 1e-9, 5.0, 3.0))
    assert d["angle_swing"].iloc[-1] > d["angle_swing"].iloc[0] + 0.02
    assert abs(d["angle_boom"].iloc[-1] - d["angle_boom"].iloc[0]) < 5e-3
    # the known tip force, carried through the link
    np.testing.assert_allclose(d.loc[d["t"] >= 0.3, ["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy(),
                               np.tile([-5.0, 2.0, 12.0], (int((d["t"] >= 0.3).sum()), 1)))
    # the same samples as the rig's own recording (which also has the truth)
    rig = read_recording(rig_record)
    assert rig.kind == "excavator" and len(rig.data) == 1001
    for c in [f"{q}_{j}" for q in ("p_a", "p_b", "angle") for j in JOINTS] + ["f_tip_z"]:
        np.testing.assert_array_equal(d[c].to_numpy(), rig.data[c].to_numpy(), err_msg=c)
    for c in [f"u_{j}" for j in JOINTS]:          # (the rig's last row: its watchdog has centred the valves)
        np.testing.assert_array_equal(d[c].to_numpy()[:-1], rig.data[c].to_numpy()[:-1], err_msg=c)
    np.testing.assert_allclose(d["x_angle_swing"], rig.data["x_swing"], atol=2e-4)


def test_the_excavator_bridge_refuses_a_boom_rig_and_the_rig_a_boom_command(bridge_fmu, excavator_rig, tmp_path):
    from boomfmi.link.client import RigClient
    from boomfmi.system import FmuError, FmuInstance
    proc, url, _ = excavator_rig(ROOT / "examples/rig/excavator_none.json")
    client = RigClient("127.0.0.1", int(url.rsplit(":", 1)[1]), KEY.encode(), timeout=2.0)
    first = client.exchange(None, 0.0)
    assert isinstance(first, p.ExcavatorSampleDatagram)
    assert client.exchange(4.0, 0.0) is None                   # a boom's command: ignored
    answer = client.exchange((4.0, 5.0, 5.0, 5.0), 0.0)
    assert answer is not None and answer.u_applied == (4.0, 5.0, 5.0, 5.0)
    client.close()
    proc.send_signal(signal.SIGTERM)
    summary, _ = proc.communicate(timeout=20)
    assert "ignored 1 malformed" in summary
    with FmuInstance(bridge_fmu, name="excavator_bridge") as bridge:
        with pytest.raises(FmuError, match="recording"):
            bridge.initialize({"mode": "replay", "recording": str(ROOT / "examples" / "nothing.csv")},
                              start_time=0.0, stop_time=1.0)
