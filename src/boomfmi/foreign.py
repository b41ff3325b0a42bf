"""Foreign measurement files: any delimited text table, read through a column map with units.

A test rig's data acquisition writes its own layout: another delimiter, no header or a
header in another language, a decimal comma, thousands separators, start-up rows to
drop, and units of its own.  A *column map* says which column holds which quantity in
which unit::

    t=1:ms,x=5:mm,p_gauge=6:bar,F=7:N          columns by number (1-based)
    t=Tijd (s):s,dp=SLA Prusa:mbar              columns by header name (with header=True)

Each entry is ``NAME=COLUMN:UNIT`` (the unit after the last colon; a header name that
holds a comma or an equals sign must be given by number).  Units are converted by pint
to SI, never by hand; a unit pint does not know, or of the wrong dimension for the
quantity (``x=5:bar``), is refused naming the map entry.  Pressures say whether they are
gauge or absolute in their name, because ``bar`` is a unit and not a reference::

    p_gauge, p_abs          a chamber pressure (the bench tools)
    p_a_gauge, p_a_abs      chamber A, p_b_gauge, p_b_abs chamber B (recordings)
    dp                      a pressure change since the first sample

A bare ``p`` is refused with that explanation.  The other known names are ``t`` (time),
``x`` (piston position), ``F`` (rod force from a load cell), ``f_ext``, ``u`` (valve
command), ``alpha`` (boom angle); any other name (a Python identifier) is read as an
extra column and kept in SI base units.

Every bad file is rejected with a :class:`~boomfmi.recording.RecordingError` (the
recordings' own error) naming the file, the line (1-based, counting skipped and header
lines) and the column: too few fields (with a hint when the line holds another
delimiter), a header name that is not there, text in a number, a non-finite number.

:func:`import_recording` converts such a file into the recording format
(``shared/spec/recording-format.md``) where its columns allow, and says which required
columns are missing where they do not.
"""
from __future__ import annotations

import csv
import json
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from .outputs import OutputSet, check_not_inputs
from .physics import reference_rig
from .recording import (OPTIONAL, REQUIRED, RecordingError, read_recording, recording_kind, sidecar_path,
                        write_recording)

#: Delimiter names: ``whitespace`` splits on runs of blanks and tabs.
DELIMITERS = {"tab": "\t", "comma": ",", "semicolon": ";", "space": " ", "whitespace": None}

#: Known quantities: name -> (meaning, SI unit, pint dimensionality).
QUANTITIES = {
    "t": ("time", "s", "[time]"),
    "x": ("piston position", "m", "[length]"),
    "F": ("rod force (load cell)", "N", "[force]"),
    "f_ext": ("external force on the piston", "N", "[force]"),
    "u": ("valve command", "V", "[electric_potential]"),
    "alpha": ("boom angle", "rad", ""),
    "p_gauge": ("chamber pressure, gauge", "Pa", "[pressure]"),
    "p_abs": ("chamber pressure, absolute", "Pa", "[pressure]"),
    "p_a_gauge": ("chamber A pressure, gauge", "Pa", "[pressure]"),
    "p_a_abs": ("chamber A pressure, absolute", "Pa", "[pressure]"),
    "p_b_gauge": ("chamber B pressure, gauge", "Pa", "[pressure]"),
    "p_b_abs": ("chamber B pressure, absolute", "Pa", "[pressure]"),
    "dp": ("pressure change since the first sample", "Pa", "[pressure]"),
}

#: Ready-made read options for known sources' file layouts (README, docs/real-data.md).
#: ``zillen2021``: the friction tests of Zillen, Vallery and Smit (2021), tab separated,
#: no header, 15 start-up rows, columns t [ms], three raw signals [V], x [mm], p [bar
#: gauge], F [N].  ``zillen2021-leak``: their leak-down tests, ';' separated, the time
#: written as milliseconds with three decimals and '.' for both separators
#: (``143.495.000``) while the pressure has a decimal point (``7.547``): with ``.`` as the
#: thousands separator of the time column only, its digits are microseconds.
PRESETS = {
    "zillen2021": {"map": "t=1:ms,x=5:mm,p_gauge=6:bar,F=7:N", "delimiter": "tab", "skip_rows": 15},
    "zillen2021-leak": {"map": "t=1:us,p_gauge=3:bar", "delimiter": "semicolon", "thousands": {"t": "."}},
}


