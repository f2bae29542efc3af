#!/usr/bin/env bash
# What `cortex chaos` needs besides the `cortex` binary: `ip` (iproute2) for the network namespaces, veth pairs
# and the bridge, and `nft` (nftables) for the loss, one-way and partition rules. Installs whichever is missing
# (Debian packages; needs root, as the campaign itself does). Safe to run again.
set -euo pipefail
source "$(dirname "$0")/apt-missing.sh"
missing=()
command -v ip >/dev/null || missing+=(iproute2)
command -v nft >/dev/null || missing+=(nftables)
install_missing chaos-deps "run as root (cortex chaos needs root anyway)" "${missing[@]}"
