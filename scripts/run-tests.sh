#!/usr/bin/env bash
# Sourced by scripts/test.sh and scripts/test-python.sh: `run_tests ARG...` runs the test executables listed on
# standard input (scripts/test-binaries.py's lines: directory, executable, label) as `cargo test` runs them, each
# in its package's directory with the arguments given and no standard input; stops at the first that fails.
run_tests() {
  local dir executable label
  while IFS="$(printf "\t")" read -r dir executable label; do
    echo "     Running $label ($executable)"
    (cd "$dir" && CARGO_MANIFEST_DIR="$dir" "$executable" "$@" < /dev/null)
  done
}