@lru_cache(maxsize=1)
def units():
    """The pint unit registry (one for the process)."""
    import pint
    return pint.UnitRegistry()


@dataclass(frozen=True)
class MapEntry:
    """One ``NAME=COLUMN:UNIT`` of a column map."""
    name: str
    column: int | str       #: 1-based column number, or a header name
    unit: str
    text: str               #: the entry as written, for messages

    @property
    def label(self) -> str:
        """The column as a message names it."""
        return str(self.column)


@dataclass
class ForeignTable:
    """A foreign file read through a column map: every mapped quantity in SI units."""
    path: Path
    columns: dict[str, np.ndarray]              #: name -> values in SI units
    lines: np.ndarray                           #: each sample's line number in the file (1-based)
    entries: list[MapEntry] = field(default_factory=list)
    P_atm: float = reference_rig.P_atm

    def __len__(self) -> int:
        return len(self.lines)

    def has(self, name: str) -> bool:
        return name in self.columns

    def entry_text(self, name: str) -> str:
        """The map entry of ``name`` as written, quoted (``'x=5:m'``), for messages."""
        return next((repr(e.text) for e in self.entries if e.name == name), repr(name))

    def gauge(self, chamber: str = "") -> np.ndarray:
        """A pressure as gauge [Pa]: ``p`` (chamber="") or ``p_a``/``p_b``, from its
        ``_gauge`` column or its ``_abs`` column less P_atm."""
        base = f"p_{chamber}" if chamber else "p"
        if f"{base}_gauge" in self.columns:
            return self.columns[f"{base}_gauge"]
        if f"{base}_abs" in self.columns:
            return self.columns[f"{base}_abs"] - self.P_atm
        raise RecordingError(self.path, f"the column map gives no {base}_gauge or {base}_abs")


def parse_map(text: str, path="") -> list[MapEntry]:
    """Parse a column map ``NAME=COLUMN:UNIT,...``; RecordingError naming the entry
    (and ``path``, the file it is for) where one is malformed or a unit is unknown or
    of the wrong dimension."""
    if not text or not text.strip():
        raise RecordingError(path, "empty column map: give --map NAME=COLUMN:UNIT,... (e.g. t=1:ms,x=5:mm)")
    entries, seen = [], set()
    for raw in text.split(","):
        item = raw.strip()
        name, eq, rest = item.partition("=")
        name = name.strip()
        if not eq or not name:
            raise RecordingError(path, f"map entry {item!r}: expected NAME=COLUMN:UNIT (e.g. x=5:mm)")
        if not name.isidentifier():
            raise RecordingError(path, f"map entry {item!r}: {name!r} is not a name (letters, digits, _)")
        if name == "p" or name in ("p_a", "p_b"):
            raise RecordingError(path, f"map entry {item!r}: say whether the pressure is gauge or absolute: "
                                       f"{name}_gauge=... or {name}_abs=... (a unit such as bar does not say)")
        if name in seen:
            raise RecordingError(path, f"map entry {item!r}: {name} is mapped twice")
        seen.add(name)
        column, colon, unit = rest.rpartition(":")
        column, unit = column.strip(), unit.strip()
        if not colon or not column or not unit:
            raise RecordingError(path, f"map entry {item!r}: give the column and its unit, NAME=COLUMN:UNIT "
                                       f"(e.g. {name}={rest.strip() or '1'}:{QUANTITIES.get(name, ('', 's'))[1]})")
        if column.isdigit():
            number = int(column)
            if number < 1:
                raise RecordingError(path, f"map entry {item!r}: columns are numbered from 1")
            col: int | str = number
        else:
            col = column
        entry = MapEntry(name, col, unit, item)
        _check_unit(entry, path)
        entries.append(entry)
    return entries


def _check_unit(entry: MapEntry, path) -> None:
    import pint
    ureg = units()
    try:
        q = ureg.Quantity(1.0, entry.unit)
    except (pint.errors.UndefinedUnitError, pint.errors.DefinitionSyntaxError, AttributeError,
            TypeError, ValueError, AssertionError) as e:
        raise RecordingError(path, f"map entry {entry.text!r}: pint does not know the unit {entry.unit!r} ({e})",
                             column=entry.label) from None
    if entry.name in QUANTITIES:
        meaning, si, dim = QUANTITIES[entry.name]
        want = ureg.Quantity(1.0, si).dimensionality
        if q.dimensionality != want:
            got = str(q.dimensionality) or "dimensionless"
            raise RecordingError(path, f"map entry {entry.text!r}: {entry.unit!r} is a unit of {got}, but "
                                       f"{entry.name} ({meaning}) needs a unit of {dim or 'angle'} such as {si}",
                                 column=entry.label)


