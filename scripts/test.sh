#!/usr/bin/env bash
# Set up (scripts/setup.sh) and run the default test suite; extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh test
export MPLBACKEND=Agg
.venv/bin/python -m pytest -q -p no:cacheprovider "$@"
