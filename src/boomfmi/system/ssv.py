"""SSP 1.0 parameter sets (``.ssv``): read with clear errors, and write.

A parameter set maps hierarchical names (``valve.A_max`` at system level) to typed
values.  Unlike the SSP standard, which ignores names that match no variable, boomfmi's
master treats an unknown name as an error (``boomfmi.system.ssp``): a misspelt
parameter that silently keeps its default is the error users can least afford.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple
from xml.etree import ElementTree as ET

from ..units import UNITS

NS = {"ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription"}
TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration")


class SspError(ValueError):
    """An SSP file (.ssp, .ssd or .ssv) that cannot be used; the message names the
    file and the element at fault."""


class Parameter(NamedTuple):
    name: str
    type: str
    value: object
    unit: str | None = None


def parse_parameter_set(root: ET.Element, where: str) -> dict[str, Parameter]:
    """Parameters of an ``ssv:ParameterSet`` element; ``where`` names its file for errors."""
    params: dict[str, Parameter] = {}
    for p in root.findall("ssv:Parameters/ssv:Parameter", NS):
        name = p.get("name")
        if not name:
            raise SspError(f"{where}: a parameter has no name")
        typed = [(t, p.find(f"ssv:{t}", NS)) for t in TYPES]
        typed = [(t, e) for t, e in typed if e is not None]
        if len(typed) != 1:
            raise SspError(f"{where}: parameter {name} must have exactly one of {', '.join(TYPES)}")
        typ, elem = typed[0]
        raw = elem.get("value")
        if raw is None:
            raise SspError(f"{where}: parameter {name} has no value")
        try:
            if typ == "Real":
                value = float(raw)
                if not math.isfinite(value):
                    raise ValueError
            elif typ in ("Integer", "Enumeration"):
                value = int(raw)
            elif typ == "Boolean":
                if raw not in ("true", "false", "1", "0"):
                    raise ValueError
                value = raw in ("true", "1")
            else:
                value = raw
        except ValueError:
            raise SspError(f"{where}: parameter {name}: value {raw!r} is not a valid {typ}") from None
        if name in params:
            raise SspError(f"{where}: parameter {name} is given twice")
        params[name] = Parameter(name, typ, value, elem.get("unit"))
    return params


def read_ssv(data: bytes, where: str) -> dict[str, Parameter]:
    """Parse a ``.ssv`` document; ``where`` names it in error messages."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise SspError(f"{where}: not well-formed XML: {e}") from None
    if root.tag != f"{{{NS['ssv']}}}ParameterSet":
        raise SspError(f"{where}: the root element is not an ssv:ParameterSet")
    return parse_parameter_set(root, where)


def write_ssv(path, name: str, parameters: dict[str, tuple[object, str | None]],
              description: str | None = None) -> Path:
    """Write a parameter set ``{hierarchical name: (value, unit)}``: a float is a Real
    (with its unit), a bool a Boolean, an int an Integer, a str a String."""
    ET.register_namespace("ssv", NS["ssv"])
    ET.register_namespace("ssc", NS["ssc"])
    root = ET.Element(f"{{{NS['ssv']}}}ParameterSet", version="1.0", name=name)
    if description:
        root.set("description", description)
    params = ET.SubElement(root, f"{{{NS['ssv']}}}Parameters")
    used = set()
    for pname, (value, unit) in parameters.items():
        p = ET.SubElement(params, f"{{{NS['ssv']}}}Parameter", name=pname)
        if isinstance(value, bool):
            ET.SubElement(p, f"{{{NS['ssv']}}}Boolean", value="true" if value else "false")
        elif isinstance(value, int):
            ET.SubElement(p, f"{{{NS['ssv']}}}Integer", value=str(value))
        elif isinstance(value, str):
            ET.SubElement(p, f"{{{NS['ssv']}}}String", value=value)
        else:
            attrs = {"value": repr(float(value))}
            if unit and unit != "1":
                attrs["unit"] = unit
                used.add(unit)
            ET.SubElement(p, f"{{{NS['ssv']}}}Real", attrs)
    if used:
        units = ET.SubElement(root, f"{{{NS['ssv']}}}Units")
        for unit in sorted(used):
            u = ET.SubElement(units, f"{{{NS['ssc']}}}Unit", name=unit)
            ET.SubElement(u, f"{{{NS['ssc']}}}BaseUnit", {k: str(v) for k, v in UNITS[unit][0].items()})
    ET.indent(root)
    path = Path(path)
    path.write_bytes(ET.tostring(root, encoding="UTF-8", xml_declaration=True))
    return path


__all__ = ["NS", "TYPES", "SspError", "Parameter", "parse_parameter_set", "read_ssv", "write_ssv"]