def _delimiter(name: str):
    if name in DELIMITERS:
        return DELIMITERS[name]
    if name == "\\t":
        return "\t"
    if len(name) == 1:
        return name
    raise ValueError(f"--delimiter {name!r}: give one character or one of {', '.join(DELIMITERS)}")


def _split(line: str, delim) -> list[str]:
    if delim is None:
        return line.split()
    return next(csv.reader([line], delimiter=delim))


def _number_pattern(decimal: str, thousands: str | None):
    """The regular expression a number's text must match, or None (any text float() takes)."""
    if thousands is None and decimal == ".":
        return None
    frac = re.escape(decimal)
    if thousands is None:
        return re.compile(rf"[+-]?(\d+({frac}\d*)?|{frac}\d+)([eE][+-]?\d+)?")
    sep = re.escape(thousands)
    return re.compile(rf"[+-]?(\d{{1,3}}({sep}\d{{3}})+|\d+)({frac}\d*)?([eE][+-]?\d+)?")


def _to_float(text: str, pattern, decimal: str, thousands: str | None) -> float:
    s = text.strip()
    if pattern is not None:
        if not pattern.fullmatch(s):
            raise ValueError(s)
        if thousands is not None:
            s = s.replace(thousands, "")
        if decimal != ".":
            s = s.replace(decimal, ".")
    return float(s)


def read_foreign(path, column_map, *, delimiter: str = "tab", skip_rows: int = 0, header: bool = False,
                 decimal: str | dict | None = None, thousands: str | dict | None = None,
                 encoding: str = "utf-8-sig",
                 P_atm: float = reference_rig.P_atm) -> ForeignTable:
    """Read a delimited text file through a column map (a string or parsed entries).

    ``skip_rows`` lines are dropped first (start-up samples, a preamble); with
    ``header`` the next line names the columns; every further non-blank line is a
    sample.  ``decimal`` is the decimal mark ('.', or ',' where the thousands separator
    is '.'), ``thousands`` the thousands separator (none by default; grouping is
    checked: ``1.234,5`` with thousands '.' and decimal ','), each one character for
    every column or a dict ``{name: character}`` for some (a file may write its time
    with separators and its pressure without).  Returns a
    :class:`ForeignTable` in SI units; raises RecordingError naming the file, line and
    column of any fault."""
    path = Path(path)
    entries = parse_map(column_map, path) if isinstance(column_map, str) else list(column_map)
    delim = _delimiter(delimiter)
    formats = _formats(entries, decimal, thousands, delim)
    if skip_rows < 0:
        raise ValueError(f"--skip-rows {skip_rows}: give a number >= 0")
    if not path.is_file():
        raise RecordingError(path, "no such file")
    try:
        text = path.read_text(encoding=encoding)
    except UnicodeDecodeError as e:
        raise RecordingError(path, f"not {encoding} text ({e.reason} at byte {e.start}): give --encoding") from None
    lines = text.splitlines()
    pos = skip_rows
    head: list[str] = []
    if header:
        while pos < len(lines) and not lines[pos].strip():
            pos += 1
        if pos >= len(lines):
            raise RecordingError(path, f"no header line after the {skip_rows} skipped lines", row=pos + 1)
        head = [h.strip() for h in _split(lines[pos], delim)]
        header_line = pos + 1
        pos += 1
    index: dict[str, int] = {}
    for e in entries:
        if isinstance(e.column, int):
            index[e.name] = e.column - 1
        elif not header:
            raise RecordingError(path, f"map entry {e.text!r} names a column by its header: give --header "
                                       f"(the file's first line after the skipped ones must name the columns)",
                                 column=e.label)
        elif e.column not in head:
            raise RecordingError(path, f"map entry {e.text!r}: no column {e.column!r} in the header (it has "
                                       f"{', '.join(repr(h) for h in head)})"
                                       + _delimiter_hint(head, delimiter, delim), row=header_line, column=e.label)
        else:
            index[e.name] = head.index(e.column)
    need = max(index.values()) + 1
    raw = {e.name: [] for e in entries}
    numbers: list[int] = []
    for i in range(pos, len(lines)):
        line = lines[i]
        if not line.strip():
            continue
        fields = _split(line, delim)
        if len(fields) < need:
            widest = max(entries, key=lambda e: index[e.name])
            raise RecordingError(path, _few_fields(fields, line, need, widest, delimiter, delim),
                                 row=i + 1, column=widest.label)
        for e in entries:
            raw[e.name].append(fields[index[e.name]])
        numbers.append(i + 1)
    if not numbers:
        raise RecordingError(path, f"no samples after line {pos} (skipped {skip_rows}"
                                   f"{', then a header' if header else ''})", row=pos + 1)
    columns = {}
    for e in entries:
        values = _convert(raw[e.name], numbers, e, path, *formats[e.name])
        columns[e.name] = _to_si(values, e)
    return ForeignTable(path, columns, np.asarray(numbers), entries, P_atm)


