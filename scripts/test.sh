#!/usr/bin/env bash
# The project's test command (README: "Run the tests"). Everything a test needs is set up here, so a fresh machine
# needs no hand work.
#
# Builds. Cargo resolves the features of some dependencies (build dependencies and proc-macros among them) according to
# the targets a command selects, and compiles a crate again for each different set: iceoryx2 and much of the workspace,
# about a minute each time on two cores. So one test build (`cargo test --workspace --no-run`: libraries, binaries,
# tests and examples, the Python extension among them) serves every test executable (the Python tests' too), the doc
# tests and the multicast rerun, and the planted bugs (the mutation switch, a cargo feature a normal build never
# enables) compile only the crates the switch changes. The criterion benches are not run here: selecting them
# (`--all-targets`, `--benches`) resolves the other set; clippy (`--all-targets`, in .ci/run) compiles them.
#
# Two lanes. Most tests run real processes and wait on them, leaving the machine half idle; the work that only
# needs CPU (the doc tests, the mutants' build and the model checks of the default configuration and of the
# planted bugs) runs meanwhile in a background lane at the lowest priority (`nice 19`),
# so it takes the idle time and yields the processors to the tests at once. The background lane's output is
# printed when it ends; a failure in either lane fails the command.
set -euo pipefail
cd "$(dirname "$0")/.."
# DDS Security links the system's OpenSSL: libssl-dev and pkg-config.
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
# The Python tests' virtual environment (numpy, cyclonedds); the test run below runs them (python/tests/python.rs).
bash scripts/test-python.sh venv
# No import cycle between the modules of any crate (ARCHITECTURE.md, "Conventions").
python3 scripts/module-cycles.py

target="${CARGO_TARGET_DIR:-$PWD/target}"
work="$(mktemp -d)"
background=""
# On the way out: a background lane still running (the foreground failed) is stopped, and its output so far shown.
cleanup() {
  if [ -n "$background" ] && [ ! -e "$work/background.rc" ]; then
    kill -- "-$background" 2>/dev/null || true
    for _ in $(seq 50); do
      kill -0 -- "-$background" 2>/dev/null || break
      sleep 0.2
    done
    echo "note: the background lane was stopped; its output until then:" >&2
    cat "$work/background.log" >&2 || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT

# The one test build, and the list of its test executables.
cargo test --workspace --no-run --message-format=json-render-diagnostics > "$work/build.json"
# Every intra-doc link resolves and no public item's documentation links to a private one (the API docs a user
# reads, `cargo doc`).
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --quiet

# The default `cortex check convergence` (3 replicas, 3 operations, a clock advance: some 3.3 million states), run
# in the background lane instead of with the other tests of its file.
default_check=three_replicas_three_ops_one_clock_advance_the_default_check_converge_and_match_the_spec_in_every_state

# The background lane. The mutants build comes before the model checks, so that the foreground can run the
# command's planted-bug tests while they run; it leaves a file in $work for the foreground to wait on.
background_lane() {
  set -euo pipefail
  trap 'echo $? > "$work/background.rc"' EXIT
  cargo test --workspace --doc
  # The planted bugs, in one build with the mutation switch: the tests that plant them (bica's, the model's and
  # the command's tests/mutants.rs, the scheduler model's `mod mutants`), and the scheduler model with the switch
  # built in and no bug planted. The model's tests/mutants.rs checks the other baseline itself (a mutant is killed
  # by a property that holds without it): each mutant's convergence or agents configuration, nothing planted. The command's tests/mutants.rs runs a chaos campaign, so it runs in the foreground. The build's
  # final artifacts go to a directory of their own, so that its `cortex` does not replace the one the foreground's
  # tests are running; it shares the intermediate ones (`build.build-dir`), so only what the switch changes is
  # compiled.
  CARGO_BUILD_BUILD_DIR="$target" CARGO_TARGET_DIR="$target/mutants" \
    cargo test --workspace --features harness/mutants --no-run --message-format=json-render-diagnostics \
    --test mutants --test scheduler_model > "$work/mutants.json"
  touch "$work/mutants.built"
  python3 scripts/test-binaries.py convergence_model < "$work/build.json" | run_tests --exact "$default_check"
  python3 scripts/test-binaries.py --not-package harness < "$work/mutants.json" | run_tests
}

# run_tests: the test executables listed on standard input, as `cargo test` runs them.
source scripts/run-tests.sh

# Waits until the background lane has left the file $1 in $work; fails, with the lane's output, if the lane ended
# without it.
await() {
  while [ ! -e "$work/$1" ]; do
    if [ -e "$work/background.rc" ]; then
      echo "error: the background lane ended before $1 (exit code $(cat "$work/background.rc")); its output:" >&2
      cat "$work/background.log" >&2
      exit 1
    fi
    sleep 1
  done
}

export work target default_check
export -f background_lane run_tests
setsid nice -n 19 bash -c background_lane > "$work/background.log" 2>&1 < /dev/null &
background=$!

# The foreground lane: every test executable of the build (the default check is the background's).
python3 scripts/test-binaries.py < "$work/build.json" | run_tests --skip "$default_check"
# The RTPS tests once more in a fresh network namespace whose loopback is multicast-capable, where
# `RtpsConfig::multicast` (default `Auto`) turns multicast on (two participants per transport, one datagram for all
# same-host readers), plus a non-loopback address on lo as any networked host has (rustdds never routes unicast to
# a reader that advertises only 127.0.0.1, so per-reader repairs would go to the whole group; measure::netns does the
# same). The bench tests in harness/tests/bench_netns.rs make their own namespaces.
if [ "$(id -u)" = 0 ] && command -v ip >/dev/null && unshare --net -- true 2>/dev/null; then
  python3 scripts/test-binaries.py --label-suffix " (multicast on lo)" \
    rtps_loopback calls agents_multiprocess agents_roles agents_pause < "$work/build.json" > "$work/multicast.tsv"
  unshare --net -- bash -c 'set -e; ip link set lo up; ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo
    ip addr add 198.18.0.1/32 dev lo
    run_tests < "$1"' bash "$work/multicast.tsv"
else
  echo "note: not root, unshare/ip missing, or no new network namespace allowed here: the RTPS tests do not run again with multicast on lo" >&2
fi
# The command's planted-bug tests (`cortex check mutants`, a campaign with a planted protocol bug).
await mutants.built
python3 scripts/test-binaries.py --package harness mutants < "$work/mutants.json" | run_tests

echo "     Waiting for the background lane (doc tests, the default convergence check, the planted bugs)"
wait "$background" || true
cat "$work/background.log"
rc="$(cat "$work/background.rc" 2>/dev/null || echo 1)"
if [ "$rc" != 0 ]; then
  echo "error: the background lane failed (exit code $rc); its output is above" >&2
  exit 1
fi
