"""Third-party import: fmpy's own SSP runner (``fmpy.ssp.simulation.simulate_ssp``,
fmpy 0.3.32) wires the packed .ssp as the SSD declares, and runs it in agreement
with boomfmi's Jacobi master.

What fmpy's runner does (read from its source): it steps like libcosim and our Jacobi
master (every component on the values transferred after the previous step, then all
transfers), but

* it applies none of the SSD's parameter bindings (``read_ssd`` parses them): the
  caller passes ``parameter_set`` (hierarchical names: the SSP carries its set whole
  as ``resources/reference_rig.ssv``), set before initialisation;
* it starts every connector at 0, so in its first step every connected input is 0:
  the cylinder gets no flow (that step is idle, and the run lags ours by one step)
  and the valve is evaluated at 0 Pa and 0 V (its system connector u reaches it a
  step late), whose flows reach the cylinder in the second step;
* it stamps a row with the start of the step whose end values it holds.

The last two cancel in the alignment: fmpy's row k is compared with our row k (t_k).
The valve's flows at 0 Pa and 0 V differ from those at the start pressures and U; the
difference, held over one step, puts a mass into a chamber that the isentropic chamber
turns into a pressure kick of k R T dm / V.  The runs may differ by that kick while it
exhausts through the open valve (50 ms), and after it by no more than its trace on the
trajectory (1 Pa, 1e-6 m; 0.3 Pa and 4e-8 m seen).  tests/test_system_connectors.py
runs paper_multistep and the digging cycle through the system connectors.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from boomfmi.system import fmpy_input, simulate_ssp
from boomfmi.system.ssp import read_ssp

fmpy_ssd = pytest.importorskip("fmpy.ssp.ssd")
from fmpy.ssp.simulation import simulate_ssp as fmpy_simulate_ssp  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
H = 1e-3            # communication step [s]
STOP = 1.5          # the boom extends fully by 0.8 s
U = 1.0             # valve.u [V], held: supply -> A, B -> exhaust (extend)
KICK_WINDOW = 0.05  # [s] the kick has exhausted through the valve by then
P_TOL = 1.0         # [Pa] after the kick
X_TOL = 1e-6        # [m] over the run


def _fmpy_connections(path) -> set[tuple[str, str]]:
    """fmpy's resolved connections, as ``element.connector`` pairs (system name cut)."""
    ssd = fmpy_ssd.read_ssd(str(path))
    cut = len(ssd.system.name) + 1
    pairs = set()
    for a, b in fmpy_ssd.get_connections(ssd.system):
        pairs.add((fmpy_ssd.build_path(a)[cut:], fmpy_ssd.build_path(b)[cut:]))
    return pairs


@pytest.mark.parametrize("name", ["excavator_boom", "teleoperation"])
def test_fmpy_wires_the_connections_the_ssd_declares(fmu_dir, name):
    """An input connector that no connection ends at, fmpy wires to the source of the
    connection found before it (boom_load.f_ext to cylinder.p_b) or fails; the SSDs
    declare none, so fmpy's wiring is exactly the SSD's (a system connector named bare)."""
    path = fmu_dir.parent / f"{name}.ssp"
    ours = {tuple(c.describe().split(" -> ")) for c in read_ssp(path).connections}
    assert _fmpy_connections(path) == ours


def test_pack_ssp_refuses_an_input_connector_that_no_connection_ends_at(fmu_dir, tmp_path):
    from boomfmi.fmubuild import BuildError
    from boomfmi.fmubuild.ssp import pack_ssp
    ssd = (ROOT / "ssp" / "SystemStructure.ssd").read_text()
    declared = '<ssd:Connector name="p_a" kind="input"><ssc:Real unit="Pa"/></ssd:Connector>'
    loose = '<ssd:Connector name="f_ext" kind="input"><ssc:Real unit="N"/></ssd:Connector>\n          '
    assert ssd.count(declared) == 2        # the valve's, then the boom load's
    head, _, tail = ssd.rpartition(declared)
    (tmp_path / "SystemStructure.ssd").write_text(head + loose + declared + tail)
    with pytest.raises(BuildError, match=r"boom_load\.f_ext end no connection"):
        pack_ssp(tmp_path / "SystemStructure.ssd", fmu_dir, tmp_path / "loose.ssp")
    assert not (tmp_path / "loose.ssp").exists()


