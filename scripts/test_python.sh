#!/usr/bin/env bash
# Builds the Python wheel (crates/penumbra-py, maturin, abi3) into a fresh
# virtualenv and runs its pytest suite (incl. the example loops).
#
#   scripts/test_python.sh            # venv in <target dir>/py-venv (reused if present)
#   PENUMBRA_FRESH_VENV=1 scripts/test_python.sh   # recreate it
#   PYTHON=python3.12 scripts/test_python.sh       # another interpreter (>= 3.9)
#   PENUMBRA_CARGO_PROFILE=release-test scripts/test_python.sh   # cargo profile of the wheel
#                                                  # (default release; scripts/test.sh's)
#
# The target dir is cargo's: $CARGO_TARGET_DIR when set, else ./target.
# Needs network access to PyPI on the first run (maturin, pytest, numpy,
# torch; torch from PyPI pulls CUDA libraries, ~5 GB). Set
# PENUMBRA_NO_TORCH=1 to skip torch (its tests are then skipped).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PYTHON=${PYTHON:-python3}
# cargo's own answer, so a relative or absolute CARGO_TARGET_DIR both work
TARGET=$(cargo metadata --format-version 1 --no-deps \
    | "$PYTHON" -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
VENV=${PENUMBRA_VENV:-$TARGET/py-venv}
WHEELS=$TARGET/py-wheels

if [[ "${PENUMBRA_FRESH_VENV:-0}" == 1 ]]; then
    rm -rf "$VENV"
fi
if [[ ! -x "$VENV/bin/python" ]]; then
    echo "== creating virtualenv $VENV"
    "$PYTHON" -m venv "$VENV"
    "$VENV/bin/python" -m pip install -q --upgrade pip
fi
PKGS=(maturin pytest numpy)
if [[ "${PENUMBRA_NO_TORCH:-0}" != 1 ]]; then
    PKGS+=(torch)
fi
# no-op when already installed
"$VENV/bin/python" -m pip install -q "${PKGS[@]}"

echo "== building the wheel"
rm -rf "$WHEELS"
(cd crates/penumbra-py && "$VENV/bin/maturin" build --profile "${PENUMBRA_CARGO_PROFILE:-release}" -i "$VENV/bin/python" --quiet --out "$WHEELS")
WHEEL=$(ls "$WHEELS"/penumbra-*.whl | head -n 1)
"$VENV/bin/python" -m pip install -q --force-reinstall --no-deps "$WHEEL"

echo "== pytest"
# run from outside the source tree so that the installed wheel is tested
RUN_DIR=$(mktemp -d)
trap 'rm -rf "$RUN_DIR"' EXIT
cd "$RUN_DIR"
set +e
"$VENV/bin/python" -m pytest -q -p no:cacheprovider "$ROOT/crates/penumbra-py/tests" "$@"
status=$?
set -e
if [[ $status == 5 ]]; then
    echo "pytest collected no tests: treating as a failure" >&2
    exit 1
fi
exit $status
