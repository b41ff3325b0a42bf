"""The whole excavator as an SSP (build/excavator.ssp): its parameter set from the
physics, its wiring, runs in boomfmi's master, `boomfmi simulate`, libcosim and ecos, the
linkage's fast path against the array functions, and (slow) the co-simulation's error
against the monolithic reference over the digging cycle."""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from boomfmi.physics import linkage as exc
from boomfmi.physics.linkage import JOINTS
from boomfmi.system import CoSimulation, simulate_ssp
from boomfmi.system.ssv import NS, SspError, read_ssv

ROOT = Path(__file__).resolve().parents[1]
SSP = ROOT / "build" / "excavator.ssp"


@pytest.fixture(scope="module")
def excavator_ssp() -> Path:
    """build/excavator.ssp, packed (with the linkage rebuilt) when missing or older than
    its sources."""
    sources = [ROOT / "ssp" / "excavator.ssd", ROOT / "ssp" / "excavator.ssv",
               ROOT / "fmus" / "linkage" / "linkage_fmu.py", *ROOT.joinpath("src", "boomfmi", "physics").rglob("*.py")]
    if not SSP.is_file() or any(s.stat().st_mtime > SSP.stat().st_mtime for s in sources):
        subprocess.run([sys.executable, str(ROOT / "build_fmus.py"), "linkage"], check=True, cwd=ROOT)
    return SSP


def dig_inputs(t: float) -> dict:
    from boomfmi.experiments import digging_cycle
    prof = dig_inputs.profile = getattr(dig_inputs, "profile", None) or digging_cycle()
    return {f"valve_{k[2:]}.u": u for k, u in prof(t).items()}


def test_parameter_set_is_the_physics(tmp_path, excavator_ssp):
    """ssp/excavator.ssv is what fmubuild.ssp.parameters_ssv writes for the excavator machine."""
    from boomfmi.fmubuild.ssp import parameters_ssv
    from boomfmi.model.machine import excavator_machine
    fmus = tmp_path / "fmus"
    fmus.mkdir()
    with zipfile.ZipFile(excavator_ssp) as z:
        for name in ("valve", "cylinder", "linkage"):
            (fmus / f"{name}.fmu").write_bytes(z.read(f"resources/{name}.fmu"))
    fresh = read_ssv(parameters_ssv(excavator_machine(), ROOT / "ssp" / "excavator.ssd", fmus, tmp_path / "e.ssv").read_bytes(), "fresh")
    shipped = read_ssv((ROOT / "ssp" / "excavator.ssv").read_bytes(), "ssp/excavator.ssv")
    assert set(fresh) == set(shipped)
    for name, p in fresh.items():
        assert shipped[name].value == pytest.approx(p.value, rel=1e-12), name
    ex = exc.excavator_parameters()
    for j in JOINTS:
        a = getattr(ex, j)
        assert shipped[f"valve_{j}.A_max"].value == pytest.approx(a.A_max)
        for n in ("A_a", "A_b", "L", "V_a0", "V_b0"):
            assert shipped[f"cylinder_{j}.{n}"].value == pytest.approx(getattr(a, n)), (j, n)
    assert shipped["cylinder_arm.L"].value == pytest.approx(0.08)
    assert shipped["valve_boom.A_max"].value == pytest.approx(4e-6)


