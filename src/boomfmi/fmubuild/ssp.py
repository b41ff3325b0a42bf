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
undeclared, and set by variable name, or fed by a system input connector).  That runner
applies no parameter binding either, only the ``parameter_set`` it is given, with
hierarchical names: so beside the per-component files the SSP carries each cut set
whole, for this system's components (``resources/<set>.ssv``, ``valve.A_max``), which
``fmpy.ssp.ssd.read_ssv(ssp, resource="resources/<set>.ssv")`` reads.

The parameter sets themselves, ``ssp/reference_rig.ssv`` (the boom rig) and
``ssp/excavator.ssv``, are one writer's, :func:`parameters_ssv`: a machine
(``model.machine``) gives its joints' values, the FMUs the rest.
"""
from __future__ import annotations

import os
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


def system_parameter_set(source_dir: Path, set_name: str, components: list[str]) -> bytes:
    """The entries of ``source_dir/<set_name>.ssv`` that belong to ``components``, with
    their hierarchical names (``valve.A_max``): the set as fmpy's SSP runner applies one."""
    whole = source_dir / f"{set_name}.ssv"
    params = read_ssv(whole.read_bytes(), str(whole))
    part = {n: (p.value, p.unit) for n, p in params.items() if n.partition(".")[0] in components}
    with tempfile.TemporaryDirectory() as tmp:
        out = write_ssv(Path(tmp) / f"{set_name}.ssv", set_name, part,
                        f"{', '.join(components)}: their part of {whole.name}, hierarchical names "
                        f"(for hosts that apply a system-level set only, as fmpy's SSP runner)")
        return out.read_bytes()


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


#: Where build_fmus.py packs each system a second time for libcosim and ecos (``build/osp/``).
OSP_FOLDER = "osp"


def without_system_connectors(ssd_bytes: bytes) -> bytes:
    """The SSD with its system connectors left out: the system's ``Connectors``, every
    connection that starts or ends at the system, and each component connector that
    such a connection alone fed (an input nothing else drives is then left undeclared,
    set by variable name).  libcosim 0.11 ("No such node (<xmlattr>.startElement)") and
    ecos ("No element named: ") refuse a connection without ``startElement``, the
    SSP 1.0 form of one from a system connector."""
    for prefix in ("ssd", "ssc", "ssv"):
        ET.register_namespace(prefix, NS[prefix])
    ET.register_namespace("osp", "http://opensimulationplatform.com/SSP/OSPAnnotations")
    root = ET.fromstring(ssd_bytes)
    system = root.find("ssd:System", NS)
    for connectors in system.findall("ssd:Connectors", NS):
        system.remove(connectors)
    connections = system.find("ssd:Connections", NS)
    ends = set()
    for c in list(connections) if connections is not None else []:
        if not c.get("startElement") or not c.get("endElement"):
            connections.remove(c)
        else:
            ends.add((c.get("endElement"), c.get("endConnector")))
    fed = {(c.get("endElement"), c.get("endConnector")) for c in ET.fromstring(ssd_bytes).iter(f"{{{NS['ssd']}}}Connection")
           if not c.get("startElement") and c.get("endElement")}
    for comp in system.findall("ssd:Elements/ssd:Component", NS):
        declared = comp.find("ssd:Connectors", NS)
        for c in list(declared) if declared is not None else []:
            key = (comp.get("name"), c.get("name"))
            if key in fed and key not in ends:
                declared.remove(c)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def osp_ssp(ssp: Path, out: Path | None = None) -> Path:
    """The SSP archive ``ssp`` for libcosim and ecos: the same members, its
    SystemStructure.ssd without system connectors (:func:`without_system_connectors`),
    written to ``out`` (default: ``osp/<name>.ssp`` beside ``ssp``) unless that is
    already newer than ``ssp``; return its path."""
    ssp = Path(ssp)
    out = Path(out) if out is not None else ssp.parent / OSP_FOLDER / ssp.name
    if out.is_file() and out.stat().st_mtime >= ssp.stat().st_mtime:
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(f".{os.getpid()}.tmp")
    with zipfile.ZipFile(ssp) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "SystemStructure.ssd":
                data = without_system_connectors(data)
            dst.writestr(item, data)
    tmp.replace(out)
    return out


def pack_ssp(ssd: Path, fmu_dir: Path, out: Path, system_connectors: bool = True) -> Path:
    """Zip ``ssd`` as SystemStructure.ssd with the FMUs (from ``fmu_dir``) and parameter
    sets (beside ``ssd``) that it references under ``resources/``.  With
    ``system_connectors=False`` the SSD goes in without its system connectors
    (:func:`without_system_connectors`: the form libcosim and ecos read)."""
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
        if system_connectors:
            z.write(ssd, "SystemStructure.ssd")
        else:
            z.writestr("SystemStructure.ssd", without_system_connectors(ssd.read_bytes()))
        written = set()
        cut: dict[str, list[str]] = {}      # parameter set -> components given their part of it
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
            cut.setdefault(name[: -len(f"_{component}.ssv")], []).append(component)
        for set_name, components in cut.items():
            member = f"resources/{set_name}.ssv"
            if member not in written:
                z.writestr(member, system_parameter_set(ssd.parent, set_name, components))
    tmp.replace(out)
    return out


