#!/usr/bin/env python3
"""Lists the executables of named integration-test targets from cargo's JSON build messages.

Usage: cargo test --workspace --no-run --message-format=json | python3 scripts/test-binaries.py NAME...

Prints one line per executable: its package's directory, a tab, the executable. scripts/test.sh runs some test
targets a second time in another network namespace this way, from the build that ran them the first time: a cargo
command that selected only those targets would resolve some dependencies' features differently and compile much of
the workspace again (cargo's feature resolution depends on the targets selected).

Exits with 1, naming them, if a named target is missing from the messages.
"""

import json
import os
import sys


def main(names: list[str]) -> int:
    found: dict[str, tuple[str, str]] = {}
    for line in sys.stdin:
        if not line.startswith("{"):
            continue
        message = json.loads(line)
        target = message.get("target", {})
        executable = message.get("executable")
        if message.get("reason") != "compiler-artifact" or not executable or target.get("kind") != ["test"]:
            continue
        if target.get("name") in names:
            found[target["name"]] = (os.path.dirname(message["manifest_path"]), executable)
    missing = [name for name in names if name not in found]
    if missing:
        print(f"test-binaries: no test target named {', '.join(missing)} in the build messages", file=sys.stderr)
        return 1
    for name in names:
        print("\t".join(found[name]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
