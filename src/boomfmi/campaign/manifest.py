"""A campaign's manifest: which recordings belong to which machine, date and role.

The manifest is a CSV file (UTF-8, comma separated, one header row) with the columns

=========== ======== ===================================================================
column      required meaning
=========== ======== ===================================================================
machine     yes      the machine (rig, cylinder, excavator of a fleet): any text
date        yes      the day of the experiments, ISO 8601 (``2025-03-10``; a time
                     ``2025-03-10T14:00`` where a machine is tested more than once a day)
role        yes      ``fit`` (identifies the baseline, fits the effects) or ``holdout``
                     (never fitted on: every shrink is measured there)
recording   yes      the recording (recording-format.md), relative to the manifest's folder
                     or absolute
sidecar     no       its sidecar JSON where it is not the recording's own ``NAME.json``
=========== ======== ===================================================================

Other columns (notes, operator) are kept but ignored; blank lines and lines starting
with ``#`` are skipped.  Every (machine, date) is one *case*: its fit recordings and its
holdout recordings diagnosed together, as ``boomfmi diagnose`` does.

:func:`read_manifest` checks everything that can be checked before any work starts
and raises :class:`ManifestError` naming the file, the line and the column of each
fault: a missing column, an empty field, an unknown role, a date that is not ISO 8601,
a recording or sidecar that is not there, a recording whose header is neither a boom
recording's nor the whole excavator's, a sidecar its recording's reader would refuse
(``recording.read_sidecar``), a recording listed twice, a case with no fit or no holdout
recording, a case or a machine whose recordings are of both kinds.

A case of boom recordings is identified and diagnosed as ``boomfmi identify`` and
``boomfmi diagnose`` do; a case of excavator recordings by the whole machine's
diagnosis (``diagnose.report.diagnose``, per joint), its per-joint parameters (``K_v_arm``...)
in the trends.
"""
from __future__ import annotations

import csv
import hashlib
import io
import re
from dataclasses import dataclass, field
from datetime import date, datetime
from pathlib import Path

from ..names import MAX_NAME
from ..recording import KINDS, RecordingError, read_header, read_sidecar, recording_kind

REQUIRED = ("machine", "date", "role", "recording")
OPTIONAL = ("sidecar",)
ROLES = ("fit", "holdout")
#: most faults listed in one error (the rest are counted)
MAX_LISTED = 25


class ManifestError(ValueError):
    """A manifest that cannot be run: every fault found, each naming its line."""

    def __init__(self, path, problems: list[str]):
        self.path, self.problems = Path(path), list(problems)
        shown = self.problems[:MAX_LISTED]
        more = len(self.problems) - len(shown)
        text = "\n  ".join(shown) + (f"\n  ... and {more} more" if more > 0 else "")
        super().__init__(f"{path}: {len(self.problems)} problem(s) in the manifest; nothing was run:\n  {text}")


@dataclass(frozen=True)
class Entry:
    """One row of the manifest."""
    line: int                 #: its line in the file (the header is line 1)
    machine: str
    date: str                 #: ISO 8601, as normalised (date, or date and time)
    role: str                 #: "fit" or "holdout"
    recording: Path           #: resolved
    sidecar: Path | None      #: resolved; None: the recording's own NAME.json, if any
    kind: str = "boom"        #: the recording's kind (``recording.recording_kind``): boom or excavator


@dataclass
class Case:
    """One machine on one date: its fit and holdout recordings."""
    machine: str
    date: str
    entries: list = field(default_factory=list)

    @property
    def key(self) -> tuple[str, str]:
        return (self.machine, self.date)

    def role(self, role: str) -> list[Entry]:
        return [e for e in self.entries if e.role == role]

    @property
    def kind(self) -> str:
        """Its recordings' kind (the manifest's reader refuses a case of both)."""
        return self.entries[0].kind if self.entries else "boom"

    @property
    def folder(self) -> Path:
        """Its folder under the campaign's ``cases/``: the machine, then the date."""
        return Path(slug(self.machine)) / slug(self.date)

    @property
    def label(self) -> str:
        return f"{self.machine} {self.date}"


@dataclass
class Manifest:
    path: Path
    cases: list           #: Case, by machine (in the order first listed), then by date

    @property
    def machines(self) -> list[str]:
        return list(dict.fromkeys(c.machine for c in self.cases))


