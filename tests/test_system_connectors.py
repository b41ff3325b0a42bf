"""System-level input connectors (issue 37, item 5): the boom's SSD declares ``u`` and the
excavator's ``u_swing``, ``u_boom``, ``u_arm``, ``u_bucket``, each wired to its valve's
command, so that fmpy's own SSP runner (``fmpy.ssp.simulation.simulate_ssp``, 0.3.32)
drives ``paper_multistep`` and the digging cycle with ``input=`` and no edit of the SSD.

What fmpy does with them (read from its source): before each step it sets each system
input connector to ``input[name](time)``, at its float time (the step added up:
2.9999999999997806 for 3 s); a connection copies the value to the valve's connector
after the step, so the valve gets it one step later than boomfmi's master gives it;
every connector starts at 0, so in its first step each valve gets 0 V (full extend)
and 0 Pa.  Its first step is idle for the cylinders (no flow yet), which puts the two
runs back in step: fmpy's row k holds the master's row k.  ``fmpy_input`` reads the
command at the communication point nearest the float fmpy sends.
"""
from __future__ import annotations

import numpy as np
import pytest

from boomfmi.experiments import digging_cycle, paper_multistep
from boomfmi.physics.linkage import JOINTS
from boomfmi.system import CoSimulation, fmpy_input, simulate_ssp
from boomfmi.system.ssp import read_ssp

fmpy_ssd = pytest.importorskip("fmpy.ssp.ssd")
from fmpy.ssp.simulation import simulate_ssp as fmpy_simulate_ssp  # noqa: E402

from conftest import ROOT, rewrite_ssp  # noqa: E402

H = 1e-3
LATE = 0.05         # [s] the comparison starts after fmpy's first step has settled


def nrmse(theirs, ours, column: str, n: int) -> float:
    """RMS difference over the master's range of ``column``, rows from LATE on."""
    a, b = np.asarray(theirs[column][:n], float), ours[column].to_numpy()[:n]
    keep = ours["time"].to_numpy()[:n] >= LATE
    return float(np.sqrt(np.mean((a[keep] - b[keep]) ** 2)) / np.ptp(b))


def run_fmpy(ssp, profile, stop: float, parameter_set: str):
    return fmpy_simulate_ssp(str(ssp), stop_time=stop, step_size=H,
                             parameter_set=fmpy_ssd.read_ssv(str(ssp), resource=f"resources/{parameter_set}.ssv"),
                             input=fmpy_input(ssp, profile, H))


@pytest.fixture(scope="module")
def excavator_ssp(fmu_dir):
    path = fmu_dir.parent / "excavator.ssp"
    if not path.is_file():
        pytest.skip(f"{path} is not built")
    return path


def test_the_ssds_declare_a_system_input_per_valve_wired_to_its_command(ssp_path, excavator_ssp):
    boom = read_ssp(ssp_path)
    assert boom.connectors == {"u": "input"}
    assert [c.describe() for c in boom.connections if not c.start_element] == ["u -> valve.u"]
    exc = read_ssp(excavator_ssp)
    assert exc.connectors == {f"u_{j}": "input" for j in JOINTS}
    assert sorted(c.describe() for c in exc.connections if not c.start_element) == \
        sorted(f"u_{j} -> valve_{j}.u" for j in JOINTS)


def test_fmpy_runs_the_digging_cycle_on_the_excavator(excavator_ssp):
    """Within 1 % NRMSE but for chamber A's pressure of the joints whose valve stays
    closed for a while: fmpy's first step hands every valve 0 V (full extend), and the
    air it lets into chamber A stays there until the joint's valve opens (0.6 to 2.5 %).
    The master given 0 V over its first step agrees with fmpy on every chamber A (within
    1 %, most within 0.05 %); chamber B differs by up to 2 % instead: fmpy's valve also
    sees 0 Pa in that step (every connector starts at 0), so exhaust air flows INTO
    chamber B, where the master's valve sees the chamber's start pressure (consistent
    start values) and lets air out."""
    profile = digging_cycle()
    theirs = run_fmpy(excavator_ssp, profile, profile.duration, "excavator")
    ours = simulate_ssp(excavator_ssp, profile.duration, H, "jacobi", inputs=profile)
    n = min(len(theirs), len(ours))
    assert n >= round(profile.duration / H)
    x = {j: nrmse(theirs, ours, f"linkage.x_{j}", n) for j in JOINTS}
    p_b = {j: nrmse(theirs, ours, f"cylinder_{j}.p_b", n) for j in JOINTS}
    p_a = {j: nrmse(theirs, ours, f"cylinder_{j}.p_a", n) for j in JOINTS}
    assert max(x.values()) < 0.01 and max(p_b.values()) < 0.01, (x, p_b)
    assert max(p_a.values()) < 0.03, p_a
    zero_start = simulate_ssp(excavator_ssp, profile.duration, H, "jacobi",     # 0 V over the first step
                              inputs=lambda t: {n: 0.0 for n in profile(t)} if t < H / 2 else profile(t))
    same_start = {c: nrmse(theirs, zero_start, c, n)
                  for c in [f"linkage.x_{j}" for j in JOINTS] + [f"cylinder_{j}.p_{s}" for j in JOINTS for s in "ab"]}
    assert max(same_start[f"cylinder_{j}.p_a"] for j in JOINTS) < 0.01, same_start
    assert max(same_start[f"linkage.x_{j}"] for j in JOINTS) < 0.001, same_start
    assert max(same_start[f"cylinder_{j}.p_b"] for j in JOINTS) < 0.025, same_start
    for j in JOINTS:        # and every joint moved: the comparison is not of a still machine
        assert np.ptp(ours[f"linkage.x_{j}"]) > 0.01, j


