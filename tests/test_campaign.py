"""boomfmi campaign: the manifest's checks, trends and flags, the Dask engine (resume,
failures; a worker killed mid-case on a real scheduler is tests/test_campaign_lost_worker.py),
and the virtual fleet."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from boomfmi.campaign import ManifestError, read_manifest, write_manifest
from boomfmi.campaign.fleet import plan_fleet, score_fleet
from boomfmi.campaign.trend import machine_trends, parameter_move

ROOT = Path(__file__).resolve().parents[1]


def cli(*args, cwd, timeout=900, env=None):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


# --- the manifest ------------------------------------------------------------------------

HEADER = "t,u,p_a,p_b,alpha\n0,5,0,0,0.6\n"


def _files(tmp_path, *names):
    for n in names:
        (tmp_path / n).write_text(HEADER)


def _manifest(tmp_path, text):
    path = tmp_path / "manifest.csv"
    path.write_text(text)
    return path


def test_a_good_manifest_groups_cases_by_machine_and_date(tmp_path):
    _files(tmp_path, "a1.csv", "a2.csv", "a3.csv", "a4.csv", "b1.csv", "b2.csv")
    (tmp_path / "rig.json").write_text('{"rig": {"M": 25.0}}')
    m = read_manifest(_manifest(tmp_path, "machine,date,role,recording,sidecar,notes\n"
                                          "# comment\n"
                                          "rig A,2025-01-13,fit,a1.csv,,week 2\n"
                                          "rig A,2025-01-13,holdout,a2.csv,,\n"
                                          "\n"
                                          "B,2025-01-06,fit,b1.csv,rig.json,\n"
                                          "B,2025-01-06,HOLDOUT,b2.csv,,\n"
                                          "rig A,2025-01-06,fit,a3.csv,,\n"
                                          "rig A,2025-01-06,holdout,a4.csv,,\n"))
    assert [(c.machine, c.date) for c in m.cases] == [("rig A", "2025-01-06"), ("rig A", "2025-01-13"),
                                                     ("B", "2025-01-06")]
    b = m.cases[2]
    assert [e.role for e in b.entries] == ["fit", "holdout"] and b.entries[0].sidecar == tmp_path / "rig.json"
    assert b.entries[0].line == 6
    assert str(m.cases[0].folder).startswith("rig_A-")          # a folder name that cannot clash


@pytest.mark.parametrize("text, expected", [
    ("machine,date,role,recording\nA,2025-01-06,fit,a1.csv\nA,2025-01-06,holdout,gone.csv\n",
     "line 3, column recording: gone.csv: no such file"),
    ("machine,date,role,recording\nA,2025-01-06,fit,a1.csv\nA,2025-01-06,hold,a2.csv\n",
     "line 3, column role: 'hold' is not a role: fit or holdout"),
    ("machine,date,role,recording\nA,2025-01-06,fit,a1.csv\nA,2025-01-06,holdout,a2.csv\n"
     "B,2025-01-06,fit,b1.csv\nB,2025-01-13,holdout,b2.csv\n",
     "line 4: machine 'B' on 2025-01-06 has no holdout recording (only fit)"),
    ("machine,date,role,recording\nA,06.01.2025,fit,a1.csv\nA,2025-01-06,holdout,a2.csv\n",
     "line 2, column date: '06.01.2025' is not an ISO 8601 date"),
    ("machine,date,role,recording\nA,2025-01-06,fit,a1.csv\nA,2025-01-06,holdout,a1.csv\n",
     "line 3, column recording: a1.csv is listed already on line 2"),
    ("machine;date;role;recording\nA;2025-01-06;fit;a1.csv\n",
     "line 1: missing column(s) machine, date, role, recording; the header has 'machine;date;role;recording' "
     "(the header is separated by ';'"),
    ("machine,date,role,recording\nA,,fit,a1.csv\nA,2025-01-06,holdout,a2.csv\n",
     "line 2, column date: empty"),
    ("machine,date,role,recording,sidecar\nA,2025-01-06,fit,a1.csv,nope.json\nA,2025-01-06,holdout,a2.csv,\n",
     "line 2, column sidecar: nope.json: no such file"),
    ("machine,date,role,recording\nA,2025-01-06,fit,notrec.csv\nA,2025-01-06,holdout,a2.csv\n",
     "line 2, column recording: notrec.csv: not a boom recording"),
    ("machine,date,role,recording\n", "no recordings listed below the header"),
])
def test_a_bad_manifest_is_refused_naming_the_line(tmp_path, text, expected):
    _files(tmp_path, "a1.csv", "a2.csv", "b1.csv", "b2.csv")
    (tmp_path / "notrec.csv").write_text("time,volts\n0,5\n")
    with pytest.raises(ManifestError) as err:
        read_manifest(_manifest(tmp_path, text))
    assert expected in str(err.value) and "manifest.csv" in str(err.value)


def test_every_fault_is_listed_and_the_cli_starts_no_work(tmp_path):
    _files(tmp_path, "a1.csv")
    path = _manifest(tmp_path, "machine,date,role,recording\nA,2025-01-06,fit,a1.csv\n"
                               "A,2025-01-06,test,gone.csv\nB,2025-13-01,fit,a1.csv\n")
    proc = cli("campaign", path, "--out", tmp_path / "out", cwd=tmp_path)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    for text in ("line 3, column role: 'test'", "line 3, column recording: gone.csv: no such file",
                 "line 4, column date: '2025-13-01'", "line 2: machine 'A' on 2025-01-06 has no holdout",
                 "nothing was run"):
        assert text in proc.stderr, (text, proc.stderr)
    assert not (tmp_path / "out").exists()          # refused before any work: no folder, no cluster


# --- trends and flags ---------------------------------------------------------------------

def _summary(verdict=(), gap=0.01, effects=None, **params):
    return {"judgeable": True, "verdict": list(verdict), "gap_threshold": gap, "effects": effects or {},
            "params": {k: {"value": v, "ci95": [lo, hi], "identified": ok} for k, (v, lo, hi, ok) in params.items()}}


def test_a_parameter_flags_where_its_interval_leaves_the_reference():
    assert parameter_move({"value": 10, "ci95": [9, 11]}, {"value": 8, "ci95": [7, 9.5]}) == 0    # overlap
    assert parameter_move({"value": 10, "ci95": [9.6, 11]}, {"value": 8, "ci95": [7, 9.5]}) == 1
    assert parameter_move({"value": 6, "ci95": [5, 6.9]}, {"value": 8, "ci95": [7, 9.5]}) == -1
    assert parameter_move({"value": 10, "ci95": [None, 11]}, {"value": 8, "ci95": [7, 9.5]}) == 0
    cases = [{"date": d, "status": "done", "summary": _summary(F_d=f, F_s=s)} for d, f, s in (
        ("2025-01-20", (95.0, 93.0, 97.0, True), (120.0, 100.0, 140.0, True)),
        ("2025-01-06", (85.0, 83.0, 87.0, True), (60.0, 40.0, 200.0, False)),     # F_s not told: no reference
        ("2025-01-13", (86.0, 84.0, 88.0, True), (112.0, 105.0, 118.0, True)),
        ("2025-01-27", (99.0, 97.0, 101.0, True), (140.0, 130.0, 150.0, True)))]
    tr = machine_trends(cases)
    assert tr["reference"] == "2025-01-06" and tr["parameter_reference"] == {"F_s": "2025-01-13", "F_d": "2025-01-06"}
    flags = {f["name"]: f for f in tr["flags"]}
    assert flags["F_d"]["date"] == "2025-01-20" and flags["F_d"]["dates"] == ["2025-01-20", "2025-01-27"]
    assert flags["F_d"]["status"] == "confirmed" and flags["F_d"]["confirmed_by"] == "2025-01-27"
    assert flags["F_d"]["direction"] == "rises" and "85 [83, 87] (2025-01-06) to 95 [93, 97]" in flags["F_d"]["text"]
    # F_s against 2025-01-13, the first date that tells it; moved on the newest date only
    assert flags["F_s"]["dates"] == ["2025-01-27"] and flags["F_s"]["status"] == "provisional"
    assert [p["move"] for p in tr["parameters"]["F_d"]] == [0, 0, 1, 1]


def test_a_move_that_the_next_date_does_not_show_is_no_flag():
    from boomfmi.campaign.trend import persistent
    assert persistent([("a", 0), ("b", 1), ("c", 0), ("d", 0)]) is None               # a single outlier
    assert persistent([("a", 1), ("b", -1), ("c", -1)])["date"] == "b"
    assert persistent([("a", 0), ("b", 0), ("c", -1)])["status"] == "provisional"
    f = persistent([("a", 0), ("b", 1), ("c", 1), ("d", 0), ("e", 1)])
    assert (f["date"], f["confirmed_by"], f["dates"], f["direction"]) == ("b", "c", ["b", "c", "e"], 1)
    cases = [{"date": f"2025-01-{d:02d}", "status": "done", "summary": _summary(F_d=(v, v - 2, v + 2, True))}
             for d, v in ((6, 85.0), (13, 92.0), (20, 86.0), (27, 84.0))]
    tr = machine_trends(cases)
    assert tr["flags"] == [] and [p["move"] for p in tr["parameters"]["F_d"]] == [0, 1, 0, 0]


def test_an_effect_flags_where_it_appears_or_grows_and_a_failed_date_is_skipped():
    leak = lambda g: {"piston_leakage": {"params": {"C": 1e-12}, "shrink": 0.9, "gain": g},
                      "heat_transfer": {"params": {"n": 1.3}, "shrink": 0.1, "gain": g / 10}}
    cases = [
        {"date": "2025-01-06", "status": "done", "summary": _summary()},
        {"date": "2025-01-13", "status": "failed", "summary": None},
        {"date": "2025-01-20", "status": "done", "summary": _summary(["piston_leakage"], 0.012, leak(0.03))},
        {"date": "2025-01-27", "status": "done", "summary": _summary(["piston_leakage"], 0.012, leak(0.04))},
        {"date": "2025-02-03", "status": "done", "summary": _summary(["unexplained"], 0.012, leak(0.02))}]
    tr = machine_trends(cases)
    kinds = {(f["kind"], f["name"]): f for f in tr["flags"]}
    leak_flag = kinds[("effect", "piston_leakage")]
    assert (leak_flag["date"], leak_flag["confirmed_by"], leak_flag["direction"]) == ("2025-01-20", "2025-01-27",
                                                                                      "appears")
    assert ("effect", "heat_transfer") not in kinds          # fitted, never named: no flag
    assert kinds[("unexplained", "unexplained")]["date"] == "2025-02-03"
    assert kinds[("unexplained", "unexplained")]["status"] == "provisional"
    assert [p["date"] for p in tr["effects"]["piston_leakage"]] == ["2025-01-06", "2025-01-20", "2025-01-27",
                                                                    "2025-02-03"]
    # named on the reference date too: a flag only where it grows beyond both margins
    grow = [{"date": f"2025-02-0{i}", "status": "done", "summary": _summary(["piston_leakage"], 0.01, leak(g))}
            for i, g in ((1, 0.03), (2, 0.045), (3, 0.06), (4, 0.07))]
    tr = machine_trends(grow)
    assert [(f["name"], f["date"], f["direction"]) for f in tr["flags"]] == [("piston_leakage", "2025-02-03", "grows")]


# --- the engine ---------------------------------------------------------------------------

def fit_and_holdout(d: Path, duration: float) -> Path:
    """Two short effect-free recordings of the virtual rig in ``d``: ``fit.csv`` and
    ``hold.csv``, each ``duration`` [s] of random steps."""
    from boomfmi.experiments import random_steps
    from boomfmi.recording import write_recording
    from boomfmi.rig.offline import run_offline
    fit, hold = random_steps(3, duration=duration), random_steps(4, duration=duration)
    write_recording(d / "fit.csv", run_offline({"seed": 5}, fit, fit.duration))
    write_recording(d / "hold.csv", run_offline({"seed": 6}, hold, hold.duration))
    return d


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Two short effect-free recordings of the virtual rig (fit and holdout)."""
    return fit_and_holdout(tmp_path_factory.mktemp("rec"), 4.0)


