"""The SSP system and boomfmi's co-simulation master."""
from __future__ import annotations

import math
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from boomfmi.experiments import paper_multistep
from boomfmi.physics import reference_rig
from boomfmi.model import Model
from boomfmi.model.reference import simulate_reference
from boomfmi.system import CoSimulation, SspError, simulate_ssp
from boomfmi.system.ssp import read_ssp, validate_ssd
from boomfmi.system.ssv import read_ssv, write_ssv
from conftest import rewrite_ssp

ROOT = Path(__file__).resolve().parents[1]


def extend(t):
    return {"valve.u": 10.0 if t < 0.5 else 1.0}


def test_source_and_packed_ssd_validate_against_the_ssp_1_0_schema(ssp_path):
    validate_ssd(ROOT.joinpath("ssp", "SystemStructure.ssd").read_bytes(), "ssp/SystemStructure.ssd")
    with zipfile.ZipFile(ssp_path) as z:
        validate_ssd(z.read("SystemStructure.ssd"), "packed")
        names = set(z.namelist())
    assert {"SystemStructure.ssd", "resources/valve.fmu", "resources/cylinder.fmu",
            "resources/boom_load.fmu", "resources/reference_rig_valve.ssv"} <= names


def test_schema_violation_is_reported_with_its_line(ssp_path, tmp_path):
    bad = rewrite_ssp(ssp_path, tmp_path / "bad.ssp",
                      edit=lambda s: s.replace('<ssd:Elements>', '<ssd:Elements><ssd:Bogus/>', 1))
    with pytest.raises(SspError, match=r"SSP 1.0 schema:\n  line \d+"):
        read_ssp(bad)


def test_reference_parameter_set_is_the_reference_rig():
    params = read_ssv(ROOT.joinpath("ssp", "reference_rig.ssv").read_bytes(), "reference_rig.ssv")
    expected = {"valve.P_s": reference_rig.P_s, "valve.A_max": reference_rig.A_max, "valve.T": reference_rig.T,
                "cylinder.A_b": reference_rig.A_b, "cylinder.V_a0": reference_rig.V_a0, "cylinder.L": reference_rig.L,
                "boom_load.K_v": reference_rig.K_v, "boom_load.F_s": reference_rig.F_s, "boom_load.F_d": reference_rig.F_d,
                "boom_load.F_L": reference_rig.F_L, "boom_load.M": reference_rig.M, "boom_load.a": reference_rig.a,
                "boom_load.l_min": reference_rig.l_min}
    for name, value in expected.items():
        assert params[name].value == value, name
    assert params["valve.A_max"].unit == "m2"


def test_packed_parameter_sets_are_per_component_with_bare_names(ssp_path):
    with zipfile.ZipFile(ssp_path) as z:
        part = read_ssv(z.read("resources/reference_rig_boom_load.ssv"), "boom_load part")
    assert part["M"].value == reference_rig.M and "boom_load.M" not in part
    assert all("." not in n for n in part)


def test_first_row_is_t0_at_the_fmus_start_values(ssp_path):
    result = simulate_ssp(ssp_path, stop_time=0.01, step=1e-3)
    np.testing.assert_array_equal(result["time"], np.round(np.arange(11) * 1e-3, 12))
    first = result.iloc[0]
    assert first["time"] == 0.0
    assert first["cylinder.p_a"] == reference_rig.P_atm and first["cylinder.p_b"] == reference_rig.P_atm
    assert first["boom_load.x"] == 0.0 and first["valve.u"] == 5.0
    assert first["boom_load.alpha"] == pytest.approx(math.acos((reference_rig.a**2 + reference_rig.b**2 - reference_rig.l_min**2) / (2 * reference_rig.a * reference_rig.b)))


def test_rows_belong_to_their_time(ssp_path):
    """The input at t_k shows in the row at t_k, and the valve's flows in that row are
    those of the inputs at t_k (evaluated before the row is recorded)."""
    result = simulate_ssp(ssp_path, stop_time=0.01, step=1e-3,
                          inputs=lambda t: {"valve.u": 0.0 if t >= 0.005 - 1e-9 else 5.0})
    assert list(result["valve.u"][:7]) == [5, 5, 5, 5, 5, 0, 0]
    assert result["valve.mdot_a"][4] == 0.0 and result["valve.mdot_a"][5] > 0.0
    assert result["cylinder.p_a"][5] == reference_rig.P_atm and result["cylinder.p_a"][6] > reference_rig.P_atm


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_cosimulation_matches_the_monolithic_reference(ssp_path, algorithm):
    profile = paper_multistep()
    ref = simulate_reference(Model(), profile, 4.5, breakpoints=profile.breakpoints)
    co = simulate_ssp(ssp_path, stop_time=4.5, step=1e-3, algorithm=algorithm,
                      inputs=lambda t: {"valve.u": profile(t)["u"]})
    assert len(co) == len(ref) == 4501
    for name, col in (("x", "boom_load.x"), ("p_a", "cylinder.p_a"), ("p_b", "cylinder.p_b")):
        err = np.sqrt(np.mean((co[col].to_numpy() - ref[name].to_numpy()) ** 2))
        assert err / (ref[name].max() - ref[name].min()) < 0.01, name


