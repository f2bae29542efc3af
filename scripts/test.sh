#!/usr/bin/env bash
# The project's test command (README: "Run the tests"). Everything a test needs is set up here, so a fresh machine
# needs no hand work.
#
# The mutation switch is a cargo feature that a normal build never enables, so the mutant checks build the model
# and the scheduler once more with `--features mutants`.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --workspace --all-targets
cargo test --workspace --doc
cargo test -p bica -p model -p harness --features mutants --all-targets
