#!/usr/bin/env bash
# Installability check: build the wheel, install it into a brand-new venv, and run `koopguide demo` in an
# empty folder (no checkout around it: the defaults must come from the installed package).
# Used by .ci/run; also handy before a release. Needs python3 >= 3.11 and network access to PyPI (or a
# local CPU torch wheel, as on the project's machines).
set -euo pipefail
cd "$(dirname "$0")/.."
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
python3 -m venv "$work/venv"
PY="$work/venv/bin/python"
"$PY" -m pip install -q --upgrade pip >/dev/null 2>&1 || true
# torch first, CPU build (see scripts/bootstrap.sh): a plain torch requirement would pull a CUDA build
if [ -n "${KOOPGUIDE_TORCH:-}" ]; then
    "$PY" -m pip install -q "$KOOPGUIDE_TORCH"
else
    "$PY" -m pip install -q "torch==2.13.0" 2>/dev/null || "$PY" -m pip install -q "torch>=2.2"
fi
"$PY" -m pip wheel -q --no-deps -w "$work/dist" .
"$PY" -m pip install -q "$work"/dist/koopguide-*.whl
demo_dir="$work/empty"
mkdir "$demo_dir"
cd "$demo_dir"
"$work/venv/bin/koopguide" demo
test -s out/demo.png
echo "check_wheel: the installed wheel ran koopguide demo in an empty folder"