def test_jacobi_holds_the_end_stop_as_gauss_seidel_does(ssp_path, tmp_path):
    """Issue 36, item 6: valve.u = 1 V held, the piston on its stop.  A host stepping
    Jacobi hands the cylinder the valve's flows of the previous communication point; the
    valve passes the pressures it evaluated them at (p_a_flow, p_b_flow) and the cylinder
    carries them along their slopes to its own.  Without those two connections chamber
    B's pressure alternates about the exhaust's every step."""
    def tail(ssp, algorithm):
        co = simulate_ssp(ssp, stop_time=1.5, step=1e-3, algorithm=algorithm, inputs={"valve.u": 1.0})
        assert co["boom_load.x"].iloc[-1] == pytest.approx(reference_rig.L)      # on its stop
        return co.iloc[-500:][["cylinder.p_a", "cylinder.p_b"]].to_numpy()
    gauss_seidel = tail(ssp_path, "gauss-seidel")
    assert np.abs(gauss_seidel[:, 1] - reference_rig.P_atm).max() < 1.0
    assert np.abs(tail(ssp_path, "jacobi") - gauss_seidel).max() < 244.0       # the sensors' noise floor
    at_cylinder = rewrite_ssp(ssp_path, tmp_path / "at_cylinder.ssp", edit=lambda s: re.sub(
        r'\s*<ssd:Connection startElement="valve" startConnector="p_[ab]_flow"[^>]*/>', "", s))
    chatter = tail(at_cylinder, "jacobi")[:, 1]
    assert np.abs(chatter - reference_rig.P_atm).max() > 244.0 and np.std(np.diff(chatter)) > 244.0


def test_extra_parameters_are_applied(ssp_path, tmp_path):
    moved = simulate_ssp(ssp_path, stop_time=0.002, parameters={"boom_load.x0": 0.03})
    assert moved["boom_load.x"][0] == 0.03
    ssv = write_ssv(tmp_path / "closed.ssv", "closed", {"valve.A_max": (0.0, "m2")})
    closed = simulate_ssp(ssp_path, stop_time=0.5, inputs=extend, parameters=ssv)
    assert (closed["cylinder.p_b"] == reference_rig.P_atm).all()


def test_component_binding_is_applied(ssp_path, tmp_path):
    """Change the packed per-component set: the run must follow it."""
    with zipfile.ZipFile(ssp_path) as z:
        text = z.read("resources/reference_rig_cylinder.ssv").decode()
    text = re.sub(r'(name="p_b0">\s*<ssv:Real value=")[^"]+', r"\g<1>301325.0", text)
    changed = rewrite_ssp(ssp_path, tmp_path / "p.ssp", drop={"resources/reference_rig_cylinder.ssv"},
                          add={"resources/reference_rig_cylinder.ssv": text.encode()})
    assert simulate_ssp(changed, stop_time=0.001)["cylinder.p_b"][0] == 301325.0


#: the SSD's system connector u (and its connection to valve.u) replaced by these
SYSTEM_U = '''
      <ssd:Connector name="u" kind="input"><ssc:Real unit="V"/></ssd:Connector>
    </ssd:Connectors>'''
U_CONNECTION = '''
      <ssd:Connection startConnector="u" endElement="valve" endConnector="u"/>'''
SYSTEM_IO = '''
      <ssd:Connector name="command" kind="input"><ssc:Real unit="V"/></ssd:Connector>
      <ssd:Connector name="p_a_gauge" kind="output"><ssc:Real unit="Pa"/></ssd:Connector>
    </ssd:Connectors>'''
SYSTEM_CONNECTIONS = '''
      <ssd:Connection startConnector="command" endElement="valve" endConnector="u">
        <ssc:LinearTransformation factor="-1" offset="10"/>
      </ssd:Connection>
      <ssd:Connection startElement="cylinder" startConnector="p_a" endConnector="p_a_gauge">
        <ssc:LinearTransformation factor="1" offset="-101325"/>
      </ssd:Connection>
    </ssd:Connections>'''


def test_linear_transformations_and_system_connectors(ssp_path, tmp_path):
    def edit(s):
        assert SYSTEM_U in s and U_CONNECTION in s
        s = s.replace(SYSTEM_U, SYSTEM_IO, 1).replace(U_CONNECTION, "", 1)
        return s.replace("\n    </ssd:Connections>", SYSTEM_CONNECTIONS, 1)
    variant = rewrite_ssp(ssp_path, tmp_path / "io.ssp", edit=edit)
    # command 9 V -> valve.u = 10 - 9 = 1 V: the boom extends
    out = simulate_ssp(variant, stop_time=1.0, inputs={"command": 9.0})
    np.testing.assert_allclose(out["p_a_gauge"], out["cylinder.p_a"] - 101325.0, rtol=0, atol=1e-9)
    same = simulate_ssp(ssp_path, stop_time=1.0, inputs={"valve.u": 1.0})
    np.testing.assert_allclose(out["boom_load.x"], same["boom_load.x"], rtol=0, atol=0)
    assert out["boom_load.x"].iloc[-1] > 0.05