def _delimiter_hint(head, delimiter, delim) -> str:
    """A hint when a header split by ``delim`` is one field that another delimiter splits."""
    if len(head) != 1:
        return ""
    found = [(n, ch) for n, ch in DELIMITERS.items() if ch and ch != delim and ch != " " and ch in head[0]]
    if not found:
        return ""
    name, ch = max(found, key=lambda f: head[0].count(f[1]))
    return (f": the header looks {ch!r}-separated, not by --delimiter {delimiter!r}: "
            f"add --delimiter {name}")


def _few_fields(fields, line, need, entry, delimiter, delim) -> str:
    msg = (f"{len(fields)} field{'s' if len(fields) != 1 else ''} where the map needs column {need} "
           f"({entry.name}, map entry {entry.text!r})")
    if len(fields) == 1:
        found = [n for n, ch in DELIMITERS.items() if ch and ch != delim and ch != " " and ch in line]
        if found:
            return msg + f": the line is not separated by --delimiter {delimiter!r}; it holds {found[0]}s"
        return msg + f": is --delimiter {delimiter!r} the file's delimiter?"
    return msg + ": a column the file does not have"


def _formats(entries, decimal, thousands, delim) -> dict:
    """Each entry's (number pattern, decimal mark, thousands separator)."""
    names = {e.name for e in entries}
    out = {}
    for what, spec in (("--decimal", decimal), ("--thousands", thousands)):
        if isinstance(spec, dict):
            for name, ch in spec.items():
                if name not in names:
                    raise ValueError(f"{what} {name}={ch}: the column map has no {name}")
    for e in entries:
        dec = decimal.get(e.name) if isinstance(decimal, dict) else decimal
        th = thousands.get(e.name) if isinstance(thousands, dict) else thousands
        if dec is None:                  # not given: the mark that is not the thousands separator
            dec = "," if th == "." else "."
        for what, ch in (("--decimal", dec), ("--thousands", th)):
            if ch is not None and (len(ch) != 1 or ch.isdigit() or ch in "+-eE"):
                raise ValueError(f"{what} {ch!r}: give one character that is not a digit, sign or exponent")
        if th is not None and th == dec:
            raise ValueError(f"--thousands and --decimal are both {dec!r} for {e.name}: give --decimal too "
                             f"(e.g. --decimal , --thousands .)")
        if delim is not None and delim in (dec, th):
            raise ValueError(f"the delimiter {delim!r} is also {e.name}'s decimal mark or thousands separator")
        out[e.name] = (_number_pattern(dec, th), dec, th)
    return out


#: A number whose digits are grouped in threes by one separator used at least twice
#: (``1.002.000``, ``1,002,000``, ``1'002'000``): it can only be a thousands separator.
_GROUPED = re.compile(r"[+-]?\d{1,3}(([.,' ])\d{3})(\2\d{3})+([.,]\d*)?")


