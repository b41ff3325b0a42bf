"""Shared fixtures: the built FMUs (built once per session if build/fmus lacks them)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FMU_NAMES = ("valve", "cylinder", "boom_load", "force_estimator")


def _sources_newer_than(fmu: Path) -> bool:
    stamp = fmu.stat().st_mtime
    sources = [*ROOT.joinpath("src", "boomfmi").rglob("*.py"), *ROOT.joinpath("src", "boomfmi").rglob("*.c"),
               *ROOT.joinpath("fmus").rglob("*_fmu.py")]
    return any(s.stat().st_mtime > stamp for s in sources)


@pytest.fixture(scope="session")
def fmu_dir() -> Path:
    """Folder holding the built FMUs: $BOOMFMI_FMU_DIR, else build/fmus (rebuilt when stale)."""
    if "BOOMFMI_FMU_DIR" in os.environ:
        return Path(os.environ["BOOMFMI_FMU_DIR"])
    out = ROOT / "build" / "fmus"
    fmus = [out / f"{n}.fmu" for n in FMU_NAMES]
    if not all(f.is_file() for f in fmus) or any(_sources_newer_than(f) for f in fmus):
        subprocess.run([sys.executable, str(ROOT / "build_fmus.py")], check=True, cwd=ROOT)
    return out


@pytest.fixture(scope="session")
def fmu(fmu_dir):
    """Path of a built FMU by name: ``fmu("valve")``."""
    def path(name: str) -> Path:
        return fmu_dir / f"{name}.fmu"
    return path
