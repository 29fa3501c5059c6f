#!/usr/bin/env bash
# Runs every test of the project: formatting, lints, the Rust test suite
# (unit tests, reference-scene comparisons, gradient checks, bad-input
# corpus, CLI), then the Python package's tests (wheel built into a
# virtualenv, pytest, example loops).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --release -- -D warnings
# the release build without LTO across crates (Cargo.toml, release-test);
# the wheel of the Python tests is built with it too, from the same objects
cargo test --workspace --profile release-test
PENUMBRA_CARGO_PROFILE=release-test ./scripts/test_python.sh
