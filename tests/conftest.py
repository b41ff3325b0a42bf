"""Shared fixtures: the built FMUs (built once per session if build/fmus lacks them;
under pytest-xdist the workers take turns on a lock, so only the first one builds)."""
from __future__ import annotations

import contextlib
import fcntl
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FMU_NAMES = ("valve", "cylinder", "boom_load", "force_estimator", "hardware_bridge",
             "excavator_force_estimator")


def _sources_newer_than(fmu: Path) -> bool:
    stamp = fmu.stat().st_mtime
    sources = [*ROOT.joinpath("src", "boomfmi").rglob("*.py"), *ROOT.joinpath("src", "boomfmi").rglob("*.c"),
               *ROOT.joinpath("fmus").rglob("*_fmu.py")]
    return any(s.stat().st_mtime > stamp for s in sources)


@contextlib.contextmanager
def _build_lock():
    """One test process at a time builds into build/ (pytest-xdist runs several)."""
    lock = ROOT / "build" / ".test-build.lock"
    lock.parent.mkdir(exist_ok=True)
    with open(lock, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def fmu_dir() -> Path:
    """Folder holding the built FMUs: $BOOMFMI_FMU_DIR, else build/fmus (rebuilt when stale)."""
    if "BOOMFMI_FMU_DIR" in os.environ:
        return Path(os.environ["BOOMFMI_FMU_DIR"])
    out = ROOT / "build" / "fmus"
    fmus = [out / f"{n}.fmu" for n in FMU_NAMES]
    ssp = out.parent / "excavator_boom.ssp"
    with _build_lock():
        if (not all(f.is_file() for f in fmus) or any(_sources_newer_than(f) for f in fmus)
                or not ssp.is_file()
                or ROOT.joinpath("ssp", "SystemStructure.ssd").stat().st_mtime > ssp.stat().st_mtime):
            subprocess.run([sys.executable, str(ROOT / "build_fmus.py")], check=True, cwd=ROOT)
    return out


@pytest.fixture(scope="session")
def hybrid():
    """benchmarks/hybrid_rig.py, the simulator written apart from boomfmi's model, as a
    module (loaded once per process, as ``hybrid_rig``)."""
    import importlib.util
    if "hybrid_rig" not in sys.modules:
        spec = importlib.util.spec_from_file_location("hybrid_rig", ROOT / "benchmarks" / "hybrid_rig.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules["hybrid_rig"] = module
        spec.loader.exec_module(module)
    return sys.modules["hybrid_rig"]


@pytest.fixture(scope="session")
def fmu(fmu_dir):
    """Path of a built FMU by name: ``fmu("valve")``."""
    def path(name: str) -> Path:
        return fmu_dir / f"{name}.fmu"
    return path


@pytest.fixture(scope="session")
def ssp_path(fmu_dir) -> Path:
    """The packed boom system, build/excavator_boom.ssp (built with the FMUs)."""
    path = fmu_dir.parent / "excavator_boom.ssp"
    with _build_lock():
        if not path.is_file():
            subprocess.run([sys.executable, str(ROOT / "build_fmus.py")], check=True, cwd=ROOT)
    return path


def rewrite_ssp(src: Path, dst: Path, edit=None, drop=(), add=None) -> Path:
    """Copy an SSP, passing SystemStructure.ssd's text through ``edit``, leaving out the
    members in ``drop`` and adding ``add`` ({member: bytes})."""
    import zipfile
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            if item.filename in drop:
                continue
            data = zin.read(item.filename)
            if item.filename == "SystemStructure.ssd" and edit is not None:
                data = edit(data.decode()).encode()
            zout.writestr(item, data)
        for name, data in (add or {}).items():
            zout.writestr(name, data)
    return dst
