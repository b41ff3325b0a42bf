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
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .physics import Valve, reference_rig
from .physics.excavator import JOINTS

if TYPE_CHECKING:
    import pandas as pd

REQUIRED = ("t", "u", "p_a", "p_b", "alpha")
#: Reference-rig values a sidecar may override (``{"rig": {...}}``), by the FMUs'
#: parameter names (SI, pressures absolute), plus the spec's own example key.
RIG_KEYS = ("A_max", "P_s", "P_e", "k", "R", "T", "A_a", "A_b", "L", "V_a0", "V_b0", "a", "b",
            "h", "l_min", "K_v", "F_s", "F_d", "F_L", "M", "P_atm", "supply_pressure_gauge")
OPTIONAL = ("f_ext", "x")
#: (``JOINTS``, the excavator's joints, are the linkage's: ``physics.excavator.JOINTS``.)
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
UNITS = {"t": "s", "u": "V", "p_a": "Pa (gauge)", "p_b": "Pa (gauge)", "alpha": "rad",
         "f_ext": "N", "x": "m",
         **{f"{q}_{j}": unit for j in JOINTS for q, unit in (("u", "V"), ("p_a", "Pa (gauge)"),
                                                            ("p_b", "Pa (gauge)"), ("angle", "rad"), ("x", "m"))},
         "f_tip_x": "N", "f_tip_y": "N", "f_tip_z": "N"}
#: The largest joint angle a recording may hold [rad]: beyond it, the angles are in degrees.
MAX_ANGLE = 2 * math.pi


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


def _read_sidecar(path: Path) -> dict:
    """The sidecar of the recording at ``path`` (its ``NAME.json``), ``{}`` where it has none."""
    side = path.with_suffix(".json")
    return read_sidecar(side) if side.is_file() else {}


