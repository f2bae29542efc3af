#!/usr/bin/env bash
# The Python module's part of the test command (scripts/test.sh runs it; it also runs alone): builds `cortex_dsr`
# into a virtual environment under the cargo target directory with maturin, builds the `cortex` binary for the
# two-process and ROS 2 bridge tests, and runs the Python tests (plain unittest). As root on a machine without
# Python's venv module, installs it first with apt.
#
# `scripts/test-python.sh build` stops once the module is installed and `scripts/test-python.sh run` only runs the
# tests: scripts/test.sh builds in the background while the Rust tests run, and runs these tests after them.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-$PWD/target}"
venv="$target/python-venv"

build_module() {
  if ! command -v python3 >/dev/null || ! python3 -c 'import venv, ensurepip' 2>/dev/null; then
    if [ "$(id -u)" = 0 ]; then
      (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3 python3-venv python3-pip) >/dev/null
    else
      echo "error: python3 with its venv module is needed (Debian: apt-get install python3-venv)" >&2
      exit 1
    fi
  fi
  if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
  fi
  # cyclonedds: Eclipse Cyclone DDS's Python binding (its wheel bundles the C library), the second vendor's DDS
  # that python/tests/test_ros2_bridge.py runs `cortex bridge ros2` against.
  "$venv/bin/python" -m pip install -q --disable-pip-version-check "maturin>=1.9,<2" "numpy>=1.21" "cyclonedds>=11,<12"
  # The `cortex` binary as the workspace's test build makes it (for the command's own tests; nothing to do when
  # scripts/test.sh has made that build: a plain `cargo build` resolves some dependencies' features differently
  # and would compile much of the workspace twice).
  cargo test -q --workspace --no-run
  # A debug build, installed into the venv (README: `pip install ./python` builds the release wheel instead).
  # maturin builds the one package, so cargo resolves its dependencies' features for it alone: about two minutes
  # of compiling on two cores that the workspace's build does not share.
  VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" maturin develop -q --manifest-path python/Cargo.toml
}

run_tests() {
  CARGO_TARGET_DIR="$target" "$venv/bin/python" -m unittest discover -s python/tests -t python/tests -v
}

case "${1:-all}" in
  all) build_module; run_tests ;;
  build) build_module ;;
  run) run_tests ;;
  *) echo "usage: $0 [build|run]" >&2; exit 2 ;;
esac
