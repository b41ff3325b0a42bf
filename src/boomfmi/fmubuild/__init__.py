"""Build the boomfmi FMUs: pythonfmu, plus what pythonfmu 0.7.0 leaves out.

For each ``fmus/<name>/<name>_fmu.py`` this

1. stages the script beside a private copy of ``boomfmi.physics``, ``boomfmi.model``
   (the assembled model and the catalogue of effects, without the scipy reference
   solver) and ``boomfmi.fmislave`` in a package named ``boomfmi_<name>_lib``, which the script
   imports.  Each FMU thus carries its own physics under a name no other FMU and no
   host-installed ``boomfmi`` can shadow (pythonfmu issue #228);
2. builds the FMU with pythonfmu;
3. completes ``modelDescription.xml`` from the class's variable table: SI
   ``UnitDefinitions``, ``unit``/``min``/``max`` on every Real, ``Outputs`` with their
   declared direct dependencies, ``InitialUnknowns`` (pythonfmu issue #193) and a
   ``DefaultExperiment``;
4. puts the status shim (``status_shim.c``) in front of pythonfmu's binaries: on Linux
   always, on Windows where the build has mingw-w64 (``x86_64-w64-mingw32-gcc``).  The
   shim loads the Python runtime the FMU was built with (recorded in
   ``resources/boomfmi_runtime.txt``) in a host that has none, starts its interpreter
   (a wrong PYTHONHOME is fmi2Error, not a fatal exit), says why when it cannot, makes a
   rejected parameter return fmi2Error instead of fmi2Fatal and lets a plain C host
   exit cleanly; ``modelDescription.xml`` states the platforms in a
   ``VendorAnnotations`` tool entry;
5. validates the result with ``fmpy.validation.validate_fmu``.

No path of the build's venv or checkout goes into an FMU.  Each states the Python
version and packages it needs (``resources/boomfmi_requirements.txt``, checked by
``fmu_requirements.py`` before the script imports anything else); a portable build
(``build_fmu(..., portable=True)``, ``build_fmus.py --portable``) carries them too.
"""
from __future__ import annotations

import contextlib
import importlib
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from ..units import unit_definition, unit_problem

PACKAGE_ROOT = Path(__file__).resolve().parents[1]   # src/boomfmi
SHIM_SOURCE = Path(__file__).with_name("status_shim.c")
#: Checked in the FMU before anything else is imported: copied into each bundle
REQUIREMENTS_CHECK = Path(__file__).with_name("fmu_requirements.py")
#: resources/<this>: the Python version and packages an FMU needs, what it carries
REQUIREMENTS_NAME = "boomfmi_requirements.txt"
#: The packages beyond the standard library that an FMU's Python code imports
THIRD_PARTY = ("numpy",)


class BuildError(RuntimeError):
    """An FMU could not be built or does not validate."""


def bundle_name(name: str) -> str:
    """The private package name under which FMU ``name`` carries its physics."""
    return f"boomfmi_{name}_lib"


def requirements(portable: tuple[str, ...] = ()) -> str:
    """resources/boomfmi_requirements.txt (read by ``fmu_requirements.py`` in the FMU): this
    build's Python version, each package of :data:`THIRD_PARTY` as a range around the
    version built with (same major version, at least its minor), and the platforms whose
    packages the FMU carries."""
    lines = ["# What this FMU's Python code needs, checked at fmi2Instantiate (boomfmi.fmubuild).",
             "# A portable FMU carries these packages for each platform listed under portable=,",
             "# in resources/python/<platform>/; elsewhere the Python that runs the FMU must have them.",
             f"python={sys.version_info.major}.{sys.version_info.minor}"]
    for name in THIRD_PARTY:
        version = importlib.import_module(name).__version__
        major, minor = (int(x) for x in version.split(".")[:2])
        lines.append(f"require={name}>={major}.{minor},<{major + 1} built={version}")
    lines.append(f"portable={' '.join(portable)}")
    return "\n".join(lines) + "\n"