def _campaign(folder: Path, recordings: Path, machines, dates, broken=()) -> Path:
    """A manifest of copies of the two recordings, one pair per machine and date;
    ``broken``: (machine, date) whose fit recording has text in a number."""
    rows = []
    for m in machines:
        for d in dates:
            for role, src in (("fit", "fit.csv"), ("holdout", "hold.csv")):
                p = folder / m / f"{d}_{role}.csv"
                p.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(recordings / src, p)
                if role == "fit" and (m, d) in broken:
                    lines = p.read_text().splitlines()
                    fields = lines[50].split(",")
                    fields[lines[0].split(",").index("p_a")] = "n/a"
                    lines[50] = ",".join(fields)
                    p.write_text("\n".join(lines) + "\n")
                rows.append({"machine": m, "date": d, "role": role, "recording": p})
    return write_manifest(folder / "manifest.csv", rows)


@pytest.mark.slow
def test_a_local_campaign_reports_a_failing_case_and_resumes(tmp_path, recordings):
    from boomfmi.campaign import run_campaign
    manifest = _campaign(tmp_path, recordings, ["m1", "m2"], ["2025-01-06", "2025-01-13"],
                         broken=[("m2", "2025-01-06")])
    out, text = tmp_path / "out", []
    doc = run_campaign(manifest, out, workers=2, ssp=tmp_path / "no.ssp", progress=text.append)
    assert doc["run"]["cases"] == 4 and doc["run"]["failed"] == 1 and doc["run"]["worker_threads"] == 2
    by = {(c["machine"], c["date"]): c for c in doc["cases"]}
    bad = by[("m2", "2025-01-06")]
    assert bad["status"] == "failed" and "2025-01-06_fit.csv, line 51, column 'p_a'" in bad["error"]
    assert str(tmp_path / "m2") in bad["error"] and "boomfmi-case-" not in bad["error"]   # its own path
    for key in (("m1", "2025-01-06"), ("m1", "2025-01-13"), ("m2", "2025-01-13")):
        c = by[key]
        assert c["status"] == "done" and c["verdict"] == [] and c["params"]["F_d"]["ci95"][0] < c["params"]["F_d"]["value"]
        folder = out / c["folder"]
        for name in ("diagnosis.json", "report.html", "params.json", "params.ssv", "case.json"):
            assert (folder / name).is_file(), (key, name)
        diag = json.loads((folder / "diagnosis.json").read_text())
        assert diag["verdict"] == [] and diag["confirmation"]["skipped"]
        rec = json.loads((folder / "case.json").read_text())
        assert rec["status"] == "done" and rec["worker"].startswith("tcp://127.0.0.1:")
        assert str(tmp_path / c["machine"]) in json.dumps(json.loads((folder / "params.json").read_text()))
    assert json.loads((out / "cases/m2/2025-01-06/case.json").read_text())["traceback"]
    assert "4/4 cases (1 failed)" in "".join(text)
    html = (out / "campaign.html").read_text()
    assert "<b>failed</b>: RecordingError" in html and (out / "trend_m1.png").stat().st_size > 5000
    assert doc["machines"]["m1"]["flags"] == [] and doc["machines"]["m2"]["last"]["verdict"] == []
    # a re-run skips what is done and runs the failed case again (still failing)
    done_before = (out / "cases/m1/2025-01-06/case.json").stat().st_mtime_ns
    again = run_campaign(manifest, out, workers=1, ssp=tmp_path / "no.ssp")
    assert again["run"]["resumed"] == 3 and again["run"]["ran"] == 1 and again["run"]["failed"] == 1
    assert (out / "cases/m1/2025-01-06/case.json").stat().st_mtime_ns == done_before
    # a recording that changed is the same case with another input: run again
    shutil.copy(recordings / "hold.csv", tmp_path / "m1" / "2025-01-13_fit.csv")
    shutil.copy(recordings / "fit.csv", tmp_path / "m1" / "2025-01-13_holdout.csv")
    third = run_campaign(manifest, out, workers=1, ssp=tmp_path / "no.ssp")
    ran = {(c["machine"], c["date"]) for c in third["cases"] if not c["resumed"]}
    assert ran == {("m1", "2025-01-13"), ("m2", "2025-01-06")}


