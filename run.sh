#!/usr/bin/env bash
# The main job, end to end: set up .venv, build every FMU, check them, and run the boom.
set -euo pipefail
cd "$(dirname "$0")"
scripts/bootstrap.sh
mkdir -p out
.venv/bin/boomfmi check build/fmus
.venv/bin/boomfmi describe build/fmus/*.fmu > out/fmu-interfaces.md
echo "wrote out/fmu-interfaces.md"
.venv/bin/boomfmi simulate build/excavator_boom.ssp --experiment paper_multistep --step 0.001 --out out/paper_multistep.csv