def _import_bundle_first(source: str, bundle: str) -> str:
    """The script with ``import <bundle>`` before its first import (after the docstring
    and any ``from __future__`` line), so that the FMU's requirements are checked (and a
    portable FMU's packages put on sys.path) before anything else is imported."""
    import ast
    body = ast.parse(source).body
    first = next((node for node in body if isinstance(node, (ast.Import, ast.ImportFrom))
                  and not (isinstance(node, ast.ImportFrom) and node.module == "__future__")), None)
    line = (first.lineno if first is not None else len(source.splitlines()) + 1) - 1
    lines = source.splitlines(keepends=True)
    return "".join(lines[:line] + [f"import {bundle}  # first: checks the FMU's requirements (added by boomfmi.fmubuild)\n"]
                   + lines[line:])


def stage(fmu_dir: Path, staging: Path, portable: tuple[str, ...] = ()) -> Path:
    """Copy the FMU script (importing its bundle first) and its private bundle into
    ``staging``, with ``staging/boomfmi_requirements.txt`` (:func:`requirements`); return
    the script."""
    name = fmu_dir.name
    script = fmu_dir / f"{name}_fmu.py"
    if not script.is_file():
        raise BuildError(f"{fmu_dir}: no script {script.name}")
    if f"from {bundle_name(name)}" not in script.read_text():
        raise BuildError(f"{script}: must import its physics from {bundle_name(name)}")
    staging.mkdir(parents=True, exist_ok=True)
    (staging / script.name).write_text(_import_bundle_first(script.read_text(), bundle_name(name)))
    bundle = staging / bundle_name(name)
    bundle.mkdir()
    (bundle / "__init__.py").write_text(
        f'"""The physics and model of the boomfmi {name} FMU: a private copy of boomfmi."""\n'
        "from ._requirements import check as _check\n\n"
        "_check()       # resources/boomfmi_requirements.txt, before numpy is imported\n")
    shutil.copy2(REQUIREMENTS_CHECK, bundle / "_requirements.py")
    (staging / REQUIREMENTS_NAME).write_text(requirements(portable))
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(PACKAGE_ROOT / "physics", bundle / "physics", ignore=ignore)
    # the assembled model and its catalogue of effects; not the scipy reference solver
    shutil.copytree(PACKAGE_ROOT / "model", bundle / "model",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "reference.py"))
    shutil.copy2(PACKAGE_ROOT / "fmislave.py", bundle / "fmislave.py")
    bundle_plugins(name, bundle)
    # further boomfmi modules an FMU needs, one per line in fmus/<name>/bundle.txt
    extra = fmu_dir / "bundle.txt"
    if extra.is_file():
        for line in extra.read_text().splitlines():
            module = line.split("#")[0].strip()
            if not module:
                continue
            source = PACKAGE_ROOT / module
            if source.is_dir():
                shutil.copytree(source, bundle / module, ignore=ignore)
            elif source.is_file():
                shutil.copy2(source, bundle / module)
            else:
                raise BuildError(f"{extra}: no module {module} in {PACKAGE_ROOT}")
    return staging / script.name


