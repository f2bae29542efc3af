#!/usr/bin/env bash
# What one small update costs on its way between two agents over same-host shared memory, counted rather than
# timed: instructions, and the cache lines it touches when it starts cold (a sensor's rate: each sample finds the
# cores' caches holding nothing of the agents). Deterministic for one binary: valgrind's callgrind simulates the
# caches, and `impl/agent/examples/hop_cost.rs` flushes them between hops. Beside the agents, the same loop over
# their shared-memory transport alone, so that the agents' own share shows.
#
#   bash scripts/hop-footprint.sh [HOPS] [TOP]     # defaults: 100 hops, the 25 functions with most lines
#
# Needs valgrind (Debian's `valgrind`). About a minute on two cores after the example's release build.
set -euo pipefail
cd "$(dirname "$0")/.."
hops=${1:-100}
top=${2:-25}
command -v valgrind >/dev/null || { echo "hop-footprint: valgrind is not installed (apt-get install valgrind)" >&2; exit 2; }
cargo build --release --quiet -p agent --example hop_cost
bin="${CARGO_TARGET_DIR:-target}/release/examples/hop_cost"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for mode in transport agents; do
    for n in "$hops" $((2 * hops)); do
        # Collected only inside the hop loops: the writer's, the transport's receiving thread's, and the receiving
        # agent's turns (which include its join, the same in both runs).
        HOP_COST_FLUSH_MB=64 valgrind --tool=callgrind --cache-sim=yes --LL=8388608,16,64 --collect-atstart=no \
            --toggle-collect='hop_cost::write_loop*' --toggle-collect='hop_cost::receive_loop*' \
            --toggle-collect='*Inner<T>>::serve_once' \
            --callgrind-out-file="$out/$mode.$n" "$bin" "$mode" "$n" >/dev/null 2>&1
    done
    echo "== $mode ($(git rev-parse --short HEAD)$(git diff --quiet || echo '+changes'))"
    python3 scripts/hop-footprint.py "$out/$mode.$hops" "$out/$mode.$((2 * hops))" "$hops" \
        "$([ "$mode" = agents ] && echo "$top" || echo 0)"
done
