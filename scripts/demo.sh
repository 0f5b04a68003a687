#!/usr/bin/env bash
# Set up (scripts/setup.sh) and run `skinfit demo` on the shipped datasets.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh test
export MPLBACKEND=Agg
.venv/bin/skinfit demo "$@"
