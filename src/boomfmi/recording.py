"""Recordings: read, validate and write (``shared/spec/recording-format.md``).

A recording is a UTF-8, comma-separated CSV with a header row and one row per sample:
``t`` [s], ``u`` [V], ``p_a``, ``p_b`` [Pa gauge], ``alpha`` [rad], optionally
``f_ext`` [N] and ``x`` [m]; other columns are kept.  A sidecar ``run.json`` beside
``run.csv`` may override reference-rig values (``{"rig": {...}}``) and carry notes.

An **excavator** recording (``shared/spec/excavator.md``) has the same columns per joint
(:data:`JOINTS`: swing, boom, arm, bucket), suffixed: ``t``, ``u_<joint>`` [V],
``p_a_<joint>``, ``p_b_<joint>`` [Pa gauge], ``angle_<joint>`` [rad] (the boom's is
Eq. 12's alpha, the arm's and bucket's relative to the link before, the swing's about
z), optionally ``f_tip_x``, ``f_tip_y``, ``f_tip_z`` [N, world frame, the environment's
force on the bucket] and ``x_<joint>`` [m].  :func:`recording_kind` tells the two
apart by the header; a boom-only recording reads as before.  The same reader, checks
and writer serve both.

:func:`read_recording` rejects a bad file with :class:`RecordingError`, whose message
names the file, the line (the header is line 1) and the column.  It never drops rows.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ._json import read_object
from .physics import Cylinder, Geometry, Valve, alpha_from_x, reference_rig
from .physics.linkage import JOINTS, excavator_from_values, excavator_value_names
from .physics import (Gas, Load, ParameterError, check_cylinder, check_gas, check_geometry, check_load,
                      check_valve)
from .physics.params import L_MAX
from .physics.validation import require_positive

if TYPE_CHECKING:
    import pandas as pd

REQUIRED = ("t", "u", "p_a", "p_b", "alpha")
#: Reference-rig values a sidecar may override (``{"rig": {...}}``), by the FMUs'
#: parameter names (SI, pressures absolute), plus the spec's own example key.
RIG_KEYS = ("A_max", "P_s", "P_e", "k", "R", "T", "A_a", "A_b", "L", "V_a0", "V_b0", "a", "b",
            "h", "l_min", "K_v", "F_s", "F_d", "F_L", "M", "P_atm", "supply_pressure_gauge")
#: Each rig value's SI unit (a machine file may give any unit of its dimension: ``machine.py``).
RIG_UNITS = {"A_max": "m2", "P_s": "Pa", "P_e": "Pa", "k": "1", "R": "J/(kg.K)", "T": "K", "A_a": "m2",
             "A_b": "m2", "L": "m", "V_a0": "m3", "V_b0": "m3", "a": "m", "b": "m", "h": "m", "l_min": "m",
             "K_v": "N.s/m", "F_s": "N", "F_d": "N", "F_L": "N", "M": "kg", "P_atm": "Pa",
             "supply_pressure_gauge": "Pa"}
#: The whole excavator's values a sidecar may set (``physics.linkage.excavator_from_values``:
#: ``<field>_<joint>``, ``<field>_<link>``, h, pivot_forward, pivot_height, P_atm), SI units.
EXCAVATOR_RIG_KEYS = excavator_value_names()
_FIELD_UNITS = {"bore": "m", "rod": "m", "stroke": "m", "c1": "m", "c2": "m", "l_min": "m", "lower": "rad",
                "A_max": "m2", "V_a0": "m3", "V_b0": "m3", "K_v": "N.s/m", "F_s": "N", "F_d": "N",
                "length": "m", "mass": "kg", "com": "m", "h": "m", "pivot_forward": "m", "pivot_height": "m",
                "P_atm": "Pa"}
EXCAVATOR_RIG_UNITS = {k: _FIELD_UNITS[k if k in _FIELD_UNITS else k.rsplit("_", 1)[0]] for k in EXCAVATOR_RIG_KEYS}
OPTIONAL = ("f_ext", "x")
#: (``JOINTS``, the excavator's joints, are the linkage's: ``physics.linkage.JOINTS``.)
#: An excavator recording's required columns: t, then each quantity for every joint.
EXCAVATOR_REQUIRED = ("t",) + tuple(f"{q}_{j}" for q in ("u", "p_a", "p_b", "angle") for j in JOINTS)
#: Its optional columns: the tip force (world frame) and each piston measured directly.
EXCAVATOR_OPTIONAL = ("f_tip_x", "f_tip_y", "f_tip_z") + tuple(f"x_{j}" for j in JOINTS)
#: Each kind of recording: its required and optional (numeric) columns, its valve
#: commands (0 to 10 V), its chamber pressures (gauge, >= -P_atm) and its angles [rad].
KINDS = {
    "boom": {"required": REQUIRED, "optional": OPTIONAL, "commands": ("u",), "pressures": ("p_a", "p_b"),
             "angles": ("alpha",)},
    "excavator": {"required": EXCAVATOR_REQUIRED, "optional": EXCAVATOR_OPTIONAL,
                  "commands": tuple(f"u_{j}" for j in JOINTS),
                  "pressures": tuple(f"{q}_{j}" for j in JOINTS for q in ("p_a", "p_b")),
                  "angles": tuple(f"angle_{j}" for j in JOINTS)},
}
#: The sidecar's top-level keys: ``rig`` and ``notes`` (recording-format.md) and
#: ``incomplete``, the reason a recorder gives when a run ended early.
SIDECAR_KEYS = ("rig", "notes", "incomplete")
#: The largest recording read [bytes] (about an hour at 1 kHz); $BOOMFMI_MAX_RECORDING_MB raises it.
MAX_BYTES = 256 * 2**20
#: Fewest samples identification and diagnosis work on (0.1 s at the 1 ms DAQ).
MIN_SAMPLES = 100
#: Sample spacing [s] a recording's t may have: the DAQ samples every 1 ms.
DT_RANGE = (1e-5, 0.05)
#: Each channel's unit as a recording's columns hold it (pressures gauge).
CHANNEL_UNITS = {"t": "s", "u": "V", "p_a": "Pa (gauge)", "p_b": "Pa (gauge)", "alpha": "rad",
                 "f_ext": "N", "x": "m",
                 **{f"{q}_{j}": unit for j in JOINTS for q, unit in (("u", "V"), ("p_a", "Pa (gauge)"),
                                                                    ("p_b", "Pa (gauge)"), ("angle", "rad"),
                                                                    ("x", "m"))},
                 "f_tip_x": "N", "f_tip_y": "N", "f_tip_z": "N"}
#: The largest joint angle a recording may hold [rad]: beyond it, the angles are in degrees.
MAX_ANGLE = 2 * math.pi
#: How far [rad] the boom's angle may lie beyond its stroke's ends (Eq. 12 at x = 0 and
#: x = L of the recording's rig): sensor noise and an offset; far beyond, a wrong unit.
ALPHA_MARGIN = 0.1
#: Consecutive samples two recordings may share: a longer shared run (of quantised
#: u, pressures and angles, held samples counted once) is the same measurement, so a
#: holdout that shares one with a fit recording is fitted on, and two fit recordings
#: that share one count the same data twice.  1 s at the 1 ms DAQ.
OVERLAP_SAMPLES = 1000
#: The quantisation of the overlap check, per unit: a copy written with fewer digits
#: (``%.10g``) still matches; a recording of the same manoeuvre with its own noise does not.
OVERLAP_STEP = {"V": 1e-4, "Pa (gauge)": 1.0, "rad": 1e-7}


def recording_kind(source) -> str:
    """``"excavator"`` or ``"boom"``: which kind of recording ``source`` is, by its
    header.  ``source`` is a :class:`Recording`, a path to a recording (only its header
    row is read; :class:`RecordingError` when there is none) or its column names.  A
    recording with any excavator column beyond ``t`` (``u_boom``, ``angle_arm``...) is
    an excavator's, whose reader then wants all of them; any other is the boom's."""
    if isinstance(source, Recording):
        columns = list(source.data.columns)
    elif isinstance(source, (str, os.PathLike)):
        columns = read_header(source)
    else:
        columns = [str(c).strip() for c in source]
    excavator = set(EXCAVATOR_REQUIRED) - {"t"}
    return "excavator" if any(c in excavator for c in columns) else "boom"


def read_header(path) -> list[str]:
    """The column names of the recording at ``path``, from its header row alone (the
    rest is not read); :class:`RecordingError` where the file is missing, is not UTF-8
    text or has no header row."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(path, "no such file")
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            first = f.readline(1 << 16)
    except UnicodeDecodeError as e:
        raise RecordingError(path, f"not UTF-8 text ({e.reason} at byte {e.start})") from None
    if not first.strip():
        raise RecordingError(path, "empty file: no header row", row=1)
    return [h.strip() for h in next(csv.reader([first]))]


