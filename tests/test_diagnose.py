"""boomfmi diagnose: the report's contract (diagnosis-report.md) and its bad input."""
from __future__ import annotations

import json
import subprocess
import sys

import pandas as pd
import pytest

from boomfmi.experiments import random_steps
from boomfmi.recording import read_recording, write_recording
from boomfmi.rig.offline import run_offline

def strict_json(text: str):
    """The file's JSON as a strict reader takes it: NaN and Infinity are not JSON."""
    def refuse(name):
        raise ValueError(f"not JSON: {name}")
    return json.loads(text, parse_constant=refuse)



@pytest.fixture(scope="module")
def leaky(tmp_path_factory):
    d = tmp_path_factory.mktemp("diag")
    cfg = {"seed": 5, "effects": {"piston_leakage": {}}}
    fit, hold = random_steps(3, duration=7.0), random_steps(4, duration=7.0)
    write_recording(d / "fit.csv", run_offline(cfg, fit, fit.duration))
    write_recording(d / "hold.csv", run_offline(dict(cfg, seed=6), hold, hold.duration))
    return d


def run(*args, cwd):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", "diagnose", *map(str, args)],
                          cwd=cwd, capture_output=True, text=True, timeout=600)


def test_a_leaking_piston_is_found_and_the_report_follows_the_spec(leaky, ssp_path):
    out = leaky / "out"
    proc = run(leaky / "fit.csv", "--holdout", leaky / "hold.csv", "--out", out, "--ssp", ssp_path, cwd=leaky)
    assert proc.returncode == 0, proc.stderr
    doc = strict_json((out / "diagnosis.json").read_text())
    assert set(doc["baseline"]["params"]) == {"K_v", "F_s", "F_d", "F_L", "M"}
    assert set(doc["baseline"]["nrmse_holdout"]) == {"p_a", "p_b", "x"}
    assert doc["verdict"] == ["piston_leakage"]
    best = doc["effects"][0]
    assert best["name"] == "piston_leakage" and best["shrink"] > 0.6 and 0 < best["score"] <= 1
    assert {e["name"] for e in doc["effects"]} >= {"valve_dynamics", "heat_transfer", "sensor_lag"}
    assert doc["where"] and doc["where"][0]["subsystem"] == "cylinder"
    assert all({"channel", "regime", "subsystem", "share", "windows"} <= set(w) for w in doc["where"])
    html = (out / "report.html").read_text()
    assert html.index("piston_leakage") < html.index("<h2>Baseline")     # the verdict comes first
    for png in ("overlay_x.png", "overlay_p_a.png", "overlay_p_b.png", "residual_breakdown.png"):
        assert (out / png).stat().st_size > 5000 and png in html
    assert "verdict: ['piston_leakage']" in proc.stdout
    conf = doc["confirmation"]                  # the FMUs, with the verdict's option, agree
    assert conf["ssp"] == str(ssp_path) and set(conf["effects"]) == {"piston_leakage"}
    assert conf["agrees"] and conf["shrink"] > 0.6
    assert abs(conf["shrink"] - conf["reference_shrink"]) < 0.05
    assert "Confirmation through the FMUs" in html and "they agree" in html
    # a report for people: one sentence to act on first, parameters with units and
    # intervals (no raw JSON), the candidates as a chart, and every figure inside the page
    assert html.index('<p class="act">Most likely cause: piston_leakage') < html.index("replace the piston seal") \
        < html.index("<h2>Baseline")
    assert "Most likely cause: piston_leakage" in proc.stdout and "replace the piston seal" in proc.stdout
    assert "95 % interval" in html and "N&middot;s/m" in html and "kg/(s&middot;Pa)" in html
    assert '{"' not in html and "How probable each explanation is" in html
    probs = doc["probabilities"]     # the verdict is the most probable set; none and unexplained weighed too
    assert next(iter(probs)) == "piston_leakage" and {"none", "unexplained"} <= set(probs)
    assert abs(sum(probs.values()) - 1.0) < 1e-3 and best["score"] == probs["piston_leakage"]
    assert 'src="data:image/png;base64,' in html and 'src="overlay_' not in html
    lo, hi = doc["baseline"]["ci95"]["K_v"]
    assert lo <= doc["baseline"]["params"]["K_v"] <= hi and doc["baseline"]["units"]["K_v"] == "N.s/m"


