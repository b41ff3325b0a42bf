"""Build the FMI 3.0 versions of the boomfmi model FMUs with pythonfmu3.

The FMI 3.0 FMU of ``fmus/<name>`` is made from the same adapter and the same bundled
physics as the FMI 2.0 one; nothing of the model is written twice.  For each FMU this

1. stages the adapter and its private bundle as :func:`boomfmi.fmubuild.stage` does
   for FMI 2.0, under names of their own (``<name>_fmi3`` and
   ``boomfmi_<name>_fmi3_lib``, so that an FMI 2.0 and an FMI 3.0 copy of one FMU can
   run in one process), with ``FMI_VERSION = 3`` in the bundle's ``__init__``: that
   makes ``fmislave.BoomSlave`` a pythonfmu3 ``Fmi3Slave``.  pythonfmu3 finds a
   model's class by a ``class X(... Fmi3Slave ...):`` line in the script, so one is
   appended: the adapter's class with ``Fmi3Slave`` named as a base, nothing else;
2. builds the FMU with pythonfmu3;
3. completes ``modelDescription.xml`` from the class's variable table with
   :func:`boomfmi.fmubuild.complete_model_description` (units, min/max, output
   dependencies, initial unknowns, a default experiment), as for FMI 2.0;
4. puts a status shim in front of pythonfmu3's Linux binary (:data:`SHIM_TEMPLATE`,
   compiled against the FMI 3.0 headers that fmpy ships), and leaves out pythonfmu3's
   C++ ``sources/``, which would build a binary without the shim;
5. validates the result with ``fmpy.validation.validate_fmu``.

Why the shim: pythonfmu3 0.3.4 gives a Python slave no way to fail
``fmi3ExitInitializationMode`` (or a get/set) with ``fmi3Error``.  It ignores what
``exit_initialization_mode`` returns and what was logged; a Python exception becomes
``fmi3Fatal`` after pythonfmu3 has released the instance's Python object (a later call,
or ``fmi3FreeInstance``, then touches freed memory).  Only ``do_step`` can choose its
status (``Fmi3StepResult``).  So, as for FMI 2.0 (``status_shim.c``), the shim raises a
call's status to the worst status the slave logged during it, and turns ``fmi3Fatal``
into ``fmi3Error`` for that instance alone, which it then keeps away from pythonfmu3.

Also left by pythonfmu3: it never calls the slave's ``setup_experiment``, so the start
time of ``fmi3EnterInitializationMode`` does not reach the model (the model FMUs do not
use it).
"""
from __future__ import annotations

import importlib
import importlib.util
import re
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

from . import REQUIREMENTS_NAME, BuildError, bundle_name, compile_shim, complete_model_description, stage, validate

#: The FMUs built for FMI 3.0: every one of the FMI 2.0 set (build_fmus.FMU_NAMES).
FMI3_NAMES = ("valve", "cylinder", "boom_load", "force_estimator", "hardware_bridge", "linkage", "excavator_bridge",
              "excavator_force_estimator")
#: pythonfmu3's platform folder for Linux, and the name its library gets beside the shim.
PLATFORM = "x86_64-linux"
INNER_SUFFIX = "_pythonfmu3.so"
#: how pythonfmu3 (builder and binary alike) finds the model's class in the script
_FMI3_CLASS = re.compile(r"^class (\w+)\(([^)]*\bFmi3Slave(?:Base)?\b[^)]*)\)\s*:", re.M)


def bundle_name3(name: str) -> str:
    """The private package name under which FMU ``name``'s FMI 3.0 version carries its physics."""
    return f"boomfmi_{name}_fmi3_lib"


def module_name3(name: str) -> str:
    """The module name of FMU ``name``'s FMI 3.0 script."""
    return f"{name}_fmi3"


