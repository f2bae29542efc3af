#!/usr/bin/env bash
# The project's test command (README: "Run the tests").
# Installs nothing today; later issues add their set-up steps here, so a fresh machine needs no hand work.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --workspace --all-targets
cargo test --workspace --doc
