#!/usr/bin/env bash
# The Python module's part of the test command (scripts/test.sh runs it; it also runs alone): a virtual environment
# under the cargo target directory with numpy and cyclonedds, then the workspace's test build, which builds the
# extension `cortex_dsr` and the `cortex` binary, and the test target that runs the Python tests against them
# (python/tests/python.rs: plain unittest, including a Python agent beside `cortex agent` processes). As root on a
# machine without Python's venv module, installs it first with apt.
#
# `scripts/test-python.sh venv` only makes the environment: scripts/test.sh does that, and its test run then runs
# the Python tests with the others.
set -euo pipefail
cd "$(dirname "$0")/.."
# run_tests: the test executables listed on standard input, as `cargo test` runs them.
source scripts/run-tests.sh
target="${CARGO_TARGET_DIR:-$PWD/target}"
venv="$target/python-venv"

make_venv() {
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
  "$venv/bin/python" -m pip install -q --disable-pip-version-check "numpy>=1.21" "cyclonedds>=11,<12"
}

# The workspace's test build (a build of the Python package alone resolves its dependencies' features otherwise
# and compiles much of the workspace again), then its Python test target.
run_python_tests() {
  cargo test --workspace --no-run --message-format=json-render-diagnostics \
    | python3 scripts/test-binaries.py python | run_tests
}

case "${1:-all}" in
  all) make_venv; run_python_tests ;;
  venv) make_venv ;;
  *) echo "usage: $0 [venv]" >&2; exit 2 ;;
esac
