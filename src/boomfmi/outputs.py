"""Writing a set of output files as one: all of them or none.

A command that writes several files (``params.json``, ``params.ssv``, ``params.png``;
``diagnosis.json``, ``report.html`` and its PNGs) writes each to a hidden temporary
name beside its final place, and only when every file of the set is written moves them
into place (``os.replace``: atomic per file).  An interrupt or an error before that
leaves the previous set untouched, and the temporary files are removed.  Files of the
set's name that this run did not produce (a PNG an earlier run drew) are removed at
the end, so that no stale file passes for this run's.

    with OutputSet(out_dir, stale=("residual_breakdown.png",)) as out:
        out.path("diagnosis.json").write_text(...)
"""
from __future__ import annotations

import os
from pathlib import Path


class OutputSet:
    """A set of files in ``folder``, moved into place together on success.  ``stale``:
    names that belong to the set whether or not this run writes them."""

    def __init__(self, folder, stale=()):
        self.folder = Path(folder)
        self.stale = tuple(stale)
        self._pending: dict[str, Path] = {}

    def path(self, name: str) -> Path:
        """The temporary path to write ``name`` to (moved to ``folder / name`` at commit)."""
        tmp = self.folder / f".{name}.partial-{os.getpid()}"
        self._pending[name] = tmp
        return tmp

    def written(self) -> list[Path]:
        """The final paths of the files written so far."""
        return [self.folder / n for n in self._pending]

    def commit(self) -> None:
        for name, tmp in self._pending.items():
            os.replace(tmp, self.folder / name)
        for name in self.stale:
            if name not in self._pending:
                (self.folder / name).unlink(missing_ok=True)
        self._pending.clear()

    def discard(self) -> None:
        for tmp in self._pending.values():
            tmp.unlink(missing_ok=True)
        self._pending.clear()

    def __enter__(self):
        self.folder.mkdir(parents=True, exist_ok=True)
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.commit()
        else:
            self.discard()