def test_fmpy_input_reads_the_command_at_the_nearest_communication_point(ssp_path):
    profile = paper_multistep()
    feed = fmpy_input(ssp_path, profile, H)
    assert list(feed) == ["u"]
    t, late = 0.0, []
    for k in range(round(profile.duration / H)):       # fmpy's float time
        if profile(t)["u"] != profile(k * H)["u"]:
            late.append(k)
        assert feed["u"](t) == profile(k * H)["u"], k
        t += H
    assert late == [3000, 4000]          # where a plain function of fmpy's time lands late
    # a table's change between two points is applied from the next point on
    import pandas as pd
    table = pd.DataFrame({"t": [0.0, 0.3005], "u": [10.0, 1.0]})
    feed = fmpy_input(ssp_path, table, H)
    assert feed["u"](0.3 - 1e-13) == 10.0 and feed["u"](0.301 - 1e-13) == 1.0


def test_fmpy_input_names_what_the_system_does_not_take(ssp_path, excavator_ssp):
    with pytest.raises(ValueError, match=r"none of excavator\.ssp's system input connectors u_swing, u_boom"):
        fmpy_input(excavator_ssp, paper_multistep(), H)
    with pytest.raises(ValueError, match=r"no free input \['u_arm'\]"):
        fmpy_input(ssp_path, {"u_arm": 1.0}, H)
    with pytest.raises(ValueError, match=r"step must be > 0 s"):
        fmpy_input(ssp_path, {"u": 1.0}, 0.0)


def test_the_master_takes_a_system_connector_by_either_name_through_its_transformation(ssp_path, tmp_path):
    """u feeds valve.u through the connection's linear transformation (2 u + 1 here);
    the run lists valve.u (what the valve gets) and takes u or valve.u, not both."""
    doubled = rewrite_ssp(ssp_path, tmp_path / "doubled.ssp", edit=lambda s: s.replace(
        '<ssd:Connection startConnector="u" endElement="valve" endConnector="u"/>',
        '<ssd:Connection startConnector="u" endElement="valve" endConnector="u">'
        '<ssc:LinearTransformation factor="2" offset="1"/></ssd:Connection>'))
    by_system = simulate_ssp(doubled, 0.05, H, "jacobi", inputs={"u": 0.5})
    by_valve = simulate_ssp(doubled, 0.05, H, "jacobi", inputs={"valve.u": 2.0})
    plain = simulate_ssp(ssp_path, 0.05, H, "jacobi", inputs={"valve.u": 2.0})
    assert list(by_system.columns) == list(plain.columns) and "u" not in by_system.columns
    assert (by_system["valve.u"] == 2.0).all()
    np.testing.assert_array_equal(by_system.to_numpy(), by_valve.to_numpy())
    np.testing.assert_array_equal(by_system.to_numpy(), plain.to_numpy())
    with CoSimulation(doubled, H) as cs:
        assert cs.inputs == ["valve.u", "boom_load.f_ext"]
        with pytest.raises(ValueError, match=r"'u' and 'valve\.u', one system input connector under two names"):
            cs.simulate(0.01, {"u": 1.0, "valve.u": 3.0})


def test_the_ssp_carries_its_parameter_set_whole_for_fmpy(ssp_path, excavator_ssp):
    """fmpy applies no binding, only ``parameter_set`` with hierarchical names: the SSP
    carries the set its components bind, whole, as resources/<set>.ssv."""
    for path, name in ((ssp_path, "reference_rig"), (excavator_ssp, "excavator")):
        whole = fmpy_ssd.read_ssv(str(path), resource=f"resources/{name}.ssv")
        bound = read_ssp(path).parameters
        assert {p.name for p in whole.parameters} == set(bound), path
        for p in whole.parameters:
            assert float(p.value) == float(bound[p.name].value), p.name


def test_the_osp_copy_leaves_the_system_connectors_out_for_libcosim_and_ecos(ssp_path, tmp_path):
    """libcosim ("No such node (<xmlattr>.startElement)") and ecos ("No element named: ")
    refuse a connection from a system connector: osp_ssp writes the same SSP without
    them, the valve's u a free input again, and runs as the SSP does."""
    from boomfmi.fmubuild.ssp import osp_ssp
    copy = tmp_path / ssp_path.name
    copy.write_bytes(ssp_path.read_bytes())
    osp = osp_ssp(copy)
    assert osp == tmp_path / "osp" / ssp_path.name
    structure = read_ssp(osp)
    assert structure.connectors == {} and "u" not in structure.components["valve"].connectors
    assert len(structure.connections) == len(read_ssp(ssp_path).connections) - 1
    profile = paper_multistep()
    a = simulate_ssp(osp, 0.2, H, "jacobi", inputs=lambda t: {"valve.u": profile(t)["u"]})
    b = simulate_ssp(ssp_path, 0.2, H, "jacobi", inputs=profile)
    np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())
    assert ROOT.joinpath("ssp", "SystemStructure.ssd").read_text().count('startConnector="u"') == 1