def bundle_plugins(name: str, bundle: Path) -> tuple[str, ...]:
    """Put the effect plug-ins loaded here (``model.catalogue.load_plugins``: installed
    packages, ``$BOOMFMI_EFFECTS``) that have an effect in FMU ``name`` into its
    ``bundle``, as ``<bundle>/effect_plugins/<module>``; the bundled catalogue loads them
    from there, never from the host's site-packages.  Returns their module names."""
    from ..model.catalogue import BUNDLED_PLUGINS, EFFECTS, load_plugins
    modules = []
    for plugin in load_plugins():
        if not any(EFFECTS[e].fmu == name for e in plugin.effects):
            continue
        source = Path(plugin.source)
        if not plugin.source or not source.exists():
            raise BuildError(f"effect plug-in {plugin.name}: no source to bundle into the {name} FMU "
                             f"({plugin.source or 'none known'})")
        module = source.stem if source.is_file() else source.name
        if module in modules:
            raise BuildError(f"effect plug-in {plugin.name}: a second plug-in module named {module!r} in the {name} FMU")
        modules.append(module)
        target = bundle / BUNDLED_PLUGINS
        target.mkdir(exist_ok=True)
        if source.is_file():
            shutil.copy2(source, target / f"{module}.py")
        else:
            shutil.copytree(source, target / module, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    if modules:
        (bundle / BUNDLED_PLUGINS / "__init__.py").write_text(
            '"""The effect plug-ins this FMU was built with (boomfmi.fmubuild): its catalogue loads them."""\n'
            f"MODULES = {tuple(modules)!r}\n")
    return tuple(modules)


def _format(value) -> str:
    return f"{value:.16g}" if isinstance(value, float) else str(value)


#: FMI 3.0's element for each type of :class:`boomfmi.fmislave.Variable`
FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}


def complete_model_description(xml: bytes, variables, default_step: float = 1e-3,
                               default_stop: float = 1.0) -> bytes:
    """Add units, bounds, output dependencies, initial unknowns and a default experiment
    to a pythonfmu (FMI 2.0) or pythonfmu3 (FMI 3.0) modelDescription.xml, from the FMU
    class's ``variables`` table."""
    root = ET.fromstring(xml)
    fmi3 = root.get("fmiVersion", "").startswith("3.")
    spec = {v.name: v for v in variables}
    used_units = set()
    if fmi3:        # a typed element per variable, referred to by its value reference
        nodes = list(root.find("ModelVariables"))
        for node in [n for n in nodes if n.get("causality") == "independent"]:
            nodes.remove(node)          # time, which fmislave registers for FMI 3.0
            node.set("unit", "s")
            used_units.add("s")
        ref = {node.get("name"): node.get("valueReference") for node in nodes}
    else:           # a ScalarVariable per variable, referred to by its index from 1
        nodes = root.find("ModelVariables").findall("ScalarVariable")
        ref = {node.get("name"): str(i + 1) for i, node in enumerate(nodes)}
    missing = set(spec) ^ set(ref)
    if missing:
        raise BuildError(f"variables declared and registered differ: {sorted(missing)}")

    for node in nodes:
        var = spec[node.get("name")]
        if not var.description:
            raise BuildError(f"variable {var.name} has no description")
        if fmi3:
            if node.tag != FMI3_TYPES[var.type]:
                raise BuildError(f"variable {var.name}: registered as {node.tag}, declared {var.type}")
            type_node = node
        else:
            type_node = node.find(var.type)
        if var.type == "Real":
            problem = unit_problem(var.unit)
            if problem:
                raise BuildError(f"variable {var.name}: {problem}")
            type_node.set("unit", var.unit)
            used_units.add(var.unit)
        for bound in ("min", "max"):
            value = getattr(var, bound)
            if value is not None:
                type_node.set(bound, _format(float(value) if var.type == "Real" else int(value)))
        if var.min is not None and var.max is not None and not var.min <= var.max:
            raise BuildError(f"variable {var.name}: min {var.min!r} > max {var.max!r}")

    # UnitDefinitions come right after CoSimulation in the FMI 2.0 and 3.0 schemas.
    units_node = ET.Element("UnitDefinitions")
    for unit in sorted(used_units):
        exponents, factor, display = unit_definition(unit)     # from pint's SI dimensionality
        u = ET.SubElement(units_node, "Unit", name=unit)
        base = {k: str(v) for k, v in exponents.items()}
        if factor != 1.0:
            base["factor"] = _format(factor)
        ET.SubElement(u, "BaseUnit", base)
        for dname, (factor, offset) in display.items():
            attrs = {"name": dname, "factor": _format(factor)}
            if offset:
                attrs["offset"] = _format(offset)
            ET.SubElement(u, "DisplayUnit", attrs)
    children = list(root)
    cosim = root.find("CoSimulation")
    root.insert(children.index(cosim) + 1, units_node)

    if root.find("DefaultExperiment") is None:
        experiment = ET.Element("DefaultExperiment", startTime="0", stopTime=_format(default_stop),
                                stepSize=_format(default_step))
        root.insert(list(root).index(root.find("ModelVariables")), experiment)

    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    outputs = [v for v in variables if v.causality == "output"]
    for var in outputs:
        for dep in var.depends:
            if spec.get(dep) is None or spec[dep].causality != "input":
                raise BuildError(f"output {var.name} depends on {dep!r}, which is not an input")
    if outputs and fmi3:
        for var in outputs:
            ET.SubElement(structure, "Output", valueReference=ref[var.name],
                          dependencies=" ".join(ref[d] for d in var.depends),
                          dependenciesKind=" ".join("dependent" for _ in var.depends))
        for var in outputs:
            ET.SubElement(structure, "InitialUnknown", valueReference=ref[var.name])
    elif outputs:
        out_node = ET.SubElement(structure, "Outputs")
        for var in outputs:
            ET.SubElement(out_node, "Unknown", index=ref[var.name],
                          dependencies=" ".join(ref[d] for d in var.depends),
                          dependenciesKind=" ".join("dependent" for _ in var.depends))
        init_node = ET.SubElement(structure, "InitialUnknowns")
        for var in outputs:
            ET.SubElement(init_node, "Unknown", index=ref[var.name])
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


