#!/usr/bin/env bash
# Profile-guided release builds of the `penumbra` command and the Python
# wheel: the same code, laid out by the compiler after the branch and call
# counts of training runs (scripts/pgo_train.py): renders 6-21 % and
# reverse-mode gradients 15-18 % faster than `cargo build --release` on
# this project's benchmarks, images bit for bit the same
# (docs/perf/pgo.md). Takes about twice a plain release build: each side
# is built instrumented, run on the training jobs, and built again with
# the merged profile.
#
#   scripts/build_pgo.sh            # both: <target>/pgo/release/penumbra and
#                                   #       <target>/pgo/wheels/penumbra-*.whl
#   scripts/build_pgo.sh --cli      # the command only
#   scripts/build_pgo.sh --wheel    # the wheel only
#
# then e.g. `cp <target>/pgo/release/penumbra ~/.local/bin/` or
# `pip install --force-reinstall <target>/pgo/wheels/penumbra-*.whl`.
# <target> is $CARGO_TARGET_DIR, or ./target without it. Needs the
# toolchain's llvm-profdata (`rustup component add llvm-tools`, done here
# when rustup is present): a profile is read by the LLVM that wrote it.
# Each side gets its own profile: the wheel's build compiles the library
# with other crate hashes than the command's, and the profile names
# functions by their symbols.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PYTHON=${PYTHON:-python3}

cli=1
wheel=1
case "${1:-}" in
    "") ;;
    --cli) wheel=0 ;;
    --wheel) cli=0 ;;
    *) echo "usage: scripts/build_pgo.sh [--cli | --wheel]" >&2; exit 2 ;;
esac

TARGET=$(cargo metadata --format-version 1 --no-deps \
    | "$PYTHON" -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
PGO=$TARGET/pgo

host=$(rustc -vV | sed -n 's/^host: //p')
profdata="$(rustc --print sysroot)/lib/rustlib/$host/bin/llvm-profdata"
if [[ ! -x "$profdata" ]] && command -v rustup >/dev/null 2>&1; then
    echo "== rustup component add llvm-tools (for llvm-profdata)"
    rustup component add llvm-tools
fi
if [[ ! -x "$profdata" ]]; then
    echo "build_pgo.sh: $profdata not found; install the toolchain's LLVM tools" \
         "(rustup component add llvm-tools) or use a plain cargo build --release" >&2
    exit 1
fi

# one build: $1 = "generate" or "use", $2 = profile folder or file, then the
# command that builds (cargo or maturin), into CARGO_TARGET_DIR=$PGO/$1.
# The profile flag goes through CARGO_BUILD_RUSTFLAGS, which cargo joins to
# the flags of .cargo/config.toml (RUSTFLAGS would replace them).
build() {
    local kind=$1 path=$2
    shift 2
    CARGO_BUILD_RUSTFLAGS="${CARGO_BUILD_RUSTFLAGS:-} -Cprofile-$kind=$path" \
        CARGO_TARGET_DIR="$PGO/$kind" "$@"
}

if [[ $cli == 1 ]]; then
    echo "== the command, instrumented"
    rm -rf "$PGO/raw-cli"
    build generate "$PGO/raw-cli" cargo build --release -q -p penumbra-cli
    echo "== training"
    "$PYTHON" scripts/pgo_train.py --cli "$PGO/generate/release/penumbra"
    "$profdata" merge -o "$PGO/cli.profdata" "$PGO/raw-cli"
    echo "== the command, optimised with its profile"
    build use "$PGO/cli.profdata" cargo build --release -q -p penumbra-cli
    mkdir -p "$PGO/release"
    cp "$PGO/use/release/penumbra" "$PGO/release/penumbra"
    echo "built $PGO/release/penumbra"
fi

if [[ $wheel == 1 ]]; then
    VENV=$PGO/venv
    if [[ ! -x "$VENV/bin/python" ]]; then
        echo "== virtualenv for building and training the wheel: $VENV"
        "$PYTHON" -m venv "$VENV"
        "$VENV/bin/python" -m pip install -q --upgrade pip
    fi
    "$VENV/bin/python" -m pip install -q maturin numpy
    wheel_build() {
        rm -rf "$PGO/wheels-$1"
        (cd crates/penumbra-py && build "$1" "$2" "$VENV/bin/maturin" build --release \
            -i "$VENV/bin/python" --quiet --out "$PGO/wheels-$1")
    }
    echo "== the wheel, instrumented"
    rm -rf "$PGO/raw-wheel"
    wheel_build generate "$PGO/raw-wheel"
    "$VENV/bin/python" -m pip install -q --force-reinstall --no-deps "$PGO"/wheels-generate/penumbra-*.whl
    echo "== training"
    (cd "$PGO" && "$VENV/bin/python" "$ROOT/scripts/pgo_train.py" --python)
    "$profdata" merge -o "$PGO/wheel.profdata" "$PGO/raw-wheel"
    echo "== the wheel, optimised with its profile"
    wheel_build use "$PGO/wheel.profdata"
    rm -rf "$PGO/wheels"
    mv "$PGO/wheels-use" "$PGO/wheels"
    "$VENV/bin/python" -m pip install -q --force-reinstall --no-deps "$PGO"/wheels/penumbra-*.whl
    echo "built $(ls "$PGO"/wheels/penumbra-*.whl) (installed in $VENV)"
fi
