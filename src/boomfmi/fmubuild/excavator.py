"""The excavator SSP's parameter set, ``ssp/excavator.ssv``, from ``physics.excavator``.

Every parameter of the nine components (``valve_<joint>``, ``cylinder_<joint>``,
``linkage``) at its FMU's default, with each joint's valve and cylinder set from its
actuator (``A_max``; ``A_a``, ``A_b``, ``L``, ``V_a0``, ``V_b0``) and its chambers
starting at the pressures that hold the machine still at mid-stroke
(``model.excavator_reference.holding_pressures``), so that the SSP and the monolithic
reference start from one state; the linkage takes one substep per millisecond
(:data:`LINKAGE_SUBSTEP`).  ``build_fmus.py --write-references`` rewrites it;
``tests/test_excavator_ssp.py`` checks that the shipped file is what this writes.
"""
from __future__ import annotations

from pathlib import Path
from xml.etree import ElementTree as ET

from ..model.excavator_reference import ExcavatorMachine
from ..physics.excavator import JOINTS
from ..system.ssv import NS, write_ssv
from .ssp import component_fmu

SET_NAME = "excavator"
#: The linkage's longest substep in the excavator SSP [s] (its FMU's default: 0.25 ms).
LINKAGE_SUBSTEP = 1e-3


def excavator_parameters_ssv(ssd: Path, fmu_dir: Path, out: Path) -> Path:
    """Write ``out`` for the components of ``ssd`` (FMUs from ``fmu_dir``)."""
    from fmpy import read_model_description
    machine = ExcavatorMachine()
    ex = machine.ex
    x0, p_a0, p_b0 = machine.start()
    own = {}
    for i, j in enumerate(JOINTS):
        a = getattr(ex, j)
        own[f"valve_{j}.A_max"] = a.A_max
        own.update({f"cylinder_{j}.{n}": getattr(a, n) for n in ("A_a", "A_b", "L", "V_a0", "V_b0")})
        own[f"cylinder_{j}.p_a0"] = float(p_a0[i])
        own[f"cylinder_{j}.p_b0"] = float(p_b0[i])
        own[f"linkage.x0_{j}"] = float(x0[i])
    # one linkage substep per 1 ms communication step: within 0.06 % NRMSE of the
    # reference on the digging cycle, as four substeps are (docs/cosim-accuracy.md),
    # at about half the linkage's cost
    own["linkage.max_substep"] = LINKAGE_SUBSTEP
    params: dict = {}
    for comp in ET.parse(ssd).getroot().iter(f"{{{NS['ssd']}}}Component"):
        name = comp.get("name")
        md = read_model_description(str(component_fmu(ssd, comp, fmu_dir)))
        for v in md.modelVariables:
            if v.causality != "parameter":
                continue
            key = f"{name}.{v.name}"
            if v.type == "Real":
                params[key] = (float(own.get(key, float(v.start))), v.unit)
            else:
                params[key] = ({"Integer": int, "Boolean": lambda s: s in ("true", "1"),
                                "String": str}[v.type](v.start), None)
    unknown = set(own) - set(params)
    if unknown:
        raise ValueError(f"{ssd}: no component parameter {sorted(unknown)}")
    return write_ssv(out, SET_NAME, params,
                     "The whole excavator of shared/spec/excavator.md (physics.excavator), at rest at mid-stroke")