#: The FMI 2.0 platforms a boomfmi FMU has binaries for: pythonfmu 0.7.0 ships these two
#: and nothing else (no darwin64, no aarch64, no 32-bit).  For each: the compilers that
#: build its shim (the first found on PATH), the binary's suffix and the extra flags.
SHIM_PLATFORMS = {
    "linux64": (("cc", "gcc"), ".so", ["-fPIC"], ["-ldl"]),
    "win64": (("x86_64-w64-mingw32-gcc",), ".dll", [], ["-static-libgcc", "-ladvapi32"]),
}
#: Where the shim reads the Python runtime the FMU was built with.
RUNTIME_RECORD = "resources/boomfmi_runtime.txt"
#: The environment variable that names another libpython / python3XY.dll.
LIBPYTHON_ENV = "BOOMFMI_LIBPYTHON"
_said_no_win64 = False


def shim_compiler(platform: str) -> str | None:
    """The compiler on PATH that builds the shim for ``platform``, or None."""
    for name in SHIM_PLATFORMS[platform][0]:
        found = shutil.which(name)
        if found:
            return found
    return None


def compile_shim(out: Path, platform: str = "linux64", source: Path = SHIM_SOURCE) -> Path:
    """Compile the status shim (``source``: FMI 2.0's by default) for ``platform`` with
    the FMI headers that fmpy ships."""
    import fmpy
    include = Path(fmpy.__file__).parent / "c-code"
    cc = shim_compiler(platform)
    if cc is None:
        names = " or ".join(SHIM_PLATFORMS[platform][0])
        raise BuildError(f"no C compiler ({names}) on PATH: needed for the FMUs' {platform} status shim")
    _, _, flags, libs = SHIM_PLATFORMS[platform]
    cmd = [cc, "-shared", *flags, "-O2", "-Wall", "-Wextra", "-Werror", f"-I{include}",
           "-o", str(out), str(source), *libs]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise BuildError(f"compiling {Path(source).name} for {platform} failed:\n{proc.stderr}")
    return out