def stage3(fmu_dir: Path, staging: Path) -> Path:
    """Stage ``fmus/<name>`` for pythonfmu3 in ``staging``; return the script."""
    name = Path(fmu_dir).name
    script2 = stage(Path(fmu_dir), staging)
    bundle = staging / bundle_name3(name)
    (staging / bundle_name(name)).rename(bundle)
    with (bundle / "__init__.py").open("a") as f:
        f.write("\n#: read by fmislave: this copy targets FMI 3.0 (pythonfmu3)\nFMI_VERSION = 3\n")
    source = script2.read_text()
    script2.unlink()
    classes = re.findall(r"^class (\w+)\((?:BoomSlave|RigBridge)\):", source, flags=re.M)
    if len(classes) != 1:
        raise BuildError(f"{fmu_dir}: needs exactly one class deriving BoomSlave (or the bridges' RigBridge), "
                         f"found {classes}")
    cls = classes[0]
    source = source.replace(bundle_name(name), bundle_name3(name))
    source += (
        "\n\n# -- added by boomfmi.fmubuild.fmi3: pythonfmu3 finds the model's class by a line that\n"
        "# -- names Fmi3Slave; the class is the adapter above (whose BoomSlave already is one).\n"
        "from pythonfmu3 import Fmi3Slave  # noqa: E402\n\n\n"
        f"class {cls}Fmi3({cls}, Fmi3Slave):\n"
        f'    """{name} as an FMI 3.0 co-simulation FMU: the adapter {cls}, unchanged."""\n')
    found = _FMI3_CLASS.search(source)
    if found is None or found.group(1) != f"{cls}Fmi3":
        raise BuildError(f"{fmu_dir}: pythonfmu3 would take {found and found.group(1)!r} for the model's class")
    script = staging / f"{module_name3(name)}.py"
    script.write_text(source)
    return script


def _model_class(script: Path, name: str):
    """Import the staged script and return the class pythonfmu3 finds in it; forget the
    modules after."""
    sys.path.insert(0, str(script.parent))
    try:
        spec = importlib.util.spec_from_file_location(script.stem, script)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return getattr(module, _FMI3_CLASS.search(script.read_text()).group(1))
    finally:
        sys.path.remove(str(script.parent))
        _forget(name)


def _forget(name: str) -> None:
    """Drop the staged FMI 3.0 modules of FMU ``name`` from ``sys.modules``: the FMU
    must import its own copy when a host in this process loads it."""
    for mod in [m for m in sys.modules
                if m == module_name3(name) or m.startswith(bundle_name3(name))]:
        del sys.modules[mod]
    importlib.invalidate_caches()


# -- the status shim ----------------------------------------------------------------------------
SHIM_TEMPLATE = r"""/*
 * The entry library of a boomfmi FMI 3.0 FMU on Linux, generated by boomfmi.fmubuild.fmi3.
 *
 * pythonfmu3's library is renamed <id>_pythonfmu3.so beside this one; every FMI 3.0
 * function is forwarded to it, with two changes (see fmi3.py's docstring for why):
 *
 *  1. A call's status is raised to the worst status the slave logged during that call:
 *     a Python slave reports a bad parameter by logging it with status fmi3Error, and
 *     the call then returns fmi3Error with that message.
 *  2. After pythonfmu3 reports fmi3Fatal (an unexpected Python exception) the instance
 *     is dead: that call and every later one return fmi3Error without touching it, and
 *     fmi3FreeInstance does not hand pythonfmu3 an object it has already released.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

typedef struct {
    fmi3Instance inner;
    fmi3InstanceEnvironment host_env;
    fmi3LogMessageCallback host_log;
    fmi3Status worst;              /* worst status logged during the current call */
    int dead;
} Shim;

#define FMI3_FUNCTIONS(X) @FUNCTIONS@

static void *inner_lib = NULL;
static int live_instances = 0;
static struct {
#define DECLARE(fn) fn##TYPE *fn;
    FMI3_FUNCTIONS(DECLARE)
#undef DECLARE
} inner;

static int load_inner(void) {
    Dl_info info;
    char path[4096];
    const char *slash, *base, *dot;
    size_t dir_len, base_len;
    if (inner_lib) return 1;
    if (!dladdr((void *)&load_inner, &info) || !info.dli_fname) return 0;
    slash = strrchr(info.dli_fname, '/');
    dir_len = slash ? (size_t)(slash - info.dli_fname) + 1 : 0;
    base = slash ? slash + 1 : info.dli_fname;
    dot = strrchr(base, '.');
    base_len = dot ? (size_t)(dot - base) : strlen(base);
    if (dir_len + base_len + strlen("@INNER_SUFFIX@") + 1 > sizeof path) return 0;
    memcpy(path, info.dli_fname, dir_len);
    memcpy(path + dir_len, base, base_len);
    strcpy(path + dir_len + base_len, "@INNER_SUFFIX@");
    inner_lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!inner_lib) return 0;
#define LOOKUP(fn) inner.fn = (fn##TYPE *)dlsym(inner_lib, #fn); if (!inner.fn) return 0;
    FMI3_FUNCTIONS(LOOKUP)
#undef LOOKUP
    return 1;
}

/* When the host unloads this library, unload pythonfmu3's with it. */
__attribute__((destructor)) static void unload_inner(void) {
    if (inner_lib && live_instances == 0) {
        dlclose(inner_lib);
        inner_lib = NULL;
    }
}

static void shim_logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                        fmi3String message) {
    Shim *s = (Shim *)env;
    if (!s) return;
    if (status > s->worst) s->worst = status;
    if (s->host_log)
        s->host_log(s->host_env, status, category && *category ? category : "logAll",
                    message ? message : "");
}

static void host_log(Shim *s, fmi3Status status, const char *message) {
    if (s->host_log) s->host_log(s->host_env, status, "logStatusError", message);
}

static fmi3Status finish(Shim *s, fmi3Status st) {
    if (st == fmi3Fatal) {
        s->dead = 1;
        host_log(s, fmi3Error, "the FMU's Python code raised an exception (see the message above); "
                               "this instance cannot continue");
        return fmi3Error;
    }
    if (s->worst > st && s->worst <= fmi3Error) st = s->worst;
    return st;
}

#define GUARD(c)                                                                    \
    Shim *s = (Shim *)(c);                                                          \
    if (!s) return fmi3Error;                                                       \
    if (s->dead) {                                                                  \
        host_log(s, fmi3Error, "this instance failed earlier and cannot be used");   \
        return fmi3Error;                                                           \
    }                                                                               \
    s->worst = fmi3OK;

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    Shim *s = (Shim *)calloc(1, sizeof(Shim));
    (void)intermediateUpdate;      /* pythonfmu3 has no intermediate update */
    if (!s) return NULL;
    s->host_env = instanceEnvironment;
    s->host_log = logMessage;
    if (!load_inner()) {
        host_log(s, fmi3Error, "cannot load the FMU's pythonfmu3 library beside the shim");
        free(s);
        return NULL;
    }
    s->inner = inner.fmi3InstantiateCoSimulation(
        instanceName, instantiationToken, resourcePath, visible, loggingOn, eventModeUsed,
        earlyReturnAllowed, requiredIntermediateVariables, nRequiredIntermediateVariables,
        (fmi3InstanceEnvironment)s, shim_logger, NULL);
    if (!s->inner) {
        host_log(s, fmi3Error, "pythonfmu3 could not instantiate the model (see the message above)");
        free(s);
        return NULL;
    }
    live_instances++;
    return (fmi3Instance)s;
}

static fmi3Instance co_simulation_only(fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    if (log) log(env, fmi3Error, "logStatusError", "this FMU supports co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateModelExchange(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    return co_simulation_only(instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    return co_simulation_only(instanceEnvironment, logMessage);
}

void fmi3FreeInstance(fmi3Instance c) {
    Shim *s = (Shim *)c;
    if (!s) return;
    if (!s->dead) {
        /* a dead instance is left to leak: pythonfmu3 has already released its object */
        inner.fmi3FreeInstance(s->inner);
        --live_instances;
    }
    free(s);
}

@FORWARDERS@
"""

