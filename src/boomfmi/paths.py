"""Where the built FMUs and SSPs and the FMUs' reference results are, from any working
directory: every command's default FMU, SSP or references folder comes from here.

The build folder is ``$BOOMFMI_BUILD`` where that is set, else ``build/`` of the
checkout this package runs from (``src/boomfmi/`` two folders down: an editable
install, or ``PYTHONPATH=src``).  The references folder is the checkout's ``fmus/``.
A default that does not exist is refused by :func:`default_file`, naming where it
looked and how to build it.
"""
from __future__ import annotations

import os
from pathlib import Path

#: The environment variable naming the build folder (``fmus/*.fmu``, ``*.ssp``).
BUILD_ENV = "BOOMFMI_BUILD"


def checkout() -> Path:
    """The checkout this package runs from (``src/boomfmi/`` lies two folders below it)."""
    return Path(__file__).resolve().parents[2]


def build_dir() -> Path:
    """``$BOOMFMI_BUILD`` where set, else the checkout's ``build/``."""
    env = os.environ.get(BUILD_ENV, "").strip()
    return Path(env).expanduser().resolve() if env else checkout() / "build"


def built(relative: str) -> Path:
    """A built file's default place, e.g. ``built("fmus/excavator_bridge.fmu")``:
    absolute, whatever the working directory."""
    return build_dir() / relative


def references_dir() -> Path:
    """The FMUs' reference inputs and results (``<name>/<name>_in.csv``, ``_ref.csv``)."""
    return checkout() / "fmus"


def default_file(relative: str, option: str) -> Path:
    """:func:`built` ``(relative)`` where it is a file; else FileNotFoundError naming where
    it looked, how to build it and the ``option`` that names another file."""
    path = built(relative)
    if path.is_file():
        return path
    name = Path(relative).stem
    how = (f"python build_fmus.py {name}" if relative.startswith("fmus/") else "python build_fmus.py")
    raise FileNotFoundError(
        f"{path}: no such {'FMU' if path.suffix == '.fmu' else 'file'} (the default; looked in "
        f"{'$' + BUILD_ENV if os.environ.get(BUILD_ENV, '').strip() else 'the checkout'}'s build folder "
        f"{build_dir()}): build it with `{how}` in {checkout()}, set ${BUILD_ENV} to the folder holding "
        f"it, or give {option}")


__all__ = ["BUILD_ENV", "checkout", "build_dir", "built", "references_dir", "default_file"]
