#!/usr/bin/env bash
# What `cortex chaos` needs besides the `cortex` binary: `ip` (iproute2) for the network namespaces, veth pairs
# and the bridge, and `nft` (nftables) for the loss, one-way and partition rules. Installs whichever is missing
# (Debian packages; needs root, as the campaign itself does). Safe to run again.
set -euo pipefail
missing=()
command -v ip >/dev/null || missing+=(iproute2)
command -v nft >/dev/null || missing+=(nftables)
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
if [ "$(id -u)" != 0 ]; then
  echo "chaos-deps: ${missing[*]} missing and not root: run as root (cortex chaos needs root anyway)" >&2
  exit 1
fi
(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}") >/dev/null
