#!/usr/bin/env bash
# What building the workspace needs besides Rust and a C compiler: DDS Security (rustdds's `security` feature,
# issue 22) links the system's OpenSSL, which `openssl-sys` finds through pkg-config (Debian's libssl-dev and
# pkg-config). Installs whichever is missing (Debian packages; needs root). Safe to run again.
#
# Without them, `--features vendored-openssl` on the harness builds OpenSSL from source instead (then `make` and
# `perl` with its core modules are needed; about three minutes of one core, once per profile).
set -euo pipefail
source "$(dirname "$0")/apt-missing.sh"
missing=()
command -v pkg-config >/dev/null || missing+=(pkg-config)
pkg-config --exists openssl 2>/dev/null || missing+=(libssl-dev)
install_missing build-deps "install them (DDS Security links OpenSSL)" "${missing[@]}"
