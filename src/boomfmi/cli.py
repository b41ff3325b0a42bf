"""The ``boomfmi`` command: a thin layer over the library.

    boomfmi describe FMU [FMU ...]      the FMUs' interfaces as Markdown tables
    boomfmi check FMU_DIR               validate every FMU and replay its reference result
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _describe(args) -> int:
    from .describe import interface_table
    for path in args.fmus:
        print(interface_table(path))
    return 0


def _check(args) -> int:
    """Validate the FMUs in a folder and replay each one's reference result."""
    import numpy as np
    import pandas as pd
    from fmpy.validation import validate_fmu

    from .system.instance import run_table
    failures = 0
    for fmu in sorted(Path(args.fmu_dir).glob("*.fmu")):
        problems = validate_fmu(str(fmu))
        status = "valid" if not problems else "INVALID: " + "; ".join(problems)
        ref_dir = Path(args.references) / fmu.stem
        in_csv, ref_csv = ref_dir / f"{fmu.stem}_in.csv", ref_dir / f"{fmu.stem}_ref.csv"
        if in_csv.is_file() and ref_csv.is_file():
            got = run_table(fmu, pd.read_csv(in_csv))
            want = pd.read_csv(ref_csv)
            err = max(float(np.max(np.abs(got[c] - want[c]) / (np.abs(want[c]) + 1e-12)))
                      for c in want.columns)
            status += f", reference result max rel. error {err:.1e}"
            failures += err > 1e-9
        failures += bool(problems)
        print(f"{fmu.name:24s} {status}")
    return 1 if failures else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="boomfmi", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("describe", help="print FMU interfaces as Markdown tables")
    p.add_argument("fmus", nargs="+", type=Path)
    p.set_defaults(run=_describe)
    p = sub.add_parser("check", help="validate FMUs and replay their reference results")
    p.add_argument("fmu_dir", type=Path)
    p.add_argument("--references", type=Path, default=Path("fmus"),
                   help="folder with <name>/<name>_in.csv and _ref.csv (default: fmus)")
    p.set_defaults(run=_check)
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except (FileNotFoundError, ValueError, RuntimeError) as e:
        print(f"boomfmi {args.command}: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
