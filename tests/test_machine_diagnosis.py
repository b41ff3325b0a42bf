"""Diagnosis of the whole excavator (issue 32, item 2): every effect of the catalogue on any
joint, fitted on the fit recordings and scored on the holdouts, pairs across joints,
friction through each joint's load cut; on the four-joint virtual rig
(``rig.run_excavator_offline``), through ``diagnose.report.diagnose``
(the command's entry point)."""
import json
import math

import pytest

from boomfmi import experiments as E
from boomfmi.diagnose.attribute import MIN_SHRINK
from boomfmi.diagnose.joints import (PNEUMATIC_STAGES, candidates, diagnose_joints, joint_cut, joint_gap,
                                     joint_pressures, unlagged)
from boomfmi.diagnose.report import diagnose
from boomfmi.recording import write_recording
from boomfmi.rig import run_excavator_offline


def _recording(frame, path):
    """The rig's run as a recording: its measured columns only (not its true x, v)."""
    return write_recording(path, frame.drop(columns=[c for c in frame if c.startswith(("x_", "v_"))]))


def _runs(joints, fit_seconds, hold, hold_seconds):
    """A fit run on ``excavator_excitation`` (seed 1) and a holdout run of ``hold``
    (another noise draw) of the rig with ``joints``' effects."""
    cfg = {"machine": "excavator", "joints": joints, "seed": 5}
    return (run_excavator_offline(cfg, E.excavator_excitation(seed=1, duration=fit_seconds), fit_seconds),
            run_excavator_offline(dict(cfg, seed=6), hold, hold_seconds))


def _case(tmp_path, joints, fit_seconds, hold, hold_seconds):
    """The runs as recordings through the command's entry point, written to
    ``tmp_path/out``."""
    fit, hold = _runs(joints, fit_seconds, hold, hold_seconds)
    fit, hold = _recording(fit, tmp_path / "fit.csv"), _recording(hold, tmp_path / "hold.csv")
    doc = diagnose([fit], [hold], tmp_path / "out")
    assert doc == json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    return doc


def _best(found, joint, name):
    return next(c for c in found.joints[joint].candidates if c.name == name)


def _named(doc, name, joint):
    return next(c for c in doc["effects"] if c["name"] == name and c["joint"] == joint)


def _fitted_on_fit_scored_on_holdout(entry):
    """A named candidate was fitted on the fit recordings (their gap lowered) and its
    shrink is the holdouts' (never fitted on)."""
    assert entry["named"]
    assert entry["fit_gap"] < entry["fit_gap_before"]
    before, after = entry["holdout_gaps_before"], entry["holdout_gaps_after"]
    assert entry["shrink"] == pytest.approx(1.0 - sum(after) / sum(before))
    assert entry["shrink"] >= MIN_SHRINK


def test_every_effect_of_the_pneumatic_stages_is_a_candidate():
    assert set(candidates(PNEUMATIC_STAGES)) == {"valve_dynamics", "valve_deadband", "heat_transfer",
                                                 "piston_leakage", "end_cushioning", "sensor_lag"}


def test_the_spool_and_the_sensors_lag_change_the_cut():
    """valve_dynamics is a state of the cut (the spool lags the command) and sensor_lag
    lags the cut's pressures and undoes the angle's lag on the motion driving it."""
    cmd = E.digging_cycle()
    d = run_excavator_offline({"machine": "excavator"}, cmd, 2.5)
    cut = joint_cut(d, "boom")
    base = joint_gap(cut, "boom")
    for effects in ({"valve_dynamics": {"tau": 0.01}}, {"sensor_lag": {"tau": 0.01}}):
        assert joint_gap(cut, "boom", effects=effects) > 2 * base, effects
    pa0, _ = joint_pressures(cut, "boom")
    pa1, _ = joint_pressures(cut, "boom", effects={"sensor_lag": {"delay": 0.005}})
    k = int(1.8 * cut.fs)       # the boom's valve opened at 2.0 s: the lagged pressure answers 5 ms later
    assert all(math.isfinite(v) for v in pa1)
    assert (pa0[k:] != pa1[k:]).any()
    x = cut.x
    back = unlagged(x, cut.t, 0.0, 0.005, cut.L)
    assert back[100] == pytest.approx(x[105])


