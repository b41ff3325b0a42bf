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
4. puts the status shim (``status_shim.c``) in front of pythonfmu's Linux binary, so a
   rejected parameter returns fmi2Error instead of fmi2Fatal;
5. validates the result with ``fmpy.validation.validate_fmu``.
"""
from __future__ import annotations

import importlib
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from ..units import UNITS

PACKAGE_ROOT = Path(__file__).resolve().parents[1]   # src/boomfmi
SHIM_SOURCE = Path(__file__).with_name("status_shim.c")


class BuildError(RuntimeError):
    """An FMU could not be built or does not validate."""


def bundle_name(name: str) -> str:
    """The private package name under which FMU ``name`` carries its physics."""
    return f"boomfmi_{name}_lib"


def stage(fmu_dir: Path, staging: Path) -> Path:
    """Copy the FMU script and its private bundle into ``staging``; return the script."""
    name = fmu_dir.name
    script = fmu_dir / f"{name}_fmu.py"
    if not script.is_file():
        raise BuildError(f"{fmu_dir}: no script {script.name}")
    if f"from {bundle_name(name)}" not in script.read_text():
        raise BuildError(f"{script}: must import its physics from {bundle_name(name)}")
    staging.mkdir(parents=True, exist_ok=True)
    shutil.copy2(script, staging / script.name)
    bundle = staging / bundle_name(name)
    bundle.mkdir()
    (bundle / "__init__.py").write_text(
        f'"""The physics and model of the boomfmi {name} FMU: a private copy of boomfmi."""\n')
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(PACKAGE_ROOT / "physics", bundle / "physics", ignore=ignore)
    # the assembled model and its catalogue of effects; not the scipy reference solver
    shutil.copytree(PACKAGE_ROOT / "model", bundle / "model",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "reference.py"))
    shutil.copy2(PACKAGE_ROOT / "fmislave.py", bundle / "fmislave.py")
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


def _format(value) -> str:
    return f"{value:.16g}" if isinstance(value, float) else str(value)


def complete_model_description(xml: bytes, variables, default_step: float = 1e-3,
                               default_stop: float = 1.0) -> bytes:
    """Add units, bounds, output dependencies, initial unknowns and a default experiment
    to a pythonfmu modelDescription.xml, from the FMU class's ``variables`` table."""
    root = ET.fromstring(xml)
    spec = {v.name: v for v in variables}
    scalars = root.find("ModelVariables").findall("ScalarVariable")
    index = {sv.get("name"): i + 1 for i, sv in enumerate(scalars)}
    missing = set(spec) ^ set(index)
    if missing:
        raise BuildError(f"variables declared and registered differ: {sorted(missing)}")

    used_units = set()
    for sv in scalars:
        var = spec[sv.get("name")]
        if not var.description:
            raise BuildError(f"variable {var.name} has no description")
        type_node = sv.find(var.type)
        if var.type == "Real":
            if var.unit not in UNITS:
                raise BuildError(f"variable {var.name}: unit {var.unit!r} is not in boomfmi.units")
            type_node.set("unit", var.unit)
            used_units.add(var.unit)
        for bound in ("min", "max"):
            value = getattr(var, bound)
            if value is not None:
                type_node.set(bound, _format(float(value)))

    # UnitDefinitions come right after CoSimulation in the FMI 2.0 schema.
    units_node = ET.Element("UnitDefinitions")
    for unit in sorted(used_units):
        exponents, display = UNITS[unit]
        u = ET.SubElement(units_node, "Unit", name=unit)
        ET.SubElement(u, "BaseUnit", {k: str(v) for k, v in exponents.items()})
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
    if outputs:
        out_node = ET.SubElement(structure, "Outputs")
        for var in outputs:
            for dep in var.depends:
                if spec.get(dep) is None or spec[dep].causality != "input":
                    raise BuildError(f"output {var.name} depends on {dep!r}, which is not an input")
            deps = " ".join(str(index[d]) for d in var.depends)
            ET.SubElement(out_node, "Unknown", index=str(index[var.name]), dependencies=deps,
                          dependenciesKind=" ".join("dependent" for _ in var.depends))
        init_node = ET.SubElement(structure, "InitialUnknowns")
        for var in outputs:
            ET.SubElement(init_node, "Unknown", index=str(index[var.name]))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def compile_shim(out: Path) -> Path:
    """Compile the status shim with the FMI 2.0 headers that fmpy ships."""
    import fmpy
    include = Path(fmpy.__file__).parent / "c-code"
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise BuildError("no C compiler (cc or gcc) on PATH: needed for the FMUs' status shim")
    cmd = [cc, "-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-Werror", f"-I{include}",
           "-o", str(out), str(SHIM_SOURCE), "-ldl"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise BuildError(f"compiling {SHIM_SOURCE.name} failed:\n{proc.stderr}")
    return out


def _rewrite(fmu: Path, model_description: bytes, model_identifier: str, shim: Path) -> None:
    """Replace modelDescription.xml and put the shim in front of the Linux binary."""
    linux_binary = f"binaries/linux64/{model_identifier}.so"
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        names = src.namelist()
        if linux_binary not in names:
            raise BuildError(f"{fmu.name}: pythonfmu wrote no {linux_binary}")
        for name in names:
            if name == "modelDescription.xml":
                dst.writestr(name, model_description)
            elif name == linux_binary:
                dst.writestr(f"binaries/linux64/{model_identifier}_pythonfmu.so", src.read(name))
                dst.write(shim, linux_binary)
            else:
                dst.writestr(src.getinfo(name), src.read(name))
    tmp.replace(fmu)


def build_fmu(fmu_dir: Path, out_dir: Path) -> Path:
    """Build ``fmus/<name>`` into ``out_dir/<name>.fmu``; return its path."""
    from pythonfmu.builder import FmuBuilder, get_model_class

    fmu_dir = Path(fmu_dir).resolve()
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    name = fmu_dir.name
    target = out_dir / f"{name}.fmu"
    with tempfile.TemporaryDirectory(prefix=f"boomfmi_{name}_") as tmp:
        tmp = Path(tmp)
        script = stage(fmu_dir, tmp / "stage")
        bundle = tmp / "stage" / bundle_name(name)
        sys.path.insert(0, str(script.parent))
        try:
            FmuBuilder.build_FMU(script, dest=target, project_files=[bundle])
            cls = get_model_class(script)
        finally:
            sys.path.remove(str(script.parent))
            for mod in [m for m in sys.modules if m == script.stem or m.startswith(bundle_name(name))]:
                del sys.modules[mod]
            importlib.invalidate_caches()
        with zipfile.ZipFile(target) as z:
            xml = z.read("modelDescription.xml")
        model_identifier = ET.fromstring(xml).find("CoSimulation").get("modelIdentifier")
        if model_identifier != name:
            raise BuildError(f"{script.name}: modelName must be {name!r}, is {model_identifier!r}")
        xml = complete_model_description(xml, cls.variables)
        shim = compile_shim(tmp / "shim.so")
        _rewrite(target, xml, model_identifier, shim)
    validate(target)
    return target


def validate(fmu: Path) -> None:
    """Raise :class:`BuildError` unless fmpy's validator finds nothing to report."""
    from fmpy.validation import validate_fmu
    problems = validate_fmu(str(fmu))
    if problems:
        raise BuildError(f"{fmu.name} does not validate:\n  " + "\n  ".join(problems))
