#!/usr/bin/env python3
"""Lists test executables from cargo's JSON build messages.

Usage: cargo test --workspace --no-run --message-format=json \\
         | python3 scripts/test-binaries.py [--package P] [--not-package P] [--label-suffix S] [NAME...]

Prints one line per test executable, in the order `cargo test` runs them (by package, then the library's unit
tests, the binaries', the integration tests by name): its package's directory, a tab, the executable, a tab, what
cargo's "Running" line calls it (`package: unittests src/lib.rs`, `package: tests/NAME.rs`). With NAMEs, only the
integration-test targets of those names; exits with 1, naming them, if one is missing from the messages.
`--package` keeps one package's executables, `--not-package` drops one package's (each may be given more than once);
`--label-suffix` is appended to every label (` (multicast on lo)` for a rerun).

scripts/test.sh runs the test executables of its one test build this way: a cargo command that selected only some
targets would resolve some dependencies' features differently and compile much of the workspace again (cargo's
feature resolution depends on the targets selected), and a `cargo test` would wait for the build directory's lock
while the test command builds something else in the background.
"""

import argparse
import json
import os
import sys

# The order `cargo test` runs a package's targets in.
KIND_ORDER = {"lib": 0, "bin": 1, "test": 2}


def executables(lines):
    """(package, kind, target, directory, executable, label) of every test executable in the messages."""
    found = {}
    for line in lines:
        if not line.startswith("{"):
            continue
        message = json.loads(line)
        executable = message.get("executable")
        if message.get("reason") != "compiler-artifact" or not executable:
            continue
        if not message.get("profile", {}).get("test"):
            continue  # a binary built for the tests to run, or an example: not a test executable
        target = message["target"]
        kind = target["kind"][0] if target["kind"][0] in KIND_ORDER else "lib"
        directory = os.path.dirname(message["manifest_path"])
        package = package_name(message)
        source = os.path.relpath(target["src_path"], directory)
        label = f"{package}: {'unittests ' if kind != 'test' else ''}{source}"
        found[executable] = (package, kind, target["name"], directory, executable, label)
    return sorted(found.values(), key=lambda e: (e[0], KIND_ORDER[e[1]], e[2]))


def package_name(message):
    """The package's name from a package id (`path+file:///…/dir#name@0.1.0` or `…/dir#0.1.0`)."""
    spec = message["package_id"].rsplit("#", 1)[-1]
    name = spec.split("@", 1)[0]
    if name[:1].isdigit():  # `…/dir#0.1.0`: the directory is the name
        return message["package_id"].rsplit("#", 1)[0].rstrip("/").rsplit("/", 1)[-1]
    return name


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--package", action="append", default=[])
    parser.add_argument("--not-package", action="append", default=[])
    parser.add_argument("--label-suffix", default="")
    parser.add_argument("names", nargs="*")
    args = parser.parse_args(argv)
    chosen = [
        e
        for e in executables(sys.stdin)
        if (not args.package or e[0] in args.package) and e[0] not in args.not_package
    ]
    if args.names:
        by_name = {e[2]: e for e in chosen if e[1] == "test"}
        missing = [name for name in args.names if name not in by_name]
        if missing:
            print(f"test-binaries: no test target named {', '.join(missing)} in the build messages", file=sys.stderr)
            return 1
        chosen = [by_name[name] for name in args.names]
    for package, kind, name, directory, executable, label in chosen:
        print("\t".join((directory, executable, label + args.label_suffix)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