def common_kind(paths) -> str:
    """The one kind (:func:`recording_kind`, by the header) of all the recordings at
    ``paths``; ``ValueError`` naming each kind's files where they mix (a command takes
    the boom's recordings or the whole excavator's, not both), :class:`RecordingError`
    for a file that is missing or has no header."""
    kinds: dict[str, list[str]] = {}
    for p in paths:
        kinds.setdefault(recording_kind(p), []).append(str(p))
    if not kinds:
        raise ValueError("no recordings given")
    if len(kinds) > 1:
        raise ValueError("the recordings mix the boom's and the whole excavator's; give one kind per call: "
                         f"boom: {', '.join(kinds['boom'])}; excavator: {', '.join(kinds['excavator'])}")
    return next(iter(kinds))


class RecordingError(ValueError):
    """A recording that does not follow the recording format.

    ``path``, ``row`` (the line number in the file, the header being line 1) and
    ``column`` locate the fault where it has a place."""

    def __init__(self, path, message: str, row: int | None = None, column: str | None = None):
        self.path, self.row, self.column, self.message = Path(path), row, column, message
        where = str(path)
        if row is not None:
            where += f", line {row}"
        if column is not None:
            where += f", column {column!r}"
        super().__init__(f"{where}: {message}")


@dataclass
class Recording:
    """A validated recording: ``data`` in SI units (pressures still gauge, as stored)."""
    path: Path
    data: "pd.DataFrame"
    rig: dict = field(default_factory=dict)      #: reference-rig overrides from the sidecar
    notes: str = ""

    incomplete: str = ""                         #: why the run ended early (sidecar), else ""

    @property
    def kind(self) -> str:
        """``"boom"`` or ``"excavator"`` (:func:`recording_kind`)."""
        return recording_kind(self)

    @property
    def P_atm(self) -> float:
        return float(self.rig.get("P_atm", reference_rig.P_atm))

    def rig_tuple(self, cls):
        """A physics parameter set (``physics.Geometry``, ``Cylinder``, ``Gas``...) of
        the reference rig's values with this recording's sidecar overrides."""
        over = self.rig_values()
        return cls(**{k: over[k] for k in cls._fields if k in over})

    def rig_values(self) -> dict:
        """The sidecar's overrides by parameter name (``supply_pressure_gauge`` becomes
        the absolute ``P_s``)."""
        values = {k: float(v) for k, v in self.rig.items() if k != "supply_pressure_gauge"}
        if "supply_pressure_gauge" in self.rig:
            values["P_s"] = self.P_atm + float(self.rig["supply_pressure_gauge"])
        return values