@pytest.mark.slow
def test_a_slow_spool_on_the_arm_is_named(tmp_path):
    """The issue's case: valve_dynamics on the arm (f_n 40 Hz), fit on excavator_excitation,
    holdout on the digging cycle (its first 5 s: the swing, the boom down and the arm in):
    before, ``unexplained@arm`` (the cut had no spool; fitted on the holdout itself).  The
    rig's spool is of second order: its overshoot as the arm's valve closes on the arm at
    its stop (5.0 s) puts air into the closed rod side, which the catalogue's first-order
    lag cannot (the limit of the effect's law, not of the cut)."""
    doc = _case(tmp_path, {"arm": {"effects": {"valve_dynamics": {"f_n": 40.0}}}}, 8.0, E.digging_cycle(), 5.0)
    assert doc["verdict"] == ["valve_dynamics@arm"]
    e = _named(doc, "valve_dynamics", "arm")
    _fitted_on_fit_scored_on_holdout(e)
    assert 0.002 < e["params"]["tau"] < 0.008            # 2 zeta / (2 pi f_n) = 5.6 ms
    # the sensors' lag fits the arm's cut as well, but not the other joints' (the bridge's lag is on all)
    lag = _named(doc, "sensor_lag", "arm")
    assert lag["shrink"] < e["shrink"]
    c = doc["confirmation"]            # the named effect through excavator.ssp, where it is built
    if "skipped" not in c:
        assert c["effects"] == {"arm": {"valve_dynamics": e["params"]}} and c["shrink"] > MIN_SHRINK


def test_an_effect_free_machine_gives_no_finding():
    found = diagnose_joints(*_runs({}, 6.0, E.digging_cycle(), 6.0))
    assert found.verdict == []
    for j, f in found.joints.items():  # both cuts judged on every joint, each within its threshold
        assert not f.flagged and f.candidates == []
        assert f.pressures.gap <= f.pressures.thresholds[0]
        if f.position is not None:
            assert f.position.gap <= f.position.thresholds[0]
        else:                           # a joint the fit recording barely moves: said, not guessed
            assert any(m.startswith(f"{j}'s load cut: ") for m in found.notes), found.notes
    assert sum(f.position is not None for f in found.joints.values()) >= 3


@pytest.mark.slow
def test_a_pair_across_joints_is_named(tmp_path):
    """piston_leakage on the arm and valve_deadband on the bucket: both named, each on its
    joint (the fit and holdout: two draws of excavator_excitation, whose small openings
    show the deadband), the leak's area the rig's; the joints without an effect not
    flagged.  (This is also the test of a leak on the arm named with its joint.)"""
    joints = {"arm": {"effects": {"piston_leakage": {"A_leak": 3e-8}}},
              "bucket": {"effects": {"valve_deadband": {"overlap": 0.4}}}}
    found = diagnose_joints(*_runs(joints, 5.0, E.excavator_excitation(seed=2, duration=5.0), 5.0))
    assert sorted(found.verdict) == ["piston_leakage@arm", "valve_deadband@bucket"]
    for joint, name in (("arm", "piston_leakage"), ("bucket", "valve_deadband")):
        cut = found.joints[joint].pressures
        best = cut.candidates[0]
        assert best.name == name and best.shrink >= MIN_SHRINK and best.fit_gap < cut.fit_gap
        assert best.shrink == pytest.approx(1.0 - sum(best.hold_gaps) / sum(cut.gaps))
    assert found.joints["arm"].candidates[0].params["piston_leakage"]["A"] == pytest.approx(3e-8, rel=0.2)
    assert found.joints["bucket"].candidates[0].params["valve_deadband"]["width"] == pytest.approx(0.4, rel=0.25)
    for j in ("swing", "boom"):
        assert not found.joints[j].flagged, found.joints[j]


@pytest.mark.slow
def test_a_friction_effect_is_named_through_the_joint_load():
    """pressure_friction on the arm: it shows in the arm's load cut (the pneumatic cut
    runs on the measured motion), fitted with the arm's load re-identified.  (The boom's
    load, identified on 8 s of excitation about 9 % off in F_d, may draw a Stribeck
    curve on the holdout's lift: the load identification's spread, not asserted here.)"""
    found = diagnose_joints(*_runs({"arm": {"effects": {"pressure_friction": {}}}}, 8.0, E.digging_cycle(), 8.0))
    assert "pressure_friction@arm" in found.verdict
    lc = found.joints["arm"].position
    best = lc.candidates[0]
    assert best.name == "pressure_friction" and set(best.values) >= {"K_v", "F_s", "F_d"}
    assert best.shrink >= MIN_SHRINK and best.fit_gap < lc.fit_gap
    assert found.joints["arm"].pressures.verdict == []
    assert not any(v.endswith(("@swing", "@bucket")) for v in found.verdict)
