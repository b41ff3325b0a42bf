#!/usr/bin/env bash
# The main job, end to end: set up .venv, build every FMU and SSP, check them, run the
# paper's experiment on the model, and record it from the virtual rig through the
# hardware bridge.  Everything lands in out/.
set -euo pipefail
cd "$(dirname "$0")"
scripts/bootstrap.sh
mkdir -p out
B=.venv/bin/boomfmi
$B check build/fmus
$B describe build/fmus/*.fmu > out/fmu-interfaces.md
echo "wrote out/fmu-interfaces.md"
$B simulate build/excavator_boom.ssp --experiment paper_multistep --step 0.001 --out out/paper_multistep_model.csv

# the virtual rig in lockstep behind its authenticated link, recorded through the bridge
umask 077
.venv/bin/python -c 'import secrets; print(secrets.token_hex(16))' > out/link.key
$B rig serve --port 0 --lockstep --key-file out/link.key --record out/rig_samples.csv > out/rig.log &
rig_pid=$!
trap 'kill $rig_pid 2>/dev/null || true' EXIT
for _ in $(seq 100); do grep -q listening out/rig.log 2>/dev/null && break; sleep 0.1; done
port=$(sed -n 's/.*udp:\/\/127.0.0.1:\([0-9]*\).*/\1/p' out/rig.log)
$B record --experiment paper_multistep --rig "udp://127.0.0.1:$port" --key-file out/link.key --out out/paper_multistep_rig.csv
kill -TERM $rig_pid; wait $rig_pid || true
trap - EXIT
cat out/rig.log

# identify the model from the rig's recording, then run the identified model
$B identify out/paper_multistep_rig.csv --out out/params.json
$B simulate build/excavator_boom.ssp --experiment out/paper_multistep_rig.csv --params out/params.ssv \
    --out out/paper_multistep_identified.csv

# the virtual view of the rig's recording, rendered for the report (no browser needed);
# `boomfmi view --replay out/paper_multistep_rig.csv` serves it live on 127.0.0.1:8765
$B view --replay out/paper_multistep_rig.csv --export out/paper_multistep_rig.gif --stop 4 --fps 10 --size 800x450
