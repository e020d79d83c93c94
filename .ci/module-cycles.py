#!/usr/bin/env python3
"""Fails if a library crate's top-level modules import each other in a cycle.

Why (issue 41): a layer that imports the layer above it cannot be read, tested or
replaced on its own; esgm-shm's layers are drawn in ARCHITECTURE.md (the data plane
under the process helpers, under the control plane, under the client), and a cycle
between two of them means one no longer sits under the other.

A module's edges are the `crate::<module>` paths its files name (in `use` lines and in
code; comments and doc comments are left out), each file counting for the top-level
module it belongs to (`src/control/server.rs` is `control`; `src/process.rs` and
`src/process/access.rs` are `process`). The crate root (`lib.rs`) is left out, as it
only declares and re-exports. Test code is left out too: a `#[cfg(test)]` module,
inline or in its own file, may use any layer to build its fixtures without being one.

Usage: module-cycles.py SRC_DIR [SRC_DIR...]; prints each crate's edges and exits 1
on a cycle, naming it and a file for each of its edges.
"""

import os
import re
import sys

PATH = re.compile(r"\bcrate::([a-z_][a-z0-9_]*)")
GROUP = re.compile(r"\bcrate::\{([^}]*)\}", re.S)


def code_of(text):
    """The text without comments (line and block) and string literals."""
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    out = []
    for line in text.splitlines():
        line = re.sub(r'"(\\.|[^"\\])*"', '""', line)
        cut = line.find("//")
        out.append(line if cut < 0 else line[:cut])
    return "\n".join(out)


TEST_BLOCK = re.compile(r"#\[cfg\(test\)\]\s*(?:pub(?:\([a-z]+\))?\s+)?mod\s+[a-z_][a-z0-9_]*\s*\{")
TEST_FILE = re.compile(r"#\[cfg\(test\)\]\s*(?:pub(?:\([a-z]+\))?\s+)?mod\s+([a-z_][a-z0-9_]*)\s*;")


def without_test_blocks(code):
    """The code without its inline `#[cfg(test)] mod x { ... }` blocks (comments and
    strings are already gone, so braces balance)."""
    while True:
        m = TEST_BLOCK.search(code)
        if not m:
            return code
        depth, i = 1, m.end()
        while i < len(code) and depth:
            depth += {"{": 1, "}": -1}.get(code[i], 0)
            i += 1
        code = code[: m.start()] + code[i:]


def test_files(path, code):
    """The files of the `#[cfg(test)] mod x;` declarations in `path`'s code."""
    base = os.path.dirname(path)
    name = os.path.basename(path)
    if name not in ("mod.rs", "lib.rs", "main.rs"):
        base = os.path.join(base, name[:-3])
    found = set()
    for module in TEST_FILE.findall(code):
        found.add(os.path.normpath(os.path.join(base, module + ".rs")))
        found.add(os.path.normpath(os.path.join(base, module, "mod.rs")))
    return found


def modules_of(src):
    """Top-level module name -> list of its .rs files."""
    mods = {}
    for entry in sorted(os.listdir(src)):
        full = os.path.join(src, entry)
        if entry.endswith(".rs") and entry not in ("lib.rs", "main.rs"):
            mods.setdefault(entry[:-3], []).append(full)
        elif os.path.isdir(full):
            for root, _, files in os.walk(full):
                for f in files:
                    if f.endswith(".rs"):
                        mods.setdefault(entry, []).append(os.path.join(root, f))
    return mods


def edges_of(mods):
    codes, tests = {}, set()
    for files in mods.values():
        for f in files:
            codes[f] = code_of(open(f, encoding="utf-8").read())
            tests |= test_files(f, codes[f])
    edges = {}
    for mod, files in mods.items():
        for f in files:
            if os.path.normpath(f) in tests:
                continue
            code = without_test_blocks(codes[f])
            named = set(PATH.findall(code))
            for group in GROUP.findall(code):
                named.update(re.findall(r"(?:^|,)\s*([a-z_][a-z0-9_]*)", group))
            for other in named:
                if other != mod and other in mods:
                    edges.setdefault((mod, other), f)
    return edges


def cycles(mods, edges):
    graph = {m: sorted(o for (a, o) in edges if a == m) for m in mods}
    found, state, stack = [], {}, []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for o in graph[m]:
            if state.get(o) == "open":
                found.append(stack[stack.index(o):] + [o])
            elif o not in state:
                visit(o)
        stack.pop()
        state[m] = "done"

    for m in sorted(mods):
        if m not in state:
            visit(m)
    return found


def main():
    failed = False
    for src in sys.argv[1:]:
        mods = modules_of(src)
        edges = edges_of(mods)
        print(f"{src}: {len(mods)} modules, {len(edges)} edges")
        for cycle in cycles(mods, edges):
            failed = True
            print(f"  cycle: {' -> '.join(cycle)}", file=sys.stderr)
            for a, b in zip(cycle, cycle[1:]):
                print(f"    {a} -> {b}: {edges[(a, b)]}", file=sys.stderr)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