def _worker_settings():
    import dask
    return dask.config.get("distributed.worker.profile.enabled"), os.environ.get("MALLOC_TRIM_THRESHOLD_")


def test_the_local_clusters_workers_run_without_the_profiler_and_the_trim_threshold():
    """Both slowed a case down (docs/campaign-scaling.md); a one-thread worker per process."""
    from boomfmi.campaign import Engine
    with Engine(workers=2) as engine:
        assert engine.slots() == 2 and len(engine.client.nthreads()) == 2
        assert set(engine.client.run(_worker_settings).values()) == {(False, None)}
    with pytest.raises(ValueError, match="--workers sizes the local cluster"):
        Engine(scheduler="tcp://127.0.0.1:1", workers=2)


# --- the virtual fleet -------------------------------------------------------------------

def test_the_fleet_plan_is_seeded_and_changes_start_at_their_onsets():
    plan = plan_fleet(8, 6, seed=3)
    assert plan == plan_fleet(8, 6, seed=3) and plan != plan_fleet(8, 6, seed=4)
    kinds = [p["kind"] for p in plan.values()]
    assert kinds.count("none") == 3 and {"leak", "friction", "valve"} <= set(kinds)
    for m, p in plan.items():
        weeks = p["weeks"]
        assert [w["date"] for w in weeks][:2] == ["2025-01-06", "2025-01-13"]
        if p["kind"] == "none":
            assert p["onset"] is None and all(w["config"] == weeks[0]["config"] for w in weeks)
            continue
        o = p["onset_week"]
        assert 1 <= o <= 5 and p["onset"] == weeks[o]["date"]
        assert all(w["config"] == weeks[0]["config"] for w in weeks[:o])          # nothing before its onset
        assert weeks[o]["config"] != weeks[o - 1]["config"]
        if p["kind"] == "leak":
            sizes = [w["config"]["effects"]["piston_leakage"]["A_leak"] for w in weeks[o:]]
            assert sizes == sorted(sizes) and sizes[0] == pytest.approx(6e-9)
        if p["kind"] == "friction":
            assert weeks[o]["config"]["params"]["F_d"] == pytest.approx(1.07 * p["load"]["F_d"])


