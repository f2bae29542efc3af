#!/usr/bin/env bash
# How much a long-lived agent's memory grows with the joins of others (README, Status: "Memory against the joins of
# others").
#
# Starts a camera agent (id 1, a 360,960-byte frame at 20 Hz) and a follower (id 2), then JOINS short-lived agents
# one after the other (id 11, no state directory, so each is a new participant and a new life: it joins, runs
# 1.5 s and stops), and prints both long-lived agents' resident set size (VmRSS, kB) before, every EVERY joins and
# 5 s after the last.
#
#   scripts/joins-memory.sh [JOINS] [TRANSPORT] [DOMAIN]      (defaults: 100 rtps 44)
#   CORTEX=path/to/cortex EVERY=50 scripts/joins-memory.sh 400
#
# CORTEX defaults to target/release/cortex (build it first: cargo build --release -p harness).
set -euo pipefail
cd "$(dirname "$0")/.."
joins=${1:-100}
transport=${2:-rtps}
domain=${3:-44}
every=${EVERY:-50}
cortex=$(realpath "${CORTEX:-target/release/cortex}")
work=$(mktemp -d)
cd "$work"
"$cortex" agent --id 1 --domain "$domain" --transport "$transport" --role fixture-camera --period-ms 50 \
  --state-dir none > writer.log 2>&1 &
writer=$!
sleep 3
"$cortex" agent --id 2 --domain "$domain" --transport "$transport" --state-dir none > follower.log 2>&1 &
follower=$!
trap 'kill -INT $writer $follower 2>/dev/null; wait; rm -rf "$work"' EXIT
sleep 8
rss() {
  echo "$1: camera agent $(awk '/VmRSS/{print $2}' /proc/$writer/status) kB," \
    "follower $(awk '/VmRSS/{print $2}' /proc/$follower/status) kB"
}
rss "before"
for j in $(seq 1 "$joins"); do
  "$cortex" agent --id 11 --domain "$domain" --transport "$transport" --state-dir none --run-for-ms 1500 \
    --join-wait-ms 1000 > /dev/null 2>&1 || echo "join $j: the joiner failed" >&2
  if [ $((j % every)) = 0 ]; then rss "after $j joins"; fi
done
sleep 5
rss "5 s later"
