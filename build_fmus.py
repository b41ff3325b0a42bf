#!/usr/bin/env python3
"""Build every boomfmi FMU into build/fmus/ and pack the SSP systems into build/*.ssp.

    python build_fmus.py [--out build] [--fmi 2|3] [--portable] [NAME ...]

Each FMU is self-contained (its physics bundled under a private name), carries SI
units, bounds and output dependencies, and passes fmpy.validation.validate_fmu.
Each SSP is packed twice: build/<name>.ssp (SSP 1.0, with the system input connectors
that fmpy's SSP runner drives) and build/osp/<name>.ssp (without them, for libcosim and
ecos, which refuse them).  The FMI 3.0 version of every FMU (pythonfmu3, from the same
adapters) goes into build/fmi3/ too; the SSPs stay FMI 2.0.  ``--fmi 2`` builds the FMI
2.0 FMUs and the SSPs only, ``--fmi 3`` the FMI 3.0 FMUs only.  The FMUs are lean by
default (resources/boomfmi_requirements.txt names the Python and numpy they need, checked
at fmi2Instantiate); ``--portable`` puts numpy inside, for each platform they declare
(FMI 2.0 only: the FMI 3.0 FMUs run in Python hosts only, on the host's numpy).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "src"))

from boomfmi.fmubuild import BuildError, build_fmu  # noqa: E402

FMU_NAMES = ("valve", "cylinder", "boom_load", "force_estimator", "hardware_bridge", "linkage", "excavator_bridge",
             "excavator_force_estimator")
#: SSP archives: build/<name>.ssp from ssp/<ssd>
SSPS = {"excavator_boom": "SystemStructure.ssd", "teleoperation": "teleoperation.ssd", "excavator": "excavator.ssd"}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(FMU_NAMES), help="FMUs to build (default: all)")
    parser.add_argument("--out", type=Path, default=HERE / "build", help="output folder (default: build/)")
    parser.add_argument("--write-references", action="store_true",
                        help="also rewrite fmus/<name>/<name>_in.csv and _ref.csv from the built FMUs (a file "
                             "unchanged but for floating-point noise is kept), and, with every FMU built, "
                             "ssp/reference_rig.ssv and docs/interfaces.md; with valve, cylinder or linkage built, "
                             "ssp/excavator.ssv")
    parser.add_argument("--portable", action="store_true",
                        help="put numpy (for linux64 and win64) inside each FMU, so that a host needs only a "
                             "CPython of this build's version (about 20 MB more per FMU); default: lean FMUs "
                             "that name what they need at fmi2Instantiate")
    parser.add_argument("--fmi", choices=("2", "3"), default=None,
                        help="only one FMI version: 2 into <out>/fmus/ with the SSPs, 3 into <out>/fmi3/ "
                             "(default: both)")
    parser.add_argument("--effects", type=Path, action="append", default=[], metavar="FILE",
                        help="a Python file of your own effects (a plug-in); its options go into the FMUs of their "
                             "stages, its module into those FMUs (installed plug-ins, entry point boomfmi.effects, "
                             "and $BOOMFMI_EFFECTS are loaded anyway); repeatable")
    args = parser.parse_args(argv)
    if args.effects:
        from boomfmi.model.catalogue import PluginError, load_plugins
        try:
            load_plugins([str(f.resolve()) for f in args.effects])
        except PluginError as e:
            parser.error(str(e))
    if args.fmi == "3":
        return build_fmi3(parser, args)
    unknown = sorted(set(args.names) - set(FMU_NAMES))
    if unknown:
        parser.error(f"unknown FMU(s): {', '.join(unknown)}; known: {', '.join(FMU_NAMES)}")
    try:
        for name in args.names:
            path = build_fmu(HERE / "fmus" / name, args.out / "fmus", portable=args.portable)
            print(f"built {path}")
            if args.write_references:
                from boomfmi.fmubuild.references import INPUTS, write_references
                if name in INPUTS:      # the bridge's behaviour depends on its rig or recording
                    print(f"wrote {write_references(HERE / 'fmus' / name, path)}")
        from boomfmi.fmubuild.ssp import PARAMETER_SETS, fmus_of, osp_ssp, pack_ssp, parameters_ssv
        if args.write_references:
            from boomfmi.model.boom import Model
            from boomfmi.model.machine import boom_machine, excavator_machine
            built = set(args.names)
            # the boom's set spans two SSPs: rewritten with every FMU built; the excavator's with any of its own
            for machine, due in ((boom_machine(Model()), built == set(FMU_NAMES)),
                                 (excavator_machine(), bool({"valve", "cylinder", "linkage"} & built))):
                if due:
                    out = HERE / "ssp" / f"{PARAMETER_SETS[machine.mechanism][0]}.ssv"
                    print(f"wrote {parameters_ssv(machine, [HERE / 'ssp' / s for s in SSPS.values()], args.out / 'fmus', out)}")
        if set(args.names) == set(FMU_NAMES) and args.write_references:
            from boomfmi.describe import INTERFACES_DOC, interfaces_document
            doc, text = HERE / INTERFACES_DOC, interfaces_document([args.out / "fmus" / f"{n}.fmu" for n in FMU_NAMES])
            if not doc.is_file() or doc.read_text() != text:
                doc.write_text(text)
            print(f"wrote {doc}")
        for name, ssd in SSPS.items():
            # an SSP carries copies of its FMUs: re-pack every one that holds a rebuilt FMU
            fmus = fmus_of(HERE / "ssp" / ssd)
            if not fmus & set(args.names):
                continue
            missing = sorted(f for f in fmus if not (args.out / "fmus" / f"{f}.fmu").is_file())
            if missing:
                print(f"not packed {args.out / f'{name}.ssp'}: {', '.join(missing)} not built yet")
                continue
            packed = pack_ssp(HERE / 'ssp' / ssd, args.out / 'fmus', args.out / f'{name}.ssp')
            print(f"packed {packed}")
            print(f"packed {osp_ssp(packed)} (for libcosim and ecos: without system connectors)")
    except BuildError as e:
        print(f"build_fmus.py: {e}", file=sys.stderr)
        return 1
    if args.fmi is None and args.portable:
        print("FMI 3.0: not built with --portable (the FMI 3.0 FMUs run in Python hosts, on the host's numpy)")
    elif args.fmi is None:
        return build_fmi3(parser, args)
    return 0


def build_fmi3(parser, args) -> int:
    """``--fmi 3``: the FMI 3.0 model FMUs into <out>/fmi3/ (one shim compiled for all)."""
    import tempfile

    from boomfmi.fmubuild.fmi3 import FMI3_NAMES, build_fmu3, compile_shim3
    names = list(FMI3_NAMES) if args.names is parser.get_default("names") else args.names
    unknown = sorted(set(names) - set(FMI3_NAMES))
    if unknown:
        parser.error(f"no FMI 3.0 version of: {', '.join(unknown)}; FMI 3.0: {', '.join(FMI3_NAMES)}")
    if args.write_references and args.fmi == "3":
        parser.error("--write-references: the references are written from the FMI 2.0 FMUs")
    if args.portable:
        parser.error("--portable: FMI 2.0 only (the FMI 3.0 FMUs run in Python hosts, on the host's numpy)")
    try:
        with tempfile.TemporaryDirectory(prefix="boomfmi_fmi3_shim_") as tmp:
            shim = compile_shim3(Path(tmp) / "shim3.so")
            for name in names:
                print(f"built {build_fmu3(HERE / 'fmus' / name, args.out / 'fmi3', shim)}")
    except BuildError as e:
        print(f"build_fmus.py: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
