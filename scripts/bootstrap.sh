#!/usr/bin/env bash
# Create .venv (Python 3.11) with boomfmi and its test dependencies, install the virtual
# view's browser libraries (three.js, uPlot) with npm, and build the FMUs.  With
# --browser, also Debian's chromium and chromium-driver for the view's browser test.
# As root with apt-get, also Debian's mingw-w64 for the FMUs' win64 status shim and
# valgrind for the FMUs' clean-exit test.
# Idempotent: reinstalls only when pyproject.toml or the lock file changed;
# build_fmus.py always runs (a few seconds) so the FMUs match the sources.
set -euo pipefail
cd "$(dirname "$0")/.."

pick_python() {
    for candidate in "${PYTHON:-}" python3.11 python3; do
        [ -n "$candidate" ] || continue
        if command -v "$candidate" >/dev/null 2>&1 &&
           "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
            echo "$candidate"; return 0
        fi
    done
    echo "bootstrap: Python 3.11 is required (set PYTHON=/path/to/python3.11)" >&2
    return 1
}

if [ ! -x .venv/bin/python ]; then
    "$(pick_python)" -m venv .venv
fi
stamp=.venv/.boomfmi-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    .venv/bin/python -m pip install --quiet --upgrade pip
    .venv/bin/python -m pip install --quiet -e '.[test]'
    touch "$stamp"
fi

web=src/boomfmi/view/web
if [ ! -f "$web/node_modules/.package-lock.json" ] || [ "$web/package-lock.json" -nt "$web/node_modules/.package-lock.json" ]; then
    if command -v npm >/dev/null 2>&1; then
        npm ci --prefix "$web" --no-audit --no-fund --loglevel=error
    else
        echo "bootstrap: npm not found; the virtual view needs Node.js and npm (three.js, uPlot)" >&2
    fi
fi

if [ "${1:-}" = "--browser" ] && ! { command -v chromium && command -v chromedriver; } >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "bootstrap: installing Debian's chromium and chromium-driver (the view's browser test)"
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y -qq chromium chromium-driver >/dev/null 2>&1 ||
            { apt-get update -qq && apt-get install -y -qq chromium chromium-driver >/dev/null; }
    else
        echo "bootstrap: chromium and chromedriver are missing and cannot be installed here (needs root" \
             "and apt-get); the view's browser test will be skipped" >&2
    fi
fi

# mingw-w64 cross-compiles the FMUs' win64 status shim; without it they ship pythonfmu's
# own win64 binary (Python hosts only) and the build says so.
if ! command -v x86_64-w64-mingw32-gcc >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "bootstrap: installing Debian's gcc-mingw-w64-x86-64 (the FMUs' win64 status shim)"
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y -qq gcc-mingw-w64-x86-64 >/dev/null 2>&1 ||
            { apt-get update -qq && apt-get install -y -qq gcc-mingw-w64-x86-64 >/dev/null; } ||
            echo "bootstrap: could not install gcc-mingw-w64-x86-64; the FMUs' win64 binary stays" \
                 "pythonfmu's own" >&2
    else
        echo "bootstrap: x86_64-w64-mingw32-gcc is missing and cannot be installed here (needs root" \
             "and apt-get); the FMUs' win64 binary stays pythonfmu's own" >&2
    fi
fi

# valgrind checks that a plain C host exits cleanly with the FMUs (tests/test_travel.py,
# benchmarks/fmu_travel.py --valgrind); without it that test is skipped.
if ! command -v valgrind >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "bootstrap: installing Debian's valgrind (the FMUs' clean-exit test)"
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y -qq valgrind >/dev/null 2>&1 ||
            { apt-get update -qq && apt-get install -y -qq valgrind >/dev/null; } ||
            echo "bootstrap: could not install valgrind; the FMUs' valgrind test will be skipped" >&2
    else
        echo "bootstrap: valgrind is missing and cannot be installed here (needs root and apt-get);" \
             "the FMUs' valgrind test will be skipped" >&2
    fi
fi

.venv/bin/python build_fmus.py
