#!/usr/bin/env bash
# The main job (README, "The two commands"): installs what the build needs if it is missing (scripts/build-deps.sh:
# OpenSSL's headers and pkg-config, as root), then runs `cortex report` from a release build with the arguments
# given (`--full`, `--config FILE`, `--out DIR`, ...). Once those are installed, `cargo run --release -p harness --
# report` is the same.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build-deps.sh
exec cargo run --release -p harness -- report "$@"
