#!/usr/bin/env bash
# The project's test command (README: "Run the tests"). Everything a test needs is set up here, so a fresh machine
# needs no hand work.
#
# Builds. Cargo resolves the features of some dependencies (build dependencies and proc-macros among them)
# according to the targets a command selects, and compiles a crate again for each different set: iceoryx2 and much
# of the workspace, about a minute each time on two cores. So one test build (`cargo test --workspace`: libraries,
# binaries, tests, examples and doc tests) serves the Python tests, the test run with the doc tests and the
# multicast rerun, and the planted bugs (the mutation switch, a cargo feature a normal build never enables)
# compile only the crates the switch changes. The criterion benches are not run here: selecting them
# (`--all-targets`, `--benches`) resolves the other set; clippy (`--all-targets`, in .ci/run) compiles them.
set -euo pipefail
cd "$(dirname "$0")/.."
# DDS Security's OpenSSL is built from source: it needs perl (with its core modules) and make.
bash scripts/build-deps.sh
# The inspector's browser test (impl/inspector/tests/browser.rs) drives Debian's chromium through chromedriver.
if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then
  if [ "$(id -u)" = 0 ]; then
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver) >/dev/null
  else
    echo "note: chromium or chromedriver missing and not root: the inspector's browser test skips (fails under CI)" >&2
  fi
fi
# The chaos campaign's test (harness/tests/chaos.rs) builds network namespaces with `ip` and faults with `nft`.
if [ "$(id -u)" = 0 ]; then
  bash scripts/chaos-deps.sh
else
  echo "note: not root: the chaos campaign's test does not run (it needs network namespaces and nftables)" >&2
fi
# The Python module `cortex_dsr` (python/): installs python3-venv if needed (pyo3's build script, in the workspace
# build too, asks python3 for its version), builds the module with maturin into a venv under the target directory
# and the `cortex` binary, and runs the Python tests, including a Python agent beside `cortex agent` processes.
bash scripts/test-python.sh
# No import cycle between the modules of any crate (ARCHITECTURE.md, "Conventions").
python3 scripts/module-cycles.py
# Every intra-doc link resolves and no public item's documentation links to a private one (the API docs a user
# reads, `cargo doc`): about half a minute once clippy has checked the workspace.
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --quiet
cargo test --workspace
# The RTPS tests once more in a fresh network namespace whose loopback is multicast-capable, where
# `RtpsConfig::multicast` (default `Auto`) turns multicast on (two participants per transport, one datagram for all
# same-host readers), plus a non-loopback address on lo as any networked host has (rustdds never routes unicast to
# a reader that advertises only 127.0.0.1, so per-reader repairs would go to the whole group; measure::netns does the
# same). The bench tests in harness/tests/bench_netns.rs make their own namespaces. The executables are those the
# command above built and ran (scripts/test-binaries.py says why not `cargo test --test NAME`), run as cargo runs them.
if [ "$(id -u)" = 0 ] && command -v ip >/dev/null && unshare --net -- true 2>/dev/null; then
  binaries="$(mktemp)"
  trap 'rm -f "$binaries"' EXIT
  cargo test --workspace --no-run --message-format=json \
    | python3 scripts/test-binaries.py rtps_loopback calls agents_multiprocess agents_roles agents_pause > "$binaries"
  unshare --net -- bash -c 'set -e; ip link set lo up; ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo
    ip addr add 198.18.0.1/32 dev lo
    while IFS="$(printf "\t")" read -r dir executable; do
      echo "     Running $executable (multicast on lo)"
      (cd "$dir" && CARGO_MANIFEST_DIR="$dir" "$executable")
    done < "$1"' bash "$binaries"
else
  echo "note: not root, unshare/ip missing, or no new network namespace allowed here: the RTPS tests do not run again with multicast on lo" >&2
fi
# The planted bugs, in one build with the mutation switch: the tests that plant them (bica's, the model's and the
# command's tests/mutants.rs, the scheduler model's `mod mutants`), and the convergence and agents models with the
# switch built in and no bug planted (the baseline: a mutant is killed by the property that holds without it).
cargo test --workspace --features harness/mutants \
  --test mutants --test scheduler_model --test convergence_model --test agents_model
