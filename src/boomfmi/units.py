"""SI unit definitions for the FMUs' modelDescription.xml (FMI 2.0 ``UnitDefinitions``).

Each unit a boomfmi variable may declare, with its SI base-unit exponents and the
display units a tool may offer (display = factor * value + offset).
"""
from __future__ import annotations

import math

#: unit name -> (base-unit exponents, {display unit: (factor, offset)})
UNITS: dict[str, tuple[dict[str, int], dict[str, tuple[float, float]]]] = {
    "1": ({}, {}),
    "s": ({"s": 1}, {"ms": (1e3, 0.0)}),
    "Hz": ({"s": -1}, {}),
    "m": ({"m": 1}, {"mm": (1e3, 0.0)}),
    "m/s": ({"m": 1, "s": -1}, {"mm/s": (1e3, 0.0)}),
    "m2": ({"m": 2}, {"mm2": (1e6, 0.0)}),
    "m3": ({"m": 3}, {"cm3": (1e6, 0.0)}),
    "kg": ({"kg": 1}, {}),
    "kg/s": ({"kg": 1, "s": -1}, {"g/s": (1e3, 0.0)}),
    "kg/(s.Pa)": ({"m": 1, "s": 1}, {}),
    "W/(m2.K)": ({"kg": 1, "s": -3, "K": -1}, {}),
    "Pa": ({"kg": 1, "m": -1, "s": -2}, {"bar": (1e-5, 0.0), "kPa": (1e-3, 0.0), "MPa": (1e-6, 0.0)}),
    "N": ({"kg": 1, "m": 1, "s": -2}, {}),
    "N.m": ({"kg": 1, "m": 2, "s": -2}, {}),
    "N/s": ({"kg": 1, "m": 1, "s": -3}, {}),
    "N/m": ({"kg": 1, "s": -2}, {"N/mm": (1e-3, 0.0)}),
    "N/Pa": ({"m": 2}, {"N/bar": (1e5, 0.0)}),
    "N.s/m": ({"kg": 1, "s": -1}, {}),
    "V": ({"kg": 1, "m": 2, "s": -3, "A": -1}, {}),
    "V/s": ({"kg": 1, "m": 2, "s": -4, "A": -1}, {}),
    "K": ({"K": 1}, {"degC": (1.0, -273.15)}),
    "J/(kg.K)": ({"m": 2, "s": -2, "K": -1}, {}),
    "rad": ({"rad": 1}, {"deg": (180.0 / math.pi, 0.0)}),
}


# ----------------------------------------------------------- any unit pint understands
#: pint's base dimensions -> the attribute of an FMI ``BaseUnit``
_FMI_BASE = {"[mass]": "kg", "[length]": "m", "[time]": "s", "[current]": "A", "[temperature]": "K",
             "[substance]": "mol", "[luminosity]": "cd"}
_REGISTRY = None


def registry():
    """pint's unit registry (one for the process, built on first use)."""
    global _REGISTRY
    if _REGISTRY is None:
        import pint
        _REGISTRY = pint.UnitRegistry()
    return _REGISTRY


def pint_expression(unit: str) -> str:
    """A unit as boomfmi writes it (``N.s/(m.Pa)``, ``m2``, ``1``) as pint reads it
    (``N*s/(m*Pa)``, ``m**2``, ``dimensionless``)."""
    import re
    text = unit.strip()
    if text in ("1", ""):
        return "dimensionless"
    text = re.sub(r"(?<=[A-Za-z)])\.(?=[A-Za-z(])", "*", text)
    return re.sub(r"(?<=[A-Za-z])(-?\d+)", r"**\1", text)


def _base(unit: str):
    q = registry().Quantity(1.0, pint_expression(unit)).to_base_units()
    return q.magnitude, q


def unit_problem(unit) -> str:
    """Why ``unit`` cannot be an FMU variable's unit ('' where pint reads it and it is
    a product of SI base units with no offset, as FMI's ``BaseUnit`` states it)."""
    import pint
    if not isinstance(unit, str) or not unit.strip():
        return f"unit {unit!r}: not a unit (a text pint reads, SI: 'N.s/m', 'm2', '1')"
    try:
        factor, q = _base(unit)
    except (pint.errors.PintError, AttributeError, TypeError, ValueError, SyntaxError) as e:
        return f"unit {unit!r}: pint does not read it ({e})"
    if not registry().Quantity(1.0, pint_expression(unit))._is_multiplicative:
        return f"unit {unit!r}: has an offset (an FMU variable's unit is a multiple of SI units: 'K', not 'degC')"
    unknown = [d for d in q.dimensionality if d not in _FMI_BASE]
    if unknown:
        return f"unit {unit!r}: its dimension {', '.join(unknown)} has no FMI base unit"
    if not factor > 0.0:
        return f"unit {unit!r}: not a positive multiple of SI units"
    return ""


def unit_definition(unit: str) -> tuple[dict[str, float], float, dict[str, tuple[float, float]]]:
    """``(base-unit exponents, factor, display units)`` of ``unit`` for FMI's
    ``UnitDefinitions``: the exponents and the factor to SI from pint's dimensionality
    (any unit pint understands), the display units from :data:`UNITS` where it names
    them.  Raises ``ValueError`` (:func:`unit_problem`) for a unit it cannot state."""
    problem = unit_problem(unit)
    if problem:
        raise ValueError(problem)
    factor, q = _base(unit)
    exponents = {_FMI_BASE[d]: e for d, e in q.dimensionality.items()}
    exponents = {k: int(v) if float(v).is_integer() else float(v) for k, v in exponents.items() if v}
    if unit in UNITS and "rad" in UNITS[unit][0]:
        exponents["rad"] = UNITS[unit][0]["rad"]
    return exponents, float(factor), UNITS[unit][1] if unit in UNITS else {}

__all__ = ["UNITS", "registry", "pint_expression", "unit_problem", "unit_definition"]