def read_recording(path) -> Recording:
    """Read and validate a recording and its sidecar; raise :class:`RecordingError`."""
    import pandas as pd
    header, values, extra, sidecar = parse_recording(path)
    data = pd.DataFrame({c: values[c] for c in values})
    for c, col in extra.items():
        data[c] = col
    data = data[header]
    return Recording(Path(path), data, rig=dict(sidecar.get("rig", {})),
                     notes=str(sidecar.get("notes", "")), incomplete=str(sidecar.get("incomplete", "")))


def parse_recording(path):
    """Validate a recording without pandas: ``(header, numeric columns as arrays, other
    columns as lists of str, sidecar dict)``.  Raises :class:`RecordingError`."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(path, "no such file")
    limit = max_bytes()
    size = path.stat().st_size
    if size > limit:
        raise RecordingError(path, f"{size / 2**20:.0f} MiB is more than the {limit / 2**20:.0f} MiB a recording "
                                   f"may have (about an hour at 1 kHz): cut it into experiments, or set "
                                   f"$BOOMFMI_MAX_RECORDING_MB")
    try:
        text = path.read_text(encoding="utf-8-sig")      # a byte-order mark (Excel's) is dropped
    except UnicodeDecodeError as e:
        raise RecordingError(path, f"not UTF-8 text ({e.reason} at byte {e.start})") from None
    sidecar = _read_sidecar(path)
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise RecordingError(path, "empty file: no header row", row=1)
    header = next(csv.reader([lines[0]]))
    header = [h.strip() for h in header]
    if len(header) == 1 and any(d in lines[0] for d in (";", "\t")):
        delim = ";" if ";" in lines[0] else "tab"
        raise RecordingError(path, f"the header is separated by {delim!r}, not by commas", row=1)
    kind = recording_kind(header)
    spec = KINDS[kind]
    for col in spec["required"]:
        if col not in header:
            what = "missing required column" + (" of an excavator recording" if kind == "excavator" else "")
            raise RecordingError(path, f"{what} (the header has "
                                       f"{', '.join(repr(h) for h in header)})", row=1, column=col)
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise RecordingError(path, "the column appears twice", row=1, column=dup)
    if len(lines) < 2:
        raise RecordingError(path, "no samples after the header", row=2)

    numeric = [c for c in header if c in spec["required"] or c in spec["optional"]]
    rows = list(csv.reader(io.StringIO(text)))[1:]
    values = {c: np.empty(len(rows)) for c in numeric}
    index = {c: header.index(c) for c in header}
    extra = {c: [] for c in header if c not in numeric}
    for r, fields in enumerate(rows):
        line = r + 2
        if len(fields) != len(header):
            raise RecordingError(path, f"{len(fields)} fields where the header has {len(header)}",
                                 row=line)
        for c in numeric:
            raw = fields[index[c]].strip()
            try:
                v = float(raw)
            except ValueError:
                raise RecordingError(path, f"{raw!r} is not a number", row=line, column=c) from None
            if not math.isfinite(v):
                raise RecordingError(path, f"{raw!r} is not a finite number", row=line, column=c)
            values[c][r] = v
        for c in extra:
            extra[c].append(fields[index[c]])

    P_atm = float(sidecar.get("rig", {}).get("P_atm", reference_rig.P_atm))
    t = values["t"]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise RecordingError(path, f"time does not increase ({float(t[i - 1])!r} s, then {float(t[i])!r} s)",
                             row=i + 2, column="t")
    for c in spec["commands"]:
        u = values[c]
        bad = np.flatnonzero((u < reference_rig.u_min) | (u > reference_rig.u_max))
        if bad.size:
            i = int(bad[0])
            raise RecordingError(path, f"command {float(u[i])!r} V lies outside 0 to 10 V", row=i + 2, column=c)
    for c in spec["pressures"]:
        bad = np.flatnonzero(values[c] < -P_atm)
        if bad.size:
            i = int(bad[0])
            raise RecordingError(path, f"gauge pressure {float(values[c][i])!r} Pa is below -P_atm = {-P_atm:g} Pa",
                                 row=i + 2, column=c)
    for c in list(extra):               # other columns: kept; numbers where every value is one
        try:
            extra[c] = np.array([float(v) for v in extra[c]])
        except ValueError:
            pass
    return header, values, extra, sidecar


def sidecar_path(path) -> Path:
    """Where the sidecar of the recording at ``path`` is: its ``NAME.json``."""
    return Path(path).with_suffix(".json")


def recording_inputs(paths) -> list[tuple[Path, str]]:
    """Recordings as a command's inputs, each with its sidecar
    (``outputs.check_not_inputs``: no output may be either)."""
    return [item for p in paths for item in ((Path(p), f"the input recording {p}"),
                                             (sidecar_path(p), f"the sidecar of the input recording {p}"))]


def _read_sidecar(path: Path) -> dict:
    """The sidecar of the recording at ``path`` (its ``NAME.json``), ``{}`` where it has none."""
    side = sidecar_path(path)
    return read_sidecar(side) if side.is_file() else {}


def read_sidecar(side) -> dict:
    """Read and check the sidecar file ``side`` (recording-format.md: a JSON object of
    :data:`SIDECAR_KEYS`, its ``rig`` values finite numbers of :data:`RIG_KEYS`); raise
    :class:`RecordingError` naming it."""
    side = Path(side)
    if not side.is_file():
        raise RecordingError(side, "no such file")
    content = read_object(side, SIDECAR_KEYS, "sidecar", RecordingError)
    for k in ("notes", "incomplete"):
        if k in content and not isinstance(content[k], str):
            raise RecordingError(side, f"{k!r} must be text, not {content[k]!r}")
    rig_over = content.get("rig", {})
    if not isinstance(rig_over, dict):
        raise RecordingError(side, "'rig' must be an object of reference-rig values")
    excavator = any(k in EXCAVATOR_RIG_KEYS and k not in RIG_KEYS for k in rig_over)
    keys = EXCAVATOR_RIG_KEYS if excavator else RIG_KEYS
    for k, v in rig_over.items():
        if k not in keys:
            if k in RIG_KEYS or k in EXCAVATOR_RIG_KEYS:
                raise RecordingError(side, f"rig value {k!r} is the {'boom' if excavator else 'excavator'}'s, beside "
                                           f"the {'excavator' if excavator else 'boom'}'s values: one machine's only")
            raise RecordingError(side, f"unknown rig value {k!r}; a sidecar may set the boom's "
                                       f"{', '.join(RIG_KEYS)} or the excavator's <field>_<joint> "
                                       f"({', '.join(f for f in ('bore', 'rod', 'stroke', 'c1', 'c2', 'l_min'))}, ...)")
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise RecordingError(side, f"rig value {k!r} must be a finite number, not {v!r}")
    if excavator:
        check_excavator_values(rig_over, side)
    else:
        check_rig_values(rig_over, side)
    return content


def check_excavator_values(rig: dict, side) -> None:
    """Raise :class:`RecordingError` naming ``side`` and the value where the excavator's
    ``rig`` values leave the machine outside the physics' bounds."""
    try:
        excavator_from_values(rig)
    except ParameterError as e:
        raise RecordingError(side, f"rig value {e.name!r} is outside the physics' bounds: {e}") from None


