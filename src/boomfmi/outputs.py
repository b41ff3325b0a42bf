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

Every file being written is locked (:class:`OutputLock`: ``fcntl.flock`` on a hidden
``.NAME.lock`` beside it and on the file a name already links to), so that a second
writer of the same file, by the same name or through a link, is refused with
:class:`OutputError` naming it.  Under that lock the ``.NAME.partial-PID`` files a
killed run left are removed.  :func:`check_not_inputs` refuses an output that is (or
resolves to, through symbolic or hard links) one of the command's inputs.  The move
into place is all or nothing: a folder where a file of the set goes is refused before
anything moves, and a move that fails puts back what was moved before it.
"""
from __future__ import annotations

import fcntl
import os
import stat
from pathlib import Path


class OutputError(OSError):
    """An output that may not be written: it is an input, a folder, or another process
    is writing it.  (An ``OSError``: the command line prints it as its error.)"""

    def __str__(self) -> str:
        return self.args[0] if self.args else ""


def _identity(path) -> tuple[str, tuple[int, int] | None]:
    """``path`` resolved through links, and its file's (device, inode) where it exists."""
    try:
        st = os.stat(path)
        ident = (st.st_dev, st.st_ino)
    except OSError:
        ident = None
    return os.path.realpath(path), ident


def check_not_inputs(outputs, inputs) -> None:
    """Raise :class:`OutputError` if an output is one of ``inputs``: the same name, a
    name resolving to it through symbolic links, or a hard link to its file.  An input
    is a path or ``(path, what)`` (``what``: e.g. "the sidecar of run.csv")."""
    known = []
    for item in inputs:
        path, what = item if isinstance(item, tuple) else (item, None)
        known.append((Path(path), what, *_identity(path)))
    for out in outputs:
        real, ident = _identity(out)
        for path, what, in_real, in_ident in known:
            if real == in_real or (ident is not None and ident == in_ident):
                via = ("" if os.path.abspath(out) == os.path.abspath(path) else
                       f" (through a link: both are {in_real})" if real == in_real else " (a hard link to it)")
                raise OutputError(f"{out}: this output is {what or f'the input {path}'}{via}; writing it would "
                                  f"destroy the input: give another output")


def clean_partials(folder, name: str) -> list[Path]:
    """Remove the ``.NAME.partial-*`` files a killed run left in ``folder`` (call it
    holding ``name``'s :class:`OutputLock`: no live writer has one then)."""
    removed = []
    for p in Path(folder).glob(f".{name}.partial-*"):
        try:
            p.unlink()
            removed.append(p)
        except FileNotFoundError:
            pass
    return removed


