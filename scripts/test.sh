#!/usr/bin/env bash
# The project's test command (README: "Run the tests"). Everything a test needs is set up here, so a fresh machine
# needs no hand work.
#
# The mutation switch is a cargo feature that a normal build never enables, so the mutant checks build the model
# and the scheduler once more with `--features mutants`.
set -euo pipefail
cd "$(dirname "$0")/.."
# The inspector's browser test (impl/inspector/tests/browser.rs) drives Debian's chromium through chromedriver.
if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then
  if [ "$(id -u)" = 0 ]; then
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver) >/dev/null
  else
    echo "note: chromium or chromedriver missing and not root: the inspector's browser test skips (fails under CI)" >&2
  fi
fi
cargo test --workspace --all-targets
cargo test --workspace --doc
cargo test -p bica -p model -p harness --features mutants --all-targets
