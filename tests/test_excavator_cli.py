"""``boomfmi identify`` and ``boomfmi diagnose`` on the whole excavator's recordings, run as
the command (a subprocess) on short recordings of the excavator virtual rig: the outputs'
structure, plausible values, params.ssv through the excavator SSP, the refusal of a mix
of boom and excavator recordings, and the arm's leak named with its joint."""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi import experiments as E
from boomfmi.identify.joints import JOINTS, true_values
from boomfmi.recording import write_recording
from boomfmi.rig import run_excavator_offline
from boomfmi.system.ssv import read_ssv

ROOT = Path(__file__).resolve().parents[1]
EXCAVATOR_SSP = ROOT / "build" / "excavator.ssp"
PAYLOAD = 0.5
#: the fit recording: the digging cycle at 2.5 times its pace (4.2 s), every joint moving both ways
CYCLE = E.digging_cycle(pace=0.4)
#: the arm-leakage holdout: the cycle at twice its pace, its first 2.5 s (the arm's run in and
#: its hold), with no payload: with one the bucket's cut also flags the effect-free bucket
#: (the limit test_excavator_diagnose.py's xfail records), which is not what this tests
LEAK = E.digging_cycle(pace=0.5)
LEAK_SECONDS = 2.5


def _cli(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def _recording(frame: pd.DataFrame, path: Path) -> Path:
    """The rig's run as a recording: its measured columns only (not its true x, v)."""
    return write_recording(path, frame.drop(columns=[c for c in frame if c.startswith(("x_", "v_"))]))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("excavator_cli")
    fit = _recording(run_excavator_offline({"machine": "excavator", "payload": PAYLOAD}, CYCLE, CYCLE.duration),
                     d / "dig.csv")
    leak_cfg = json.loads((ROOT / "examples" / "rig" / "excavator_arm_leakage.json").read_text())
    leak = _recording(run_excavator_offline(leak_cfg, LEAK, LEAK_SECONDS), d / "arm_leak.csv")
    # diagnosis fits its candidates on the fit recordings: the leaking machine's own, another run
    leak_fit = _recording(run_excavator_offline(dict(leak_cfg, seed=leak_cfg.get("seed", 0) + 1), CYCLE,
                                                CYCLE.duration), d / "arm_leak_fit.csv")
    t = np.arange(200) * 1e-3
    boom = write_recording(d / "boom.csv", pd.DataFrame({"t": t, "u": 5.0, "p_a": 3e5, "p_b": 2e5, "alpha": 0.8}))
    return {"dir": d, "fit": fit, "leak": leak, "leak_fit": leak_fit, "boom": boom}


@pytest.fixture(scope="module")
def identified(runs):
    out = runs["dir"] / "id" / "params.json"
    r = _cli("identify", runs["fit"], "--holdout", runs["leak"], "--out", out)
    assert r.returncode == 0, r.stderr
    return r, json.loads(out.read_text()), out


@pytest.fixture(scope="module")
def diagnosed(runs):
    out = runs["dir"] / "diag"
    r = _cli("diagnose", runs["leak_fit"], "--holdout", runs["leak"], "--out", out)
    assert r.returncode == 0, r.stderr
    return r, json.loads((out / "diagnosis.json").read_text()), out


def test_identify_writes_every_joint_with_intervals(identified, runs):
    r, doc, out = identified
    assert doc["kind"] == "excavator" and doc["method"] == "fit-excavator"
    assert doc["recordings"] == [str(runs["fit"])] and doc["holdout"] == [str(runs["leak"])]
    names = {f"{n}_{j}" for j in JOINTS for n in ("K_v", "F_s", "F_d")} | {"payload"}
    assert set(doc["params"]) == names
    units = {"K_v": "N.s/m", "F_s": "N", "F_d": "N", "payload": "kg"}
    for name, p in doc["params"].items():
        assert p["unit"] == units[name if name == "payload" else name.rsplit("_", 1)[0]]
        assert p["joint"] == (None if name == "payload" else name.rsplit("_", 1)[1])
        assert math.isfinite(p["value"]) and len(p["ci95"]) == 2
        assert p["ssp_name"] == f"linkage.{name}"
        assert p["identified"] == (p["cannot_tell"] is None)
    assert isinstance(doc["warnings"], list)
    for where in ("nrmse_fit", "nrmse_holdout"):
        (per,) = doc[where].values()
        assert set(per) == set(JOINTS)
        assert all(math.isfinite(v) and v >= 0 for e in per.values() for v in e.values())
    assert sorted(Path(p).name for p in doc["written"]) == ["params.json", "params.png", "params.ssv"]
    assert all(Path(p).is_file() for p in doc["written"])
    # what it prints: every joint, intervals, "cannot tell" where the data cannot
    for j in JOINTS:
        assert f"  {j}" in r.stdout
    assert ("cannot tell" in r.stdout) == any(not p["identified"] for p in doc["params"].values())
    assert f"holdout {runs['leak']}" in r.stdout and "wrote " in r.stdout
    assert "identify: " in r.stderr          # progress on stderr


def test_identified_values_plausible(identified):
    """Where the data identify a parameter, within 30 % of the rig's own or its interval
    holding it (no accuracy target here: a 4 s recording at 2.5 times the cycle's pace;
    the payload came out 35 % high with the interval 0.43 to 0.82 kg around 0.5)."""
    _, doc, _ = identified
    truth = true_values(payload=PAYLOAD)
    known = {k: p for k, p in doc["params"].items() if p["identified"]}
    assert len(known) >= 6, doc["params"]
    for name, p in known.items():
        near = abs(p["value"] - truth[name]) < 0.3 * truth[name]
        assert near or p["ci95"][0] <= truth[name] <= p["ci95"][1], (name, p["value"], p["ci95"], truth[name])


def test_params_ssv_binds_the_linkage(identified):
    _, doc, out = identified
    ssv = read_ssv(out.with_suffix(".ssv").read_bytes(), "params.ssv")
    bound = {k: p["ssv_value"] for k, p in doc["params"].items() if p["ssv_value"] is not None}
    assert {f"linkage.{k}" for k in bound} == set(ssv)
    for k, v in bound.items():
        assert ssv[f"linkage.{k}"].value == pytest.approx(v)
        assert v >= 0
    for j in JOINTS:        # Eq. 9 as the linkage FMU checks it
        if f"F_s_{j}" in bound and f"F_d_{j}" in bound:
            assert bound[f"F_s_{j}"] >= bound[f"F_d_{j}"]


@pytest.mark.skipif(not EXCAVATOR_SSP.is_file(), reason="build/excavator.ssp not built (python build_fmus.py)")
def test_params_ssv_runs_through_the_excavator_ssp(identified, runs):
    """The SSP's master rejects a parameter name that no component has, so a run proves
    that every name binds."""
    _, _, out = identified
    csv = runs["dir"] / "sim.csv"
    r = _cli("simulate", EXCAVATOR_SSP, "--experiment", "digging_cycle", "--params", out.with_suffix(".ssv"),
             "--stop", "0.2", "--out", csv)
    assert r.returncode == 0, r.stderr
    assert len(pd.read_csv(csv)) == 201


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_mixed_boom_and_excavator_refused(runs, command):
    extra = ["--out", runs["dir"] / f"mixed_{command}" / ("params.json" if command == "identify" else "")]
    r = _cli(command, runs["fit"], "--holdout", runs["boom"], *extra)
    assert r.returncode == 1
    assert "mix" in r.stderr and f"boom: {runs['boom']}" in r.stderr and f"excavator: {runs['fit']}" in r.stderr
    assert not (runs["dir"] / f"mixed_{command}").exists()


def test_boom_only_options_refused(runs):
    r = _cli("identify", runs["fit"], "--method", "paper", "--out", runs["dir"] / "paper.json")
    assert r.returncode == 1 and "--method paper" in r.stderr


def test_diagnose_names_the_leaking_arm(diagnosed, runs):
    r, doc, out = diagnosed
    assert doc["kind"] == "excavator" and doc["judgeable"]
    assert doc["verdict"][0] == "piston_leakage@arm"
    assert {w["joint"] for w in doc["where"]} == set(JOINTS)
    assert doc["where"][0]["joint"] == "arm" and doc["where"][0]["flagged"]
    for w in doc["where"]:
        assert w["recording"] == str(runs["leak"])
        assert math.isfinite(w["gap"]) and math.isfinite(w["noise_floor"]) and w["threshold"] > w["noise_floor"]
        assert w["flagged"] == (w["gap"] > w["threshold"])
    best = next(c for c in doc["effects"] if c["joint"] == "arm")
    assert best["name"] == "piston_leakage" and best["shrink"] > 0.5
    assert set(doc["baseline"]["params"]) >= {"K_v_arm", "payload"}
    assert set(doc["baseline"]["nrmse_holdout"]) == set(JOINTS)
    assert doc["baseline"]["used_by_verdict"] is False
    # printed: the verdict and every joint's gap
    assert "verdict: ['piston_leakage@arm']" in r.stdout
    for j in JOINTS:
        assert any(line.strip().startswith(f"{j} ") and "gap" in line for line in r.stdout.splitlines())
    page = (out / "report.html").read_text()
    assert "piston_leakage@arm" in page and "data:image/png;base64," in page
    assert "http://" not in page and "https://" not in page and "<script" not in page
    assert sorted(p.name for p in out.iterdir()) == ["diagnosis.json", "report.html"]
