"""A machine described in one file: the boom rig (one joint) or the whole excavator (four).

Identification, diagnosis, ``recording import`` and ``record`` take it (``--machine
FILE``); without it they take each recording's sidecar (``recording-format.md``), and
without that the reference rig, and say so (:func:`assumption`).  The file::

    {"kind": "boom",
     "name": "rig 2 in hall B",
     "rig": {"A_a": "8.04 cm^2", "L": "200 mm", "P_s": "7 bar", "M": 25.0, ...}}

``rig`` holds the machine's values by the FMUs' parameter names, as a sidecar's ``rig``
does: for the boom those of ``recording.RIG_UNITS`` (valve, supply, gas, cylinder,
geometry, load, P_atm; pressures absolute), for the excavator ``<field>_<joint>`` of
each joint's cylinder, mounting, valve and friction, ``<field>_<link>`` of each link, h,
pivot_forward, pivot_height and P_atm (``recording.EXCAVATOR_RIG_UNITS``).  A value is a
number in its key's SI unit, or a text with any unit pint understands of that
dimension (``"63 mm"``, ``"7 bar"``, ``"25 degC"``).  A key left out keeps the
reference's value.  ``boomfmi machine init`` writes every key at the reference's value
with its unit beside it (``units``, for the reader; ignored on reading).

Written beside a recording, the machine's values become its sidecar's ``rig``
(:meth:`MachineFile.sidecar`); given to a command, each recording takes them, and a
recording whose own sidecar says otherwise is refused naming the value.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from ._json import read_object
from .foreign import units
from .physics import reference_rig
from .physics.linkage import (ACTUATOR_FIELDS, JOINTS, LINK_FIELDS, LINKS, MACHINE_FIELDS, Excavator,
                                excavator_from_values)
from .recording import (EXCAVATOR_RIG_UNITS, RIG_UNITS, Recording, check_excavator_values, check_rig_values,
                        RecordingError)

KINDS = ("boom", "excavator")
#: The file's top-level keys.
FILE_KEYS = ("kind", "name", "rig", "units")
#: A value given to a command over a recording's own differs when beyond this (relative).
AGREE = 1e-9


class MachineError(ValueError):
    """A machine file that cannot be used, naming the file and the key."""

    def __init__(self, path, message: str):
        super().__init__(f"{path}: {message}")
        self.path = path


def units_of(kind: str) -> dict:
    """The machine's keys with their SI units."""
    if kind not in KINDS:
        raise ValueError(f"unknown machine kind {kind!r}: one of {', '.join(KINDS)}")
    return dict(RIG_UNITS if kind == "boom" else EXCAVATOR_RIG_UNITS)


def reference_values(kind: str) -> dict:
    """Every key of the machine at the reference's value [SI]: the paper's rig
    (``reference-rig.md``) or ``excavator.md``'s machine."""
    if kind == "boom":
        out = {k: float(getattr(reference_rig, k)) for k in RIG_UNITS if hasattr(reference_rig, k)}
        out.pop("supply_pressure_gauge", None)
        return out
    ex = Excavator()
    out = {f"{f}_{j}": float(getattr(getattr(ex, j), f))
           for j in JOINTS for f in ACTUATOR_FIELDS if not (f == "lower" and j == "boom")}
    out.update({f"{f}_{n}": float(getattr(getattr(ex, f"{n}_link"), f)) for n in LINKS for f in LINK_FIELDS})
    out.update({k: float(getattr(ex, attr)) for k, attr in MACHINE_FIELDS.items()})
    return out


