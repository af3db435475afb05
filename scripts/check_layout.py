#!/usr/bin/env python3
"""The code's layout, checked (CI runs it): no Rust file over 1,000 lines, and no import cycle
between the modules (files) of any crate. A cycle is reported with each module's imports
inside it; break it by moving the shared piece down a floor (docs/architecture.md, "Floors").

Usage: scripts/check_layout.py [ROOT]   (default: the repository root). Exit 1 on a finding.
"""
import os
import re
import sys

MAX_LINES = 1000


def rust_files(root):
    for top in ("src", "plugins", "tests"):
        for folder, dirs, files in os.walk(os.path.join(root, top)):
            dirs[:] = [d for d in dirs if d != "target"]
            for name in files:
                if name.endswith(".rs"):
                    yield os.path.join(folder, name)


def crate_roots(root):
    """Each crate's `src` folder: the app's and every plugin's."""
    yield os.path.join(root, "src")
    plugins = os.path.join(root, "plugins")
    for name in sorted(os.listdir(plugins)):
        src = os.path.join(plugins, name, "src")
        if os.path.isdir(src):
            yield src


def module_of(src, path):
    rel = os.path.relpath(path, src)[: -len(".rs")]
    parts = [p for p in rel.split(os.sep) if p != "mod"]
    name = "::".join(parts)
    return "" if name in ("lib", "main") else name


def imports(text, module, modules):
    """The crate's modules that `module`'s code names (test modules left out)."""
    text = re.sub(r"//[^\n]*", "", text)
    cut = text.find("#[cfg(test)]\nmod tests")
    if cut >= 0:
        text = text[:cut]

    def resolve(path):
        parts = [p for p in path.split("::") if p]
        for k in range(len(parts), 0, -1):
            candidate = "::".join(parts[:k])
            if candidate in modules:
                return candidate
        return None

    found = set()
    for group in re.finditer(r"use crate::\{([^;]*)\};", text, re.S):
        for item in re.split(r",(?![^{]*\})", group.group(1)):
            item = item.strip()
            if "{" in item:
                prefix, inner = item.split("{", 1)
                for sub in inner.rstrip("}").split(","):
                    if sub.strip():
                        found.add(resolve(prefix + sub.strip().split(" as ")[0]))
            elif item:
                found.add(resolve(item.split(" as ")[0]))
    for path in re.finditer(r"crate::([a-z_][\w:]*)", text):
        found.add(resolve(path.group(1)))
    parent = module.rsplit("::", 1)[0] if "::" in module else ""
    for path in re.finditer(r"super::([a-z_][\w:]*)", text):
        found.add(resolve(f"{parent}::{path.group(1)}" if parent else path.group(1)))
    # A module and its own parent or children are one room.
    return {
        m
        for m in found
        if m and m != module and not m.startswith(module + "::") and not module.startswith(m + "::")
    }


def cycles(edges):
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    sys.setrecursionlimit(10000)
    for v in sorted(edges):
        if v not in index:
            strong(v)
    return out


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
    findings = []
    for path in sorted(rust_files(root)):
        with open(path, encoding="utf-8") as f:
            n = sum(1 for _ in f)
        if n > MAX_LINES:
            findings.append(f"{os.path.relpath(path, root)}: {n} lines (at most {MAX_LINES}: split it by concern)")
    for src in crate_roots(root):
        files = {}
        for folder, _, names in os.walk(src):
            for name in names:
                if name.endswith(".rs"):
                    path = os.path.join(folder, name)
                    with open(path, encoding="utf-8") as f:
                        files[module_of(src, path)] = f.read()
        modules = set(files)
        edges = {m: imports(text, m, modules) for m, text in files.items()}
        crate = os.path.relpath(src, root)
        for component in cycles(edges):
            inside = "; ".join(f"{m} -> {', '.join(sorted(edges[m] & set(component)))}" for m in component)
            findings.append(f"{crate}: import cycle between {', '.join(component)} ({inside})")
    for f in findings:
        print(f"layout: {f}")
    if findings:
        sys.exit(1)
    print("layout: no Rust file over 1000 lines, no import cycle")


if __name__ == "__main__":
    main()
