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
    "K": ({"K": 1}, {"degC": (1.0, -273.15)}),
    "J/(kg.K)": ({"m": 2, "s": -2, "K": -1}, {}),
    "rad": ({"rad": 1}, {"deg": (180.0 / math.pi, 0.0)}),
}
