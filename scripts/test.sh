#!/usr/bin/env bash
# Set up (scripts/setup.sh) and run the default test suite, a worker per CPU (pytest-xdist; a
# file's tests stay on one worker, with its fixtures); extra arguments go to pytest (-n 0: serial).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh test
export MPLBACKEND=Agg
.venv/bin/python -m pytest -q -p no:cacheprovider -n auto --dist loadfile "$@"
