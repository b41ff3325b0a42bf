"""Names read from files, checked before anything is done with them.

A name in a file (an SSP's component, an FMU's model identifier) is data: it may end up
in a temporary file's name, a library's name or a column's, and a name such as
``/home/me/.bashrc`` or ``../../x`` must never become a path outside the folder meant
for it.  :func:`name_problem` says what is wrong with a name that is not *plain*
(letters, digits, ``_`` and ``-``, at most :data:`MAX_NAME` characters: no path, no
dot, no space, nothing invisible), :func:`member_problem` what is wrong with a file's
place inside an archive (``resources/valve.fmu``: relative, ``/``-separated, no
``.``/``..`` part).  Each caller raises its own error with the file and the element
at fault.
"""
from __future__ import annotations

import re

#: the longest plain name (a file system takes 255 bytes: room for a suffix)
MAX_NAME = 100
#: the longest place inside an archive
MAX_MEMBER = 1000
PLAIN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_-]*")
_PART = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*")
_RULE = f"a name may hold letters, digits, '_' and '-' only (at most {MAX_NAME} characters)"


def _why_path(text: str) -> str | None:
    parts = re.split(r"[/\\]", text)
    if text.startswith(("/", "\\")) or re.match(r"[A-Za-z]:", text):
        return "it is an absolute path"
    if ".." in parts:
        return "it climbs out of its folder ('..')"
    return None


def name_problem(name) -> str | None:
    """What is wrong with ``name`` as a plain name, or None where it is one."""
    if not isinstance(name, str) or not name:
        return f"it is empty: {_RULE}"
    if len(name) <= MAX_NAME and PLAIN.fullmatch(name):
        return None
    why = _why_path(name)
    if why is None:
        if "/" in name or "\\" in name:
            why = "it is a path (it holds a '/' or '\\')"
        elif len(name) > MAX_NAME:
            why = f"it has {len(name)} characters"
        elif name[0] == "-":
            why = "it starts with '-'"
        else:
            why = f"it holds {next(c for c in name if not PLAIN.fullmatch(c))!r}"
    return f"{why}: {_RULE}"


def member_problem(member) -> str | None:
    """What is wrong with ``member`` as a file's place inside an archive (or a folder
    laid out like one), or None: a relative path of ``/``-separated parts, each of
    letters, digits, ``_``, ``-``, ``+`` and ``.``, none ``.`` or ``..``."""
    if not isinstance(member, str) or not member:
        return "it is empty"
    why = _why_path(member)
    if why:
        return why + ": a source is a file inside the SSP (resources/valve.fmu)"
    if len(member) > MAX_MEMBER:
        return f"it has {len(member)} characters, more than {MAX_MEMBER}"
    for part in member.split("/"):
        if not _PART.fullmatch(part):
            return (f"its part {part!r} is not a plain file name: a source is a file inside the SSP "
                    f"(resources/valve.fmu), its parts letters, digits, '_', '-', '+' and '.', "
                    f"none starting with '.'")
    return None


__all__ = ["MAX_NAME", "MAX_MEMBER", "PLAIN", "name_problem", "member_problem"]
