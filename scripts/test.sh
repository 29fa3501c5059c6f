#!/usr/bin/env bash
# Runs every test of the project: formatting, lints, and the Rust test suite
# (unit tests, reference-scene comparisons, bad-input corpus, CLI).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --release -- -D warnings
cargo test --workspace --release
