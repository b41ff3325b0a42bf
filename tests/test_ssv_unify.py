"""Issue 32 item 1 (plan 2.9): one writer of a machine's SSP parameter set,
``fmubuild.ssp.parameters_ssv(machine, ...)``, for the boom rig (``reference_rig.ssv``)
and the excavator (``excavator.ssv``): one loop over the machine's joints x components."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from boomfmi.fmubuild import BuildError
from boomfmi.fmubuild.ssp import machine_parameters, parameters_ssv
from boomfmi.model.boom import Model
from boomfmi.model.machine import boom_machine, excavator_machine
from boomfmi.physics.linkage import JOINTS
from boomfmi.system.ssv import read_ssv

ROOT = Path(__file__).resolve().parents[1]
SSDS = [ROOT / "ssp" / s for s in ("SystemStructure.ssd", "teleoperation.ssd", "excavator.ssd")]


def test_one_writer_gives_each_machine_its_own_values_per_joint(tmp_path, fmu_dir):
    """The boom's set used to be the FMUs' defaults whatever the machine; now a boom
    machine's valve, cylinder and start are written as the excavator's joints are."""
    m = Model()
    model = replace(m, valve=m.valve._replace(A_max=5e-6), x0=0.01)
    boom = read_ssv(parameters_ssv(boom_machine(model), SSDS, fmu_dir, tmp_path / "b.ssv").read_bytes(), "b")
    assert boom["valve.A_max"].value == 5e-6 and boom["boom_load.x0"].value == 0.01
    assert boom["cylinder.A_a"].value == m.cylinder.A_a and "force_estimator.K_p" in boom   # nothing lost
    assert not any(n.startswith(("linkage.", "valve_")) for n in boom)
    own = machine_parameters(excavator_machine())
    for j in JOINTS:
        assert {f"valve_{j}.A_max", f"cylinder_{j}.p_a0", f"linkage.x0_{j}"} <= set(own)
    assert own["linkage.max_substep"] == 1e-3 and "linkage.max_substep" not in machine_parameters(boom_machine(m))


def test_a_set_no_component_binds_or_a_value_none_declares_is_refused(tmp_path, fmu_dir):
    """Before, the boom's writer wrote an empty or partial set silently."""
    out = tmp_path / "ref.ssv"
    with pytest.raises(BuildError, match=r"excavator\.ssd: no component binds resources/reference_rig_"):
        parameters_ssv(boom_machine(Model()), [ROOT / "ssp" / "excavator.ssd"], fmu_dir, out)
    assert not out.exists()
    ssd = tmp_path / "SystemStructure.ssd"      # the boom's load no longer binds the set
    ssd.write_text((ROOT / "ssp" / "SystemStructure.ssd").read_text().replace(
        'source="resources/reference_rig_boom_load.ssv"', 'source="resources/other_boom_load.ssv"'))
    with pytest.raises(BuildError, match=r"SystemStructure\.ssd: no component of the reference_rig set "
                                         r"declares the machine's parameter\(s\) boom_load\.x0"):
        parameters_ssv(boom_machine(Model()), ssd, fmu_dir, out)
    assert not out.exists()
