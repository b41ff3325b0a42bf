"""One identification pipeline for a machine of one joint or four (issue 32, item 1):
``identify.identify_recordings`` takes either machine's recordings by their kind,
``preprocess.prepare_machine`` prepares either, and the outputs' functions
(``cannot_tell``, ``summary_lines``) read either machine's result.  Synthetic
recordings only (no simulation): the fits themselves are tests/test_identify.py's and
tests/test_excavator_cli.py's."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from boomfmi.identify import identify_recordings
from boomfmi.identify.fit import Estimate, FitResult
from boomfmi.identify.outputs import cannot_tell, summary_lines
from boomfmi.identify.preprocess import JointData, machine_of, prepare, prepare_machine
from boomfmi.physics.linkage import JOINTS, Excavator, joint_angles
from boomfmi.recording import read_recording, write_recording


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    """A short boom recording and a short excavator one (every joint at mid-stroke, a
    slow sine on each angle), as files."""
    d = tmp_path_factory.mktemp("unify")
    t = np.arange(400) * 1e-3
    boom = write_recording(d / "boom.csv", pd.DataFrame({"t": t, "u": 5.0 + np.sin(9 * t), "p_a": 3e5, "p_b": 2e5,
                                                         "alpha": 0.8 + 0.05 * np.sin(3 * t)}))
    ex = Excavator()
    q = joint_angles(0.5 * ex.strokes, ex)
    cols = {"t": t}
    for i, j in enumerate(JOINTS):
        cols[f"u_{j}"] = 5.0 + np.sin(7 * t + i)
        cols[f"p_a_{j}"] = np.full(len(t), 3e5)
        cols[f"p_b_{j}"] = np.full(len(t), 2e5)
        cols[f"angle_{j}"] = q[i] + 0.01 * np.sin(2 * t + i)
    excavator = write_recording(d / "excavator.csv", pd.DataFrame(cols))
    return {"boom": boom, "excavator": excavator}


def test_the_recording_says_its_machine_and_prepare_machine_takes_either(recs):
    boom, ex = read_recording(recs["boom"]), read_recording(recs["excavator"])
    mb, me = machine_of(boom), machine_of(ex)
    assert (mb.n, mb.names, me.n, me.names) == (1, ("boom",), 4, JOINTS)
    # the one-joint machine: its one entry is the boom's own preparation, value for value
    (one,) = prepare_machine(boom, mb)
    ref = prepare(boom, geometry=mb.model.geometry, P_atm=mb.model.P_atm)
    for f in ("t", "u", "p_a", "p_b", "x", "v", "a", "phi", "x_raw"):
        np.testing.assert_array_equal(getattr(one, f), getattr(ref, f))
    # the linkage: one JointData per joint, in joint order, from the machine or its linkage alike
    joints = prepare_machine(ex, me)
    assert [type(jd) for jd in joints] == [JointData] * 4
    assert [jd.p.source.rsplit(":", 1)[1] for jd in joints] == list(JOINTS)
    np.testing.assert_array_equal(joints[2].F_p, prepare_machine(ex, me.ex)[2].F_p)


def test_one_entry_refuses_the_boom_only_options_on_excavator_recordings(recs):
    """The dispatch is the library's (the CLI's own excavator branch is gone): --method
    paper and --a-max are refused naming what they are, before any fit."""
    for kw in ({"method": "paper"}, {"with_A_max": True}):
        with pytest.raises(ValueError, match=r"whole excavator's recordings are identified by the fit per joint"
                                             r".*--method paper and --a-max are the boom's"):
            identify_recordings([recs["excavator"]], **kw)


def test_one_entry_refuses_a_mix_naming_each_kinds_files(recs):
    with pytest.raises(ValueError, match="mix") as e:
        identify_recordings([recs["boom"], recs["excavator"]])
    assert f"boom: {recs['boom']}" in str(e.value) and f"excavator: {recs['excavator']}" in str(e.value)


def _est(value, lo, hi, unit="N"):
    return Estimate(value, (lo, hi), unit)


def test_cannot_tell_reads_the_boom_and_the_excavator_alike():
    boom = FitResult("fit", {"K_v": _est(3000.0, 2900.0, 3100.0, "N.s/m"), "F_s": _est(100.0, 80.0, 120.0),
                             "F_d": _est(80.0, 10.0, 150.0), "M": _est(25.0, math.nan, math.nan, "kg")},
                     details={"static_friction": {"identified": False, "starts": 3}})
    why = cannot_tell(boom)
    assert why["K_v"] is None
    assert why["F_s"] == "the starts put it anywhere in its interval"
    assert why["F_d"] == "its interval is wider than half its value" and why["M"] == "no interval"
    ex = FitResult("fit-excavator", {"F_s_arm": _est(70.0, math.nan, math.nan), "F_s_boom": _est(110.0, 90.0, 130.0),
                                     "K_v_arm": _est(1700.0, 1600.0, 1800.0), "payload": _est(0.5, 0.2, 2.0, "kg")},
                   details={"static_friction": {"arm": {"starts": 0}, "boom": {"identified": False, "starts": 4}}})
    why = cannot_tell(ex)
    assert why["F_s_arm"] == "no start of motion from rest (F_d_arm is used)"
    assert why["F_s_boom"].startswith("the starts put it anywhere in its interval, wider than 5 %")
    assert why["K_v_arm"] is None and why["payload"] is None        # the payload is never judged by its width


def test_summary_lines_of_the_boom_name_the_fit_recordings_in_a_gap():
    doc = {"method": "fit", "params": {"K_v": {"value": 3101.2, "ci95": [3068.0, 3132.0], "unit": "N.s/m"},
                                       "F_s": {"value": 101.5, "ci95": [math.nan, math.nan], "unit": "N"}},
           "warnings": ["w1"], "details": {"recordings": ["a.csv", "b.csv"]},
           "nrmse_holdout": {"h.csv": {"x": 0.01, "p_a": 0.02, "p_b": 0.03}},
           "holdout_gap": {"h.csv": {"beyond_noise": True, "nrmse_sum": 0.06, "noise_floor_sum": 0.004,
                                     "threshold": 0.014}}}
    lines = summary_lines(doc)
    assert lines[0] == "fit: K_v = 3101 N.s/m [3068, 3132], F_s = 101.5 N"
    assert lines[1] == "warning: w1"
    assert lines[2] == "holdout h.csv: NRMSE x 1.00 %, p_a 2.00 %, p_b 3.00 %"
    assert lines[3].startswith("  large: 6.00 % in all, beyond 1.40 % (3 times")
    assert lines[3].endswith("`boomfmi diagnose a.csv b.csv --holdout h.csv --out DIR` names it")
