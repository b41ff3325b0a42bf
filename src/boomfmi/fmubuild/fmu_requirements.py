"""What a boomfmi FMU's Python code needs, checked before it imports anything else.

boomfmi.fmubuild copies this file into each FMU as ``boomfmi_<name>_lib/_requirements.py``
(the bundle's ``__init__`` runs :func:`check`, and the FMU's script imports the bundle
first), beside ``resources/boomfmi_requirements.txt``, which the build writes:

    python=3.11
    require=numpy>=2.0,<3 built=2.4.6
    portable=linux64 win64

A portable FMU carries its packages for each platform it lists in
``resources/python/<platform>/``: that folder goes first on ``sys.path``, so that only a
CPython of that version is needed.  Whatever is then missing or of the wrong version is
raised as ImportError naming it and the command that installs it; pythonfmu reports
that with fmi2Error from fmi2Instantiate.  Imports nothing of boomfmi: it runs inside the FMU.
"""
from __future__ import annotations

import importlib
import os
import re
import sys

RESOURCES = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RECORD = "boomfmi_requirements.txt"


def platform_tag() -> str:
    """This process's FMI 2.0 platform folder name."""
    bits = "64" if sys.maxsize > 2 ** 32 else "32"
    if sys.platform == "win32":
        return f"win{bits}"
    return f"{'darwin' if sys.platform == 'darwin' else 'linux'}{bits}"


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in re.findall(r"\d+", text.split("+")[0])[:3])


def _satisfies(version: str, spec: str) -> bool:
    for clause in spec.split(","):
        op, bound = re.match(r"\s*(>=|<=|==|<|>)\s*(\S+)", clause).groups()
        have, want = _version(version), _version(bound)
        if not {">=": have >= want, "<=": have <= want, "==": have == want,
                "<": have < want, ">": have > want}[op]:
            return False
    return True


def read(resources: str = RESOURCES) -> dict:
    """The record as {"python": "3.11", "require": [(name, spec, built)], "portable": [...]}."""
    path = os.path.join(resources, RECORD)
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise ImportError(f"this FMU is incomplete: {path} cannot be read ({e}); rebuild it") from None
    record = {"python": "", "require": [], "portable": []}
    for line in lines:
        key, _, value = line.partition("=")
        if line.startswith("#") or not _:
            continue
        if key == "python":
            record["python"] = value.strip()
        elif key == "require":
            requirement, _, built = value.partition(" built=")
            name, spec = re.match(r"([A-Za-z0-9_.-]+)(.*)", requirement.strip()).groups()
            record["require"].append((name, spec, built.strip()))
        elif key == "portable":
            record["portable"] = value.split()
    return record


def check(resources: str = RESOURCES) -> None:
    """Put a portable FMU's packages first on sys.path, then raise ImportError naming each
    requirement this Python does not meet and how to meet it."""
    record = read(resources)
    tag = platform_tag()
    own = os.path.join(resources, "python", tag)
    if tag in record["portable"]:
        if not os.path.isdir(own):
            raise ImportError(f"this portable FMU is incomplete: {own} is missing; rebuild it")
        if own not in sys.path:
            sys.path.insert(0, own)
    running = f"{sys.version_info.major}.{sys.version_info.minor}"
    where = f"Python {sys.version.split()[0]} at {sys.base_prefix}"
    problems = []
    if record["python"] and running != record["python"]:
        problems.append(f"Python {record['python']} (this is {where})")
    missing = []
    for name, spec, built in record["require"]:
        try:
            module = importlib.import_module(name)
        except ImportError as e:
            problems.append(f"{name}{spec} (built with {built}): not importable: {e}")
            missing.append(f"{name}{spec}")
            continue
        version = getattr(module, "__version__", "")
        if spec and not _satisfies(version, spec):
            problems.append(f"{name}{spec} (built with {built}): found {name} {version} at "
                            f"{os.path.dirname(getattr(module, '__file__', '') or '')}")
            missing.append(f"{name}{spec}")
    if not problems:
        return
    python = (os.path.join(sys.base_prefix, "python.exe") if sys.platform == "win32"
              else os.path.join(sys.base_prefix, "bin", f"python{running}"))
    how = ""
    if missing:
        how = (f" Install into that Python: {python} -m pip install " + " ".join(f'"{m}"' for m in missing)
               + ", or set PYTHONPATH to a folder that holds "
               + ("them" if len(missing) > 1 else "it") + ", or use a portable build of the FMU "
               "(python build_fmus.py --portable), which carries its packages.")
    portable = (f"this FMU carries its packages for {', '.join(record['portable'])}, not for {tag}; "
                if record["portable"] else "")
    raise ImportError(f"this FMU needs, in the Python that runs it ({where}; {portable}sys.path: "
                      f"{os.pathsep.join(sys.path)}): " + "; ".join(problems) + "." + how)


__all__ = ["RESOURCES", "RECORD", "platform_tag", "read", "check"]