def compile_shims(folder: Path) -> dict[str, Path]:
    """Every shim this machine can build: linux64 always (a C compiler is required),
    win64 where mingw-w64 is installed; without it the build says so, once."""
    global _said_no_win64
    shims = {"linux64": compile_shim(Path(folder) / "shim.so", "linux64")}
    if shim_compiler("win64"):
        shims["win64"] = compile_shim(Path(folder) / "shim.dll", "win64")
    elif not _said_no_win64:
        _said_no_win64 = True
        print("boomfmi.fmubuild: x86_64-w64-mingw32-gcc is not installed, so the FMUs ship "
              "linux64 with the status shim and win64 with pythonfmu's own binary only "
              "(it loads in a Python host alone); install mingw-w64 for the win64 shim",
              file=sys.stderr)
    return shims


def _platform_tag() -> str:
    return "win64" if sys.platform == "win32" else "linux64"


def runtime_record() -> str:
    """resources/boomfmi_runtime.txt: the Python runtime this build runs in, which the
    shim loads in a host that has no Python of its own (see status_shim.c)."""
    import numpy
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    tag = _platform_tag()
    paths = []
    for entry in (sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"],
                  str(Path(numpy.__file__).resolve().parents[1])):
        if entry not in paths:
            paths.append(entry)
    if tag == "win64":
        libpython = Path(sys.base_prefix) / f"python{sys.version_info.major}{sys.version_info.minor}.dll"
        soname = libpython.name
    else:
        soname = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY") or ""
        libpython = Path(sysconfig.get_config_var("LIBDIR") or sys.base_prefix) / soname
    if not sysconfig.get_config_var("Py_ENABLE_SHARED") and tag == "linux64":
        print(f"boomfmi.fmubuild: this Python has no shared libpython: in a host without Python "
              f"the FMUs need {LIBPYTHON_ENV} to name one", file=sys.stderr)
    lines = [
        "# The Python runtime this FMU was built with (boomfmi.fmubuild).  In a host that has",
        "# no Python of its own the FMU's binary loads <platform>.libpython (else <platform>.soname",
        f"# from the loader's search path; ${LIBPYTHON_ENV} overrides both) and starts it with",
        "# PYTHONHOME=<platform>.home (only for the recorded libpython, and unless PYTHONHOME is",
        "# set).  No site-packages of the build is recorded: the packages the FMU needs are in",
        f"# {REQUIREMENTS_NAME}, and a portable build carries them (resources/python/<platform>/).",
        f"version={version}",
        f"{tag}.libpython={libpython}",
        f"{tag}.soname={soname}",
        f"{tag}.home={sys.base_prefix}",
    ]
    return "\n".join(lines) + "\n"


#: pip's --platform of each FMI platform, for a portable build's packages of another platform
WHEEL_PLATFORMS = {"linux64": "manylinux2014_x86_64", "win64": "win_amd64"}
#: Where a portable build keeps the wheels it downloads ($BOOMFMI_WHEELS overrides)
WHEEL_CACHE = Path.home() / ".cache" / "boomfmi" / "wheels"


def _carried(relative: Path) -> bool:
    """Whether a portable FMU carries this file of a package (not its tests or caches)."""
    return not ({"tests", "__pycache__"} & set(relative.parts)) and relative.suffix != ".pyc"


