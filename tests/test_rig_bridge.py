"""The bridges' plumbing written once (``boomfmi/rigbridge.py``): the excavator's bridge
has what the boom's has, through the built FMUs and fmpy."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from boomfmi.model import measure
from boomfmi.physics.linkage import JOINTS
from boomfmi.recording import write_recording
from boomfmi.system import FmuError, FmuInstance


def _excavator_recording(path, t, angle_arm, p_a_bucket):
    cols = {"t": t}
    for j in JOINTS:
        cols[f"u_{j}"] = 5.0
    for j in JOINTS:
        cols[f"p_a_{j}"] = p_a_bucket if j == "bucket" else 1e5
        cols[f"p_b_{j}"] = 2e5
    angles = {"swing": 0.0, "boom": 0.8, "arm": angle_arm, "bucket": 1.0}
    for j in JOINTS:
        cols[f"angle_{j}"] = angles[j]
    return write_recording(path, pd.DataFrame(cols))


def _replay(fmu_path, path, n, params, names):
    with FmuInstance(fmu_path) as b:
        b.initialize(dict(mode="replay", recording=str(path), **params))
        got = []
        for k in range(n - 1):
            b.step_to(k * 1e-3, 1e-3)
            got.append(b.get(*names))
    return pd.DataFrame(got)


def test_the_excavator_bridge_has_the_boom_s_sensor_lag(fmu, tmp_path):
    """delay_sensor then tau_sensor on every measured channel of the four joints: the
    outputs are the model's ``measure`` of the recording (the excavator's bridge had no
    sensor lag before the plumbing was shared)."""
    t = np.round(np.arange(0, 0.0605, 1e-3), 6)
    arm = 1.4 + 0.1 * np.sin(60.0 * t)
    p = 3e5 + 1e5 * np.cos(45.0 * t)
    path = _excavator_recording(tmp_path / "sine.csv", t, arm, p)
    got = _replay(fmu("excavator_bridge"), path, len(t), dict(delay_sensor=0.0035, tau_sensor=0.002),
                  ("angle_arm", "p_a_bucket", "p_b_bucket", "x_arm"))
    np.testing.assert_allclose(got["angle_arm"], measure(arm, t, 0.002, 0.0035)[1:], atol=1e-12)
    np.testing.assert_allclose(got["p_a_bucket"], measure(p, t, 0.002, 0.0035)[1:], rtol=1e-12)
    assert abs(got["angle_arm"][20] - arm[21]) > 5e-3              # it is late
    plain = _replay(fmu("excavator_bridge"), path, len(t), {}, ("angle_arm", "x_arm"))
    np.testing.assert_array_equal(plain["angle_arm"], arm[1:])      # off by default: the recording as it is
    assert not np.allclose(got["x_arm"], plain["x_arm"])            # x follows the lagged angle


@pytest.mark.parametrize("bridge, other", [("hardware_bridge", "excavator"), ("excavator_bridge", "boom")])
def test_each_bridge_refuses_the_other_machine_s_recording_naming_it(fmu, tmp_path, bridge, other):
    t = np.round(np.arange(0, 0.0105, 1e-3), 6)
    if other == "boom":
        path = write_recording(tmp_path / "boom.csv", pd.DataFrame({"t": t, "u": 5.0, "p_a": 0.0, "p_b": 0.0,
                                                                    "alpha": 0.7}))
    else:
        path = _excavator_recording(tmp_path / "exc.csv", t, 1.4, 3e5)
    with FmuInstance(fmu(bridge)) as b:
        with pytest.raises(FmuError) as e:
            b.initialize(dict(mode="replay", recording=str(path)))
    text = str(e.value) + " ".join(getattr(e.value, "log", []) or [])
    assert "recording" in text and f"{other}'s recording" in text, text