def test_gauss_seidel_order_puts_feedthrough_first(ssp_path):
    with CoSimulation(ssp_path, 1e-3) as cosim:
        order = cosim.step_order
    assert order.index("valve") < order.index("cylinder")


# -- bad input: each a clear error naming the thing -----------------------------------------

def test_missing_ssp(tmp_path):
    with pytest.raises(SspError, match="no such SSP file"):
        read_ssp(tmp_path / "nothing.ssp")


def test_corrupt_ssp(tmp_path, ssp_path):
    junk = tmp_path / "junk.ssp"
    junk.write_bytes(b"this is not a zip archive")
    with pytest.raises(SspError, match="junk.ssp: not an SSP archive"):
        read_ssp(junk)
    truncated = tmp_path / "truncated.ssp"
    truncated.write_bytes(ssp_path.read_bytes()[: 5000])
    with pytest.raises(SspError, match="truncated.ssp"):
        read_ssp(truncated)


def test_ssd_names_an_fmu_missing_from_the_archive(ssp_path, tmp_path):
    variant = rewrite_ssp(ssp_path, tmp_path / "missing.ssp", drop={"resources/boom_load.fmu"})
    with pytest.raises(SspError, match="component boom_load refers to resources/boom_load.fmu, which is not in missing.ssp"):
        read_ssp(variant)


def test_connection_to_an_unknown_variable(ssp_path, tmp_path):
    variant = rewrite_ssp(ssp_path, tmp_path / "conn.ssp", edit=lambda s: s.replace(
        'endElement="cylinder" endConnector="x"', 'endElement="cylinder" endConnector="x_piston"'))
    with pytest.raises(SspError, match=r"boom_load.x -> cylinder.x_piston: resources/cylinder.fmu has no variable 'x_piston'"):
        CoSimulation(variant, 1e-3)


def test_connection_to_an_unknown_element(ssp_path, tmp_path):
    variant = rewrite_ssp(ssp_path, tmp_path / "elem.ssp", edit=lambda s: s.replace(
        'startElement="boom_load" startConnector="x"', 'startElement="boom" startConnector="x"'))
    with pytest.raises(SspError, match="names an element 'boom'"):
        read_ssp(variant)


def test_parameter_set_with_an_unknown_name(ssp_path, tmp_path):
    ssv = write_ssv(tmp_path / "typo.ssv", "typo", {"valve.A_maks": (4e-6, "m2")})
    with pytest.raises(SspError, match=r"typo.ssv: parameter valve.A_maks: resources/valve.fmu has no variable 'A_maks'"):
        CoSimulation(ssp_path, 1e-3, parameters=ssv)
    ssv = write_ssv(tmp_path / "elem.ssv", "elem", {"piston.A_max": (4e-6, "m2")})
    with pytest.raises(SspError, match="parameter piston.A_max: the system has no element 'piston'"):
        CoSimulation(ssp_path, 1e-3, parameters=ssv)


def test_parameter_set_with_a_non_numeric_value(ssp_path, tmp_path):
    ssv = write_ssv(tmp_path / "text.ssv", "text", {"valve.A_max": (4e-6, "m2")})
    ssv.write_text(ssv.read_text().replace('value="4e-06"', 'value="four"'))
    with pytest.raises(SspError, match=r"text.ssv: parameter valve.A_max: value 'four' is not a valid Real"):
        CoSimulation(ssp_path, 1e-3, parameters=ssv)


def test_parameter_bound_to_an_output_is_refused(ssp_path, tmp_path):
    ssv = write_ssv(tmp_path / "out.ssv", "out", {"boom_load.x": (0.01, "m")})
    with pytest.raises(SspError, match="boom_load.x is an output, not a parameter"):
        CoSimulation(ssp_path, 1e-3, parameters=ssv)


def test_algebraic_loop_is_refused(ssp_path, tmp_path):
    loop = '''
      <ssd:Connection startElement="valve" startConnector="mdot_a" endElement="valve" endConnector="u"/>
    </ssd:Connections>'''
    variant = rewrite_ssp(ssp_path, tmp_path / "loop.ssp",    # in place of the system's u -> valve.u
                          edit=lambda s: s.replace(U_CONNECTION, "", 1).replace("\n    </ssd:Connections>", loop, 1))
    with pytest.raises(SspError, match="algebraic loop"):
        CoSimulation(variant, 1e-3)


def test_unknown_input_name_is_refused(ssp_path):
    with pytest.raises(ValueError, match="no free input"):
        simulate_ssp(ssp_path, stop_time=0.01, inputs={"w": 1.0})


def test_a_binding_on_a_free_input_holds_it(ssp_path):
    out = simulate_ssp(ssp_path, stop_time=0.01, parameters={"boom_load.f_ext": 300.0})
    assert (out["boom_load.f_ext"] == 300.0).all()


def test_a_cosimulation_runs_once(ssp_path):
    with CoSimulation(ssp_path, 1e-3) as cosim:
        cosim.simulate(0.002)
        with pytest.raises(RuntimeError, match="runs once"):
            cosim.simulate(0.002)