def _wheel(name: str, version: str, platform: str) -> Path:
    """The CPython wheel of ``name==version`` for ``platform``, downloaded once by pip."""
    cache = Path(os.environ.get("BOOMFMI_WHEELS", WHEEL_CACHE))
    py = f"{sys.version_info.major}{sys.version_info.minor}"
    pattern = f"{name}-{version}-cp{py}-*{WHEEL_PLATFORMS[platform].split('_', 1)[-1]}.whl"
    found = sorted(cache.glob(pattern))
    if not found:
        cmd = [sys.executable, "-m", "pip", "download", f"{name}=={version}", "--only-binary", ":all:",
               "--no-deps", "--platform", WHEEL_PLATFORMS[platform], "--python-version", py,
               "--implementation", "cp", "-d", str(cache)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        found = sorted(cache.glob(pattern))
        if proc.returncode != 0 or not found:
            raise BuildError(f"--portable: no {name} {version} wheel for {platform} ({pattern} in {cache}); "
                             f"{' '.join(cmd)} said:\n{(proc.stderr or proc.stdout).strip()[-1500:]}")
    return found[-1]


def portable_packages(platform: str, folder: Path) -> Path:
    """The packages of :data:`THIRD_PARTY` for ``platform``, laid out as a site-packages in
    ``folder``: this build's own where it runs on that platform, else the wheel of the
    same version (:func:`_wheel`).  Tests and caches are left out."""
    import platform as host
    folder.mkdir(parents=True, exist_ok=True)
    for name in THIRD_PARTY:
        module = importlib.import_module(name)
        version = module.__version__
        if platform == _platform_tag() and host.machine().lower() in ("x86_64", "amd64"):
            package = Path(module.__file__).resolve().parent
            site = package.parent
            for item in [package, site / f"{name}.libs", *site.glob(f"{name}-{version}.dist-info")]:
                if not item.is_dir():
                    continue
                for file in item.rglob("*"):
                    relative = file.relative_to(site)
                    if file.is_file() and _carried(relative):
                        (folder / relative).parent.mkdir(parents=True, exist_ok=True)
                        shutil.copy2(file, folder / relative)
        else:
            with zipfile.ZipFile(_wheel(name, version, platform)) as wheel:
                for member in wheel.namelist():
                    if not member.endswith("/") and _carried(Path(member)):
                        wheel.extract(member, folder)
    return folder


def _platform_notes(shims: dict[str, Path], portable=()) -> dict[str, str]:
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    dll = f"python{sys.version_info.major}{sys.version_info.minor}.dll"
    built_here = _platform_tag()
    anywhere = "runs in any FMI 2.0 host: in a Python host it uses that Python; in a host without Python it loads"
    where = {"linux64": f"libpython{version}", "win64": dll}
    notes = {}
    for platform, os_name, library in (("linux64", "x86-64 Linux (glibc)", "binary"),
                                       ("win64", "64-bit Windows", "DLL")):
        if platform not in shims:
            continue
        if platform == built_here:
            found = (f"the Python {version} this FMU was built with, as {RUNTIME_RECORD} records it, "
                     f"else {where[platform]} from the system's library search")
        else:
            found = (f"Python {version}: the {dll} the Python installer registered (PEP 514), "
                     f"else {dll} on PATH")
        packages = ", ".join(THIRD_PARTY)
        needs = (f"{packages} is inside the FMU (resources/python/{platform}/): only a CPython {version} is needed"
                 if platform in portable else
                 f"that Python must have {packages} as resources/{REQUIREMENTS_NAME} states (checked at "
                 f"fmi2Instantiate, which names what is missing)")
        notes[platform] = (f"{os_name}, status shim in front of pythonfmu's {library}; {anywhere} "
                           f"${LIBPYTHON_ENV}, else {found}; {needs}")
    if "win64" in shims and built_here != "win64":
        notes["win64"] += " (not run on Windows by boomfmi's tests)"
    if "win64" not in shims:
        notes["win64"] = ("64-bit Windows, pythonfmu's own DLL without the status shim (this build had "
                          "no mingw-w64): it loads only in a Python host whose folder holds python3.dll")
    return notes


def platform_annotation(xml: bytes, model_identifier: str, shims: dict[str, Path], portable=()) -> bytes:
    """State in an FMI 2.0 modelDescription.xml (``VendorAnnotations``, tool ``boomfmi``)
    the platforms the FMU's binaries run on, and those it has none for."""
    root = ET.fromstring(xml)
    if not root.get("fmiVersion", "").startswith("2."):
        return xml
    vendor = root.find("VendorAnnotations")
    if vendor is None:
        vendor = ET.Element("VendorAnnotations")
        # after DefaultExperiment, before ModelVariables (the FMI 2.0 schema's order)
        root.insert(list(root).index(root.find("ModelVariables")), vendor)
    for tool in vendor.findall("Tool"):
        if tool.get("name") == "boomfmi":
            vendor.remove(tool)
    tool = ET.SubElement(vendor, "Tool", name="boomfmi")
    platforms = ET.SubElement(tool, "Platforms")
    for name, note in _platform_notes(shims, portable).items():
        suffix = SHIM_PLATFORMS[name][1]
        ET.SubElement(platforms, "Platform", name=name, binary=f"binaries/{name}/{model_identifier}{suffix}",
                      shim="true" if name in shims else "false", description=note)
    ET.SubElement(platforms, "Unsupported", platforms="darwin64 aarch64 linux32 win32",
                  description="no binaries: pythonfmu 0.7.0 ships none for these platforms")
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _rewrite(fmu: Path, model_description: bytes, model_identifier: str, shim,
             win64_shim: Path | None = None, packages: dict[str, Path] | None = None) -> None:
    """Replace modelDescription.xml (stating the platforms), put the shims in front of
    pythonfmu's binaries and record the build's Python runtime.  ``shim`` is the Linux
    shim, or a ``{platform: shim}`` mapping as :func:`compile_shims` returns.  A portable
    build's ``packages`` ({platform: folder}, :func:`portable_packages`) go to
    ``resources/python/<platform>/``."""
    shims = dict(shim) if isinstance(shim, dict) else {"linux64": Path(shim)}
    if win64_shim is not None:
        shims["win64"] = Path(win64_shim)
    binaries = {f"binaries/{p}/{model_identifier}{SHIM_PLATFORMS[p][1]}": p for p in shims}
    model_description = platform_annotation(model_description, model_identifier, shims, tuple(packages or ()))
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        names = src.namelist()
        for binary in binaries:
            if binary not in names:
                raise BuildError(f"{fmu.name}: pythonfmu wrote no {binary}")
        for name in names:
            if name == "modelDescription.xml":
                dst.writestr(name, model_description)
            elif name in binaries:
                platform = binaries[name]
                suffix = SHIM_PLATFORMS[platform][1]
                dst.writestr(f"binaries/{platform}/{model_identifier}_pythonfmu{suffix}", src.read(name))
                dst.write(shims[platform], name)
            elif name == RUNTIME_RECORD:
                continue
            else:
                dst.writestr(src.getinfo(name), src.read(name))
        dst.writestr(RUNTIME_RECORD, runtime_record())
        for platform, folder in (packages or {}).items():
            for file in sorted(folder.rglob("*")):
                if file.is_file():
                    dst.write(file, f"resources/python/{platform}/{file.relative_to(folder).as_posix()}")
    tmp.replace(fmu)


@contextlib.contextmanager
def _installed_pythonfmu():
    """Within: ``import pythonfmu`` is the installed pythonfmu; yields its ``FmuBuilder``
    and ``get_model_class``.

    An FMU made by pythonfmu carries a copy of the ``pythonfmu`` package in its
    ``resources/``, and pythonfmu's C wrapper puts that folder first on ``sys.path`` when
    the FMU is instantiated in this process (fmpy does so).  Imported after that, the
    builder would be the FMU's copy, which has no binaries to pack (the build failed
    with "pythonfmu wrote no binaries/linux64/NAME.so").  Build with the installed one,
    then leave the FMU's modules as they were for the FMU still running."""
    from importlib.metadata import PackageNotFoundError, distribution
    try:
        home = Path(distribution("pythonfmu").locate_file("pythonfmu")).resolve()
    except PackageNotFoundError:
        raise BuildError("pythonfmu is not installed: pip install 'pythonfmu>=0.7,<0.8'") from None
    loaded = sys.modules.get("pythonfmu")
    if loaded is None or Path(loaded.__file__).resolve().parent == home:
        from pythonfmu.builder import FmuBuilder, get_model_class
        yield FmuBuilder, get_model_class
        return

    def ours(m):
        return m == "pythonfmu" or m.startswith("pythonfmu.")
    theirs = {m: sys.modules.pop(m) for m in list(sys.modules) if ours(m)}
    sys.path.insert(0, str(home.parent))
    try:
        from pythonfmu.builder import FmuBuilder, get_model_class
        yield FmuBuilder, get_model_class
    finally:
        sys.path.remove(str(home.parent))
        for m in [m for m in sys.modules if ours(m)]:
            del sys.modules[m]
        sys.modules.update(theirs)


def build_fmu(fmu_dir: Path, out_dir: Path, portable: bool | tuple[str, ...] = False) -> Path:
    """Build ``fmus/<name>`` into ``out_dir/<name>.fmu``; return its path.

    Lean by default: the FMU states the Python version and packages it needs
    (resources/boomfmi_requirements.txt) and names what is missing at fmi2Instantiate.
    ``portable`` also puts those packages inside, for each platform it has binaries for
    (or for the platforms it names), so that the host needs only a CPython runtime of
    the build's version."""
    fmu_dir = Path(fmu_dir).resolve()
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    name = fmu_dir.name
    target = out_dir / f"{name}.fmu"
    with tempfile.TemporaryDirectory(prefix=f"boomfmi_{name}_") as tmp:
        tmp = Path(tmp)
        platforms = tuple(SHIM_PLATFORMS) if portable is True else tuple(portable or ())
        script = stage(fmu_dir, tmp / "stage", platforms)
        bundle = tmp / "stage" / bundle_name(name)
        # laid out as in the FMU's resources/, where the staged script's check looks for them
        packages = {p: portable_packages(p, tmp / "stage" / "python" / p) for p in platforms}
        def staged(m):
            return m == script.stem or m.startswith(bundle_name(name))
        # an FMU of this name running in this process has its own modules of these names
        running = {m: sys.modules.pop(m) for m in list(sys.modules) if staged(m)}
        sys.path.insert(0, str(script.parent))
        try:
            with _installed_pythonfmu() as (FmuBuilder, get_model_class):
                FmuBuilder.build_FMU(script, dest=target, project_files=[bundle, script.parent / REQUIREMENTS_NAME])
                cls = get_model_class(script)
        finally:
            sys.path[:] = [p for p in sys.path if not p.startswith(str(script.parent))]
            for mod in [m for m in sys.modules if staged(m)]:
                del sys.modules[mod]
            sys.modules.update(running)
            importlib.invalidate_caches()
        with zipfile.ZipFile(target) as z:
            xml = z.read("modelDescription.xml")
        model_identifier = ET.fromstring(xml).find("CoSimulation").get("modelIdentifier")
        if model_identifier != name:
            raise BuildError(f"{script.name}: modelName must be {name!r}, is {model_identifier!r}")
        xml = complete_model_description(xml, cls.variables)
        _rewrite(target, xml, model_identifier, compile_shims(tmp), packages=packages)
    validate(target)
    return target


def validate(fmu: Path) -> None:
    """Raise :class:`BuildError` unless fmpy's validator finds nothing to report."""
    from fmpy.validation import validate_fmu
    problems = validate_fmu(str(fmu))
    if problems:
        raise BuildError(f"{fmu.name} does not validate:\n  " + "\n  ".join(problems))

__all__ = [
    "PACKAGE_ROOT", "SHIM_SOURCE", "REQUIREMENTS_CHECK", "REQUIREMENTS_NAME", "THIRD_PARTY",
    "BuildError", "bundle_name", "requirements", "stage", "bundle_plugins", "FMI3_TYPES",
    "complete_model_description", "SHIM_PLATFORMS", "RUNTIME_RECORD", "LIBPYTHON_ENV", "shim_compiler",
    "compile_shim", "compile_shims", "runtime_record", "WHEEL_PLATFORMS", "WHEEL_CACHE",
    "portable_packages", "platform_annotation", "build_fmu", "validate",
]
