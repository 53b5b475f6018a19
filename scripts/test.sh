#!/usr/bin/env bash
# Every test and check: lint and format (Python and Rust), clippy, Rust unit tests, pytest.
source "$(dirname "${BASH_SOURCE[0]}")/_bootstrap.sh"
export TEXSENSE_NO_PROGRESS=1
say "ruff check";            ruff check python tests benchmarks
say "ruff format --check";   ruff format --check python tests benchmarks
say "cargo fmt --check";     cargo fmt --all --check
say "cargo clippy";          cargo clippy --quiet --all-targets -- -D warnings
say "cargo test";            cargo test --quiet -p texsense-core
say "pytest";                python -m pytest -q "$@"
