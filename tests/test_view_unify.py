"""The view's one pipeline for one joint or four (issue 32, plan 2.12): one :class:`Run`,
one ``load_run`` and one ``live_frame``, whose drawing is the machine's mechanism
(``BoomMechanism``: the one-joint machine; ``LinkageMechanism``: the excavator's), the
page's JSON frames unchanged (the boom's without ``kind``, the excavator's with it)."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from boomfmi.model.boom import Model
from boomfmi.model.machine import boom_machine, excavator_machine
from boomfmi.physics import Geometry, linkage
from boomfmi.recording import write_recording
from boomfmi.view.frames import BoomMechanism, LinkageMechanism, Run, live_frame, load_run, mechanism_of

JOINTS = linkage.JOINTS


def _runs(tmp_path):
    t = np.arange(5) * 0.01
    boom = write_recording(tmp_path / "boom.csv", pd.DataFrame(
        {"t": t, "u": 5.0, "p_a": 2e5 + 1e3 * t, "p_b": 3e5, "alpha": 0.8 + 0.5 * t}))
    q0 = linkage.joint_angles(0.5 * linkage.excavator_parameters().strokes)
    d = {"t": t}
    for k, j in enumerate(JOINTS):
        d.update({f"u_{j}": 5.0, f"p_a_{j}": 2e5 + 1e4 * k, f"p_b_{j}": 3e5, f"angle_{j}": q0[k] + 0.2 * t})
    return load_run(boom), load_run(write_recording(tmp_path / "excavator.csv", pd.DataFrame(d)))


def _dumps(frame) -> str:
    return json.dumps(frame, sort_keys=True)


def test_the_boom_and_the_excavator_are_one_run_of_their_mechanism(tmp_path):
    boom, exc = _runs(tmp_path)
    assert type(boom) is Run and type(exc) is Run
    assert isinstance(boom.mechanism, BoomMechanism) and boom.mechanism.joints == ("boom",)
    assert isinstance(exc.mechanism, LinkageMechanism) and exc.mechanism.joints == JOINTS
    assert (boom.kind, exc.kind) == ("boom", "excavator") and exc.scene()["kind"] == "excavator"
    fb, fe = boom.frame(0.02), exc.frame(0.02)
    assert "kind" not in fb and fb["machine"]["alpha"] == pytest.approx(0.81) and fb["machine"]["T"] is not None
    assert fe["kind"] == "excavator" and set(fe["machine"]["angle"]) == set(JOINTS) and fe["machine"]["points"]
    # a live sample of the same row is the same frame, through the same code, for either machine
    sb = {"t": 0.02, "alpha": 0.81, "p_a": 2e5 + 20.0, "p_b": 3e5}
    assert _dumps(live_frame(sb, boom.mechanism.geom)) == _dumps(fb)
    row = pd.read_csv(exc.path, comment="#").iloc[2].to_dict()
    se = {k: v for k, v in row.items() if not k.startswith("u_")}
    assert _dumps(live_frame(se, Geometry())) == _dumps(fe)


def test_a_machine_gives_the_view_its_mechanism():
    g = Geometry(a=0.16, b=0.31, h=0.05, l_min=0.2)
    boom = mechanism_of(boom_machine(Model(geometry=g)))
    assert boom == BoomMechanism(g, Model().cylinder.L) and boom.scene()["a"] == 0.16
    exc = mechanism_of(excavator_machine())
    assert isinstance(exc, LinkageMechanism) and exc.scene()["joints"] == list(JOINTS)
    with pytest.raises(ValueError, match="alpha or alpha_measured"):
        live_frame({"t": 0.0}, g)
    with pytest.raises(ValueError, match="every joint's angle"):
        live_frame({"angle_swing": 0.1}, g)


def test_one_drawing_poses_either_machine_for_the_video(tmp_path):
    import matplotlib.pyplot as plt
    from boomfmi.view.export import BoomDrawing, Drawing, LinkageDrawing
    for run, cls, shown in zip(_runs(tmp_path), (BoomDrawing, LinkageDrawing), ("alpha", "swing")):
        drawing = Drawing.of(run, 320, 200)
        try:
            assert type(drawing) is cls and drawing.show(0.02) == []
            assert shown in drawing.text.get_text() and drawing.plots[0]["t"] == [0.02]
        finally:
            plt.close(drawing.fig)
