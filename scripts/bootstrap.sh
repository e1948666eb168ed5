#!/usr/bin/env bash
# Create ./.venv with koopguide and its test tools, once. Safe to re-run: it does nothing when the
# environment is already up to date with pyproject.toml.
#
# torch is installed first, CPU build: a plain `torch` requirement on a Linux machine with no torch
# pulls a multi-GB CUDA build. On the project's machines `torch==2.13.0` is a CPU wheel on local disk.
# Elsewhere, install any CPU torch >= 2.2 into .venv yourself (or set KOOPGUIDE_TORCH to a pip
# requirement, e.g. KOOPGUIDE_TORCH="torch==2.5.1+cpu") before running this script.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${KOOPGUIDE_VENV:-.venv}"
PY="$VENV/bin/python"
STAMP="$VENV/.koopguide-installed"

if [ -f "$STAMP" ] && [ "$STAMP" -nt pyproject.toml ] && "$PY" -c "import koopguide, torch" 2>/dev/null; then
    exit 0
fi

echo "bootstrap: creating $VENV" >&2
[ -x "$PY" ] || python3 -m venv "$VENV"

if ! "$PY" -c "import torch" 2>/dev/null; then
    if [ -n "${KOOPGUIDE_TORCH:-}" ]; then
        "$PY" -m pip install -q "$KOOPGUIDE_TORCH"
    elif probe=$(mktemp -d) && "$PY" -m pip download -q --no-index --no-deps -d "$probe" "torch==2.13.0" \
            >/dev/null 2>&1 && ls "$probe" | grep -q '+cpu'; then
        echo "bootstrap: torch 2.13.0 (CPU build) from local disk" >&2
        rm -rf "$probe"
        "$PY" -m pip install -q "torch==2.13.0"
    else
        echo "bootstrap: no local CPU torch wheel; installing torch>=2.2 from the package index" >&2
        echo "bootstrap: (on Linux that may be a large CUDA build: preinstall a CPU torch to avoid it)" >&2
        "$PY" -m pip install -q "torch>=2.2"
    fi
fi

"$PY" -m pip install -q -e ".[dev]"
# MAVProxy (a real ground station for the simulator tests) without its GUI dependencies: its default
# install pulls vtk and opencv (~1.2 GB); what it needs without the GUI (pyserial, pynmeagps,
# defusedxml, pymavlink, numpy) is in the dev extra.
"$PY" -m pip install -q --no-deps "MAVProxy==1.8.75"
touch "$STAMP"
echo "bootstrap: ready ($("$PY" -c 'import torch; print("torch", torch.__version__)'))" >&2