def _si(value, unit: str, key: str, path) -> float:
    """``value`` (a number in ``unit``, or a text with a unit of its dimension) in ``unit``."""
    if isinstance(value, bool):
        raise MachineError(path, f"rig value {key!r} must be a number or a text with its unit, not {value!r}")
    if isinstance(value, (int, float)):
        number = float(value)
    elif isinstance(value, str):
        ureg = units()
        target = unit.replace(".", "*").replace("m2", "m**2").replace("m3", "m**3")
        m = re.match(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$", value)
        if not m:
            raise MachineError(path, f"rig value {key!r} = {value!r}: not a number followed by a unit "
                                     f"(e.g. \"63 mm\", \"7 bar\")")
        try:
            q = ureg.Quantity(float(m.group(1)), m.group(2) or "dimensionless")
            number = float(q.to(ureg(target if target != "1" else "dimensionless")).magnitude)
        except Exception as e:          # pint's errors are many kinds: each names the problem
            raise MachineError(path, f"rig value {key!r} = {value!r}: not a quantity of unit {unit} "
                                     f"({type(e).__name__}: {e})") from None
    else:
        raise MachineError(path, f"rig value {key!r} must be a number or a text with its unit, not {value!r}")
    if not math.isfinite(number):
        raise MachineError(path, f"rig value {key!r} must be finite, not {value!r}")
    return number


@dataclass(frozen=True)
class MachineFile:
    """A machine file read: the machine's kind, a name, and its values [SI] by the FMUs' parameter names."""
    kind: str
    rig: dict = field(default_factory=dict)
    name: str = ""
    path: str = ""

    def excavator(self) -> Excavator:
        """The whole excavator with these values (kind ``excavator``)."""
        if self.kind != "excavator":
            raise ValueError(f"{self.path or 'the machine'} is a {self.kind}, not an excavator")
        return excavator_from_values(self.rig)

    def sidecar(self) -> dict:
        """The machine as a recording's sidecar ``rig`` values."""
        return dict(self.rig)

    def apply(self, rec: Recording) -> Recording:
        """The recording with this machine's values as its rig: a recording of the other
        kind, or whose own sidecar sets a value otherwise, is refused naming both."""
        if rec.kind != self.kind:
            raise MachineError(self.path, f"describes {'an' if self.kind == 'excavator' else 'a'} {self.kind}; "
                                          f"{rec.path} is {'an' if rec.kind == 'excavator' else 'a'} "
                                          f"{rec.kind}'s recording")
        own = rec.rig_values() if self.kind == "boom" else {k: float(v) for k, v in rec.rig.items()}
        for k, v in own.items():
            mine = self.rig.get(k)
            if mine is not None and abs(mine - v) > AGREE * max(abs(v), abs(mine)):
                raise MachineError(self.path, f"sets {k} = {mine:g}, where the sidecar of {rec.path} says "
                                              f"{v:g}: one machine per recording (edit either)")
        return replace(rec, rig={**rec.rig, **{k: v for k, v in self.rig.items() if k not in own}})


def read_machine(path) -> MachineFile:
    """Read and check a machine file (see the module's docstring); :class:`MachineError`
    names the file and the key."""
    path = Path(path)
    if not path.is_file():
        raise MachineError(path, "no such machine file (write one with: boomfmi machine init --out FILE)")
    doc = read_object(path, FILE_KEYS, "machine file", MachineError)
    kind = doc.get("kind")
    if kind not in KINDS:
        raise MachineError(path, f"'kind' must be one of {', '.join(KINDS)}, not {kind!r}")
    name = doc.get("name", "")
    if not isinstance(name, str):
        raise MachineError(path, f"'name' must be text, not {name!r}")
    rig = doc.get("rig", {})
    if not isinstance(rig, dict):
        raise MachineError(path, "'rig' must be an object of the machine's values")
    units = units_of(kind)
    values = {}
    for k, v in rig.items():
        if k not in units:
            close = ", ".join(u for u in units if u.split("_")[0] == k.split("_")[0]) or ", ".join(list(units)[:12])
            raise MachineError(path, f"unknown rig value {k!r} for {'an' if kind == 'excavator' else 'a'} {kind} "
                                     f"(e.g. {close}; every key: boomfmi machine init --kind {kind})")
        values[k] = _si(v, units[k], k, path)
    try:
        (check_rig_values if kind == "boom" else check_excavator_values)(values, path)
    except RecordingError as e:
        raise MachineError(path, str(e).split(": ", 1)[-1]) from None
    return MachineFile(kind, values, name, str(path))


def machine_document(kind: str, name: str = "") -> dict:
    """A machine file's content at the reference's values, every key with its unit."""
    values = reference_values(kind)
    units = units_of(kind)
    return {"kind": kind, "name": name or f"the reference {'rig' if kind == 'boom' else 'excavator'} (edit me)",
            "rig": values, "units": {k: units[k] for k in values}}


def assumption(recs, machine: MachineFile | None) -> str | None:
    """What a command assumes about the machine where neither ``machine`` nor any
    recording's sidecar describes it: a sentence for stderr and the report, else None."""
    if machine is not None or any(r.rig and set(r.rig) != {"P_atm"} for r in recs):
        return None
    kinds = {r.kind for r in recs}
    what = "excavator.md's excavator" if kinds == {"excavator"} else "the paper's reference rig"
    return (f"no machine described (no --machine FILE and no sidecar rig values): assuming {what}; "
            f"describe yours with: boomfmi machine init --kind {'excavator' if kinds == {'excavator'} else 'boom'} "
            f"--out machine.json")


__all__ = ["KINDS", "FILE_KEYS", "AGREE", "MachineError", "units_of", "reference_values", "MachineFile",
           "read_machine", "machine_document", "assumption"]