#: the functions the template writes by hand; every other one is a generated forwarder
_HAND_WRITTEN = {"fmi3GetVersion", "fmi3InstantiateCoSimulation", "fmi3InstantiateModelExchange",
                 "fmi3InstantiateScheduledExecution", "fmi3FreeInstance"}


def _fmi3_functions(header: str):
    """``(name, [(declaration, argument name), ...])`` of every function type in
    ``fmi3FunctionTypes.h``, in order."""
    text = re.sub(r"/\*.*?\*/", " ", header, flags=re.S)
    text = re.sub(r"//[^\n]*", " ", text)
    out = []
    for m in re.finditer(r"typedef\s+([\w\s\*]+?)\s*\b(fmi3\w+)TYPE\s*\(([^)]*)\)\s*;", text):
        ret, name, params = " ".join(m.group(1).split()), m.group(2), m.group(3).strip()
        args = []
        if params and params != "void":
            for p in params.split(","):
                p = " ".join(p.split())
                arg = re.search(r"(\w+)\s*(\[\s*\])?$", p)
                if arg is None:
                    raise BuildError(f"fmi3FunctionTypes.h: cannot read parameter {p!r} of {name}")
                args.append((p, arg.group(1)))
        out.append((name, ret, args))
    return out


def shim_source(header: str) -> str:
    """The C source of the FMI 3.0 status shim, with a forwarder for every function of
    the FMI 3.0 header ``header`` (the text of ``fmi3FunctionTypes.h``)."""
    functions = _fmi3_functions(header)
    names = [n for n, _, _ in functions]
    if len(names) < 70 or not _HAND_WRITTEN <= set(names):
        raise BuildError(f"fmi3FunctionTypes.h: found {len(names)} function types, not FMI 3.0's")
    forwarders = []
    for name, ret, args in functions:
        if name in _HAND_WRITTEN:
            continue
        if ret != "fmi3Status" or not args or args[0][0] != "fmi3Instance instance":
            raise BuildError(f"fmi3FunctionTypes.h: {name} is not fmi3Status {name}(fmi3Instance, ...)")
        decl = ", ".join(d for d, _ in args)
        call = ", ".join(["s->inner"] + [a for _, a in args[1:]])
        forwarders.append(f"{ret} {name}({decl}) {{\n    GUARD(instance);\n"
                          f"    return finish(s, inner.{name}({call}));\n}}\n")
    return (SHIM_TEMPLATE.replace("@FUNCTIONS@", " ".join(f"X({n})" for n in names))
            .replace("@INNER_SUFFIX@", INNER_SUFFIX)
            .replace("@FORWARDERS@", "\n".join(forwarders)))