def test_a_campaign_is_scored_against_the_fleets_truth():
    truth = {"machines": {"a": {"kind": "none", "onset": None}, "b": {"kind": "leak", "onset": "2025-01-20"},
                          "c": {"kind": "friction", "onset": "2025-01-13"},
                          "d": {"kind": "valve", "onset": "2025-01-13"}}}
    flag = lambda name, d: {"name": name, "date": d, "status": "confirmed"}
    camp = {"machines": {"a": {"flags": []}, "b": {"flags": [flag("piston_leakage", "2025-01-27")]},
                         "c": {"flags": [flag("F_d", "2025-01-13"), flag("M", "2025-01-20")]},
                         "d": {"flags": [flag("valve_dynamics", "2025-01-27")]}}}
    s = score_fleet(camp, truth)
    assert s["machines"]["b"]["ok"] and s["machines"]["c"]["ok"] and s["machines"]["b"]["delay_days"] == 7
    assert not s["machines"]["d"]["ok"] and s["machines"]["d"]["delay_days"] == 14
    assert s["onsets_flagged_in_time"] == 2 and s["unchanged_flagged"] == 0 and not s["all_ok"]
    camp["machines"]["a"]["flags"] = [flag("F_s", "2025-01-20")]
    camp["machines"]["b"]["flags"].append(flag("F_L", "2025-01-13"))      # before its onset
    s = score_fleet(camp, truth)
    assert s["unchanged_flagged"] == 1 and s["flags_before_onset"] == 1 and not s["machines"]["b"]["ok"]


