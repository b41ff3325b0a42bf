"""Slow command ramps, small openings and long holds (issue 35, Build 1): the chambers
fill slowly at small openings, which is not a unit mistake.  The time-scale check of
identification (``identify._check_time_scale`` on ``fit.fill_rates``) judges only the
openings wide enough to tell (beyond the widest dead band a valve has, held over the
spool's lag); where a recording holds none it says so and does not refuse.  A time
column stretched tenfold is still refused wherever the recording can tell."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from boomfmi.diagnose import report as diagnosis_report
from boomfmi.experiments import holdout_multistep, slow_ramps
from boomfmi.identify import TimeScaleError, identify_recordings, write_outputs
from boomfmi.recording import write_recording
from boomfmi.rig.offline import run_offline

#: The rig's widest spool overlap with its widest rounded edge (rig/config.py's ranges).
WIDE_DEADBAND = {"valve_deadband": {"overlap": 0.6, "edge": 0.3}}
TRUE_LOAD = {"K_v": 2829.0, "F_d": 85.727, "F_L": 261.177, "M": 22.7}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("slow_ramps")
    designs = {   # name: (effects, slow_ramps' arguments); all 10 s on the virtual rig
        # triangles 0.4 to 1.0 V deep, the command a 20 Hz staircase: refused before (0.22)
        "shallow": (WIDE_DEADBAND, dict(depth=(0.4, 1.0), step=0.05)),
        # the same held 0.5 to 2 s at each peak, the command continuous: refused before (0.33)
        "holds": (WIDE_DEADBAND, dict(depth=(0.4, 1.0), hold=(0.5, 2.0))),
        # never beyond 0.7 V from the centre: nothing to judge the time scale by
        "small": ({"valve_deadband": {"overlap": 0.4, "edge": 0.15}}, dict(depth=(0.4, 0.7), hold=(0.5, 2.0))),
        # the triangles, 0.4 to 1.6 V deep, no dead band
        "deep": ({}, dict(depth=(0.4, 1.6))),
    }
    for name, (effects, kw) in designs.items():
        df = run_offline({"seed": 1, "effects": effects}, slow_ramps(0, 10.0, **kw), 10.0)
        write_recording(d / f"{name}.csv", df)
        stretched = df.copy()
        stretched["t"] *= 10.0
        write_recording(d / f"{name}_x10.csv", stretched)
    return d


@pytest.mark.parametrize("name", ["shallow", "holds"])
def test_slow_ramps_around_the_centre_are_identified_not_refused(runs, name, tmp_path):
    result, recs, _ = identify_recordings([runs / f"{name}.csv"])
    values = result.values()
    for k in ("K_v", "F_L"):          # the load the ramps tell, within 3 % of the rig's
        assert values[k] == pytest.approx(TRUE_LOAD[k], rel=0.03), (k, values)
    assert not any("time scale" in w for w in result.warnings), result.warnings
    doc = write_outputs(result, recs, tmp_path / "params.json")      # nothing lost: the set is written
    assert (tmp_path / "params.ssv").exists() and (tmp_path / "params.json").exists()
    assert doc["params"]["K_v"]["value"] == values["K_v"]


def test_a_recording_of_small_openings_only_is_not_judged_and_says_so(runs, tmp_path):
    result, recs, _ = identify_recordings([runs / "small.csv"])
    note = [w for w in result.warnings if "time scale was not checked" in w]
    assert note and "0.75 V" in note[0], result.warnings
    assert result.values()["F_L"] == pytest.approx(TRUE_LOAD["F_L"], rel=0.03)
    write_outputs(result, recs, tmp_path / "params.json")
    assert (tmp_path / "params.ssv").exists()
    # stretched tenfold it still cannot tell: the check does not refuse, and says why
    slow, _, _ = identify_recordings([runs / "small_x10.csv"])
    assert any("time scale was not checked" in w for w in slow.warnings)


@pytest.mark.parametrize("name", ["holds", "deep"])
def test_slow_ramps_stretched_tenfold_are_still_refused(runs, name):
    """What the ramps can tell: beyond 0.75 V the opening is known within a dead band
    and a lag, and a tenfold stretch fills ten times too slowly there (``deep``, the
    command continuous, was let through before: every sample followed a change of the
    command, so the old check had nothing and did not say so)."""
    with pytest.raises(TimeScaleError, match=rf"{name}_x10\.csv: the chambers fill and empty 0\.\d+ times as fast"
                                         rf".*even with a 0\.75 V dead band.*no machine has such values"):
        identify_recordings([runs / f"{name}_x10.csv"])


class _Reached(Exception):
    pass


def test_diagnose_takes_slow_ramps_past_the_baseline(runs, monkeypatch, tmp_path):
    """diagnose identifies its baseline by the same check: the ramps pass it (the
    candidates' fits, the long part, are stopped here; nothing is written)."""
    df = run_offline({"seed": 2, "effects": WIDE_DEADBAND}, holdout_multistep(), holdout_multistep().duration)
    write_recording(tmp_path / "hold.csv", df)
    said = []

    def stop(values, *a, **k):
        said.append(values)
        raise _Reached
    monkeypatch.setattr(diagnosis_report, "attribute", stop)
    with pytest.raises(_Reached):
        diagnosis_report.diagnose([runs / "shallow.csv"], [tmp_path / "hold.csv"], tmp_path / "diag",
                                  workers=1)
    assert said and said[0]["K_v"] == pytest.approx(TRUE_LOAD["K_v"], rel=0.03)
    assert not (tmp_path / "diag" / "diagnosis.json").exists()


# ----------------------------------------------- issue 35, Build 7: real-data figures on other sessions
ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "realdata" / "cylinder-friction-leak"


@pytest.mark.skipif(not REAL.is_dir(), reason="the real friction tests are not here")
def test_real_data_quotes_the_friction_laws_on_files_they_never_saw():
    """docs/real-data.md's figures to quote are from whole files of other sessions (one
    pressure out), with the session's part and the within-file floor beside them; the
    same-file figures stay, labelled within-file."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import real_bench
    rows = real_bench.transfer_rows(laws=("pressure",), only=("O-ring257",))
    lopo = next(r for r in rows if r["mode"] == "pressure")["rmse"]["pressure"]
    loso = next(r for r in rows if r["mode"] == "seal")["rmse"]["pressure"]
    assert 0 < lopo["within"] and lopo["session"] < lopo["held"] and loso["session"] < loso["held"]
    doc = (ROOT / "docs" / "real-data.md").read_text()
    row = next(line for line in doc.splitlines() if line.startswith("| O-ring257 | 1, 3, 5, 7 |"))
    assert f"**{lopo['held']:.2f}** | {lopo['session']:.2f} | {lopo['within']:.2f} |" in row
    assert "leave one pressure out" in doc and "leave one seal out" in doc and "within-file" in doc