#: A machine's parameter set, by its mechanism (``Machine.mechanism``): ``ssp/<name>.ssv``
#: and its description.  The boom rig's is the reference rig's (every FMU at its default);
#: the excavator's starts it at rest at mid-stroke.
PARAMETER_SETS = {
    "boom": ("reference_rig", "The reference rig of shared/spec/reference-rig.md: every model parameter"),
    "linkage": ("excavator", "The whole excavator of shared/spec/excavator.md (physics.linkage), at rest at mid-stroke"),
}
#: The linkage's longest substep in the excavator SSP [s] (its FMU's default: 0.25 ms).
#: One substep per 1 ms communication step: within 0.06 % NRMSE of the reference on the
#: digging cycle, as four substeps are (docs/cosim-accuracy.md), at about half the
#: linkage's cost.
LINKAGE_SUBSTEP = 1e-3


def _component(machine, kind: str, joint: str) -> str:
    """The SSP component of ``joint``'s ``kind`` (valve, cylinder): ``valve`` (one joint)
    or ``valve_arm``, as :meth:`Machine.ssp_name` names ``A_max``'s."""
    return kind if machine.n == 1 else f"{kind}_{joint}"


def machine_parameters(machine) -> dict[str, float]:
    """The values a machine gives its SSP's components, by hierarchical name: one loop
    over its joints, each joint's valve (``A_max``), cylinder (``A_a``, ``A_b``, ``L``,
    ``V_a0``, ``V_b0``, its start pressures ``p_a0``, ``p_b0``) and its mechanism's start
    position (``boom_load.x0`` or ``linkage.x0_<joint>``); the linkage's substep
    (:data:`LINKAGE_SUBSTEP`)."""
    x0, p_a0, p_b0 = machine.start()
    own: dict[str, float] = {}
    for i, joint in enumerate(machine.joints):
        j, m = joint.name, joint.model
        own[machine.ssp_name(machine.param_name("A_max", j))] = float(m.valve.A_max)
        cylinder = _component(machine, "cylinder", j)
        own.update({f"{cylinder}.{n}": float(getattr(m.cylinder, n)) for n in ("A_a", "A_b", "L", "V_a0", "V_b0")})
        own[f"{cylinder}.p_a0"] = float(p_a0[i])
        own[f"{cylinder}.p_b0"] = float(p_b0[i])
        own[machine.ssp_name(machine.param_name("x0", j))] = float(x0[i])
    if machine.mechanism == "linkage":
        own[machine.ssp_name("max_substep")] = LINKAGE_SUBSTEP
    return own


def parameters_ssv(machine, ssds, fmu_dir: Path, out: Path) -> Path:
    """Write ``machine``'s parameter set (:data:`PARAMETER_SETS`, by its mechanism) to
    ``out``: every parameter of every component of ``ssds`` (one SSD or several) that
    binds ``resources/<set>_<component>.ssv``, at its FMU's (from ``fmu_dir``) default
    unless the machine gives it (:func:`machine_parameters`).  The boom rig
    (``boom_machine(Model())``) writes ``ssp/reference_rig.ssv``, the excavator
    (``excavator_machine()``) ``ssp/excavator.ssv``; ``build_fmus.py --write-references``
    rewrites both.  A set no component binds, or a machine's value that no component
    declares, is refused naming the SSDs (:class:`BuildError`), and nothing is written."""
    from fmpy import read_model_description
    set_name, description = PARAMETER_SETS[machine.mechanism]
    ssds = [Path(ssds)] if isinstance(ssds, (str, Path)) else [Path(s) for s in ssds]
    comps = [(ssd, c) for ssd in ssds for c in ET.parse(ssd).getroot().iter(f"{{{NS['ssd']}}}Component")
             if any(b.get("source") == f"resources/{set_name}_{c.get('name')}.ssv"
                    for b in c.iter(f"{{{NS['ssd']}}}ParameterBinding"))]
    where = ", ".join(str(s) for s in ssds)
    if not comps:
        raise BuildError(f"{where}: no component binds resources/{set_name}_<component>.ssv: "
                         f"nothing to write to {out}")
    own = machine_parameters(machine)
    params: dict[str, tuple[object, str | None]] = {}
    for ssd, comp in comps:
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
    unknown = sorted(set(own) - set(params))
    if unknown:
        raise BuildError(f"{where}: no component of the {set_name} set declares the machine's "
                         f"parameter(s) {', '.join(unknown)}")
    return write_ssv(out, set_name, params, description)

__all__ = [
    "referenced_sources", "component_parameter_set", "component_fmu", "fmus_of", "system_parameter_set",
    "unconnected_inputs", "OSP_FOLDER", "without_system_connectors", "osp_ssp", "pack_ssp",
    "PARAMETER_SETS", "LINKAGE_SUBSTEP", "machine_parameters", "parameters_ssv",
]
