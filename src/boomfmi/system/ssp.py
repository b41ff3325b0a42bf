"""Read an SSP 1.0 system: components, connections with linear transformations, and
parameter bindings, with errors that name the file and the element at fault.

``read_ssp`` takes a ``.ssp`` archive (or a folder laid out like one) and returns a
:class:`SystemStructure`.  The SSD is validated against the SSP 1.0 XSD that fmpy
ships.  ``check_against_fmus`` then matches every connection and parameter name with
the FMUs' model descriptions.
"""
from __future__ import annotations

import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET

from ..names import member_problem, name_problem
from .ssv import NS, Parameter, SspError, parse_parameter_set, read_ssv

SYSTEM = ""   # the element name of the system itself in a connection


@dataclass
class Component:
    name: str
    source: str                      #: path inside the archive, e.g. resources/valve.fmu
    connectors: dict[str, str]       #: connector name -> kind


@dataclass
class Connection:
    start_element: str               #: "" for the system's own connector
    start_connector: str
    end_element: str
    end_connector: str
    factor: float = 1.0
    offset: float = 0.0

    def describe(self) -> str:
        start = f"{self.start_element}.{self.start_connector}" if self.start_element else self.start_connector
        end = f"{self.end_element}.{self.end_connector}" if self.end_element else self.end_connector
        return f"{start} -> {end}"


@dataclass
class SystemStructure:
    path: Path
    name: str
    components: dict[str, Component]
    connectors: dict[str, str]                       #: system connector -> kind
    connections: list[Connection]
    parameters: dict[str, Parameter] = field(default_factory=dict)   #: hierarchical name -> value
    parameter_origin: dict[str, str] = field(default_factory=dict)   #: name -> file it came from
    start_time: float = 0.0
    stop_time: float | None = None

    def read(self, member: str) -> bytes:
        """Bytes of a file inside the SSP."""
        return _read_member(self.path, member)

    def bind(self, parameters: dict[str, Parameter], origin: str) -> None:
        """Apply a parameter set at system level (later bindings win)."""
        for name, p in parameters.items():
            self.parameters[name] = p
            self.parameter_origin[name] = origin


def _read_member(path: Path, member: str) -> bytes:
    problem = member_problem(member)       # a name from the SSD never leaves the SSP
    if problem:
        raise SspError(f"{path}: refers to {member!r}: {problem}")
    if path.is_dir():
        f = path / member
        if not f.is_file():
            raise SspError(f"{path}: {member} does not exist")
        return f.read_bytes()
    try:
        with zipfile.ZipFile(path) as z:
            return z.read(member)
    except KeyError:
        raise SspError(f"{path}: the archive has no {member}") from None


def _schema_errors(ssd_bytes: bytes) -> list[str]:
    from lxml import etree
    import fmpy
    xsd = Path(fmpy.__file__).parent / "ssp" / "schema" / "SystemStructureDescription.xsd"
    schema = etree.XMLSchema(file=str(xsd))
    doc = etree.fromstring(ssd_bytes)
    if schema.validate(doc):
        return []
    return [f"line {e.line}: {e.message}" for e in schema.error_log]


def validate_ssd(ssd_bytes: bytes, where: str) -> None:
    """Raise :class:`SspError` listing every deviation from the SSP 1.0 XSD."""
    errors = _schema_errors(ssd_bytes)
    if errors:
        raise SspError(f"{where} does not validate against the SSP 1.0 schema:\n  " + "\n  ".join(errors))


def read_ssp(path) -> SystemStructure:
    """Read ``SystemStructure.ssd`` and its parameter bindings from an SSP."""
    path = Path(path)
    if not path.exists():
        raise SspError(f"{path}: no such SSP file")
    if path.is_file() and not zipfile.is_zipfile(path):
        raise SspError(f"{path}: not an SSP archive (not a zip file)")
    try:
        data = _read_member(path, "SystemStructure.ssd")
    except zipfile.BadZipFile as e:
        raise SspError(f"{path}: corrupt SSP archive: {e}") from None
    where = f"{path}:SystemStructure.ssd"
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise SspError(f"{where}: not well-formed XML: {e}") from None
    validate_ssd(data, where)

    system = root.find("ssd:System", NS)
    if system.find("ssd:Elements/ssd:System", NS) is not None:
        raise SspError(f"{where}: nested systems are not supported")
    components: dict[str, Component] = {}
    for c in system.findall("ssd:Elements/ssd:Component", NS):
        if c.get("type", "application/x-fmu-sharedlibrary") != "application/x-fmu-sharedlibrary":
            raise SspError(f"{where}: component {c.get('name')} is of type {c.get('type')}, not an FMU")
        name, source = c.get("name"), c.get("source")
        problem = name_problem(name)       # names are data: never a path, never a '.' of valve.A_max
        if problem:
            raise SspError(f"{where}: component {name!r} is refused: {problem}")
        if name in components:
            raise SspError(f"{where}: two components are named {name!r}: a component's name is unique")
        problem = member_problem(source)
        if problem:
            raise SspError(f"{where}: component {name}: source {source!r} is refused: {problem}")
        components[name] = Component(name, source, _connectors(c))
    structure = SystemStructure(path=path, name=root.get("name"), components=components,
                                connectors=_connectors(system), connections=[])

    for c in system.findall("ssd:Connections/ssd:Connection", NS):
        conn = Connection(c.get("startElement") or SYSTEM, c.get("startConnector"),
                          c.get("endElement") or SYSTEM, c.get("endConnector"))
        lt = c.find("ssc:LinearTransformation", NS)
        if lt is not None:
            conn.factor = float(lt.get("factor", "1"))
            conn.offset = float(lt.get("offset", "0"))
        for element in (conn.start_element, conn.end_element):
            if element and element not in components:
                raise SspError(f"{where}: connection {conn.describe()} names an element "
                               f"{element!r} that the system does not contain")
        for element, connector in ((conn.start_element, conn.start_connector),
                                   (conn.end_element, conn.end_connector)):
            if not element and connector not in structure.connectors:
                raise SspError(f"{where}: connection {conn.describe()} names a system connector "
                               f"{connector!r} that the system does not declare")
        structure.connections.append(conn)

    _apply_bindings(structure, system, prefix="", where=where)
    for c in system.findall("ssd:Elements/ssd:Component", NS):
        _apply_bindings(structure, c, prefix=c.get("name") + ".", where=where)

    experiment = root.find("ssd:DefaultExperiment", NS)
    if experiment is not None:
        structure.start_time = float(experiment.get("startTime", "0"))
        if experiment.get("stopTime") is not None:
            structure.stop_time = float(experiment.get("stopTime"))

    for comp in components.values():
        try:
            _read_member(path, comp.source)
        except (SspError, zipfile.BadZipFile):
            raise SspError(f"{where}: component {comp.name} refers to {comp.source}, "
                           f"which is not in {path.name}") from None
    return structure