def check_rig_values(rig: dict, side) -> None:
    """Raise :class:`RecordingError` naming the sidecar ``side`` and its key where its
    ``rig`` values (finite numbers of :data:`RIG_KEYS`), over the reference rig's, lie
    outside the physics' own bounds: ``physics.check_valve``, ``check_gas``,
    ``check_cylinder`` (and a stroke of at most ``L_MAX``), ``check_load``,
    ``check_geometry`` and P_atm > 0."""
    rec = Recording(Path(side), None, rig=dict(rig))
    try:
        require_positive("P_atm", rec.P_atm)
        valve = rec.rig_tuple(Valve)
        check_valve(valve)
        if valve.A_max <= 0:                 # a closed valve (A_max = 0) is a model's, not a rig's that moved
            raise ParameterError("A_max", valve.A_max, "must be > 0: at 0 the valve passes no air, and a "
                                                       "recording is of a rig whose valve opens")
        check_gas(rec.rig_tuple(Gas))
        cylinder = rec.rig_tuple(Cylinder)
        check_cylinder(cylinder)
        if cylinder.L > L_MAX:
            raise ParameterError("L", cylinder.L, f"must be at most {L_MAX:g} m (the model's scope)")
        check_load(rec.rig_tuple(Load))
        check_geometry(rec.rig_tuple(Geometry), cylinder.L)
    except ParameterError as e:
        key = "supply_pressure_gauge" if e.name == "P_s" and "supply_pressure_gauge" in rig else e.name
        if key in rig:
            raise RecordingError(side, f"rig value {key!r} = {rig[key]!r} is outside the physics' bounds: {e}") \
                from None
        given = ", ".join(f"{k} = {v!r}" for k, v in rig.items())
        raise RecordingError(side, f"the rig values ({given}) leave the reference rig's {e.name} outside the "
                                   f"physics' bounds: {e}") from None


