"""The hardware-bridge FMU through fmpy: replay mode, and its refusals."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from boomfmi.physics import x_from_alpha
from boomfmi.recording import write_recording
from boomfmi.system import FmuError, FmuInstance


@pytest.fixture
def recording(tmp_path):
    rng = np.random.default_rng(3)
    t = np.round(np.arange(0, 0.2001, 1e-3), 6)
    data = pd.DataFrame({"t": t, "u": np.where(t < 0.1, 10.0, 2.5),
                         "p_a": rng.normal(3e5, 1e3, t.size), "p_b": rng.normal(2e5, 1e3, t.size),
                         "alpha": 0.7 + 0.1 * t + rng.normal(0, 1e-4, t.size),
                         "f_ext": np.linspace(0, -50, t.size)})
    return write_recording(tmp_path / "run.csv", data), data


def test_replay_reproduces_every_sample_exactly_at_its_time(fmu, recording):
    path, data = recording
    with FmuInstance(fmu("hardware_bridge")) as b:
        b.initialize(dict(mode="replay", recording=str(path)), stop_time=0.2)
        rows = [b.get("p_a", "p_b", "alpha", "u_applied", "f_ext", "x", "link_ok")]
        for k in range(len(data) - 1):
            b.step_to(k * 1e-3, 1e-3)
            rows.append(b.get("p_a", "p_b", "alpha", "u_applied", "f_ext", "x", "link_ok"))
    got = pd.DataFrame(rows)
    for col in ("p_a", "p_b", "alpha", "f_ext"):
        np.testing.assert_array_equal(got[col], data[col], err_msg=col)
    np.testing.assert_array_equal(got["u_applied"], data["u"])
    np.testing.assert_allclose(got["x"], x_from_alpha(data["alpha"].to_numpy()), rtol=0, atol=1e-15)
    assert got["link_ok"].all()


def test_replay_interpolates_linearly_and_holds_the_command(fmu, recording):
    path, data = recording
    with FmuInstance(fmu("hardware_bridge")) as b:
        b.initialize(dict(mode="replay", recording=str(path)))
        b.step_to(0.0, 0.0995)                                   # between samples 99 and 100
        out = b.get("p_a", "u_applied")
    w = (0.0995 - data.t[99]) / (data.t[100] - data.t[99])
    assert out["p_a"] == pytest.approx(data.p_a[99] + w * (data.p_a[100] - data.p_a[99]), rel=1e-12)
    assert out["u_applied"] == data.u[99] == 10.0                 # held, not interpolated


def test_replay_past_the_end_holds_and_flags(fmu, recording):
    path, data = recording
    with FmuInstance(fmu("hardware_bridge")) as b:
        b.initialize(dict(mode="replay", recording=str(path)))
        b.step_to(0.0, 0.25)
        out = b.get("p_a", "link_ok")
    assert out == {"p_a": data.p_a.iloc[-1], "link_ok": False}


@pytest.mark.parametrize("params, culprit", [
    ({"mode": "serial"}, "mode"),
    ({"mode": "replay", "recording": ""}, "recording"),
    ({"mode": "replay", "recording": "/nonexistent/run.csv"}, "recording"),
    ({"mode": "udp", "rig": "tcp://somewhere"}, "rig"),
    ({"mode": "udp", "timeout": 0.0}, "timeout"),
    ({"mode": "udp", "retries": -1}, "retries"),
    ({"mode": "udp", "l_min": 0.1}, "l_min"),
])
def test_bad_parameters_are_fmi_errors(fmu, params, culprit):
    with FmuInstance(fmu("hardware_bridge")) as b:
        with pytest.raises(FmuError) as err:
            b.initialize(params)
    assert err.value.status == 3 and f"parameter {culprit} =" in str(err.value)


def test_a_bad_recording_is_named_with_its_line(fmu, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,u,p_a,p_b,alpha\n0,5,0,0,0.6\n0.001,12,0,0,0.6\n")
    with FmuInstance(fmu("hardware_bridge")) as b:
        with pytest.raises(FmuError, match=r"bad.csv, line 3, column 'u': command 12.0 V lies outside"):
            b.initialize(dict(mode="replay", recording=str(bad)))


def test_udp_without_a_key_refuses_to_start(fmu, monkeypatch):
    monkeypatch.delenv("BOOMFMI_LINK_KEY", raising=False)
    with FmuInstance(fmu("hardware_bridge")) as b:
        with pytest.raises(FmuError, match="parameter key_file = '' is invalid: no link key"):
            b.initialize(dict(mode="udp"))


def test_udp_with_no_rig_fails_within_its_timeout(fmu, monkeypatch):
    import time
    monkeypatch.setenv("BOOMFMI_LINK_KEY", "k" * 32)
    with FmuInstance(fmu("hardware_bridge")) as b:
        t = time.perf_counter()
        with pytest.raises(FmuError, match="no authenticated answer from the rig"):
            b.initialize(dict(mode="udp", rig="udp://127.0.0.1:9", timeout=0.05))
        assert time.perf_counter() - t < 1.0


def test_x_alpha_x_round_trips_through_the_fmus(fmu, tmp_path):
    """boom_load's alpha, replayed through the bridge, gives back boom_load's x (Eq. 12
    one way in one FMU, the other way in the other) to 1e-12."""
    xs = np.linspace(0.0, 0.06, 41)
    alphas = []
    for x0 in xs:
        with FmuInstance(fmu("boom_load")) as boom:
            boom.initialize(dict(x0=float(x0)))
            alphas.append(boom.get("alpha")["alpha"])
    t = np.round(np.arange(len(xs)) * 1e-3, 6)
    path = write_recording(tmp_path / "alphas.csv", pd.DataFrame(
        {"t": t, "u": 5.0, "p_a": 0.0, "p_b": 0.0, "alpha": alphas}))
    got = []
    with FmuInstance(fmu("hardware_bridge")) as b:
        b.initialize(dict(mode="replay", recording=str(path)))
        got.append(b.get("x")["x"])
        for k in range(len(xs) - 1):
            b.step_to(k * 1e-3, 1e-3)
            got.append(b.get("x")["x"])
    np.testing.assert_allclose(got, xs, rtol=0, atol=1e-12)