def test_no_holdout_is_refused(leaky):
    proc = run(leaky / "fit.csv", "--out", leaky / "o", cwd=leaky)
    assert proc.returncode == 2 and "--holdout" in proc.stderr


def test_unreadable_recordings_are_named(leaky, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t;u;p_a;p_b;alpha\n0;5;0;0;0.6\n")
    proc = run(bad, "--holdout", leaky / "hold.csv", "--out", tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 1 and "bad.csv, line 1" in proc.stderr and "Traceback" not in proc.stderr
    proc = run(tmp_path / "missing.csv", "--holdout", leaky / "hold.csv", "--out", tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 1 and "missing.csv: no such file" in proc.stderr


def test_recordings_from_different_rigs_are_refused(leaky, tmp_path):
    other = tmp_path / "other.csv"
    write_recording(other, read_recording(leaky / "hold.csv").data, sidecar={"rig": {"M": 30.0}})
    proc = run(leaky / "fit.csv", "--holdout", other, "--out", tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 1 and "different rigs" in proc.stderr


def test_a_recording_without_motion_gets_a_report_not_a_crash(tmp_path):
    t = [round(k * 1e-3, 6) for k in range(2000)]
    still = pd.DataFrame({"t": t, "u": 5.0, "p_a": 0.0, "p_b": 0.0, "alpha": 0.6342})
    write_recording(tmp_path / "still.csv", still)
    write_recording(tmp_path / "still_too.csv", still.assign(alpha=0.6350))     # another still run
    proc = run(tmp_path / "still.csv", "--holdout", tmp_path / "still_too.csv", "--out", tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "o" / "diagnosis.json").read_text())
    assert doc["judgeable"] is False and "no motion" in doc["reason"] and doc["verdict"] == []
    assert "Cannot be judged" in (tmp_path / "o" / "report.html").read_text()


def test_effect_free_recordings_of_other_designs_get_no_verdict_and_no_fits(tmp_path):
    """No effect; the load off the reference; fit on an operator's manoeuvres, holdout a
    sine sweep: the baseline explains the holdout within its noise and its own
    uncertainty, so the verdict is [] and no candidate is fitted."""
    from boomfmi.diagnose import diagnose
    from boomfmi.experiments import manoeuvres, sine_sweep
    cfg = {"params": {"K_v": 2600.0, "F_s": 110.0, "F_d": 88.0, "F_L": 250.0, "M": 21.0}, "seed": 8}
    fit, hold = manoeuvres(3, duration=8.0), sine_sweep(2, duration=8.0)
    write_recording(tmp_path / "fit.csv", run_offline(cfg, fit, fit.duration))
    write_recording(tmp_path / "hold.csv", run_offline(dict(cfg, seed=9), hold, hold.duration))
    doc = diagnose([tmp_path / "fit.csv"], [tmp_path / "hold.csv"], tmp_path / "out", workers=1)
    assert doc["verdict"] == [] and not doc["gap_beyond_noise"] and doc["effects"] == []
    assert sum(doc["baseline"]["nrmse_holdout"].values()) < doc["gap_threshold"]
    for k, v in cfg["params"].items():
        assert doc["baseline"]["params"][k] == pytest.approx(v, rel=0.05), k
    assert "no candidate effect was fitted" in (tmp_path / "out" / "report.html").read_text()


def test_a_second_effect_pays_for_what_the_first_leaves_beyond_the_noise():
    """The pair's penalty counts only what the single effect leaves beyond the holdout's
    noise floor: near the noise a smaller cut pays, far beyond it 40 % is needed."""
    from boomfmi.diagnose.attribute import MIN_SHRINK_SECOND, _pays
    one = lambda total: {"x": total / 3, "p_a": total / 3, "p_b": total / 3}
    noise = 0.0033
    assert MIN_SHRINK_SECOND == 0.4
    assert _pays(one(0.0128), one(0.0085), noise)            # 0.0043 of 0.0095 beyond the noise
    assert not _pays(one(0.0128), one(0.0095), noise)        # 0.0033 of it: not enough
    assert not _pays(one(0.05), one(0.035), noise)           # 0.015 of 0.0467
    assert _pays(one(0.05), one(0.03), noise)
    assert not _pays(one(0.003), one(0.0029), noise)         # within the noise nothing pays but a cut
    assert not _pays(one(0.003), one(0.0031), noise)         # a pair that is worse never pays


def test_a_pair_starts_with_both_effects_halved_where_size_is_strength():
    """Two singles that each took the same feature whole (a spool lag and a sensor's dead
    time, each the whole delay) double it together: the pair's second start halves the
    parameters whose size is the effect's strength, within their bounds, and leaves the
    others (a polytropic exponent, whose 'off' is its top; a cushion needle's area)."""
    from boomfmi.diagnose.attribute import _halved
    from boomfmi.model import EFFECTS
    assert _halved("valve_dynamics", "tau", 0.008) == pytest.approx(0.004)
    assert _halved("sensor_lag", "delay", 0.006) == pytest.approx(0.003)
    lower = next(p.lower for p in EFFECTS["valve_deadband"].parameters if p.name == "width")
    assert _halved("valve_deadband", "width", 1.5 * lower) == pytest.approx(lower)
    assert _halved("heat_transfer", "n", 1.2) == 1.2
    assert _halved("end_cushioning", "A_n", 5e-7) == 5e-7


@pytest.mark.parametrize("doc, says", [
    ({"judgeable": False, "reason": "no motion in a.csv", "verdict": []}, "Record again with the boom moving"),
    ({"verdict": [], "gap_beyond_noise": False}, "Nothing to fix"),
    ({"verdict": [], "gap_beyond_noise": True}, "record longer or livelier motion"),
    ({"verdict": ["unexplained"], "where": [{"channel": "p_a", "regime": "stroke_end", "subsystem": "cylinder",
                                              "share": 0.7, "windows": []}]},
     "mostly in p_a during stroke end (cylinder)"),
    ({"verdict": ["valve_deadband", "piston_leakage"],
      "effects": [{"name": "valve_deadband + piston_leakage", "shrink": 0.9}]},
     "Most likely cause: valve_deadband and piston_leakage (it removes 90 % of the gap on the holdout). "
     "The valve stays shut around its centre"),
])
def test_the_report_s_first_sentence_says_what_to_do(doc, says):
    from boomfmi.diagnose.report import action_sentence
    assert says in action_sentence(doc)


def test_every_effect_of_the_catalogue_says_what_a_technician_can_do():
    from boomfmi.model import EFFECTS
    assert all(len(e.advice) > 20 for e in EFFECTS.values()), [n for n, e in EFFECTS.items() if not e.advice]


def test_a_pair_s_parameters_are_shown_with_their_units():
    from boomfmi.diagnose.report import _params_text
    text = _params_text("valve_deadband + piston_leakage",
                        {"valve_deadband": {"width": 0.3}, "piston_leakage": {"C": 2e-11}})
    assert text == "valve_deadband.width = 0.3 V, piston_leakage.C = 2e-11 kg/(s&middot;Pa)"


def test_a_parameter_told_by_the_holdout_is_named_so_in_the_report():
    """A candidate whose further parameter the holdout told (the fit recordings could not)
    says so beside its parameters: its shrink is no held-out figure for it."""
    from boomfmi.diagnose.report import _html
    doc = {"verdict": ["valve_dynamics"], "gap_beyond_noise": True,
           "baseline": {"params": {"M": 20.0}, "nrmse_holdout": {"p_a": 0.2, "p_b": 0.16, "x": 0.05}, "warnings": []},
           "effects": [{"name": "valve_dynamics", "params": {"tau": 0.0095, "rate": 145.0}, "shrink": 0.99,
                        "score": 1.0, "nrmse_holdout_after": {"p_a": 0.003, "p_b": 0.002, "x": 0.001},
                        "holdout_told": ["rate"]},
                       {"name": "sensor_lag", "params": {"tau": 0.01}, "shrink": 0.34, "score": 0.0,
                        "nrmse_holdout_after": {"p_a": 0.13, "p_b": 0.11, "x": 0.03}}]}
    html = _html(doc, [])
    assert html.count("told by the holdout") == 1
    assert "rate: told by the holdout, which the fit recordings cannot tell" in html
