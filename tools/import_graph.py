#!/usr/bin/env python3
"""The import graph of a Rust crate, and its circles.

    tools/import_graph.py crates/drbokeh/src            # cycles, exit 1 if any
    tools/import_graph.py crates/drbokeh/src --edges    # also print every edge

Each source file is a module (`lib.rs`/`main.rs` is `crate`, `a/mod.rs` is `crate::a`,
`a/b.rs` is `crate::a::b`). An edge `A -> B` means module A names an item that module B
defines: through a `use` declaration (re-exports included: a `pub use` is an import too) or
a path written in code (`crate::x::y`, `super::y`, `self::y`, or a path starting with a
name that a `use` brought in). Paths through re-exports are followed to the module that
defines the item, so `crate::Real` is an edge to `real`, not to the crate root. `mod`
declarations are not edges. Comments and string literals are ignored; `#[cfg(test)]`
modules count as part of their file.

Two graphs are checked: the file graph, and the folder graph where every module is
replaced by its top-level module under the crate root (`crate::engine::fast::tiles` ->
`crate::engine`); a circle in either is reported. Standard library only.
"""

import argparse
import os
import re
import sys

ITEM_RE = re.compile(
    r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:unsafe\s+)?(?:const\s+fn|async\s+fn|fn|struct|enum|trait|type|const|static|union)\s+([A-Za-z_][A-Za-z0-9_]*)",
    re.M,
)
MACRO_RE = re.compile(r"^\s*macro_rules!\s*([A-Za-z_][A-Za-z0-9_]*)", re.M)
MOD_RE = re.compile(r"^\s*(?:#\[[^\]]*\]\s*)*(?:pub(?:\([^)]*\))?\s+)?mod\s+([A-Za-z_][A-Za-z0-9_]*)\s*;", re.M)
USE_RE = re.compile(r"(?:^|[;{}\s])((?:pub(?:\([^)]*\))?\s+)?use\s+([^;]*);)", re.S)
PATH_RE = re.compile(r"(?<![A-Za-z0-9_:$])(\$?crate|super|self|[a-z_][a-z0-9_]*)((?:::[A-Za-z_][A-Za-z0-9_]*)+)")


