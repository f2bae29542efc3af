#!/usr/bin/env bash
# What building the workspace needs besides Rust and a C compiler: DDS Security (rustdds's `security` feature,
# issue 22) links OpenSSL, which the build compiles from source (`transport`'s `vendored-openssl`, so no system
# libssl-dev is needed); OpenSSL's configuration needs `perl` with its core modules (IPC::Cmd; Debian's perl-base
# alone lacks them) and `make`. Installs whichever is missing (Debian packages; needs root). Safe to run again.
set -euo pipefail
source "$(dirname "$0")/apt-missing.sh"
missing=()
perl -MIPC::Cmd -MFile::Compare -e1 2>/dev/null || missing+=(perl)
command -v make >/dev/null || missing+=(make)
install_missing build-deps "install them (the OpenSSL build needs them)" "${missing[@]}"