def slug(text: str) -> str:
    """A folder name for ``text``: letters, digits, ``.``, ``_`` and ``-`` kept, anything
    else ``_``; where that changed the text, a short hash of it is appended so that two
    names never share a folder.  A text longer than :data:`~boomfmi.names.MAX_NAME` is
    cut to it (with the hash): a file system takes no longer name."""
    clean = re.sub(r"[^A-Za-z0-9._-]", "_", text).strip(".") or "_"
    if clean != text or len(clean) > MAX_NAME:
        clean = clean[:MAX_NAME - 7] + "-" + hashlib.sha1(text.encode()).hexdigest()[:6]
    return clean


def parse_date(text: str) -> str:
    """An ISO 8601 date or date-time, normalised (``2025-03-10``, ``2025-03-10T14:00:00``);
    ValueError if it is neither."""
    text = text.strip()
    try:
        return date.fromisoformat(text).isoformat()
    except ValueError:
        pass
    return datetime.fromisoformat(text).isoformat()


def date_key(text: str) -> datetime:
    """A normalised date's point in time, for ordering."""
    return datetime.fromisoformat(text)


def read_manifest(path) -> Manifest:
    """Read and check the manifest at ``path``: :class:`Manifest`, or
    :class:`ManifestError` listing every fault with its line."""
    path = Path(path)
    if not path.is_file():
        raise ManifestError(path, ["no such file" if not path.exists() else "not a file"])
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise ManifestError(path, [f"not UTF-8 text ({e.reason} at byte {e.start})"]) from None
    base = path.parent
    rows = list(csv.reader(io.StringIO(text)))
    numbered = [(i + 1, r) for i, r in enumerate(rows) if any(f.strip() for f in r)
                and not r[0].lstrip().startswith("#")]
    if not numbered:
        raise ManifestError(path, ["empty: no header row (machine, date, role, recording[, sidecar])"])
    head_line, header = numbered[0]
    header = [h.strip().lower() for h in header]
    problems = []
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        delim = next((d for d in (";", "\t") if d in ",".join(rows[head_line - 1])), None)
        hint = f" (the header is separated by {delim!r}: the manifest is comma separated)" if delim else ""
        raise ManifestError(path, [f"line {head_line}: missing column(s) {', '.join(missing)}; the header has "
                                   f"{', '.join(repr(h) for h in header)}{hint}"])
    dup = sorted({h for h in header if header.count(h) > 1 and h in REQUIRED + OPTIONAL})
    if dup:
        raise ManifestError(path, [f"line {head_line}: column {', '.join(dup)} appears twice"])
    col = {h: header.index(h) for h in REQUIRED + OPTIONAL if h in header}
    entries: list[Entry] = []
    seen: dict[Path, int] = {}
    for line, fields in numbered[1:]:
        if len(fields) < len(header):
            fields = fields + [""] * (len(header) - len(fields))
        elif len(fields) > len(header) and any(f.strip() for f in fields[len(header):]):
            problems.append(f"line {line}: {len(fields)} fields where the header has {len(header)}")
            continue
        get = {c: fields[i].strip() for c, i in col.items()}
        bad = False
        for c in REQUIRED:
            if not get[c]:
                problems.append(f"line {line}, column {c}: empty")
                bad = True
        if bad:
            continue
        role = get["role"].lower()
        if role not in ROLES:
            problems.append(f"line {line}, column role: {get['role']!r} is not a role: fit or holdout")
            bad = True
        try:
            when = parse_date(get["date"])
        except ValueError:
            problems.append(f"line {line}, column date: {get['date']!r} is not an ISO 8601 date (2025-03-10)")
            bad = True
        rec = (base / get["recording"]).resolve()
        if not rec.is_file():
            problems.append(f"line {line}, column recording: {get['recording']}: "
                            f"{'not a file' if rec.exists() else 'no such file'} ({rec})")
            bad = True
        elif rec in seen:
            problems.append(f"line {line}, column recording: {get['recording']} is listed already on line "
                            f"{seen[rec]} (a recording is one experiment, on one machine and date)")
            bad = True
        else:
            seen[rec] = line
            problem, kind = _check_header(rec)
            if problem:
                problems.append(f"line {line}, column recording: {get['recording']}: {problem}")
                bad = True
        side = None
        if get.get("sidecar"):
            side = (base / get["sidecar"]).resolve()
            problem = _check_sidecar(side)
            if problem:
                problems.append(f"line {line}, column sidecar: {get['sidecar']}: {problem}")
                bad = True
        if not bad:
            entries.append(Entry(line, get["machine"], when, role, rec, side, kind))
    if not entries and not problems:
        problems.append("no recordings listed below the header")
    cases: dict[tuple, Case] = {}
    for e in entries:
        cases.setdefault((e.machine, e.date), Case(e.machine, e.date)).entries.append(e)
    for c in cases.values():
        for role in ROLES:
            if not c.role(role):
                other = "fit" if role == "holdout" else "holdout"
                lines = ", ".join(str(e.line) for e in c.entries)
                problems.append(f"line{'s' if len(c.entries) > 1 else ''} {lines}: machine {c.machine!r} on "
                                f"{c.date} has no {role} recording (only {other}); "
                                + ("the diagnosis measures every shrink on a holdout recording"
                                   if role == "holdout" else "the baseline is identified on the fit recordings"))
    kinds: dict[str, list] = {}
    for c in cases.values():
        for e in c.entries:
            kinds.setdefault(c.machine, []).append(e)
    for machine, listed in kinds.items():   # a case, and a machine's trends, are of one kind of recording
        if len({e.kind for e in listed}) > 1:
            by = {k: ", ".join(str(e.line) for e in listed if e.kind == k) for k in ("boom", "excavator")}
            problems.append(f"machine {machine!r}: lines {by['boom']} are boom recordings and lines "
                            f"{by['excavator']} the whole excavator's; a machine's recordings are of one kind")
    folders: dict[Path, str] = {}
    for c in cases.values():          # two texts that one folder would hold (a date and a date-time)
        if folders.setdefault(c.folder, c.label) != c.label:
            problems.append(f"cases {folders[c.folder]!r} and {c.label!r} would share the folder {c.folder}")
    if problems:
        raise ManifestError(path, problems)
    order = list(dict.fromkeys(e.machine for e in entries))
    ordered = sorted(cases.values(), key=lambda c: (order.index(c.machine), date_key(c.date)))
    return Manifest(path, ordered)