def read_checked(paths, kind: str | None = None, role: str = "recording", machine=None) -> list[Recording]:
    """Read recordings for identification or diagnosis: each must be complete (not
    marked ``incomplete`` in its sidecar), plausible (:func:`check_plausible`) and,
    with ``kind="excavator"``, the whole excavator's (``role`` names them in the
    errors: "fit recording", "holdout").  ``machine``: a ``machine.MachineFile`` whose
    values each recording takes (its sidecar's own values must agree).  ``ValueError``
    or :class:`RecordingError` naming the file."""
    recs = []
    for p in paths:
        r = read_recording(p)
        if machine is not None:
            r = machine.apply(r)
        if kind == "excavator" and r.kind != "excavator":
            raise ValueError(f"{r.path}: a boom recording; this {role} must be the whole excavator's "
                             f"(u_<joint>, p_a_<joint>, p_b_<joint>, angle_<joint>)")
        if r.incomplete:
            raise ValueError(f"{r.path}: the recording is marked incomplete in its sidecar ({r.incomplete}); "
                             f"record it again")
        check_plausible(r)
        recs.append(r)
    return recs


def check_same_rig(recs) -> None:
    """``ValueError`` where the recordings' sidecars name different rigs."""
    if len({json.dumps(r.rig, sort_keys=True) for r in recs}) > 1:
        raise ValueError("the recordings come from different rigs (their sidecars' 'rig' values differ): "
                         + ", ".join(str(r.path) for r in recs))


def check_distinct(fits, hold: Recording) -> None:
    """Raise ``ValueError`` where the holdout ``hold`` is, or overlaps, a fit recording:
    the same file, a copy of its samples, or a part of it (a run of more than
    :data:`OVERLAP_SAMPLES` consecutive samples in common, :func:`shared_run`: the fit
    file cut short, or with a sample changed).  Its error would be the fit's own, not
    a holdout's."""
    for f in fits:
        if Path(f.path).resolve() == Path(hold.path).resolve():
            raise ValueError(f"holdout {hold.path} is also a fit recording: a holdout must be a recording "
                             f"that is not fitted on")
        if f.data.shape == hold.data.shape and f.data.equals(hold.data):
            raise ValueError(f"holdout {hold.path} holds the same samples as the fit recording {f.path}: a "
                             f"holdout must be a recording that is not fitted on")
        shared = shared_run(f, hold)
        if shared:
            raise ValueError(f"holdout {hold.path} shares {_describe_run(shared, f, hold)}: it is (a part of) "
                             f"that recording, and a holdout must be a recording that is not fitted on")


def check_no_duplicates(recs, role: str = "fit recording") -> None:
    """Raise ``ValueError`` where two of the recordings ``recs`` are one measurement: the
    same file given twice, a copy, or an overlap (a shared run of more than
    :data:`OVERLAP_SAMPLES` samples, :func:`shared_run`).  Fitted twice, its samples
    would count double and narrow the intervals without any new information."""
    for i, a in enumerate(recs):
        for b in recs[i + 1:]:
            if Path(a.path).resolve() == Path(b.path).resolve():
                raise ValueError(f"{a.path} is given twice as a {role}: each recording counts once")
            if a.data.shape == b.data.shape and a.data.equals(b.data):
                raise ValueError(f"{b.path} holds the same samples as {a.path}: the same recording given twice "
                                 f"as a {role} would count its samples double (and narrow the intervals); "
                                 f"give it once")
            shared = shared_run(a, b)
            if shared:
                raise ValueError(f"{b.path} shares {_describe_run(shared, a, b)}: one measurement given twice "
                                 f"as a {role} would count those samples double (and narrow the intervals); "
                                 f"give each once")


def _describe_run(shared, a: Recording, b: Recording) -> str:
    rows, (a0, a1), (b0, b1) = shared
    return (f"{rows} consecutive samples with {a.path} (its lines {b0} to {b1} are lines {a0} to {a1} of "
            f"{a.path}; more than {OVERLAP_SAMPLES} in common are one measurement)")


def _sample_keys(rec: Recording):
    """Each sample's quantised commands, pressures and angles (:data:`OVERLAP_STEP`) as
    one 64-bit hash, a sample equal to the one before dropped (a still or held stretch
    counts once): ``(hashes, their row indices)``."""
    spec = KINDS[rec.kind]
    cols = [c for c in (*spec["commands"], *spec["pressures"], *spec["angles"]) if c in rec.data]
    h = np.zeros(len(rec.data), dtype=np.uint64)
    for k, c in enumerate(cols):
        q = np.round(rec.data[c].to_numpy(float) / OVERLAP_STEP[CHANNEL_UNITS[c]]).astype(np.int64).view(np.uint64)
        h = _mix(h ^ _mix(q + np.uint64(k + 1)))
    keep = np.ones(len(h), dtype=bool)
    keep[1:] = h[1:] != h[:-1]
    return h[keep], np.flatnonzero(keep)


