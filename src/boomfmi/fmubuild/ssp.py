"""Pack the SSP archive: ``SystemStructure.ssd`` with its parameter sets and FMUs.

``build/excavator_boom.ssp`` is a zip holding ``SystemStructure.ssd`` (from ``ssp/``),
the ``.ssv`` files it binds and the FMUs it names, under ``resources/``, so the whole
boom can be opened by any SSP tool.

Third-party tools (libcosim, ecos) apply parameter sets only where they are bound to a
component, with bare names.  The source of the parameters stays one file with
hierarchical names, ``ssp/reference_rig.ssv``; a component binding of
``resources/<set>_<component>.ssv`` that has no file of its own in ``ssp/`` is cut from
``ssp/<set>.ssv`` when packing: the entries ``<component>.*``, with bare names, in a
parameter set named ``<set>``.

fmpy's own SSP runner (``fmpy.ssp.simulation``, 0.3.32) wires a component's input
connector that no connection ends at to the source of the connection found before it,
or fails; :func:`pack_ssp` therefore refuses such a connector (a free input is left
undeclared, and set by variable name).
"""
from __future__ import annotations

import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from ..names import member_problem
from ..system.ssv import NS, read_ssv, write_ssv
from . import BuildError


def referenced_sources(ssd: Path) -> list[tuple[str, str | None]]:
    """Every ``source`` the SSD refers to, with the component it belongs to (None at
    system level)."""
    root = ET.parse(ssd).getroot()
    sources = []
    for c in root.iter(f"{{{NS['ssd']}}}Component"):
        sources.append((c.get("source"), c.get("name")))
        for b in c.iter(f"{{{NS['ssd']}}}ParameterBinding"):
            if b.get("source"):
                sources.append((b.get("source"), c.get("name")))
    system = root.find("ssd:System", NS)
    for b in system.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        if b.get("source"):
            sources.append((b.get("source"), None))
    return sources


def component_parameter_set(source_dir: Path, file_name: str, component: str) -> bytes | None:
    """The ``.ssv`` for ``<set>_<component>.ssv`` cut from ``source_dir/<set>.ssv``."""
    suffix = f"_{component}.ssv"
    if not file_name.endswith(suffix):
        return None
    set_name = file_name[: -len(suffix)]
    whole = source_dir / f"{set_name}.ssv"
    if not whole.is_file():
        return None
    params = read_ssv(whole.read_bytes(), str(whole))
    prefix = component + "."
    part = {n[len(prefix):]: (p.value, p.unit) for n, p in params.items() if n.startswith(prefix)}
    with tempfile.TemporaryDirectory() as tmp:
        out = write_ssv(Path(tmp) / file_name, set_name, part,
                        f"{component}'s part of {whole.name}")
        return out.read_bytes()


def component_fmu(ssd: Path, component, fmu_dir: Path) -> Path:
    """The FMU file in ``fmu_dir`` that ``ssd``'s ``component`` element takes from
    ``resources/``; a source that would leave ``fmu_dir`` is refused."""
    source = component.get("source")
    problem = member_problem(source)
    if problem or not source.startswith("resources/"):
        raise BuildError(f"{ssd}: component {component.get('name')!r}: source {source!r} must lie under "
                         f"resources/" + (f": {problem}" if problem else ""))
    return Path(fmu_dir) / source.removeprefix("resources/")


def fmus_of(ssd: Path) -> set[str]:
    """The names of the FMUs that ``ssd``'s components take from ``resources/``
    (``resources/valve.fmu`` -> ``valve``)."""
    return {source.removeprefix("resources/").removesuffix(".fmu")
            for source, _ in referenced_sources(Path(ssd)) if source.endswith(".fmu")}


def unconnected_inputs(ssd: Path) -> list[str]:
    """``component.connector`` of every input connector that ``ssd`` declares on a
    component but that no connection ends at."""
    system = ET.parse(ssd).getroot().find("ssd:System", NS)
    ends = {(c.get("endElement"), c.get("endConnector"))
            for c in system.findall("ssd:Connections/ssd:Connection", NS)}
    return [f"{comp.get('name')}.{c.get('name')}"
            for comp in system.findall("ssd:Elements/ssd:Component", NS)
            for c in comp.findall("ssd:Connectors/ssd:Connector", NS)
            if c.get("kind") == "input" and (comp.get("name"), c.get("name")) not in ends]


def pack_ssp(ssd: Path, fmu_dir: Path, out: Path) -> Path:
    """Zip ``ssd`` as SystemStructure.ssd with the FMUs (from ``fmu_dir``) and parameter
    sets (beside ``ssd``) that it references under ``resources/``."""
    ssd = Path(ssd)
    loose = unconnected_inputs(ssd)
    if loose:
        raise BuildError(f"{ssd}: input connector(s) {', '.join(loose)} end no connection; fmpy's "
                         f"SSP runner would wire them to another connection's source.  Leave a "
                         f"free input undeclared (it is set by variable name)")
    for source, _ in referenced_sources(ssd):      # never a file outside fmu_dir or ssd's folder
        problem = member_problem(source)
        if problem or not source.startswith("resources/"):
            raise BuildError(f"{ssd}: source {source!r} must lie under resources/"
                             + (f": {problem}" if problem else ""))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(ssd, "SystemStructure.ssd")
        written = set()
        for source, component in referenced_sources(ssd):
            if source in written:           # one FMU serving several components is packed once
                continue
            written.add(source)
            name = source.removeprefix("resources/")
            origin = (fmu_dir / name) if name.endswith(".fmu") else (ssd.parent / name)
            if origin.is_file():
                z.write(origin, source)
                continue
            part = component_parameter_set(ssd.parent, name, component) if component else None
            if part is None:
                raise BuildError(f"{ssd}: references {source}, but {origin} does not exist")
            z.writestr(source, part)
    tmp.replace(out)
    return out


def write_reference_parameters(ssds: list[Path], fmu_dir: Path, out: Path) -> Path:
    """Write the reference rig's parameter set for the components of ``ssds`` that bind
    it: every parameter of every such component FMU at its default value (the
    reference rig's)."""
    from fmpy import read_model_description
    params: dict[str, tuple[float, str | None]] = {}
    comps = [(Path(ssd), c) for ssd in ssds for c in ET.parse(ssd).getroot().iter(f"{{{NS['ssd']}}}Component")
             if any(b.get("source", "").startswith("resources/reference_rig_")
                    for b in c.iter(f"{{{NS['ssd']}}}ParameterBinding"))]
    for ssd, comp in comps:
        name = comp.get("name")
        md = read_model_description(str(component_fmu(ssd, comp, fmu_dir)))
        for v in md.modelVariables:
            if v.causality == "parameter" and v.type == "Real":
                params[f"{name}.{v.name}"] = (float(v.start), v.unit)
            elif v.causality == "parameter":
                params[f"{name}.{v.name}"] = ({"Integer": int, "Boolean": lambda s: s in ("true", "1"),
                                                "String": str}[v.type](v.start), None)
    return write_ssv(out, "reference_rig", params,
                     "The reference rig of shared/spec/reference-rig.md: every model parameter")