def read_sidecar(side) -> dict:
    """Read and check the sidecar file ``side`` (recording-format.md: a JSON object of
    :data:`SIDECAR_KEYS`, its ``rig`` values finite numbers of :data:`RIG_KEYS`); raise
    :class:`RecordingError` naming it."""
    side = Path(side)
    if not side.is_file():
        raise RecordingError(side, "no such file")
    try:
        content = json.loads(side.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise RecordingError(side, f"the sidecar is not valid JSON: {e}") from None
    if not isinstance(content, dict):
        raise RecordingError(side, "the sidecar must hold a JSON object")
    for k in content:
        if k not in SIDECAR_KEYS:
            raise RecordingError(side, f"unknown key {k!r}; a sidecar may hold {', '.join(SIDECAR_KEYS)}")
    for k in ("notes", "incomplete"):
        if k in content and not isinstance(content[k], str):
            raise RecordingError(side, f"{k!r} must be text, not {content[k]!r}")
    rig_over = content.get("rig", {})
    if not isinstance(rig_over, dict):
        raise RecordingError(side, "'rig' must be an object of reference-rig values")
    for k, v in rig_over.items():
        if k not in RIG_KEYS:
            raise RecordingError(side, f"unknown rig value {k!r}; a sidecar may set {', '.join(RIG_KEYS)}")
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise RecordingError(side, f"rig value {k!r} must be a finite number, not {v!r}")
    return content


def read_checked(paths, kind: str | None = None, role: str = "recording") -> list[Recording]:
    """Read recordings for identification or diagnosis: each must be complete (not
    marked ``incomplete`` in its sidecar), plausible (:func:`check_plausible`) and,
    with ``kind="excavator"``, the whole excavator's (``role`` names them in the
    errors: "fit recording", "holdout").  ``ValueError`` or
    :class:`RecordingError` naming the file."""
    recs = []
    for p in paths:
        r = read_recording(p)
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
    """Raise ``ValueError`` where the holdout ``hold`` is one of the fit recordings (the
    same file, or a copy of its samples): its error would be the fit's own, not a
    holdout's."""
    for f in fits:
        if Path(f.path).resolve() == Path(hold.path).resolve():
            raise ValueError(f"holdout {hold.path} is also a fit recording: a holdout must be a recording "
                             f"that is not fitted on")
        if f.data.shape == hold.data.shape and f.data.equals(hold.data):
            raise ValueError(f"holdout {hold.path} holds the same samples as the fit recording {f.path}: a "
                             f"holdout must be a recording that is not fitted on")


def max_bytes() -> int:
    """The size limit of a recording [bytes]: :data:`MAX_BYTES` or $BOOMFMI_MAX_RECORDING_MB."""
    env = os.environ.get("BOOMFMI_MAX_RECORDING_MB")
    if env:
        try:
            return int(float(env) * 2**20)
        except ValueError:
            raise ValueError(f"$BOOMFMI_MAX_RECORDING_MB must be a number, not {env!r}") from None
    return MAX_BYTES


def check_plausible(rec: Recording) -> None:
    """Raise :class:`RecordingError` where a recording reads well but cannot be what the
    format says: too few samples to judge anything, a time column that is not in
    seconds at a DAQ's rate, pressures far out of scale with the rig's supply (bar or
    kPa where Pa belong), samples held while the link was lost."""
    d, path = rec.data, rec.path
    n = len(d)
    if n < MIN_SAMPLES:
        raise RecordingError(path, f"{n} samples: identification and diagnosis need at least {MIN_SAMPLES} "
                                   f"(0.1 s at the 1 ms DAQ)")
    dt = float(np.median(np.diff(d["t"].to_numpy(float))))
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
        if opened and peak < 0.02 * supply:
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
    if "link_ok" in d:
        held = np.flatnonzero(d["link_ok"].to_numpy(float) == 0)
        if held.size:
            raise RecordingError(path, f"{held.size} samples were held while the link was lost (link_ok = 0), "
                                       f"the first at line {int(held[0]) + 2}: they are not measurements; "
                                       f"cut them off or record again", row=int(held[0]) + 2, column="link_ok")


class RecordingWriter:
    """Write a recording row by row, crash-safe: each row is flushed to the OS as it is
    written, so a process killed mid-run leaves a file whose every row is complete."""

    def __init__(self, path, columns=REQUIRED, sidecar: dict | None = None):
        self.path = Path(path)
        self.columns = list(columns)
        kind = recording_kind(self.columns)
        for c in KINDS[kind]["required"]:
            if c not in self.columns:
                raise ValueError(f"a recording needs column {c!r}" + (" (an excavator's: each joint's u, p_a, "
                                                                      "p_b and angle)" if kind == "excavator" else ""))
        if len(set(self.columns)) != len(self.columns):
            raise ValueError(f"a recording's columns must be distinct: {self.columns}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if sidecar:
            self.set_sidecar(sidecar)
        self._f = open(self.path, "w", encoding="utf-8", newline="")
        self._f.write(",".join(self.columns) + "\n")
        self._f.flush()

    def set_sidecar(self, sidecar: dict) -> None:
        """Write the sidecar (atomically: a reader sees the old one or the new one)."""
        side = self.path.with_suffix(".json")
        tmp = side.with_name(f".{side.name}.partial-{os.getpid()}")
        tmp.write_text(json.dumps(sidecar, indent=2))
        os.replace(tmp, side)

    def write(self, row) -> None:
        """Append one sample: a mapping by column name or a sequence in column order."""
        if isinstance(row, dict):
            row = [row[c] for c in self.columns]
        self._f.write(",".join(repr(float(v)) for v in row) + "\n")
        self._f.flush()

    def close(self) -> None:
        if not self._f.closed:
            self._f.flush()
            os.fsync(self._f.fileno())
            self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def write_recording(path, data, sidecar: dict | None = None) -> Path:
    """Write a whole DataFrame as a recording (the required columns of its kind first)."""
    required = KINDS[recording_kind(data.columns)]["required"]
    cols = [c for c in required if c in data] + [c for c in data.columns if c not in required]
    with RecordingWriter(path, cols, sidecar) as w:
        for row in data[cols].itertuples(index=False):
            w.write(row)
    return Path(path)
