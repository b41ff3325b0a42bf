#!/usr/bin/env bash
# Run build/osp/excavator_boom.ssp in ecos (the C++ host of the ecospy wheel) under
# paper_multistep, from the repository's root after ./run.sh:
#     examples/hosts/ecos/run.sh [stop time, s: 9]      -> excavator_boom.csv here
# ecos takes the OSP copy (it refuses a connection from a system connector), the
# reference_rig parameter set, scenario.xml (the command over time) and csv.xml (what it
# writes).  It needs no Python in its environment: each FMU loads the Python it was built
# with.  LD_LIBRARY_PATH finds libtbb.so.12 from the tbb wheel, which ecos itself needs.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
PY="${PY:-$root/.venv/bin/python}"
ssp="${SSP:-$root/build/osp/excavator_boom.ssp}"   # SSP=... names another build's OSP copy
[ -f "$ssp" ] || { echo "run.sh: error: $ssp does not exist (run ./run.sh or build_fmus.py first)" >&2; exit 2; }
ecos_dir="$("$PY" -c 'import importlib.util, os; print(os.path.dirname(importlib.util.find_spec("ecospy").origin))')"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cp "$ecos_dir/binaries/ecos" "$work/ecos" && chmod +x "$work/ecos"   # the wheel installs it without an exec bit
cp "$here/scenario.xml" "$here/csv.xml" "$work/"
out="$PWD"
(cd "$work" && LD_LIBRARY_PATH="$("$PY" -c 'import sys; print(sys.prefix)')/lib" TMPDIR="$work" \
  ./ecos simulate --path "$ssp" --stepSize 0.001 --stopTime "${1:-9}" --parameterSet reference_rig \
  --scenarioConfig scenario.xml --csvConfig csv.xml)
cp "$work/excavator_boom.csv" "$out/excavator_boom.csv"
echo "ecos wrote $out/excavator_boom.csv"
