#!/usr/bin/env python3
"""FMUs that travel (issue 37): each FMU copied to a fresh folder and run by a minimal C
FMI 2.0 host that this script compiles with the system's C compiler, under ``env -i``
(PATH=/usr/bin:/bin, no PYTHONPATH, no venv), as on a machine that never saw the build.

    python benchmarks/fmu_travel.py [--fmus build/fmus] [--runs 20] [--reloads 10] [--valgrind]

Prints, per FMU: its size, the exit codes of ``--runs`` runs of the host (load,
instantiate, 10 steps, free, unload), one run that loads, runs, frees and unloads the
same FMU ``--reloads`` times in one process, and with ``--valgrind`` valgrind's summary of
one run.  The tests (tests/test_travel.py) use the host from here on a few FMUs.
"""
from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

#: The host: argv = unpacked FMU folder, model identifier, GUID, steps, loads, "vr=value,..."
#: (or -), "vr,vr,..." to print after the last step.  Each load: dlopen, instantiate,
#: setup, initialise, set, steps of 1 ms, get, terminate, free, dlclose.  A NULL from
#: fmi2Instantiate is reported (with what the FMU logged) and the host goes on to unload;
#: the exit status is 0 unless the host itself could not run.
HOST_C = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    char text[8192];
    va_list ap;
    (void)env;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message, ap);
    va_end(ap);
    printf("log status=%d instance=%s category=%s: %s\n", (int)status, name ? name : "",
           category ? category : "", text);
    fflush(stdout);
}

#define GET(fn) fn##TYPE *fn = (fn##TYPE *)dlsym(lib, #fn); if (!fn) { printf("no %s\n", #fn); return 2; }

int main(int argc, char **argv) {
    char path[4096], uri[4200];
    int steps, loads, load;
    if (argc != 8) { fprintf(stderr, "usage: host dir id guid steps loads sets gets\n"); return 2; }
    steps = atoi(argv[4]);
    loads = atoi(argv[5]);
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    for (load = 0; load < loads; load++) {
        fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
        fmi2Component c;
        fmi2Status st;
        int k;
        char buf[4096], *tok;
        void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
        if (!lib) { printf("dlopen failed: %s\n", dlerror()); return 2; }
        {
            GET(fmi2Instantiate) GET(fmi2SetupExperiment) GET(fmi2EnterInitializationMode)
            GET(fmi2ExitInitializationMode) GET(fmi2DoStep) GET(fmi2SetReal) GET(fmi2GetReal)
            GET(fmi2Terminate) GET(fmi2FreeInstance)
            c = fmi2Instantiate("travel", fmi2CoSimulation, argv[3], uri, &cb, fmi2False, fmi2False);
            if (!c) {
                printf("load %d: fmi2Instantiate returned NULL\n", load);
            } else {
                st = fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
                st |= fmi2EnterInitializationMode(c);
                st |= fmi2ExitInitializationMode(c);
                if (strcmp(argv[6], "-") != 0) {
                    snprintf(buf, sizeof buf, "%s", argv[6]);
                    for (tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
                        fmi2ValueReference vr = (fmi2ValueReference)strtoul(tok, NULL, 10);
                        fmi2Real v = strtod(strchr(tok, '=') + 1, NULL);
                        st |= fmi2SetReal(c, &vr, 1, &v);
                    }
                }
                for (k = 0; k < steps; k++) st |= fmi2DoStep(c, k * 1e-3, 1e-3, fmi2True);
                snprintf(buf, sizeof buf, "%s", argv[7]);
                for (tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
                    fmi2ValueReference vr = (fmi2ValueReference)strtoul(tok, NULL, 10);
                    fmi2Real v = 0.0;
                    st |= fmi2GetReal(c, &vr, 1, &v);
                    printf("load %d: vr %u = %.17g\n", load, vr, v);
                }
                st |= fmi2Terminate(c);
                fmi2FreeInstance(c);
                printf("load %d: status %d\n", load, (int)st);
            }
        }
        if (dlclose(lib) != 0) { printf("dlclose failed: %s\n", dlerror()); return 2; }
        fflush(stdout);
    }
    printf("host done\n");
    return 0;
}
"""

#: The environment of "another machine": nothing of the build's venv or checkout.
CLEAN_ENV = {"PATH": "/usr/bin:/bin", "HOME": "/nonexistent", "LANG": "C.UTF-8"}


def compile_host(folder: Path) -> Path:
    """The host compiled with the system's C compiler (``cc``) and fmpy's FMI headers."""
    import fmpy
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (cc or gcc) on PATH")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "host.c").write_text(HOST_C)
    exe = folder / "host"
    subprocess.run([cc, "-O1", "-Wall", "-Werror", f"-I{Path(fmpy.__file__).parent / 'c-code'}",
                    "-o", str(exe), str(folder / "host.c"), "-ldl"], check=True, capture_output=True, text=True)
    return exe


def unpack(fmu: Path, folder: Path) -> tuple[Path, str, str, dict[str, int]]:
    """Copy ``fmu`` into a fresh ``folder`` and unpack it there: (folder, identifier,
    GUID, {variable: value reference})."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    copy = folder / Path(fmu).name
    shutil.copy2(fmu, copy)
    tree = folder / "unpacked"
    with zipfile.ZipFile(copy) as z:
        z.extractall(tree)
    root = ET.parse(tree / "modelDescription.xml").getroot()
    refs = {v.get("name"): int(v.get("valueReference")) for v in root.iter("ScalarVariable")}
    return tree, root.find("CoSimulation").get("modelIdentifier"), root.get("guid"), refs


