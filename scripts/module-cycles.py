#!/usr/bin/env python3
"""Finds import cycles between the modules of every crate in the workspace.

Usage: python3 scripts/module-cycles.py [CRATE_DIR ...]   (default: every crate of the workspace)

Exit code 0 when no crate has a cycle, 1 otherwise (each cycle is printed).

What counts as an import: every `crate::…`, `super::…` and `self::…` path in a source file (in `use` trees and
inline), resolved to the module that defines the item, through `pub use` re-exports. A use of a module's own
descendants or ancestors is structure, not layering (a parent declares and re-exports its children, a child uses its
parent's shared types), so an edge from module M to module T is lifted to the two children of their lowest common
ancestor that contain M and T, and a cycle is a strongly connected set of sibling modules. Test code sits above
everything it tests, so `#[cfg(test)]` modules (inline blocks and files) are left out.

The check reads source text (comments and string literals stripped); it does not expand macros.
"""

import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def strip_comments_and_strings(text):
    """Removes comments, string and char literals, keeping line structure roughly intact."""
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    text = re.sub(r'r(#*)".*?"\1', '""', text, flags=re.S)
    text = re.sub(r'"(?:\\.|[^"\\])*"', '""', text, flags=re.S)
    text = re.sub(r"//[^\n]*", "", text)
    return text


TEST_MOD_RE = re.compile(r"#\[cfg\(test\)\]\s*(?:#\[[^\]]*\]\s*)*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*([;{])")


def strip_test_modules(text):
    """Removes inline `#[cfg(test)] mod x { ... }` blocks; returns the text and the names of `#[cfg(test)] mod x;`."""
    out, files, pos = [], set(), 0
    for match in TEST_MOD_RE.finditer(text):
        if match.start() < pos:
            continue
        if match.group(2) == ";":
            files.add(match.group(1))
            continue
        depth, i = 0, match.end() - 1
        while i < len(text):
            if text[i] == "{":
                depth += 1
            elif text[i] == "}":
                depth -= 1
                if depth == 0:
                    break
            i += 1
        out.append(text[pos : match.start()])
        pos = i + 1
    out.append(text[pos:])
    return "".join(out), files


def module_files(src):
    """Maps module path (tuple of names) to its file, for every .rs file under a crate's src/."""
    modules = {}
    for path in sorted(src.rglob("*.rs")):
        rel = path.relative_to(src).with_suffix("")
        parts = list(rel.parts)
        if parts in (["lib"], ["main"]):
            parts = []
        elif parts[-1] == "mod":
            parts = parts[:-1]
        elif len(parts) >= 2 and parts[0] == "bin":
            continue  # binaries are crates of their own
        modules[tuple(parts)] = path
    return modules


def expand_use_tree(tree):
    """Expands `a::{b, c::{d, e}}` into ["a::b", "a::c::d", "a::c::e"] (globs and `as` renames kept as names)."""
    tree = re.sub(r"\s+", "", tree)
    depth, split_at = 0, None
    for i, ch in enumerate(tree):
        if ch == "{":
            if depth == 0 and split_at is None:
                split_at = i
            depth += 1
        elif ch == "}":
            depth -= 1
    if split_at is None:
        return [re.sub(r"as\w+$", "", tree)] if tree else []
    prefix, inner = tree[:split_at], tree[split_at + 1 : tree.rfind("}")]
    parts, depth, start = [], 0, 0
    for i, ch in enumerate(inner):
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(inner[start:i])
            start = i + 1
    parts.append(inner[start:])
    out = []
    for part in parts:
        for sub in expand_use_tree(part):
            out.append(prefix + sub if sub != "self" else prefix.rstrip(":"))
    return out


USE_RE = re.compile(r"\b(pub(?:\([^)]*\))?\s+)?use\s+([^;]+);")
PATH_RE = re.compile(r"\b((?:crate|super|self)(?:::(?:super|[A-Za-z_][A-Za-z0-9_]*))+)")


def absolute(module, path):
    """Turns a `crate::`/`super::`/`self::` path used in `module` into a list of segments from the crate root."""
    segs = path.split("::")
    if segs[0] == "crate":
        return segs[1:]
    base = list(module)
    while segs and segs[0] in ("super", "self"):
        if segs[0] == "super":
            if not base:
                return None
            base.pop()
        segs = segs[1:]
    return base + segs


def analyse(src):
    modules = module_files(src)
    texts, test_children = {}, set()
    for module, path in modules.items():
        text, files = strip_test_modules(strip_comments_and_strings(path.read_text(encoding="utf-8")))
        texts[module] = text
        test_children.update(module + (name,) for name in files)
    tests = {m for m in modules if any(m[: len(t)] == t for t in test_children)}
    modules = {m: p for m, p in modules.items() if m not in tests}
    texts = {m: t for m, t in texts.items() if m not in tests}
    reexports = {}  # (module, name) -> absolute path segments
    refs = {m: [] for m in modules}
    for module, text in texts.items():
        for match in USE_RE.finditer(text):
            is_pub = match.group(1) is not None
            for path in expand_use_tree(match.group(2)):
                first = path.split("::")[0]
                if first not in ("crate", "super", "self") and tuple(list(module) + [first]) not in modules:
                    continue  # an external crate
                if first not in ("crate", "super", "self"):
                    path = "self::" + path
                segs = absolute(module, path)
                if segs is None:
                    continue
                refs[module].append(segs)
                if is_pub and segs and segs[-1] != "*":
                    reexports[(module, segs[-1])] = segs
        for match in PATH_RE.finditer(text):
            segs = absolute(module, match.group(1))
            if segs is not None:
                refs[module].append(segs)

    def resolve(segs, seen=0):
        longest = ()
        for i in range(len(segs) + 1):
            if tuple(segs[:i]) in modules:
                longest = tuple(segs[:i])
        rest = segs[len(longest) :]
        if rest and (longest, rest[0]) in reexports and seen < 8:
            target = reexports[(longest, rest[0])]
            if target != segs:
                return resolve(target + rest[1:], seen + 1)
        return longest

    edges = {}  # parent -> {child: set(children)}
    for module, paths in refs.items():
        for segs in paths:
            target = resolve(segs)
            common = 0
            while common < min(len(module), len(target)) and module[common] == target[common]:
                common += 1
            if common == len(module) or common == len(target):
                continue  # ancestor or descendant
            parent = module[:common]
            edges.setdefault(parent, {}).setdefault(module[common], set()).add(target[common])
    return modules, edges


def cycles(graph):
    """Tarjan's strongly connected components with more than one member."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def crates():
    for manifest in sorted(ROOT.glob("**/Cargo.toml")):
        if "target" in manifest.parts or manifest.parent == ROOT:
            continue
        if (manifest.parent / "src").is_dir():
            yield manifest.parent


def main(argv):
    dirs = [Path(a).resolve() for a in argv] or list(crates())
    failed = False
    for crate in dirs:
        modules, edges = analyse(crate / "src")
        found = []
        for parent, graph in sorted(edges.items()):
            for comp in cycles(graph):
                found.append((parent, comp))
        name = os.path.relpath(crate, ROOT) if crate.is_relative_to(ROOT) else str(crate)
        if not found:
            print(f"{name}: {len(modules)} modules, no import cycle")
            continue
        failed = True
        for parent, comp in found:
            where = "::".join(("crate",) + parent)
            detail = "; ".join(
                f"{a} -> {', '.join(sorted(b for b in edges[parent][a] if b in comp))}" for a in comp
            )
            print(f"{name}: import cycle among {where}::{{{', '.join(comp)}}}: {detail}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