def test_wiring(excavator_ssp):
    with zipfile.ZipFile(excavator_ssp) as z:
        root = ET.fromstring(z.read("SystemStructure.ssd"))
        names = set(z.namelist())
    comps = [c.get("name") for c in root.iter(f"{{{NS['ssd']}}}Component")]
    assert sorted(comps) == sorted([f"{k}_{j}" for k in ("valve", "cylinder") for j in JOINTS] + ["linkage"])
    conns = {(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
             for c in root.iter(f"{{{NS['ssd']}}}Connection")}
    assert len(conns) == 4 * 12 + 4                             # + u_<joint> -> valve_<joint>.u
    for j in JOINTS:
        assert ("cylinder_" + j, "p_a", "linkage", f"p_a_{j}") in conns
        assert ("linkage", f"x_{j}", "cylinder_" + j, "x") in conns
        assert ("valve_" + j, "dmdot_b_dp_b", "cylinder_" + j, "dmdot_b_dp_b") in conns
        assert ("valve_" + j, "p_b_flow", "cylinder_" + j, "p_b_flow") in conns
    assert sum(n.endswith(".fmu") for n in names) == 3          # each FMU packed once


def test_master_runs_it_and_joints_move_and_hold(excavator_ssp):
    """At rest with closed valves the machine holds still (the start pressures hold it);
    opening the swing's valve swings only the swing."""
    with CoSimulation(excavator_ssp, 1e-3) as cs:
        assert cs.inputs[:4] == [f"valve_{j}.u" for j in JOINTS]
        df = cs.simulate(1.0, lambda t: {"valve_swing.u": 5.0 if t < 0.5 else 2.0})
    rest = df[df.time <= 0.5]
    for j in JOINTS:
        assert np.ptp(rest[f"linkage.x_{j}"]) < 1e-9, j
    assert df["linkage.x_swing"].iloc[-1] > 0.03
    for j in ("boom", "arm", "bucket"):
        assert abs(df[f"linkage.x_{j}"].iloc[-1] - df[f"linkage.x_{j}"].iloc[0]) < 1e-3, j


def test_connected_components_must_agree_on_one_quantity(ssp_path, excavator_ssp):
    """The joints' cylinders differ (their own strokes), but the boom's cylinder and boom
    load, joined by connections, must agree."""
    with CoSimulation(excavator_ssp, 1e-3):
        pass
    with pytest.raises(SspError, match="L is one quantity"):
        CoSimulation(ssp_path, 1e-3, parameters={"cylinder.L": 0.05})


def test_boomfmi_simulate_writes_the_excavator_columns(excavator_ssp, tmp_path):
    out = tmp_path / "dig.csv"
    proc = subprocess.run([sys.executable, "-m", "boomfmi.cli", "simulate", str(excavator_ssp),
                           "--experiment", "digging_cycle", "--stop", "2.5", "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, PYTHONPATH=str(ROOT / "src")))
    assert proc.returncode == 0, proc.stderr[-2000:]
    from boomfmi.recording import EXCAVATOR_REQUIRED, read_recording
    df = pd.read_csv(out)
    assert set(EXCAVATOR_REQUIRED) <= set(df.columns)
    assert len(df) == 2501
    assert df["u_swing"].iloc[1000] == pytest.approx(3.0)                  # swing to the trench
    assert df["angle_swing"].iloc[-1] > df["angle_swing"].iloc[0] + 0.3
    assert df["p_a_boom"].iloc[0] == pytest.approx(679511.17 - 101325.0, rel=1e-6)   # gauge
    rec = read_recording(out)
    assert rec.kind == "excavator"


def test_fast_linkage_terms_equal_the_array_functions():
    rng = np.random.default_rng(3)
    ex = exc.excavator_parameters()
    for _ in range(10):
        x = rng.uniform(0.0, 1.0, 4) * ex.strokes
        payload = rng.uniform(0.0, 2.0)
        q = exc.joint_angles(x, ex)
        P = exc._prepared(ex, payload)
        M, _, G = exc._rigid_terms(list(q), [0.0] * 4, P)
        np.testing.assert_allclose(M, exc.mass_matrix(q, payload, ex), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(G, exc.gravity(q, payload, ex), rtol=1e-12, atol=1e-12)
        f = rng.normal(0.0, 50.0, 3)
        np.testing.assert_allclose(exc._fast_tip_torques(list(q), f, P), exc.tip_torques(q, f, ex), atol=1e-10)
        angles, tip = exc.angles_and_tip(x, ex)
        np.testing.assert_allclose(angles, q, atol=1e-12)
        np.testing.assert_allclose(tip, exc.tip_position(q, ex), atol=1e-12)


def test_holding_pressures_hold_the_machine():
    from boomfmi.model.machine import ExcavatorMachine
    m = ExcavatorMachine()
    x0, p_a, p_b = m.start()
    acc = exc.piston_accelerations(x0, np.zeros(4), exc.cylinder_forces(p_a, p_b, m.ex), ex=m.ex)
    np.testing.assert_allclose(acc, 0.0, atol=1e-9)
    assert p_a[0] < p_b[0]              # the swing carries no gravity: equal forces, unequal areas


# -- third-party hosts ---------------------------------------------------------------------

N_STEPS = 1500


def swing_and_boom(t: float) -> dict:
    return {"valve_swing.u": 5.0 if t < 0.3 else 2.0, "valve_boom.u": 5.0 if t < 0.6 else 7.0}


def test_libcosim_runs_it_and_agrees_with_the_jacobi_master(excavator_ssp):
    pytest.importorskip("libcosimpy", reason="libcosimpy is a test dependency")
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    log_output_level(CosimLogLevel.WARNING)
    from boomfmi.fmubuild.ssp import osp_ssp     # libcosim refuses system connectors
    ex = CosimExecution.from_ssp_file(str(osp_ssp(excavator_ssp)), step_size=1_000_000)
    names = [f"{k}_{j}" for k in ("valve", "cylinder") for j in JOINTS] + ["linkage"]
    idx = {n: ex.slave_index_from_instance_name(n) for n in names}
    ref = {(n, v.name.decode()): v.reference for n, i in idx.items() for v in ex.slave_variables(i)}
    observer = CosimObserver.create_last_value()
    manipulator = CosimManipulator.create_override()
    assert ex.add_observer(observer) and ex.add_manipulator(manipulator)
    rows, now = [], {}
    for k in range(N_STEPS):
        for name, u in swing_and_boom(k * 1e-3).items():
            if now.get(name) != u:
                comp = name.partition(".")[0]
                assert manipulator.slave_real_values(idx[comp], [ref[(comp, "u")]], [u])
                now[name] = u
        assert ex.step()
        xs = observer.last_real_values(idx["linkage"], [ref[("linkage", f"x_{j}")] for j in JOINTS])
        ps = [observer.last_real_values(idx[f"cylinder_{j}"], [ref[(f"cylinder_{j}", "p_a")]])[0] for j in JOINTS]
        rows.append([ex.status().current_time / 1e9, *xs, *ps])
    lib = np.array(rows)
    # the per-component parameter sets were applied
    assert observer.last_real_values(idx["cylinder_arm"], [ref[("cylinder_arm", "L")]])[0] == pytest.approx(0.08)
    ours = simulate_ssp(excavator_ssp, stop_time=N_STEPS * 1e-3, step=1e-3, algorithm="jacobi",
                        inputs=swing_and_boom).iloc[1:]
    np.testing.assert_allclose(lib[:, 0], ours["time"], atol=1e-12)
    for i, j in enumerate(JOINTS):
        np.testing.assert_allclose(lib[:, 1 + i], ours[f"linkage.x_{j}"], rtol=1e-6, atol=1e-12, err_msg=j)
        np.testing.assert_allclose(lib[:, 5 + i], ours[f"cylinder_{j}.p_a"], rtol=1e-6, err_msg=j)
    assert lib[-1, 1] == pytest.approx(0.05)          # the swing ran to its end
    assert lib[-1, 2] < 0.03 - 0.005                  # the boom came down


ECOS_SCENARIO = """<?xml version="1.0" encoding="UTF-8"?>
<ecos:Scenario xmlns:ecos="http://github.com/Ecos-platform/libecos/resources/schema/ScenarioConfig" eps="0.0001">
  <ecos:action t="0"><ecos:variable id="valve_swing::u"><ecos:real value="5.0"/></ecos:variable></ecos:action>
  <ecos:action t="0"><ecos:variable id="valve_boom::u"><ecos:real value="5.0"/></ecos:variable></ecos:action>
  <ecos:action t="0.3"><ecos:variable id="valve_swing::u"><ecos:real value="2.0"/></ecos:variable></ecos:action>
  <ecos:action t="0.6"><ecos:variable id="valve_boom::u"><ecos:real value="7.0"/></ecos:variable></ecos:action>
</ecos:Scenario>
"""
ECOS_CSV = """<?xml version="1.0" encoding="UTF-8"?>
<ecos:CsvConfig xmlns:ecos="http://github.com/Ecos-platform/libecos/resources/schema/CsvConfig">
  <ecos:components>
    <ecos:component name="linkage"><ecos:variable name="x_swing"/><ecos:variable name="x_boom"/></ecos:component>
    <ecos:component name="cylinder_boom"><ecos:variable name="p_a"/></ecos:component>
  </ecos:components>
</ecos:CsvConfig>
"""


def test_ecos_runs_it(excavator_ssp, tmp_path):
    """The ecos recipe of tests/test_native_host.py (no Python in ecos's environment)."""
    from test_native_host import ecos_binary, libpython
    if libpython() is None:
        pytest.skip("this Python has no shared libpython for the FMUs to load")
    exe = ecos_binary(tmp_path)
    (tmp_path / "scenario.xml").write_text(ECOS_SCENARIO)
    (tmp_path / "csv.xml").write_text(ECOS_CSV)
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("PYTHON") and k not in ("LD_PRELOAD", "BOOMFMI_LIBPYTHON", "VIRTUAL_ENV")}
    env.update(LD_LIBRARY_PATH=os.path.join(sys.prefix, "lib"), TMPDIR=str(tmp_path))
    from boomfmi.fmubuild.ssp import osp_ssp     # ecos refuses system connectors
    proc = subprocess.run([str(exe), "simulate", "--path", str(osp_ssp(excavator_ssp)), "--stepSize", "0.001",
                           "--stopTime", "1.5", "--parameterSet", "excavator",
                           "--scenarioConfig", "scenario.xml", "--csvConfig", "csv.xml"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    out = pd.read_csv(tmp_path / "excavator.csv", skipinitialspace=True)
    out.columns = [c.strip() for c in out.columns]
    ours = simulate_ssp(excavator_ssp, stop_time=1.5, step=1e-3, algorithm="jacobi", inputs=swing_and_boom)
    theirs = out.set_index(np.round(out["time"].to_numpy(), 6))
    mine = ours.set_index(np.round(ours["time"].to_numpy(), 6))
    common = theirs.index.intersection(mine.index)
    assert len(common) > 1000
    for col in ("x_swing", "x_boom"):
        np.testing.assert_allclose(theirs.loc[common, f"linkage::{col}[REAL]"], mine.loc[common, f"linkage.{col}"],
                                   rtol=0, atol=1e-6, err_msg=col)
    np.testing.assert_allclose(theirs.loc[common, "cylinder_boom::p_a[REAL]"], mine.loc[common, "cylinder_boom.p_a"],
                               rtol=1e-5)
    assert theirs["linkage::x_swing[REAL]"].iloc[-1] == pytest.approx(0.05)


# -- accuracy --------------------------------------------------------------------------------

@pytest.mark.slow
def test_cosimulation_within_one_percent_of_the_monolithic_reference(excavator_ssp):
    """At 1 ms (Gauss-Seidel), over the digging cycle: every joint's x, p_a and p_b
    within 1 % NRMSE of the monolithic reference (benchmarks/excavator_cosim.py prints the
    figures)."""
    from boomfmi.experiments import digging_cycle
    from boomfmi.model.reference import simulate_excavator_reference
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from excavator_cosim import nrmse_table
    prof = digging_cycle()
    ref = simulate_excavator_reference(prof, prof.duration)
    co = simulate_ssp(excavator_ssp, stop_time=prof.duration, step=1e-3, inputs=dig_inputs)
    table = nrmse_table(co, ref)
    assert len(table) == 12
    worst = max(table.values())
    assert worst < 0.01, table
    # every joint moved over most of its stroke: the comparison is not of a still machine
    for j in JOINTS:
        assert np.ptp(ref[f"x_{j}"]) > 0.5 * getattr(exc.excavator_parameters(), j).stroke, j


def test_fmpy_wires_the_connections_the_ssd_declares(excavator_ssp):
    """fmpy's SSP reader resolves exactly the SSD's fifty-two connections (no undeclared
    free input for it to mis-wire; a system connector is named bare, u_swing)."""
    fmpy_ssd = pytest.importorskip("fmpy.ssp.ssd")
    from boomfmi.system.ssp import read_ssp
    ssd = fmpy_ssd.read_ssd(str(excavator_ssp))
    cut = len(ssd.system.name) + 1
    theirs = {(fmpy_ssd.build_path(a)[cut:], fmpy_ssd.build_path(b)[cut:])
              for a, b in fmpy_ssd.get_connections(ssd.system)}
    ours = {tuple(c.describe().split(" -> ")) for c in read_ssp(excavator_ssp).connections}
    assert theirs == ours and len(ours) == 52             # 48 + the system's u_<joint> -> valve_<joint>.u
