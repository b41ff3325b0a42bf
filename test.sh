#!/usr/bin/env bash
# The test suite: set up .venv and the FMUs if needed, then run pytest.
set -euo pipefail
cd "$(dirname "$0")"
scripts/bootstrap.sh --browser
exec .venv/bin/python -m pytest "$@"