def _mix(x: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser, element-wise (uint64 arithmetic wraps)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _window_keys(h: np.ndarray, n: int) -> np.ndarray:
    """A key of every run of ``n`` consecutive sample hashes: the sum of its ``n - 1``
    pairs' hashes (each pair's order kept), by a wrapping cumulative sum."""
    if len(h) < n:
        return np.empty(0, dtype=np.uint64)
    pairs = _mix(h[:-1] ^ ((h[1:] << np.uint64(17)) | (h[1:] >> np.uint64(47))))
    c = np.concatenate([np.zeros(1, dtype=np.uint64), np.cumsum(pairs, dtype=np.uint64)])
    return c[n - 1:] - c[:len(c) - n + 1]


def shared_run(a: Recording, b: Recording, n: int = OVERLAP_SAMPLES):
    """Where the recordings ``a`` and ``b`` share more than ``n`` consecutive samples (of
    their quantised commands, pressures and angles, :func:`_sample_keys`; held samples
    counted once): ``(rows of b, (first, last line in a), (first, last line in b))`` of
    the first such run, else ``None``."""
    ha, ia = _sample_keys(a)
    hb, ib = _sample_keys(b)
    ka, kb = _window_keys(ha, n + 1), _window_keys(hb, n + 1)
    if not len(ka) or not len(kb):
        return None
    order = np.argsort(ka, kind="stable")
    pos = np.searchsorted(ka[order], kb)
    hit = (pos < len(ka)) & (ka[order][np.minimum(pos, len(ka) - 1)] == kb)
    if not hit.any():
        return None
    j = int(np.argmax(hit))
    i = int(order[pos[j]])
    length = n + 1
    while i + length < len(ha) and j + length < len(hb) and ha[i + length] == hb[j + length]:
        length += 1

    def lines(index, k, total):              # the run's first and last line (the header is line 1)
        last = index[k + length] - 1 if k + length < len(index) else total - 1
        return int(index[k]) + 2, int(last) + 2

    (a0, a1), (b0, b1) = lines(ia, i, len(a.data)), lines(ib, j, len(b.data))
    return b1 - b0 + 1, (a0, a1), (b0, b1)


def max_bytes() -> int:
    """The size limit of a recording [bytes]: :data:`MAX_BYTES` or $BOOMFMI_MAX_RECORDING_MB."""
    env = os.environ.get("BOOMFMI_MAX_RECORDING_MB")
    if env:
        try:
            mb = float(env)
        except ValueError:
            raise ValueError(f"$BOOMFMI_MAX_RECORDING_MB must be a number, not {env!r}") from None
        if not (math.isfinite(mb) and mb > 0):
            raise ValueError(f"$BOOMFMI_MAX_RECORDING_MB must be a finite number of MiB > 0, not {env!r} "
                             f"(unset, the limit is {MAX_BYTES // 2**20} MiB)")
        return max(1, int(mb * 2**20))
    return MAX_BYTES


def read_experiment(path) -> Recording:
    """Read a recording that drives a simulation (``simulate --experiment RUN.csv``, its
    ``--replay``): :func:`read_recording` and the scale checks of :func:`check_plausible`
    that an experiment's command and start need (time in seconds, pressures and angles
    in their units), so that a time in milliseconds is named before a thousandfold run."""
    rec = read_recording(path)
    check_plausible(rec, measured=False)
    return rec


def check_plausible(rec: Recording, measured: bool = True) -> None:
    """Raise :class:`RecordingError` where a recording reads well but cannot be what the
    format says: a time column that is not in seconds at a DAQ's rate, pressures far out
    of scale with the rig's supply (bar or kPa where Pa belong), angles beyond their
    physical range (degrees where radians belong: the boom's alpha beyond its stroke's
    ends by Eq. 12 at the recording's rig, :data:`ALPHA_MARGIN`), and, for a recording
    taken as measurements (``measured``: identification, diagnosis), too few samples
    to judge anything, pressures that stay at nothing while the valve opens, samples
    held while the link was lost.  ``measured=False``: an experiment's command."""
    d, path = rec.data, rec.path
    n = len(d)
    if measured and n < MIN_SAMPLES:
        raise RecordingError(path, f"{n} samples: identification and diagnosis need at least {MIN_SAMPLES} "
                                   f"(0.1 s at the 1 ms DAQ)")
    dt = float(np.median(np.diff(d["t"].to_numpy(float)))) if n > 1 else DT_RANGE[0]
    if not DT_RANGE[0] <= dt <= DT_RANGE[1]:
        unit = "milliseconds" if dt > DT_RANGE[1] else "microseconds"
        raise RecordingError(path, f"the samples are {dt:g} s apart (median): t must be in seconds at the DAQ's "
                                   f"rate ({DT_RANGE[0]:g} to {DT_RANGE[1]:g} s apart); is it in {unit}?",
                             column="t")
    supply = rec.rig_tuple(Valve).P_s - rec.P_atm
    spec = KINDS[rec.kind]
    for u_col, (pa, pb) in zip(spec["commands"], zip(spec["pressures"][::2], spec["pressures"][1::2])):
        peak = max(float(np.max(np.abs(d[pa].to_numpy(float)))), float(np.max(np.abs(d[pb].to_numpy(float)))))
        opened = bool(np.any(np.abs(d[u_col].to_numpy(float) - reference_rig.u_centre) > 0.5))
        if measured and opened and peak < 0.02 * supply:
            raise RecordingError(path, f"the chamber pressures peak at {peak:g} Pa gauge while the valve opens, "
                                       f"{100 * peak / supply:.2g} % of the supply's {supply:g} Pa: are they in "
                                       f"bar or kPa? The format wants Pa (gauge)", column=pa)
        if peak > 1.5 * supply + 1e5:
            raise RecordingError(path, f"the chamber pressures reach {peak:g} Pa gauge, beyond the supply's "
                                       f"{supply:g} Pa: a wrong unit, or set the supply in the sidecar "
                                       f"(rig.supply_pressure_gauge)", column=pa)
    if rec.kind == "excavator":
        for c in spec["angles"]:
            a = d[c].to_numpy(float)
            bad = np.flatnonzero(np.abs(a) > MAX_ANGLE)
            if bad.size:
                i = int(bad[0])
                raise RecordingError(path, f"the joint angle {float(a[i])!r} is beyond +-2 pi: the format wants "
                                           f"radians; is it in degrees?", row=i + 2, column=c)
    if rec.kind == "boom":
        _check_alpha(rec)
    if measured and "link_ok" in d:
        held = np.flatnonzero(d["link_ok"].to_numpy(float) == 0)
        if held.size:
            raise RecordingError(path, f"{held.size} samples were held while the link was lost (link_ok = 0), "
                                       f"the first at line {int(held[0]) + 2}: they are not measurements; "
                                       f"cut them off or record again", row=int(held[0]) + 2, column="link_ok")


def _check_alpha(rec: Recording) -> None:
    """:class:`RecordingError` where the boom's angle lies beyond its stroke's ends (Eq. 12
    at x = 0 and x = L of the recording's rig, widened by :data:`ALPHA_MARGIN`), naming
    the likely unit: degrees where the values reach tens."""
    geom, L = rec.rig_tuple(Geometry), rec.rig_tuple(Cylinder).L
    lo, hi = sorted(float(alpha_from_x(x, geom)) for x in (0.0, L))
    a = rec.data["alpha"].to_numpy(float)
    bad = np.flatnonzero((a < lo - ALPHA_MARGIN) | (a > hi + ALPHA_MARGIN))
    if not bad.size:
        return
    i = int(bad[0])
    value = float(a[i])
    if abs(value) > MAX_ANGLE or lo - ALPHA_MARGIN <= math.radians(value) <= hi + ALPHA_MARGIN:
        hint = f"is it in degrees ({value:g} deg = {math.radians(value):.4g} rad)?"
    else:
        hint = ("is it in another unit, or is the rig's geometry (a, b, l_min, L) not the sidecar's? Describe "
                "the machine with --machine FILE (boomfmi machine init)")
    raise RecordingError(rec.path, f"the boom angle {value!r} rad lies outside its physical range, "
                                   f"{lo:.4g} to {hi:.4g} rad ({math.degrees(lo):.1f} to {math.degrees(hi):.1f} deg: "
                                   f"the stroke's ends by Eq. 12 at the rig's geometry, +-{ALPHA_MARGIN:g} rad); the "
                                   f"format wants radians; {hint}", row=i + 2, column="alpha")


class RecordingWriter:
    """Write a recording row by row, crash-safe: each row is flushed to the OS as it is
    written, so a process killed mid-run leaves a file whose every row is complete.

    The file is locked while it is written (``outputs.OutputLock``: a second writer, by
    the same name or through a link, is refused with ``outputs.OutputError``).  A new
    recording is written in its place from the first row.  Where a file (or a link) is
    at ``path`` already, the rows and the sidecar go to hidden ``.partial-PID`` files and
    replace it only when the writer closes after a run that ended well
    (:meth:`close`): a run that fails, is interrupted or is killed leaves the existing
    recording and its sidecar as they were, and a link's target is never written.
    ``inputs``: the command's input files, which the recording and its sidecar may not
    be (``outputs.check_not_inputs``)."""

    def __init__(self, path, columns=REQUIRED, sidecar: dict | None = None, inputs=()):
        from .outputs import OutputLock, check_not_folder, check_not_inputs, clean_partials
        self.path = Path(path)
        self.columns = list(columns)
        kind = recording_kind(self.columns)
        for c in KINDS[kind]["required"]:
            if c not in self.columns:
                raise ValueError(f"a recording needs column {c!r}" + (" (an excavator's: each joint's u, p_a, "
                                                                      "p_b and angle)" if kind == "excavator" else ""))
        if len(set(self.columns)) != len(self.columns):
            raise ValueError(f"a recording's columns must be distinct: {self.columns}")
        side = sidecar_path(self.path)
        check_not_inputs([self.path, side], inputs)
        check_not_folder(self.path)
        check_not_folder(side)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = OutputLock(self.path)
        self._f = None
        #: the rows written so far; where a failed run's rows were kept (beside an
        #: existing recording that stays as it was), their file
        self.rows, self.kept = 0, None
        #: where a failed run's rows would be kept
        self.kept_path = self.path.with_name(f"{self.path.stem}.incomplete-{time.strftime('%Y%m%dT%H%M%S')}-"
                                             f"{os.getpid()}{self.path.suffix}")
        self._side_lock = None
        try:
            self._side_lock = OutputLock(side)          # the sidecar is this writer's too
            for name in (self.path.name, side.name):
                clean_partials(self.path.parent, name)
            #: writing beside an existing file, to replace it when the run has ended well
            self.replacing = os.path.lexists(self.path)
            self._side_tmp = None
            if self.replacing:
                self._target = self.path.with_name(f".{self.path.name}.partial-{os.getpid()}")
                fd = os.open(self._target, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o644)
            else:
                self._target = self.path
                fd = os.open(self._target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            self._f = open(fd, "w", encoding="utf-8", newline="")
            self._lock.hold(fd)
            if sidecar:
                self.set_sidecar(sidecar)
            self._f.write(",".join(self.columns) + "\n")
            self._f.flush()
        except BaseException:
            self.close(ok=False)
            raise

    def set_sidecar(self, sidecar: dict) -> None:
        """Write the sidecar (atomically: a reader sees the old one or the new one; where
        an existing recording is being replaced, only when it is)."""
        side = sidecar_path(self.path)
        tmp = side.with_name(f".{side.name}.partial-{os.getpid()}")
        tmp.write_text(json.dumps(sidecar, indent=2))
        if self.replacing:
            self._side_tmp = tmp
        else:
            os.replace(tmp, side)

    def write(self, row) -> None:
        """Append one sample: a mapping by column name or a sequence in column order."""
        if isinstance(row, dict):
            row = [row[c] for c in self.columns]
        self._f.write(",".join(repr(float(v)) for v in row) + "\n")
        self._f.flush()
        self.rows += 1

    def close(self, ok: bool = True) -> None:
        """Finish the file; where an existing recording is being replaced, replace it
        (``ok``) or remove this run's rows and leave it as it was (not ``ok``)."""
        if self._f is not None and not self._f.closed:
            self._f.flush()
            os.fsync(self._f.fileno())
            self._f.close()
            if getattr(self, "replacing", False):
                if ok:
                    os.replace(self._target, self.path)
                    if self._side_tmp is not None:
                        os.replace(self._side_tmp, sidecar_path(self.path))
                else:
                    self._keep_failed_rows()
        elif self._f is None and getattr(self, "replacing", False):
            self._target.unlink(missing_ok=True)
        self._lock.release()
        if self._side_lock is not None:
            self._side_lock.release()

    def _keep_failed_rows(self) -> None:
        """A run that did not end well beside an existing recording: its rows, where it
        has any, go to a visible ``NAME.incomplete-STAMP.csv`` with a sidecar marked
        ``incomplete`` (:attr:`kept`), so that nothing recorded is lost and nothing
        replaces the existing recording; a run with no rows leaves nothing."""
        side_tmp, self._side_tmp = self._side_tmp, None
        rows = self.rows
        if rows:
            kept = self.kept_path
            os.replace(self._target, kept)
            sidecar = {}
            if side_tmp is not None:
                try:
                    sidecar = json.loads(side_tmp.read_text())
                except (OSError, ValueError):
                    sidecar = {}
            sidecar.setdefault("incomplete", "the run did not end well")
            sidecar_path(kept).write_text(json.dumps(sidecar, indent=2))
            self.kept = kept
        else:
            self._target.unlink(missing_ok=True)
        if side_tmp is not None:
            side_tmp.unlink(missing_ok=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(ok=exc_type is None)


def write_recording(path, data, sidecar: dict | None = None) -> Path:
    """Write a whole DataFrame as a recording (the required columns of its kind first)."""
    required = KINDS[recording_kind(data.columns)]["required"]
    cols = [c for c in required if c in data] + [c for c in data.columns if c not in required]
    with RecordingWriter(path, cols, sidecar) as w:
        for row in data[cols].itertuples(index=False):
            w.write(row)
    return Path(path)


__all__ = ["REQUIRED", "RIG_KEYS", "RIG_UNITS", "EXCAVATOR_RIG_KEYS", "EXCAVATOR_RIG_UNITS", "OPTIONAL",
           "EXCAVATOR_REQUIRED", "EXCAVATOR_OPTIONAL", "KINDS", "SIDECAR_KEYS", "MAX_BYTES", "MIN_SAMPLES", "DT_RANGE",
           "CHANNEL_UNITS", "MAX_ANGLE", "ALPHA_MARGIN", "OVERLAP_SAMPLES", "OVERLAP_STEP", "recording_kind",
           "read_header", "common_kind", "RecordingError", "Recording", "read_recording", "parse_recording",
           "sidecar_path", "recording_inputs", "read_sidecar", "check_excavator_values", "check_rig_values",
           "read_checked", "check_same_rig", "check_distinct", "check_no_duplicates", "shared_run", "max_bytes",
           "read_experiment", "check_plausible", "RecordingWriter", "write_recording"]