def test_make_fleet_writes_a_manifest_the_campaign_reads_and_keeps_what_is_made(tmp_path):
    from boomfmi.campaign.fleet import make_fleet
    from boomfmi.recording import read_recording
    manifest = make_fleet(tmp_path / "fleet", machines=2, weeks=2, seed=1, duration=0.3, workers=1)
    m = read_manifest(manifest)
    assert [(c.machine, c.date, len(c.role("fit")), len(c.role("holdout"))) for c in m.cases] == [
        ("m01", "2025-01-06", 1, 1), ("m01", "2025-01-13", 1, 1), ("m02", "2025-01-06", 1, 1), ("m02", "2025-01-13", 1, 1)]
    truth = json.loads((tmp_path / "fleet" / "truth.json").read_text())
    assert truth["machines"]["m02"]["kind"] == "leak" and truth["machines"]["m02"]["onset"] == "2025-01-13"
    rec = read_recording(tmp_path / "fleet" / "m02" / "2025-01-13_fit.csv")
    assert len(rec.data) == 301 and not list((tmp_path / "fleet").rglob("*.partial.csv"))
    stamp = (tmp_path / "fleet" / "m01" / "2025-01-06_fit.csv").stat().st_mtime_ns
    make_fleet(tmp_path / "fleet", machines=2, weeks=2, seed=1, duration=0.3, workers=1)
    assert (tmp_path / "fleet" / "m01" / "2025-01-06_fit.csv").stat().st_mtime_ns == stamp     # kept
    make_fleet(tmp_path / "fleet", machines=2, weeks=2, seed=2, duration=0.3, workers=1)        # another plan
    assert (tmp_path / "fleet" / "m01" / "2025-01-06_fit.csv").stat().st_mtime_ns != stamp