def _convert(texts, numbers, entry: MapEntry, path, pattern, decimal, thousands) -> np.ndarray:
    if pattern is None:
        try:
            values = np.array(texts, dtype=float)
        except ValueError:
            values = None
    else:
        values = None
    if values is None:
        values = np.empty(len(texts))
        for k, s in enumerate(texts):
            try:
                values[k] = _to_float(s, pattern, decimal, thousands)
            except ValueError:
                hint = ""
                if pattern is not None:
                    hint = f" (with --decimal {decimal!r}" + (f" and --thousands {thousands!r})" if thousands else ")")
                elif _GROUPED.fullmatch(s.strip()):
                    sep = _GROUPED.fullmatch(s.strip()).group(2)
                    hint = (f" (digits grouped by {sep!r}: thousands separators? give --thousands {sep}, or "
                            f"--thousands {entry.name}={sep} for this column only)")
                elif "," in s:
                    hint = " (a decimal comma? give --decimal ,)"
                raise RecordingError(path, f"{s.strip()!r} is not a number{hint} ({entry.name}, map entry "
                                           f"{entry.text!r})", row=int(numbers[k]), column=entry.label) from None
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        k = int(bad[0])
        raise RecordingError(path, f"{texts[k].strip()!r} is not a finite number ({entry.name})",
                             row=int(numbers[k]), column=entry.label)
    return values


def _to_si(values: np.ndarray, entry: MapEntry) -> np.ndarray:
    q = units().Quantity(values, entry.unit)
    if entry.name in QUANTITIES:
        return np.asarray(q.to(QUANTITIES[entry.name][1]).magnitude, dtype=float)
    return np.asarray(q.to_base_units().magnitude, dtype=float)


def read_options(preset: str | None = None, **given) -> dict:
    """The read options of a preset (:data:`PRESETS`) with the given ones (not None) on
    top: ``map``, ``delimiter``, ``skip_rows``, ``header``, ``decimal``, ``thousands``,
    ``encoding``.  ValueError for an unknown preset or no map."""
    opts = {"map": None, "delimiter": "tab", "skip_rows": 0, "header": False, "decimal": None,
            "thousands": None, "encoding": "utf-8-sig"}
    if preset is not None:
        if preset not in PRESETS:
            raise ValueError(f"--preset {preset!r}: known presets are {', '.join(PRESETS)}")
        opts.update(PRESETS[preset])
    opts.update({k: v for k, v in given.items() if v is not None})
    if not opts["map"]:
        raise ValueError("give --map NAME=COLUMN:UNIT,... (e.g. \"t=1:ms,x=5:mm,p_gauge=6:bar,F=7:N\") or --preset")
    return opts


def read_with(path, opts: dict, P_atm: float = reference_rig.P_atm) -> ForeignTable:
    """:func:`read_foreign` with the options of :func:`read_options`."""
    o = dict(opts)
    return read_foreign(path, o.pop("map"), P_atm=P_atm, **o)


def recording_frame(table: ForeignTable):
    """The recording-format DataFrame of a foreign table (SI, gauge pressures): the
    required columns, the optional ones it has, then its other columns.  RecordingError
    listing every required column the map does not give."""
    import pandas as pd
    c = table.columns
    data: dict[str, np.ndarray] = {}
    missing = []
    for name in REQUIRED:
        if name in ("p_a", "p_b"):
            if f"{name}_gauge" in c or f"{name}_abs" in c:
                data[name] = table.gauge(name[-1])
            else:
                missing.append(f"{name} (as {name}_gauge or {name}_abs)")
        elif name in c:
            data[name] = c[name]
        else:
            missing.append(f"{name} ({QUANTITIES[name][0]})")
    if missing:
        have = ", ".join(c) or "nothing"
        raise RecordingError(table.path, f"cannot become a recording: the map gives no {', '.join(missing)}; a "
                                         f"recording needs {', '.join(REQUIRED)} (shared/spec/recording-format.md), "
                                         f"and this map gives {have}")
    for name in OPTIONAL:
        if name in c:
            data[name] = c[name]
    used = {"p_a_gauge", "p_a_abs", "p_b_gauge", "p_b_abs", *REQUIRED, *OPTIONAL}
    for name, values in c.items():
        if name not in used:
            data[name] = values
    return pd.DataFrame(data)


