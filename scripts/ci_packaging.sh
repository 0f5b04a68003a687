#!/usr/bin/env bash
# CI jobs for the package as users get it (after scripts/test.sh, which made .venv):
#  1. the lowest direct dependency versions pyproject allows (uv --resolution lowest-direct),
#     running a fast subset of the tests;
#  2. a wheel built from this checkout, installed in a clean venv and run from an empty folder.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export MPLBACKEND=Agg UV_SYSTEM_CERTS=1
PY=$(bash scripts/find_python.sh)
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
.venv/bin/python -m pip install --quiet "uv>=0.13.9"  # UV_SYSTEM_CERTS: the system CA store
UV="$ROOT/.venv/bin/uv"  # absolute: the sdist job runs it from inside the unpacked sdist

echo "== lowest direct versions =="
"$UV" venv -q --python "$PY" "$WORK/low"
VIRTUAL_ENV="$WORK/low" "$UV" pip install -q --resolution lowest-direct -e ".[test]"
VIRTUAL_ENV="$WORK/low" "$UV" pip freeze | grep -Ei '^(numpy|scipy|pandas|xarray|arviz[a-z-]*|emcee|nlopt|h5netcdf|h5py|matplotlib|pillow|jinja2|platformdirs|threadpoolctl)=='
"$WORK/low/bin/python" -m pytest -q -p no:cacheprovider -n auto --dist loadfile -m "not slow" tests/test_models.py tests/test_priors.py \
  tests/test_data.py tests/test_physics_electroadhesion.py tests/test_fit.py tests/test_compare.py \
  tests/test_references.py tests/test_public_api.py tests/test_figure_files.py tests/test_startup.py \
  tests/test_netcdf.py tests/test_workers.py

echo "== wheel in a clean venv, run from an empty folder =="
.venv/bin/python -m pip wheel --quiet --no-deps -w "$WORK/dist" .
"$UV" venv -q --python "$PY" "$WORK/wheel"
VIRTUAL_ENV="$WORK/wheel" "$UV" pip install -q "$WORK"/dist/skinfit-*.whl
mkdir "$WORK/empty"
cd "$WORK/empty"
SK="$WORK/wheel/bin/skinfit"
set -x
"$SK" --version
"$SK" models | grep -c '^[a-z_]*: '
"$SK" datasets | grep -c '^[a-z_]*_synthetic '
"$SK" fit electroadhesion electroadhesion_synthetic --out X --seed 1 --quiet | tail -n 3
test -s X/fit.nc
"$SK" report X --out R | tail -n 1
test -s R/index.html && test "$(ls R/figures/*.png R/figures/*.pdf | wc -l)" -eq 8  # 4 figures of one fit, PNG + PDF
! grep -q "could not be drawn" R/index.html
set +x
cd "$ROOT"
echo "wheel checks passed"

echo "== sdist unpacked, installed in a clean venv, its own tests run from its tree =="
# the tests that read files outside tests/ (bench/, examples/, docs/, the cards); the sdist's file
# list itself is checked by test_packaging (the campaign and browser mechanics run from the checkout
# in .ci/run); test_plugin installs the example plug-in for its process where pip has not
.venv/bin/python -m pip install --quiet "build>=1.2"
.venv/bin/python -m build --sdist -o "$WORK/sdist" . > /dev/null
tar xzf "$WORK"/sdist/skinfit-*.tar.gz -C "$WORK/sdist"
"$UV" venv -q --python "$PY" "$WORK/sdvenv"
(cd "$WORK"/sdist/skinfit-*/ && VIRTUAL_ENV="$WORK/sdvenv" "$UV" pip install -q ".[test]" \
  && "$WORK/sdvenv/bin/python" -m pytest -q -p no:cacheprovider -n auto --dist loadfile -m "not slow" tests/test_plugin.py \
     tests/test_posterior.py tests/test_sampling.py tests/test_tutorial.py \
     tests/test_own_model.py::test_the_executed_tutorial_runs_and_recovers_its_truth \
     tests/test_references.py tests/test_priors.py tests/test_models.py tests/test_student_t.py tests/test_packaging.py)
echo "sdist checks passed"

echo "== documentation: mkdocs build --strict (executes the tutorial notebook) =="
"$UV" venv -q --python "$PY" "$WORK/docs"
VIRTUAL_ENV="$WORK/docs" "$UV" pip install -q -e ".[docs]"
NO_MKDOCS_2_WARNING=1 "$WORK/docs/bin/mkdocs" build --strict -d "$WORK/site"
echo "documentation built"
