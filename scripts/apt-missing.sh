#!/usr/bin/env bash
# Sourced by the scripts that set up what a build or a test needs: `install_missing WHO HINT PACKAGE...` installs
# the Debian packages named (nothing if none), as root; not root, it says what is missing and HINT, and fails.
install_missing() {
  local who=$1 hint=$2
  shift 2
  [ $# -eq 0 ] && return 0
  if [ "$(id -u)" != 0 ]; then
    echo "$who: $* missing and not root: $hint" >&2
    return 1
  fi
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@") >/dev/null
}