def _connectors(element) -> dict[str, str]:
    return {c.get("name"): c.get("kind") for c in element.findall("ssd:Connectors/ssd:Connector", NS)}


def _apply_bindings(structure: SystemStructure, element, prefix: str, where: str) -> None:
    for b in element.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        if b.find("ssd:ParameterMapping", NS) is not None:
            raise SspError(f"{where}: parameter mappings are not supported")
        full_prefix = prefix + (b.get("prefix") or "")
        source = b.get("source")
        if source:
            problem = member_problem(source)
            if problem:
                raise SspError(f"{where}: the parameter binding of {prefix[:-1] or 'the system'}: "
                               f"source {source!r} is refused: {problem}")
            params = read_ssv(structure.read(source), f"{structure.path}:{source}")
            origin = source
        else:
            inline = b.find("ssd:ParameterValues/ssv:ParameterSet", NS)
            if inline is None:
                continue
            params = parse_parameter_set(inline, f"{where} (inline parameter set)")
            origin = "SystemStructure.ssd"
        structure.bind({full_prefix + n: p._replace(name=full_prefix + n) for n, p in params.items()},
                       origin)


def check_against_fmus(structure: SystemStructure, model_descriptions: dict) -> None:
    """Match connections and parameter names with the FMUs' variables.

    ``model_descriptions`` maps component names to fmpy model descriptions.  Raises
    :class:`SspError` naming the connection or parameter that does not fit.
    """
    variables = {name: {v.name: v for v in md.modelVariables} for name, md in model_descriptions.items()}
    for conn in structure.connections:
        for element, connector, role in ((conn.start_element, conn.start_connector, "start"),
                                         (conn.end_element, conn.end_connector, "end")):
            if not element:
                kind = structure.connectors[connector]
                if (role == "start") != (kind in ("input", "parameter")):
                    raise SspError(f"{structure.path}: connection {conn.describe()}: system connector "
                                   f"{connector} is an {kind}, it cannot be the {role} of a connection")
                continue
            var = variables[element].get(connector)
            comp = structure.components[element]
            if var is None:
                raise SspError(f"{structure.path}: connection {conn.describe()}: "
                               f"{comp.source} has no variable {connector!r}")
            wanted = "output" if role == "start" else "input"
            if var.causality != wanted:
                raise SspError(f"{structure.path}: connection {conn.describe()}: {element}.{connector} "
                               f"is an {var.causality}, a connection's {role} must be an {wanted}")
            if var.type != "Real" and (conn.factor != 1.0 or conn.offset != 0.0):
                raise SspError(f"{structure.path}: connection {conn.describe()}: a linear "
                               f"transformation needs Real variables")
    for name, p in structure.parameters.items():
        origin = structure.parameter_origin.get(name, "parameter set")
        element, _, var_name = name.partition(".")
        if element not in structure.components:
            raise SspError(f"{origin}: parameter {name}: the system has no element {element!r}")
        var = variables[element].get(var_name)
        if var is None:
            raise SspError(f"{origin}: parameter {name}: {structure.components[element].source} "
                           f"has no variable {var_name!r}")
        if var.causality not in ("parameter", "input"):
            raise SspError(f"{origin}: parameter {name}: {element}.{var_name} is an {var.causality}, "
                           f"not a parameter")
        if var.type == "Real" and p.type == "Integer":      # an integer is a valid real
            if abs(p.value) > 1e308:                        # beyond any float
                raise SspError(f"{origin}: parameter {name} = an integer of {len(str(abs(p.value)))} digits: "
                               f"must be a finite number")
            p = structure.parameters[name] = p._replace(type="Real", value=float(p.value))
        if var.type != p.type and not (var.type == "Enumeration" and p.type == "Integer"):
            raise SspError(f"{origin}: parameter {name} is given as {p.type}, the FMU declares {var.type}")
        if p.type in ("Real", "Integer"):
            _check_finite(name, float(p.value), origin)


def _check_finite(name: str, value: float, origin: str) -> None:
    """Raise :class:`SspError` unless the value bound to parameter ``name`` is finite: no
    parameter of the machine is infinite, and the master computes with some of them (the
    stable step, the view's geometry).  Its range is the FMU's to judge: each checks its
    declared min and max, with its reasons, when it is initialised."""
    if not math.isfinite(value):
        raise SspError(f"{origin}: parameter {name} = {value}: must be a finite number")


__all__ = ["SYSTEM", "Component", "Connection", "SystemStructure", "validate_ssd", "read_ssp", "check_against_fmus"]