def run_host(host: Path, tree: Path, identifier: str, guid: str, sets: dict[int, float] | None = None,
             gets=(), steps: int = 10, loads: int = 1, env: dict | None = None, prefix=(),
             timeout: float = 120) -> subprocess.CompletedProcess:
    """Run the compiled host on an unpacked FMU under ``env`` (default: :data:`CLEAN_ENV`
    only, as ``env -i`` would)."""
    set_arg = ",".join(f"{vr}={v!r}" for vr, v in (sets or {}).items()) or "-"
    get_arg = ",".join(str(vr) for vr in gets) or "0"
    return subprocess.run([*prefix, str(host), str(tree), identifier, guid, str(steps), str(loads), set_arg, get_arg],
                          env=dict(CLEAN_ENV if env is None else env), capture_output=True, text=True,
                          timeout=timeout, cwd=tree.parent)


def values(stdout: str, load: int = 0) -> dict[int, float]:
    """The values the host printed for load ``load``."""
    return {int(m.group(1)): float(m.group(2))
            for m in re.finditer(rf"^load {load}: vr (\d+) = (\S+)$", stdout, re.M)}


def invalid_accesses(stderr: str, identifier: str) -> tuple[list[str], list[str]]:
    """valgrind's invalid reads, writes and frees: (those in the FMU's shim or pythonfmu's
    library, the others).  An error is ours when its first three frames name
    ``<identifier>.so`` or ``<identifier>_pythonfmu.so``."""
    ours, others = [], []
    for block in re.split(r"\n==\d+== \n", stderr):
        if not re.search(r"Invalid (?:read|write|free)", block):
            continue
        frames = [line for line in block.splitlines() if re.search(r"==\d+==\s+(at|by) 0x", line)][:3]
        mine = any(f"{identifier}.so" in f or f"{identifier}_pythonfmu.so" in f for f in frames)
        (ours if mine else others).append(block)
    return ours, others


def valgrind_summary(stderr: str, identifier: str) -> str:
    """valgrind's ERROR SUMMARY line and its invalid accesses, ours and the others."""
    summary = next((line.split("== ", 1)[-1] for line in stderr.splitlines() if "ERROR SUMMARY" in line), "none")
    ours, others = invalid_accesses(stderr, identifier)
    where = sorted({re.search(r"\((\S+?):\d+\)|\(in (\S+)\)", b).group(0) for b in others
                    if re.search(r"\((\S+?):\d+\)|\(in (\S+)\)", b)})
    return (f"{summary}; invalid accesses in the shim or pythonfmu: {len(ours)}; elsewhere: {len(others)}"
            + (f" (first frame {', '.join(where)})" if where else ""))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmus", type=Path, default=ROOT / "build" / "fmus")
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--reloads", type=int, default=10)
    parser.add_argument("--valgrind", action="store_true")
    parser.add_argument("--libpython", help="BOOMFMI_LIBPYTHON for the runs (default: the FMU's own choice)")
    parser.add_argument("names", nargs="*")
    args = parser.parse_args(argv)
    import tempfile
    fmus = [args.fmus / f"{n}.fmu" for n in args.names] if args.names else sorted(args.fmus.glob("*.fmu"))
    env = dict(CLEAN_ENV, **({"BOOMFMI_LIBPYTHON": args.libpython} if args.libpython else {}))
    with tempfile.TemporaryDirectory(prefix="boomfmi_travel_") as tmp:
        host = compile_host(Path(tmp) / "host")
        print("| FMU | size | exit codes over runs | results | load/free/reload | valgrind |")
        print("|---|---|---|---|---|---|")
        for fmu in fmus:
            tree, ident, guid, _ = unpack(fmu, Path(tmp) / fmu.stem)
            codes, nulls = [], 0
            for _ in range(args.runs):
                proc = run_host(host, tree, ident, guid, env=env)
                codes.append(proc.returncode)
                nulls += "returned NULL" in proc.stdout
            reload = run_host(host, tree, ident, guid, loads=args.reloads, env=env)
            ok_loads = len(re.findall(r"^load \d+: status 0$", reload.stdout, re.M))
            grind = "not run"
            if args.valgrind and shutil.which("valgrind"):
                proc = run_host(host, tree, ident, guid, env=env, timeout=900,
                                prefix=("valgrind", "--error-exitcode=99", "--trace-children=no"))
                grind = f"rc {proc.returncode}; " + valgrind_summary(proc.stderr, ident)
            counts = {c: codes.count(c) for c in sorted(set(codes))}
            print(f"| {fmu.stem} | {fmu.stat().st_size / 1e6:.1f} MB | "
                  f"{', '.join(f'rc {c}: {n}' for c, n in counts.items())} | "
                  f"{args.runs - nulls}/{args.runs} instantiated | rc {reload.returncode}, "
                  f"{ok_loads}/{args.reloads} loads status 0 | {grind} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
