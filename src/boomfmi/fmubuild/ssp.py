"""Pack the SSP archive: ``SystemStructure.ssd`` with its parameter sets and FMUs.

``build/excavator_boom.ssp`` is a zip holding ``SystemStructure.ssd`` (from ``ssp/``),
the ``.ssv`` files it binds and the FMUs it names, under ``resources/``, so the whole
boom can be opened by any SSP tool.
"""
from __future__ import annotations

import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from ..system.ssv import NS, write_ssv
from . import BuildError


def referenced_sources(ssd: Path) -> list[str]:
    """Every ``source`` the SSD refers to (components and parameter bindings)."""
    root = ET.parse(ssd).getroot()
    sources = [c.get("source") for c in root.iter(f"{{{NS['ssd']}}}Component")]
    sources += [b.get("source") for b in root.iter(f"{{{NS['ssd']}}}ParameterBinding") if b.get("source")]
    return sources


def pack_ssp(ssd: Path, fmu_dir: Path, out: Path) -> Path:
    """Zip ``ssd`` as SystemStructure.ssd with the FMUs (from ``fmu_dir``) and parameter
    sets (beside ``ssd``) that it references under ``resources/``."""
    ssd = Path(ssd)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(ssd, "SystemStructure.ssd")
        for source in referenced_sources(ssd):
            if not source.startswith("resources/"):
                raise BuildError(f"{ssd}: source {source!r} must lie under resources/")
            name = source.removeprefix("resources/")
            origin = (fmu_dir / name) if name.endswith(".fmu") else (ssd.parent / name)
            if not origin.is_file():
                raise BuildError(f"{ssd}: references {source}, but {origin} does not exist")
            z.write(origin, source)
    tmp.replace(out)
    return out


def write_reference_parameters(ssd: Path, fmu_dir: Path, out: Path) -> Path:
    """Write the reference rig's parameter set for the components of ``ssd``: every
    parameter of every component FMU at its default value (the reference rig's)."""
    from fmpy import read_model_description
    root = ET.parse(ssd).getroot()
    params: dict[str, tuple[float, str | None]] = {}
    for comp in root.iter(f"{{{NS['ssd']}}}Component"):
        name = comp.get("name")
        fmu = Path(fmu_dir) / comp.get("source").removeprefix("resources/")
        md = read_model_description(str(fmu))
        for v in md.modelVariables:
            if v.causality == "parameter" and v.type == "Real":
                params[f"{name}.{v.name}"] = (float(v.start), v.unit)
    return write_ssv(out, "reference_rig", params,
                     "The reference rig of shared/spec/reference-rig.md: every model parameter")
