"""The next experiment (issue 35 item 4): which design tells two explanations apart,
the command CSV it is written as, and ``diagnose --propose`` never writing over an input."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi.cli import main
from boomfmi.compare import CHANNELS
from boomfmi.diagnose.propose import Hypothesis, Proposal, ambiguous, propose, separation, write_command_csv
from boomfmi.experiments import command_samples, profile, slow_ramps
from boomfmi.recording import Recording
from boomfmi.outputs import OutputError

VALUES = {"K_v": 2900.0, "F_s": 130.0, "F_d": 100.0, "M": 21.0, "F_L": 260.0}


def _start() -> Recording:
    """A recording that only gives the rig and the start (the piston at rest, retracted)."""
    t = np.arange(0.0, 0.2, 1e-3)
    data = pd.DataFrame({"t": t, "u": 5.0, "p_a": 0.0, "p_b": 0.0, "alpha": -0.3})
    return Recording(Path("start.csv"), data, {})


def test_separation_is_the_expected_log_likelihood_ratio():
    a = {c: np.zeros(100) for c in CHANNELS}
    b = {c: np.zeros(100) for c in CHANNELS}
    b["p_a"] += 200.0                  # 200 Pa on p_a over 100 samples, sigma 400 Pa: 1/2 * 100 * (1/2)^2
    assert separation(a, b, {"p_a": 400.0, "p_b": 1.0, "x": 1.0}) == pytest.approx(12.5)


def test_ambiguous_picks_the_two_to_tell_apart():
    assert ambiguous({"a": 0.5, "b": 0.4, "none": 0.1}) == ("a", "b")
    assert ambiguous({"a": 0.95, "b": 0.05}) is None                     # 19 times as probable: decided
    assert ambiguous({"a": 0.95, "b": 0.05}, factor=float("inf")) == ("a", "b")
    # unexplained has no model: its most probable named explanation against the baseline
    assert ambiguous({"unexplained": 0.6, "none": 0.3, "x + y": 0.08, "x": 0.02}) == ("x + y", "none")
    assert ambiguous({"unexplained": 0.99, "none": 0.01}) is None        # nothing named to test
    assert ambiguous({"x": 0.999, "unexplained": 0.001}) is None        # a distant second decides nothing
    assert ambiguous({"x": 0.6, "unexplained": 0.3, "none": 0.1}) == ("x", "none")


def test_a_slow_effect_is_told_apart_by_holds_not_by_a_fast_sweep():
    """A piston leak shows while the valve is centred and the piston held (the chambers
    equalise through the seal, the piston sinks): an operator's manoeuvres, with holds at
    exactly 5 V in mid-stroke, separate the leak from the baseline far better than a
    fast sine sweep, where the valve never rests."""
    hyps = (Hypothesis("piston_leakage", VALUES, {"piston_leakage": {"C": 0.0, "A": 2e-8}}),
            Hypothesis("none", VALUES))
    designs = (("sine_sweep", {"seed": 1, "duration": 3.0}), ("manoeuvres", {"seed": 1, "duration": 3.0}))
    noise = {"p_a": 1000.0, "p_b": 1000.0, "x": 3e-5}
    p = propose(hyps, _start(), noise, designs=designs, workers=1)
    assert p.design == "manoeuvres" and p.hypotheses == ("piston_leakage", "none")
    by = {row["design"]: row["separation"] for row in p.table}
    assert by["manoeuvres"] > 10.0 * by["sine_sweep"] > 0.0
    # the predictions shown are the chosen design's, under each hypothesis
    assert set(p.predictions) == {"piston_leakage", "none"}
    assert separation(p.predictions["piston_leakage"], p.predictions["none"], noise) == pytest.approx(p.separation)


def test_the_command_csv_round_trips_through_the_command_reader(tmp_path):
    t, u = command_samples(slow_ramps(3, duration=2.0))
    prop = Proposal("slow_ramps", {"seed": 3, "duration": 2.0}, ("a", "b"), 1.0, t, u, {}, {}, [])
    path = write_command_csv(prop, tmp_path / "next.csv")
    back = profile(str(path))            # as `boomfmi record --experiment next.csv` reads it
    assert back.duration == pytest.approx(t[-1])
    assert np.allclose([back(float(s))["u"] for s in t], u, atol=1e-6)
    from boomfmi.simulate import experiment_inputs, rig_parameters   # and `boomfmi simulate --experiment next.csv`
    assert rig_parameters(str(path), {"valve": {"P_s"}}) == {}          # a command has no rig of its own
    table, stop = experiment_inputs(str(path), ["valve.u"])
    assert stop == pytest.approx(t[-1]) and np.allclose(table["valve.u"], u, atol=1e-6)


@pytest.mark.parametrize("text, where", [("time,u\n0,5\n", "line 1"),
                                         ("t,u\n0,5\n0.001,abc\n", "line 3, column 'u'"),
                                         ("t,u\n0,5\n0.001,12\n", "line 3, column 'u'"),
                                         ("t,u\n0,5\n0,6\n", "line 3, column 't'")])
def test_a_bad_command_csv_is_refused_where_it_is_wrong(tmp_path, text, where):
    path = tmp_path / "cmd.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=f"cmd.csv, {where}"):
        profile(str(path))


def test_propose_onto_an_input_is_refused_and_nothing_is_lost(tmp_path, capsys):
    fit, hold = tmp_path / "fit.csv", tmp_path / "hold.csv"
    for p in (fit, hold):
        p.write_text("t,u,p_a,p_b,alpha\n0,5,0,0,0\n")
    before = hold.read_bytes()
    code = main(["diagnose", str(fit), "--holdout", str(hold), "--out", str(tmp_path / "out"),
                 "--propose", str(hold)])
    err = capsys.readouterr().err
    assert code == 1 and f"{hold}" in err and "the input recording" in err and "Traceback" not in err
    assert hold.read_bytes() == before
    # nor onto the diagnosis' own report
    code = main(["diagnose", str(fit), "--holdout", str(hold), "--out", str(tmp_path / "out"),
                 "--propose", str(tmp_path / "out" / "report.html")])
    err = capsys.readouterr().err
    assert code == 1 and "--propose" in err and "report.html" in err
    assert not (tmp_path / "out").exists()
    with pytest.raises(OutputError):      # the library's writer refuses it too
        write_command_csv(Proposal("x", {}, ("a", "b"), 0.0, np.array([0.0, 1e-3]), np.array([5.0, 5.0]),
                                   {}, {}, []), hold, inputs=[(hold, "the input recording")])
    assert hold.read_bytes() == before


def test_diagnose_passes_propose_and_says_what_to_record(tmp_path, capsys, monkeypatch):
    import boomfmi.diagnose as diagnose_package
    fit, hold = tmp_path / "fit.csv", tmp_path / "hold.csv"
    for p in (fit, hold):
        p.write_text("t,u,p_a,p_b,alpha\n0,5,0,0,0\n")
    seen = {}

    def fake(fit_paths, hold_paths, out, ssp=None, progress=None, machine=None, propose=None):
        seen["propose"] = propose
        return {"judgeable": False, "reason": "a stub", "verdict": [], "effects": [],
                "next_experiment": {"design": "manoeuvres", "params": {"seed": 1}, "hypotheses": ["a", "b"],
                                    "separation": 12.5, "csv": str(propose)}}
    monkeypatch.setattr(diagnose_package, "diagnose", fake)
    code = main(["diagnose", str(fit), "--holdout", str(hold), "--out", str(tmp_path / "out"),
                 "--propose", str(tmp_path / "next.csv")])
    out = capsys.readouterr().out
    assert code == 0 and seen["propose"] == tmp_path / "next.csv"
    assert f"next experiment: manoeuvres {{'seed': 1}} tells a from b" in out and f"{tmp_path / 'next.csv'}" in out


def test_the_report_shows_both_predictions_inline(tmp_path):
    """report.html holds the proposal's plot (both predictions, embedded: the page is
    mailed alone) beside next_experiment.png, and says what to record and why."""
    from boomfmi.diagnose import report
    t = np.arange(0.0, 0.5, 1e-3)
    pred = {c: np.zeros_like(t) for c in CHANNELS}
    prop = Proposal("manoeuvres", {"seed": 1, "duration": 10.0}, ("valve_dynamics", "sensor_lag"), 12.5, t,
                    np.full_like(t, 5.0), {"valve_dynamics": pred, "sensor_lag": {**pred, "p_a": pred["p_a"] + 1e3}},
                    {"p_a": 500.0, "p_b": 500.0, "x": 3e-5}, [{"design": "manoeuvres", "params": {}, "separation": 12.5}],
                    "valve_dynamics (0.6) against sensor_lag (0.4)")
    doc = {"judgeable": False, "reason": "a stub", "verdict": [], "next_experiment": {**prop.summary(), "needed": True}}
    report._write(tmp_path, doc, None, None, None, None, prop)
    page = (tmp_path / "report.html").read_text()
    assert (tmp_path / "next_experiment.png").stat().st_size > 1000
    assert "The next experiment" in page and "<b>manoeuvres</b>" in page and "valve_dynamics (0.6)" in page
    assert 'src="data:image/png;base64,' in page.split("The next experiment")[1]


def test_record_never_writes_its_recording_over_the_command_csv(tmp_path, capsys):
    cmd = tmp_path / "next.csv"
    cmd.write_text("t,u\n0,5\n0.001,4\n")
    before = cmd.read_bytes()
    code = main(["record", "--experiment", str(cmd), "--rig", "udp://127.0.0.1:9", "--out", str(cmd)])
    err = capsys.readouterr().err
    assert code == 1 and f"{cmd}" in err and "destroy the input" in err
    assert cmd.read_bytes() == before