def strip(text):
    """Removes comments, string and char literals (keeps line structure roughly)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            i = n if j < 0 else j + 2
        elif c == "r" and re.match(r'r#*"', text[i:i + 10]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'r(#*)"', text[i:])
            end = '"' + m.group(1)
            j = text.find(end, i + len(m.group(0)))
            i = n if j < 0 else j + len(end)
            out.append('""')
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            i = j + 1
            out.append('""')
        elif c == "'" and re.match(r"'(\\.|[^\\'])'", text[i:i + 4]):
            m = re.match(r"'(\\.|[^\\'])'", text[i:])
            i += len(m.group(0))
            out.append("' '")
        else:
            out.append(c)
            i += 1
    return "".join(out)


def split_use_tree(tree):
    """`a::{b, c::{d as e, self}}` -> [(['a','b'], 'b'), (['a','c','d'], 'e'), (['a','c'], 'c')]."""
    tree = re.sub(r"\s+", "", tree)
    out = []

    def walk(prefix, t):
        depth, parts, cur = 0, [], ""
        for ch in t:
            if ch == "," and depth == 0:
                parts.append(cur)
                cur = ""
                continue
            depth += ch == "{"
            depth -= ch == "}"
            cur += ch
        if cur:
            parts.append(cur)
        for p in parts:
            if "{" in p:
                head, rest = p.split("{", 1)
                head = head.rstrip(":")
                walk(prefix + ([s for s in head.split("::") if s] if head else []), rest[:-1])
            else:
                alias = None
                if "as" in p and re.search(r"[A-Za-z0-9_]as[A-Za-z_]", p):
                    m = re.match(r"(.*?)as([A-Za-z_][A-Za-z0-9_]*)$", p)
                    if m and not m.group(1).endswith(":"):
                        p, alias = m.group(1), m.group(2)
                segs = [s for s in p.split("::") if s]
                if segs == ["self"]:
                    segs = []
                path = prefix + segs
                if not path:
                    continue
                if p.endswith("*"):
                    out.append((path, "*"))
                else:
                    out.append((path, alias or path[-1]))

    walk([], tree)
    return out


def inline_modules(text):
    """The (start, end) character ranges of inline `mod name { ... }` blocks."""
    out = []
    for m in re.finditer(r"\bmod\s+[A-Za-z_][A-Za-z0-9_]*\s*\{", text):
        depth, j = 0, m.end() - 1
        while j < len(text):
            depth += text[j] == "{"
            depth -= text[j] == "}"
            if depth == 0:
                break
            j += 1
        out.append((m.start(), j))
    return out


def inside(regions, pos):
    return any(a <= pos <= b for a, b in regions)


def inline_path(segs):
    """In an inline module (a file's `mod tests { .. }`), `super` is the file's module."""
    segs = list(segs)
    if segs and segs[0] == "super":
        return ["self"] + segs[1:]
    return segs


class Crate:
    def __init__(self, src):
        self.src = os.path.abspath(src)
        self.modules = {}  # path tuple -> dict(file, text)
        for root, _, files in os.walk(self.src):
            for f in files:
                if not f.endswith(".rs"):
                    continue
                rel = os.path.relpath(os.path.join(root, f), self.src)
                parts = rel[:-3].split(os.sep)
                if parts[-1] in ("mod", "lib", "main"):
                    parts = parts[:-1]
                key = tuple(parts)
                if key in self.modules:  # both lib.rs and main.rs: keep lib.rs
                    continue
                with open(os.path.join(root, f), encoding="utf-8") as fh:
                    text = strip(fh.read())
                self.modules[key] = {"file": rel, "text": text}
        for key, m in self.modules.items():
            m["items"] = set(ITEM_RE.findall(m["text"])) | set(MACRO_RE.findall(m["text"]))
            m["inline"] = inline_modules(m["text"])
            m["uses"] = []  # (path segments, local name, is_pub)
            for u in USE_RE.finditer(m["text"]):
                full, tree = u.group(1), u.group(2)
                is_pub = full.lstrip().startswith("pub")
                for path, name in split_use_tree(tree):
                    if inside(m["inline"], u.start(1)):
                        path = inline_path(path)
                    m["uses"].append((path, name, is_pub))

    def absolute(self, module, segs):
        """Makes a path absolute (tuple of segments from the crate root) or None if external."""
        segs = list(segs)
        if not segs:
            return None
        head = segs[0]
        if head in ("crate", "$crate"):
            return tuple(segs[1:])
        if head == "self":
            return tuple(module) + tuple(segs[1:])
        if head == "super":
            base = list(module)
            while segs and segs[0] == "super":
                if base:
                    base.pop()
                segs = segs[1:]
            return tuple(base) + tuple(segs)
        if tuple(module) + (head,) in self.modules or head in self.modules[module]["items"]:
            return tuple(module) + tuple(segs)
        for path, name, _ in self.modules[module]["uses"]:
            if name == head and name != "*" and path != [head]:
                target = self.absolute(module, path)
                if target is None:
                    return None
                return target + tuple(segs[1:])
        return None

    def resolve(self, path, seen=None):
        """The module defining the item at absolute `path` (the deepest module on the path
        when the path names a module)."""
        seen = seen or set()
        if path in seen:
            return None
        seen = seen | {path}
        mod = ()
        for i, seg in enumerate(path):
            if mod + (seg,) in self.modules:
                mod = mod + (seg,)
                continue
            m = self.modules.get(mod)
            if m is None:
                return None
            if seg in m["items"]:
                return mod
            for upath, name, _ in m["uses"]:
                if name == seg:
                    target = self.absolute(mod, upath)
                    if target is None:
                        return None  # re-export of an external item
                    return self.resolve(target + tuple(path[i + 1:]), seen)
            for upath, name, _ in m["uses"]:
                if name == "*":
                    base = self.absolute(mod, upath)
                    if base is not None:
                        r = self.resolve(base + (seg,) + tuple(path[i + 1:]), seen)
                        if r is not None:
                            return r
            return mod
        return mod

    def edges(self):
        out = {}
        for key, m in self.modules.items():
            targets = set()
            for path, name, _ in m["uses"]:
                if name == "*":
                    ab = self.absolute(key, path)
                    if ab is not None:
                        r = self.resolve(ab)
                        if r is not None:
                            targets.add(r)
                    continue
                ab = self.absolute(key, path)
                if ab is not None:
                    r = self.resolve(ab)
                    if r is not None:
                        targets.add(r)
            body = USE_RE.sub(lambda u: " " * len(u.group(0)), m["text"])
            for p in PATH_RE.finditer(body):
                head, tail = p.group(1), p.group(2)
                segs = [head] + [s for s in tail.split("::") if s]
                if inside(m["inline"], p.start()):
                    segs = inline_path(segs)
                ab = self.absolute(key, segs)
                if ab is not None:
                    r = self.resolve(ab)
                    if r is not None:
                        targets.add(r)
            targets.discard(key)
            out[key] = targets
        return out


def cycles(graph):
    """Strongly connected components with more than one node (Tarjan)."""
    index, low, stack, on, comps, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
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
                comps.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return comps


def name(key):
    return "crate" + "".join("::" + k for k in key)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("src", nargs="+", help="a crate's src directory")
    ap.add_argument("--edges", action="store_true", help="print every edge")
    args = ap.parse_args()
    found = False
    for src in args.src:
        c = Crate(src)
        g = c.edges()
        folder = {}
        for a, bs in g.items():
            fa = a[:1]
            for b in bs:
                fb = b[:1]
                if fa and fb and fa != fb:
                    folder.setdefault(fa, set()).add(fb)
        n_edges = sum(len(v) for v in g.values())
        print(f"{src}: {len(g)} modules, {n_edges} edges")
        if args.edges:
            for a in sorted(g):
                for b in sorted(g[a]):
                    print(f"  {name(a)} -> {name(b)}")
        for label, graph in (("file", g), ("folder", folder)):
            cs = cycles(graph)
            if not cs:
                print(f"  {label} graph: no circle")
            for comp in cs:
                found = True
                print(f"  {label} graph circle: " + " <-> ".join(name(k) for k in comp))
                for a in comp:
                    for b in sorted(graph.get(a, ())):
                        if b in comp:
                            print(f"    {name(a)} -> {name(b)}")
    sys.exit(1 if found else 0)


if __name__ == "__main__":
    main()
