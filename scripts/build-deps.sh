#!/usr/bin/env bash
# What building the workspace needs besides Rust and a C compiler: DDS Security (rustdds's `security` feature,
# issue 22) links OpenSSL, which the build compiles from source (`transport`'s `vendored-openssl`, so no system
# libssl-dev is needed); OpenSSL's configuration needs `perl` with its core modules (IPC::Cmd; Debian's perl-base
# alone lacks them) and `make`. Installs whichever is missing (Debian packages; needs root). Safe to run again.
set -euo pipefail
missing=()
perl -MIPC::Cmd -MFile::Compare -e1 2>/dev/null || missing+=(perl)
command -v make >/dev/null || missing+=(make)
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
if [ "$(id -u)" != 0 ]; then
  echo "build-deps: ${missing[*]} missing and not root: install them (the OpenSSL build needs them)" >&2
  exit 1
fi
(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}") >/dev/null
