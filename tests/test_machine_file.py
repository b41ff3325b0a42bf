"""Your own machine in one file (``boomfmi machine``, ``--machine FILE``): written,
read with units, checked naming the key, applied to recordings, written beside them;
and the guide's path end to end on a machine that is not the reference rig."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from boomfmi.experiments import random_steps
from boomfmi.machine import MachineError, machine_document, read_machine
from boomfmi.physics.linkage import Excavator
from boomfmi.recording import RecordingError, read_recording, read_sidecar, write_recording
from boomfmi.rig.offline import run_offline

#: a machine that is not the reference rig: a 40 mm bore, 100 mm stroke, 5 bar supply
BORE, ROD, STROKE, SUPPLY_GAUGE = 0.040, 0.016, 0.100, 5e5
MINE = {"A_a": math.pi / 4 * BORE ** 2, "A_b": math.pi / 4 * (BORE ** 2 - ROD ** 2), "L": STROKE,
        "P_s": 101_325.0 + SUPPLY_GAUGE, "M": 30.0, "F_L": 300.0, "K_v": 3500.0, "F_s": 160.0, "F_d": 120.0}


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=cwd)


def test_machine_init_writes_every_value_with_its_unit_and_check_reads_it_back(tmp_path):
    for kind, n in (("boom", 21), ("excavator", 64)):
        out = tmp_path / f"{kind}.json"
        proc = cli("machine", "init", "--kind", kind, "--out", out)
        assert proc.returncode == 0, proc.stderr
        doc = json.loads(out.read_text())
        assert doc["kind"] == kind and len(doc["rig"]) == n and set(doc["units"]) == set(doc["rig"])
        m = read_machine(out)
        assert m.rig == pytest.approx(doc["rig"])
        proc = cli("machine", "check", out)
        assert proc.returncode == 0 and "within the physics' bounds" in proc.stdout, proc.stderr
    proc = cli("machine", "init", "--out", tmp_path / "boom.json")          # never over a file
    assert proc.returncode == 1 and "boom.json: exists" in proc.stderr
    assert read_machine(tmp_path / "excavator.json").excavator() == Excavator()


def test_values_may_carry_any_unit_of_their_dimension(tmp_path):
    doc = machine_document("boom")
    doc["rig"].update(L="100 mm", A_a="12.566 cm^2", P_s="6.01325 bar", T="25 degC", K_v="3.5 N*s/mm")
    (tmp_path / "m.json").write_text(json.dumps(doc))
    m = read_machine(tmp_path / "m.json")
    assert m.rig["L"] == pytest.approx(0.1) and m.rig["A_a"] == pytest.approx(12.566e-4)
    assert m.rig["P_s"] == pytest.approx(601_325.0) and m.rig["T"] == pytest.approx(298.15)
    assert m.rig["K_v"] == pytest.approx(3500.0)


@pytest.mark.parametrize("change, says", [
    ({"L": "2 kg"}, "rig value 'L' = '2 kg': not a quantity of unit m"),
    ({"L": -0.1}, "rig value 'L' = -0.1 is outside the physics' bounds"),
    ({"stroke": 0.1}, "unknown rig value 'stroke' for a boom"),
    ({"L": "about 6 cm"}, "rig value 'L' = 'about 6 cm': not a number followed by a unit"),
    ({"L": True}, "rig value 'L' must be a number or a text with its unit"),
    ({"h": "20 cm"}, "rig value 'h' = 0.2 is outside the physics' bounds"),   # the geometry's own check
])
def test_a_bad_value_is_named_with_the_file_and_its_key(tmp_path, change, says):
    doc = machine_document("boom")
    doc["rig"].update(change)
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(MachineError) as e:
        read_machine(path)
    assert str(path) in str(e.value) and says in str(e.value)
    proc = cli("identify", "nothing.csv", "--machine", path, "--out", tmp_path / "p.json")
    assert proc.returncode == 1 and says in proc.stderr and "Traceback" not in proc.stderr


def test_an_excavator_s_values_reach_its_sidecar_and_its_identification(tmp_path):
    from boomfmi.identify.preprocess import machine_for
    doc = machine_document("excavator")
    doc["rig"].update(stroke_arm="90 mm", bore_bucket="22 mm", K_v_arm=900.0)
    (tmp_path / "ex.json").write_text(json.dumps(doc))
    m = read_machine(tmp_path / "ex.json")
    side = tmp_path / "run.json"
    side.write_text(json.dumps({"rig": {k: m.rig[k] for k in ("stroke_arm", "bore_bucket", "K_v_arm")}}))
    read_sidecar(side)                                          # a sidecar may hold the excavator's values
    ex = m.excavator()
    assert (ex.arm.stroke, ex.bucket.bore, ex.arm.K_v) == (0.09, 0.022, 900.0)
    t = np.arange(0.0, 0.2, 1e-3)
    cols = {"t": t, **{f"{q}_{j}": v for j in ("swing", "boom", "arm", "bucket")
                       for q, v in (("u", 5.0), ("p_a", 1e5), ("p_b", 1e5))},
            "angle_swing": 0.0, "angle_boom": 0.8, "angle_arm": 1.4, "angle_bucket": 1.0}
    rec = read_recording(write_recording(tmp_path / "run.csv", pd.DataFrame(cols)))
    assert machine_for(m.apply(rec)).arm.stroke == 0.09
    side.write_text(json.dumps({"rig": {"stroke_arm": 0.09, "L": 0.06}}))
    with pytest.raises(RecordingError, match="'L' is the boom's, beside the excavator's"):
        read_sidecar(side)


@pytest.fixture(scope="module")
def own_rig(tmp_path_factory):
    """Recordings of a machine that is not the reference rig (no sidecar, as a foreign
    import makes them), one with a leaking piston, and its machine file."""
    d = tmp_path_factory.mktemp("own")
    doc = machine_document("boom", "hall B, rig 2")
    doc["rig"].update(A_a=f"{math.pi / 4 * BORE ** 2 * 1e4:.6f} cm^2", A_b=MINE["A_b"], L="100 mm",
                      P_s=f"{MINE['P_s'] / 1e5:.5f} bar", M=MINE["M"], F_L=MINE["F_L"], K_v=MINE["K_v"],
                      F_s=MINE["F_s"], F_d=MINE["F_d"])
    (d / "machine.json").write_text(json.dumps(doc, indent=2))
    for name, seed, effects in (("fit", 3, {}), ("hold", 4, {}), ("leaky_fit", 3, {"piston_leakage": {}}),
                                ("leaky_hold", 4, {"piston_leakage": {}})):
        prof = random_steps(seed, duration=7.0)
        df = run_offline({"params": MINE, "seed": seed, "effects": effects}, prof, prof.duration)
        write_recording(d / f"{name}.csv", df[["t", "u", "p_a", "p_b", "alpha"]])
    return d


def test_identify_takes_the_machine_and_says_when_it_assumes_the_reference_rig(own_rig, tmp_path):
    proc = cli("identify", own_rig / "fit.csv", "--machine", own_rig / "machine.json", "--out", tmp_path / "p.json")
    assert proc.returncode == 0, proc.stderr
    got = json.loads((tmp_path / "p.json").read_text())["params"]
    for k in ("K_v", "F_s", "F_d", "F_L", "M"):
        assert got[k]["value"] == pytest.approx(MINE[k], rel=0.08), k
    assert "assuming" not in proc.stdout
    plain = cli("identify", own_rig / "fit.csv", "--out", tmp_path / "q.json")      # its angles do not fit the
    assert plain.returncode == 1 and "--machine FILE (boomfmi machine init)" in plain.stderr   # reference rig
    prof = random_steps(5, duration=3.0)
    write_recording(tmp_path / "ref.csv", run_offline({"seed": 5}, prof, prof.duration))
    plain = cli("identify", tmp_path / "ref.csv", "--out", tmp_path / "r.json")
    assert plain.returncode == 0, plain.stderr
    assert "warning: no machine described (no --machine FILE and no sidecar rig values): assuming the paper's " \
           "reference rig; describe yours with: boomfmi machine init" in plain.stdout
    assert "assuming the paper's reference rig" in json.dumps(json.loads((tmp_path / "r.json").read_text()))


def test_a_sidecar_that_disagrees_with_the_machine_is_refused_naming_both(own_rig, tmp_path):
    rec = tmp_path / "fit.csv"
    rec.write_bytes((own_rig / "fit.csv").read_bytes())
    (tmp_path / "fit.json").write_text(json.dumps({"rig": {"L": 0.06}}))
    proc = cli("identify", rec, "--machine", own_rig / "machine.json", "--out", tmp_path / "p.json")
    assert proc.returncode == 1 and "sets L = 0.1, where the sidecar of" in proc.stderr and "fit.csv" in proc.stderr
    assert not (tmp_path / "p.json").exists()


def test_recording_import_writes_the_machine_beside_the_recording(own_rig, tmp_path):
    data = read_recording(own_rig / "fit.csv").data
    foreign = tmp_path / "foreign.txt"
    foreign.write_text("\n".join(f"{1e3 * t:.0f};{u:.4f};{pa / 1e5:.6f};{pb / 1e5:.6f};{math.degrees(al):.6f}"
                                 for t, u, pa, pb, al in data[["t", "u", "p_a", "p_b", "alpha"]].to_numpy()) + "\n")
    out = tmp_path / "imported.csv"
    proc = cli("recording", "import", foreign, "--delimiter", "semicolon",
               "--map", "t=1:ms,u=2:V,p_a_gauge=3:bar,p_b_gauge=4:bar,alpha=5:deg",
               "--machine", own_rig / "machine.json", "--out", out)
    assert proc.returncode == 0, proc.stderr
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["rig"]["L"] == pytest.approx(0.1) and side["rig"]["P_s"] == pytest.approx(MINE["P_s"])
    assert read_recording(out).rig_values()["L"] == pytest.approx(0.1)


@pytest.mark.slow
def test_the_guide_end_to_end_on_a_machine_that_is_not_the_reference_rig(own_rig, tmp_path):
    """Describe the machine, identify, diagnose: the leaking piston is named, on a rig of
    another bore, stroke and supply."""
    m = own_rig / "machine.json"
    proc = cli("diagnose", own_rig / "leaky_fit.csv", "--holdout", own_rig / "leaky_hold.csv", "--machine", m,
               "--out", tmp_path / "d")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "d" / "diagnosis.json").read_text())
    assert doc["verdict"] == ["piston_leakage"], doc["verdict"]
    assert "Most likely cause: piston_leakage" in proc.stdout
    assert "assuming" not in proc.stdout + proc.stderr