class OutputLock:
    """An exclusive lock on the file at ``path`` for writing it, held until
    :meth:`release`: ``fcntl.flock`` on ``.NAME.lock`` beside it (removed on release)
    and, where ``path`` exists as a regular file (or links to one), on that file, so
    that two names of one file (symbolic or hard links) are one lock.  A second writer
    gets :class:`OutputError` naming the file."""

    def __init__(self, path):
        self.path = Path(path)
        self._fds: list[int] = []
        self.lockfile = self.path.parent / f".{self.path.name}.lock"
        try:
            self._lock_file()
            self._lock_target()
        except BaseException:
            self.release()
            raise

    def _busy(self) -> OutputError:
        return OutputError(f"{self.path}: another writer (a command of this or another process) has it "
                           f"open now; refusing to write it too (wait until that one has finished, or give another "
                           f"output)")

    def _lock_file(self) -> None:
        for _ in range(10):
            fd = os.open(self.lockfile, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise self._busy() from None
            try:
                same = os.stat(self.lockfile, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:                        # not a lock file its last holder removed meanwhile
                self._fds.append(fd)
                return
            os.close(fd)
        raise self._busy()

    def _lock_target(self) -> None:
        try:
            st = os.stat(self.path)
        except OSError:
            return
        if not stat.S_ISREG(st.st_mode):
            return
        fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        self._fds.append(fd)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise self._busy() from None

    def hold(self, fd: int) -> None:
        """Also lock the file open as ``fd`` (a file this writer has just created)."""
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise self._busy() from None

    def release(self) -> None:
        if self._fds:
            try:
                os.unlink(self.lockfile)
            except OSError:
                pass
        for fd in self._fds:
            os.close(fd)
        self._fds = []


def check_not_folder(path) -> None:
    """Raise :class:`OutputError` if ``path``, where a file goes, is a folder."""
    if os.path.isdir(path) and not os.path.islink(path):
        raise OutputError(f"{path}: is a folder, where this output file goes; nothing was written (the folder "
                          f"and the other outputs are as they were): give a file name")


class OutputSet:
    """A set of files in ``folder``, moved into place together on success.  ``stale``:
    names that belong to the set whether or not this run writes them.  ``inputs``: the
    command's input files (paths or ``(path, what)``), which no file of the set may be
    (:func:`check_not_inputs`).  Each name is locked (:class:`OutputLock`) from its
    first use until the set is committed or discarded."""

    def __init__(self, folder, stale=(), inputs=()):
        self.folder = Path(folder)
        self.stale = tuple(stale)
        self.inputs = tuple(inputs)
        self._pending: dict[str, Path] = {}
        self._locks: dict[str, OutputLock] = {}

    def _claim(self, name: str) -> None:
        """Check ``name`` against the inputs, lock it, remove a killed run's partials of it."""
        if name in self._locks:
            return
        check_not_inputs([self.folder / name], self.inputs)
        self._locks[name] = OutputLock(self.folder / name)
        clean_partials(self.folder, name)

    def path(self, name: str) -> Path:
        """The temporary path to write ``name`` to (moved to ``folder / name`` at commit)."""
        self._claim(name)
        tmp = self.folder / f".{name}.partial-{os.getpid()}"
        self._pending[name] = tmp
        return tmp

    def written(self) -> list[Path]:
        """The final paths of the files written so far."""
        return [self.folder / n for n in self._pending]

    def commit(self) -> None:
        """Move every file written into place and remove the stale ones: all or nothing.
        A folder where one goes is refused (:class:`OutputError`) before anything moves;
        a move that fails puts back the files moved before it."""
        for name in self.stale:
            self._claim(name)
        for name in (*self._pending, *self.stale):
            check_not_folder(self.folder / name)
        placed: list[tuple[Path, bool, Path | None]] = []   # (final path, existed, a link to its old file)
        try:
            for name, tmp in self._pending.items():
                final = self.folder / name
                existed, backup = os.path.lexists(final), None
                if existed:
                    backup = self.folder / f".{name}.partial-{os.getpid()}.old"
                    try:
                        os.link(final, backup, follow_symlinks=False)
                    except OSError:             # no hard links here: this one cannot be put back
                        backup = None
                os.replace(tmp, final)
                placed.append((final, existed, backup))
        except BaseException:
            for final, existed, backup in reversed(placed):
                if backup is not None:
                    os.replace(backup, final)
                elif not existed:
                    final.unlink(missing_ok=True)
            for name in self._pending:          # the link made for the move that failed
                (self.folder / f".{name}.partial-{os.getpid()}.old").unlink(missing_ok=True)
            raise
        for _, _, backup in placed:
            if backup is not None:
                backup.unlink(missing_ok=True)
        for name in self.stale:
            if name not in self._pending:
                (self.folder / name).unlink(missing_ok=True)
        self._pending.clear()
        self._release()

    def discard(self) -> None:
        for tmp in self._pending.values():
            tmp.unlink(missing_ok=True)
        self._pending.clear()
        self._release()

    def _release(self) -> None:
        for lock in self._locks.values():
            lock.release()
        self._locks.clear()

    def __enter__(self):
        self.folder.mkdir(parents=True, exist_ok=True)
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            try:
                self.commit()
            except BaseException:
                self.discard()
                raise
        else:
            self.discard()


__all__ = ["OutputError", "check_not_inputs", "clean_partials", "OutputLock", "check_not_folder", "OutputSet"]