def import_recording(path, out, opts: dict, P_atm: float = reference_rig.P_atm, machine=None) -> Path:
    """Convert a foreign file into a recording at ``out``: read it with ``opts``
    (:func:`read_options`), write it in the recording format and read it back through
    :func:`~boomfmi.recording.read_recording`; a fault found there is reported at the
    foreign file's own line.  Nothing is left at ``out`` on an error, and an existing
    ``out`` is as it was.  ``out`` may not be the foreign file (nor a link to it), and
    is locked while it is written (``outputs.OutputSet``).  ``machine``: a
    ``machine.MachineFile`` the file is of: its values are the recording's sidecar (written
    with it, as one set), and its P_atm converts gauge and absolute pressures."""
    out = Path(out)
    side = sidecar_path(out)
    check_not_inputs([out, side], [Path(path)])
    if machine is not None:
        P_atm = float(machine.rig.get("P_atm", P_atm))
    table = read_with(path, opts, P_atm)
    frame = recording_frame(table)
    if machine is not None and recording_kind(frame.columns) != machine.kind:
        raise ValueError(f"{machine.path}: describes {'an' if machine.kind == 'excavator' else 'a'} {machine.kind}; "
                         f"the map of {path} makes a {recording_kind(frame.columns)}'s recording")
    with OutputSet(out.parent, inputs=[Path(path)]) as files:
        tmp = files.path(out.name)
        write_recording(tmp, frame)
        if machine is not None:                # the sidecar: written with the recording, as one set
            files.path(side.name).write_text(json.dumps({"rig": machine.sidecar()}, indent=2) + "\n")
        try:
            read_recording(tmp)
        except RecordingError as e:
            raise _at_source(e, table) from None
    return out


def _at_source(e: RecordingError, table: ForeignTable) -> RecordingError:
    """The recording reader's error on the converted file, placed in the foreign file."""
    message = e.message
    row = None
    if e.row is not None and 2 <= e.row < len(table.lines) + 2:
        row = int(table.lines[e.row - 2])
    column = e.column
    for entry in table.entries:
        if entry.name == e.column or entry.name in (f"{e.column}_gauge", f"{e.column}_abs"):
            column = entry.label
            message += f" ({entry.name}, map entry {entry.text!r}, in SI units)"
    return RecordingError(table.path, f"as a recording: {message}", row=row, column=column)


def increasing_time(table: ForeignTable) -> np.ndarray:
    """The table's time [s], checked to increase strictly (RecordingError at the first
    line where it does not)."""
    if "t" not in table.columns:
        raise RecordingError(table.path, "the column map gives no t (time)")
    t = table.columns["t"]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        entry = next(e for e in table.entries if e.name == "t")
        raise RecordingError(table.path, f"time does not increase ({t[i - 1]!r} s, then {t[i]!r} s; map entry "
                                         f"{entry.text!r})", row=int(table.lines[i]), column=entry.label)
    return t


def check_time_scale(table: ForeignTable, t: np.ndarray, what: str, spacing: tuple[float, float],
                     duration: tuple[float, float] | None = None) -> None:
    """RecordingError where the samples' median spacing lies outside ``spacing`` [s] or
    the run's length outside ``duration`` [s] (``what``: "friction test", "leak-down
    run"): the map's unit of t is not the file's (s for ms or us, ms for s), and the
    message names the map entry and the option that fixes it."""
    dt = float(np.median(np.diff(t))) if len(t) > 1 else spacing[0]
    span = float(t[-1] - t[0])
    label = next((e.label for e in table.entries if e.name == "t"), None)
    fault = None
    if not spacing[0] <= dt <= spacing[1]:
        fault = (f"the samples are {dt:g} s apart (median), and a {what}'s are {spacing[0]:g} to {spacing[1]:g} s "
                 f"apart", dt > spacing[1])
    elif duration is not None and not duration[0] <= span <= duration[1]:
        fault = (f"the {what} lasts {span:g} s ({span / 86400:.3g} days), and a {what} lasts {duration[0]:g} to "
                 f"{duration[1]:g} s", span > duration[1])
    if fault is not None:
        text, long = fault
        way = "smaller unit than the map's (ms or us where it says s?)" if long else \
            "larger unit than the map's (s or ms where it says ms or us?)"
        raise RecordingError(table.path, f"{text}: is the file's time in a {way} Give t's unit in --map (map "
                                         f"entry {table.entry_text('t')}), e.g. t=COLUMN:ms", column=label)


__all__ = ["DELIMITERS", "QUANTITIES", "PRESETS", "units", "MapEntry", "ForeignTable", "parse_map", "read_foreign",
           "read_options", "read_with", "recording_frame", "import_recording", "increasing_time", "check_time_scale"]
