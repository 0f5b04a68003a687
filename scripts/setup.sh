#!/usr/bin/env bash
# Create .venv with a Python >= 3.12 and install skinfit from this checkout (editable) + extras.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c 'import sys; sys.exit(sys.version_info < (3, 12))'; then
  PY=$(bash scripts/find_python.sh)
  echo "creating .venv with $PY ($("$PY" --version))"
  rm -rf .venv
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e ".[${1:-test}]"
# the example plug-in package (a model added through the skinfit.io.models entry point), which
# tests/test_plugin.py fits end to end
if [ "${1:-test}" = test ]; then
  .venv/bin/python -m pip install --quiet -e examples/skinfit-example-plugin
fi