def _bound_parameters(path) -> dict[str, tuple[str, str]]:
    """The component bindings as fmpy reads them: ``{component.name: (type, value)}``."""
    ssd = fmpy_ssd.read_ssd(str(path))
    return {f"{c.name}.{p.name}": (p.type, p.value)
            for c in fmpy_ssd.find_components(ssd.system)
            for b in c.parameterBindings for s in b.parameterValues for p in s.parameters}


def test_fmpy_reads_the_bound_parameter_sets(ssp_path):
    """fmpy parses (and validates) the per-component .ssv files; it does not apply them,
    but a caller can pass what it read as ``parameter_set``."""
    bound = _bound_parameters(ssp_path)
    ours = read_ssp(ssp_path).parameters
    assert set(bound) == set(ours)
    for name, (typ, value) in bound.items():
        assert typ == ours[name].type, name
        assert float(value) == float(ours[name].value), name
    assert float(bound["valve.A_max"][1]) == 4e-6


def _kick(ours, theirs, chamber: str, params) -> float:
    """Pressure kick [Pa] in ``chamber`` from fmpy's first valve flows (at 0 Pa) against
    ours (at the start pressures), held over one step: k R T dm / V at x = 0."""
    dm = abs(theirs[f"valve.mdot_{chamber}"][0] - ours[f"valve.mdot_{chamber}"].iloc[0]) * H
    p = {n.partition(".")[2]: float(v.value) for n, v in params.items() if n.startswith("cylinder.")}
    volume = p[f"V_{chamber}0"] + (p["A_b"] * p["L"] if chamber == "b" else 0.0)
    return p["k"] * p["R"] * p["T"] * dm / volume


def test_fmpy_runs_the_ssp_and_agrees_with_the_jacobi_master(ssp_path):
    # the SSP's parameter set whole, and the system connector u held at U
    parameter_set = fmpy_ssd.read_ssv(str(ssp_path), resource="resources/reference_rig.ssv")
    theirs = fmpy_simulate_ssp(str(ssp_path), stop_time=STOP, step_size=H, parameter_set=parameter_set,
                               input=fmpy_input(ssp_path, {"u": U}, H))
    # fmpy's first step hands the valve 0 V (every connector starts at 0), whose flows the
    # cylinder takes in the next: ours starts the valve at 0 V (the flows the cylinder
    # takes in its first step), then drives u = U
    ours = simulate_ssp(ssp_path, stop_time=STOP, step=H, algorithm="jacobi",
                        parameters={"valve.u": 0.0}, inputs={"u": U})

    # fmpy adds the step to a float time: 1500 or 1501 rows; row k is stamped t_k
    n = min(len(theirs), len(ours))
    assert n == len(ours) - 1 or n == len(ours)
    assert n >= round(STOP / H)
    np.testing.assert_allclose(theirs["time"][:n], ours["time"].iloc[:n], rtol=0, atol=1e-9)
    theirs, ours = theirs[:n], ours.iloc[:n]

    params = read_ssp(ssp_path).parameters
    early = ours["time"].to_numpy() < KICK_WINDOW
    for chamber in ("a", "b"):
        col = f"cylinder.p_{chamber}"
        d = np.abs(theirs[col] - ours[col].to_numpy())
        kick = _kick(ours, theirs, chamber, params)
        assert d[early].max() <= 1.05 * kick + P_TOL, (col, d[early].max(), kick)
        assert d[~early].max() <= P_TOL, (col, d[~early].max())
    dx = np.abs(theirs["boom_load.x"] - ours["boom_load.x"].to_numpy())
    assert dx.max() <= X_TOL, dx.max()
    # and the run did something: the boom extended fully, chamber A reached supply
    assert theirs["boom_load.x"][-1] == pytest.approx(0.06)
    assert theirs["cylinder.p_a"][-1] == pytest.approx(701325.0, rel=1e-3)