def _check_header(rec: Path) -> tuple[str | None, str]:
    """``(problem, kind)``: what is wrong with a recording's header row, where a look at
    it tells (the full reading comes with its case), and its kind
    (``recording.recording_kind``: any excavator column makes it the whole excavator's):
    the kind's required columns (``recording.KINDS``)."""
    try:
        header = read_header(rec)
    except RecordingError as e:
        return e.message, "boom"
    except OSError as e:
        return f"cannot be read ({e.strerror})", "boom"
    kind = recording_kind(header)
    missing = [c for c in KINDS[kind]["required"] if c not in header]
    if missing and kind == "boom":
        return (f"not a boom recording (recording-format.md): no column {', '.join(missing)} "
                f"in its header ({', '.join(repr(h) for h in header[:8])})"), kind
    if missing:
        other = next(h for h in header if h in KINDS["excavator"]["required"] and h != "t")
        return (f"not a whole excavator's recording (shared/spec/excavator.md), which its column {other!r} "
                f"makes it: no column {', '.join(missing)} in its header"), kind
    return None, kind


def _check_sidecar(side: Path) -> str | None:
    """What is wrong with a sidecar, as its recording's reader would find it."""
    if not side.is_file():
        return f"{'not a file' if side.exists() else 'no such file'} ({side})"
    try:
        read_sidecar(side)
    except RecordingError as e:
        return e.message
    except OSError as e:
        return f"cannot be read ({e.strerror})"
    return None


def write_manifest(path, rows) -> Path:
    """Write a manifest: ``rows`` of dicts with machine, date, role, recording (and
    optionally sidecar); paths are written relative to the manifest's folder where
    they lie below it."""
    path = Path(path)
    base = path.parent.resolve()
    has_sidecar = any(r.get("sidecar") for r in rows)
    cols = list(REQUIRED) + (["sidecar"] if has_sidecar else [])

    def rel(p):
        if not p:
            return ""
        p = Path(p).resolve()
        try:
            return p.relative_to(base).as_posix()
        except ValueError:
            return str(p)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([r["machine"], r["date"], r["role"], rel(r["recording"])]
                   + ([rel(r.get("sidecar"))] if has_sidecar else []))
    path.write_text(buf.getvalue())
    return path


__all__ = ["REQUIRED", "OPTIONAL", "ROLES", "MAX_LISTED", "ManifestError", "Entry", "Case", "Manifest", "slug",
           "parse_date", "date_key", "read_manifest", "write_manifest"]