def compile_shim3(out: Path) -> Path:
    """Generate the FMI 3.0 status shim from the FMI 3.0 headers that fmpy ships, and
    compile it (:func:`boomfmi.fmubuild.compile_shim`)."""
    import fmpy
    source = out.with_suffix(".c")
    source.write_text(shim_source((Path(fmpy.__file__).parent / "c-code" / "fmi3FunctionTypes.h").read_text()))
    return compile_shim(out, "linux64", source)


def _rewrite3(fmu: Path, model_description: bytes, model_identifier: str, shim: Path) -> None:
    """Replace modelDescription.xml, put the shim in front of the Linux binary and leave
    out ``sources/``."""
    linux_binary = f"binaries/{PLATFORM}/{model_identifier}.so"
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        names = src.namelist()
        if linux_binary not in names:
            raise BuildError(f"{fmu.name}: pythonfmu3 wrote no {linux_binary}")
        for name in names:
            if name.startswith("sources/"):
                continue
            if name == "modelDescription.xml":
                dst.writestr(name, model_description)
            elif name == linux_binary:
                dst.writestr(f"binaries/{PLATFORM}/{model_identifier}{INNER_SUFFIX}", src.read(name))
                dst.write(shim, linux_binary)
            else:
                dst.writestr(src.getinfo(name), src.read(name))
    tmp.replace(fmu)


def _describe(xml: bytes, cls) -> bytes:
    """The model's description, author and licence on the root, as the FMI 2.0 FMU has
    them (pythonfmu3 overwrites the class's with None)."""
    root = ET.fromstring(xml)
    for attr in ("description", "author", "license"):
        value = getattr(cls, attr, None)
        if isinstance(value, str) and value:
            root.set(attr, value)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def build_fmu3(fmu_dir: Path, out_dir: Path, shim: Path | None = None) -> Path:
    """Build ``fmus/<name>`` as FMI 3.0 into ``out_dir/<name>.fmu``; return its path.

    ``shim`` is a compiled shim to reuse (see :func:`compile_shim3`); by default one is
    compiled for this FMU.
    """
    from pythonfmu3.builder import FmuBuilder

    fmu_dir = Path(fmu_dir).resolve()
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    name = fmu_dir.name
    if name not in FMI3_NAMES:
        raise BuildError(f"{name}: no FMI 3.0 version (only {', '.join(FMI3_NAMES)})")
    with tempfile.TemporaryDirectory(prefix=f"boomfmi_{name}_fmi3_") as tmp:
        tmp = Path(tmp)
        script = stage3(fmu_dir, tmp / "stage")
        try:
            built = FmuBuilder.build_FMU(script, dest=tmp / "out",
                                         project_files=[tmp / "stage" / bundle_name3(name),
                                                        tmp / "stage" / REQUIREMENTS_NAME],
                                         canHandleVariableCommunicationStepSize=True)
        finally:
            _forget(name)
        cls = _model_class(script, name)
        with zipfile.ZipFile(built) as z:
            xml = z.read("modelDescription.xml")
        model_identifier = ET.fromstring(xml).find("CoSimulation").get("modelIdentifier")
        if model_identifier != name:
            raise BuildError(f"{script.name}: modelName must be {name!r}, is {model_identifier!r}")
        xml = complete_model_description(_describe(xml, cls), cls.variables)
        _rewrite3(built, xml, model_identifier, shim or compile_shim3(tmp / "shim3.so"))
        target = out_dir / f"{name}.fmu"
        shutil.move(str(built), target)
    validate(target)
    return target


__all__ = ["FMI3_NAMES", "PLATFORM", "INNER_SUFFIX", "bundle_name3", "module_name3", "stage3", "SHIM_TEMPLATE",
           "shim_source", "compile_shim3", "build_fmu3"]
