#!/usr/bin/env python3
"""Finds import cycles between the modules of each Rust crate and of the Python package.

A module (one source file) depends on another when it names it: for Rust a
``use`` declaration or a path in code starting with ``crate::``, ``super::``,
``self::`` or a child module's name; for Python an ``import`` or
``from … import`` of a module of the package (also inside functions). A name
reached through a re-export (``pub use`` in Rust, an import in a package's
``__init__.py``) counts as a dependency on the module that defines it, so a
facade that re-exports its children makes no cycle by itself. Comments, doc
comments (intra-doc links are not imports), string literals, ``#[cfg(test)]``
items and Rust binaries (``src/bin``) are left out.

A cycle is a set of modules that reach each other (a strongly connected
component); each is printed with one shortest loop through it and the line of
every dependency on that loop.

Usage::

    python3 scripts/check_imports.py                      # every crate and python/edccif
    python3 scripts/check_imports.py --crate edccif-core  # one crate (repeatable)
    python3 scripts/check_imports.py --no-python          # the crates only
    python3 scripts/check_imports.py --self-test          # the checker on its own fixtures

Exit status 0 when no selected crate or package has a cycle, 1 otherwise, 2 on
bad arguments.
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
import tempfile
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

IDENT = r"[A-Za-z_][A-Za-z0-9_]*"


# --------------------------------------------------------------------------- graph


@dataclass
class Graph:
    """Modules, and for each dependency ``(a, b)`` the first place it occurs."""

    name: str
    modules: set[str] = field(default_factory=set)
    edges: dict[tuple[str, str], str] = field(default_factory=dict)

    def add(self, a: str, b: str, where: str) -> None:
        if a != b and b in self.modules:
            self.edges.setdefault((a, b), where)

    def successors(self) -> dict[str, list[str]]:
        succ: dict[str, list[str]] = {m: [] for m in self.modules}
        for a, b in sorted(self.edges):
            succ[a].append(b)
        return succ


def components(g: Graph) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    succ = g.successors()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in sorted(g.modules):
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter
                counter += 1
                stack.append(v)
                on_stack.add(v)
            if i < len(succ[v]):
                work.append((v, i + 1))
                w = succ[v][i]
                if w not in index:
                    work.append((w, 0))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
    return sorted(out)


def shortest_loop(g: Graph, comp: list[str]) -> list[str]:
    """A shortest loop through the first module of ``comp``, inside ``comp``."""
    members = set(comp)
    succ = g.successors()
    start = comp[0]
    prev: dict[str, str] = {}
    queue = deque([start])
    seen = {start}
    while queue:
        v = queue.popleft()
        for w in succ[v]:
            if w not in members:
                continue
            if w == start:
                path = [v]
                while path[-1] != start:
                    path.append(prev[path[-1]])
                return list(reversed(path)) + [start]
            if w not in seen:
                seen.add(w)
                prev[w] = v
                queue.append(w)
    return [start, start]


def report(g: Graph, out) -> int:
    """Prints the cycles of ``g``; returns how many there are."""
    comps = components(g)
    if not comps:
        print(f"{g.name}: no import cycles ({len(g.modules)} modules)", file=out)
        return 0
    print(f"{g.name}: {len(comps)} import cycle(s)", file=out)
    for comp in comps:
        loop = shortest_loop(g, comp)
        print(f"  {' -> '.join(loop)}", file=out)
        if len(comp) > len(loop) - 1:
            print(f"    (all of: {', '.join(comp)})", file=out)
        for a, b in zip(loop, loop[1:]):
            print(f"    {a} -> {b}: {g.edges[(a, b)]}", file=out)
    return len(comps)


# --------------------------------------------------------------------------- Rust


def strip_rust(src: str) -> str:
    """``src`` with comments, string and char literals blanked (newlines kept)."""
    out: list[str] = []
    i, n = 0, len(src)

    def blank(s: str) -> str:
        return "".join(c if c == "\n" else " " for c in s)

    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
            out.append(blank(src[i:j]))
            i = j
        elif src.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if src.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif src.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(blank(src[i:j]))
            i = j
        elif (m := re.match(r'b?r(#*)"', src[i:])) and (i == 0 or not re.match(r"\w", src[i - 1])):
            close = '"' + m.group(1)
            j = src.find(close, i + m.end())
            j = n if j < 0 else j + len(close)
            out.append(blank(src[i:j]))
            i = j
        elif c == '"' or (c == "b" and src.startswith('b"', i)
                          and (i == 0 or not re.match(r"\w", src[i - 1]))):
            j = i + (2 if c == "b" else 1)
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            out.append(blank(src[i:j + 1]))
            i = j + 1
        elif c == "'":
            m = re.match(r"'(\\(x..|u\{[0-9a-fA-F]*\}|.)|[^\\'])'", src[i:], re.S)
            if m:  # a char literal; otherwise a lifetime or label
                out.append(blank(m.group(0)))
                i += m.end()
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def matching_brace(s: str, open_at: int) -> int:
    depth = 0
    for j in range(open_at, len(s)):
        if s[j] == "{":
            depth += 1
        elif s[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(s) - 1


def drop_cfg_test(s: str) -> str:
    """Blanks every item under ``#[cfg(test)]`` (test modules, test-only imports)."""
    while m := re.search(r"#\s*\[\s*cfg\s*\(\s*test\s*\)\s*\]", s):
        j = m.end()
        semi, brace = s.find(";", j), s.find("{", j)
        if semi < 0 and brace < 0:
            end = len(s) - 1
        elif brace < 0 or (0 <= semi < brace):
            end = semi
        else:
            end = matching_brace(s, brace)
        s = s[:m.start()] + "".join(c if c == "\n" else " " for c in s[m.start():end + 1]) \
            + s[end + 1:]
    return s


def split_top(s: str) -> list[str]:
    """``s`` split at the commas outside braces."""
    parts, depth, cur = [], 0, []
    for c in s:
        if c == "{":
            depth += 1
        elif c == "}":
            depth -= 1
        if c == "," and depth == 0:
            parts.append("".join(cur))
            cur = []
        else:
            cur.append(c)
    parts.append("".join(cur))
    return [p.strip() for p in parts if p.strip()]


def expand_use_tree(tree: str, prefix: list[str]) -> list[tuple[list[str], str | None]]:
    """The paths of a use tree, each with the name it binds (``None`` for a glob)."""
    tree = re.sub(r"\s+", "", re.sub(r"\s+as\s+", "@", tree))
    if tree.startswith("::"):
        tree = tree[2:]
    if "{" in tree and tree.endswith("}"):
        head, _, body = tree.partition("{")
        base = prefix + [p for p in head.split("::") if p]
        out = []
        for part in split_top(body[:-1]):
            out += expand_use_tree(part, base)
        return out
    path, _, alias = tree.partition("@")  # `path as alias`
    segs = prefix + [p for p in path.split("::") if p]
    if segs and segs[-1] == "*":
        return [(segs[:-1], None)]
    if segs and segs[-1] == "self":
        segs = segs[:-1]
    name = alias or (segs[-1] if segs else None)
    return [(segs, name)]


@dataclass
class RustModule:
    path: tuple[str, ...]
    file: Path
    text: str  # stripped
    children: set[str] = field(default_factory=set)
    defined: set[str] = field(default_factory=set)
    # name -> (absolute path segments, line) of every `use` binding
    bindings: dict[str, tuple[list[str], int]] = field(default_factory=dict)
    globs: list[tuple[list[str], int]] = field(default_factory=list)


USE_RE = re.compile(r"\b(?:pub\s*(?:\([^)]*\))?\s*)?use\s+([^;]+);")
ITEM_RE = re.compile(
    rf"\b(?:fn|struct|enum|trait|type|const|static|union|mod|macro_rules!)\s+({IDENT})")
PATH_RE = re.compile(rf"(?<![\w:])((?:{IDENT})(?:\s*::\s*{IDENT})+)")


def rust_modules(src: Path) -> dict[tuple[str, ...], RustModule]:
    mods: dict[tuple[str, ...], RustModule] = {}
    for f in sorted(src.rglob("*.rs")):
        rel = f.relative_to(src)
        if rel.parts[0] == "bin":
            continue
        parts = list(rel.with_suffix("").parts)
        if parts in (["lib"], ["main"]):
            parts = []
        elif parts[-1] == "mod":
            parts = parts[:-1]
        text = drop_cfg_test(strip_rust(f.read_text(encoding="utf-8")))
        mods[tuple(parts)] = RustModule(tuple(parts), f, text)
    for p, m in mods.items():
        m.children = {c[-1] for c in mods if len(c) == len(p) + 1 and c[:len(p)] == p}
        m.defined = set(ITEM_RE.findall(m.text))
    return mods


def absolute(mod: RustModule, segs: list[str]) -> list[str] | None:
    """``segs`` (as written in ``mod``) as a path from the crate root, or ``None``
    when it names something outside the crate."""
    cur = list(mod.path)
    if not segs:
        return None
    if segs[0] == "crate":
        return segs[1:]
    if segs[0] in ("super", "self"):
        i = 0
        while i < len(segs) and segs[i] in ("super", "self"):
            if segs[i] == "super":
                if not cur:
                    return None
                cur = cur[:-1]
            i += 1
        return cur + segs[i:]
    if segs[0] in mod.children:
        return cur + segs
    return None


def resolve(mods: dict[tuple[str, ...], RustModule], segs: list[str], depth: int = 0) -> str | None:
    """The module that defines what the absolute path ``segs`` names."""
    k = len(segs)
    while k > 0 and tuple(segs[:k]) not in mods:
        k -= 1
    if k == 0 and () not in mods:
        return None
    m = mods[tuple(segs[:k])]
    rest = segs[k:]
    if rest and depth < 16 and rest[0] not in m.defined:
        name = rest[0]
        if name in m.bindings:
            target = m.bindings[name][0]
            return resolve(mods, target + rest[1:], depth + 1) or "::".join(m.path)
        for glob, _ in m.globs:
            if provides(mods, glob, name, depth + 1):
                return resolve(mods, glob + rest, depth + 1) or "::".join(m.path)
    return "::".join(m.path)


def provides(mods: dict[tuple[str, ...], RustModule], segs: list[str], name: str,
             depth: int) -> bool:
    """Whether the module at ``segs`` defines or imports ``name``."""
    m = mods.get(tuple(segs))
    if m is None or depth >= 16:
        return False
    if name in m.defined or name in m.bindings or name in m.children:
        return True
    return any(provides(mods, g, name, depth + 1) for g, _ in m.globs)


def rust_graph(name: str, src: Path) -> Graph:
    mods = rust_modules(src)
    g = Graph(name, {"::".join(p) for p in mods})
    uses: list[tuple[RustModule, list[str], int]] = []
    for m in mods.values():
        spans = []
        for u in USE_RE.finditer(m.text):
            line = m.text.count("\n", 0, u.start()) + 1
            spans.append((u.start(), u.end()))
            for segs, bound in expand_use_tree(u.group(1), []):
                a = absolute(m, segs)
                if a is None:
                    continue
                if bound is None:
                    m.globs.append((a, line))
                else:
                    m.bindings[bound] = (a, line)
                uses.append((m, a, line))
        code = list(m.text)
        for s, e in spans:
            code[s:e] = [c if c == "\n" else " " for c in code[s:e]]
        code_text = "".join(code)
        for p in PATH_RE.finditer(code_text):
            segs = [x.strip() for x in p.group(1).split("::")]
            a = absolute(m, segs)
            if a is not None:
                uses.append((m, a, code_text.count("\n", 0, p.start()) + 1))
    root = src.parent
    for m, a, line in uses:
        t = resolve(mods, a)
        if t is not None:
            where = f"{m.file.relative_to(root)}:{line} ({'::'.join(['crate'] + a)})"
            g.add("::".join(m.path), t, where)
    g.modules.discard("")
    g.edges = {e: w for e, w in g.edges.items() if "" not in e}
    return g


# --------------------------------------------------------------------------- Python


def python_graph(pkg: Path) -> Graph:
    base = pkg.name
    files: dict[str, Path] = {}
    for f in sorted(pkg.rglob("*.py")) + sorted(pkg.rglob("*.pyi")):
        parts = list(f.relative_to(pkg.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        files.setdefault(".".join(parts), f)
    g = Graph(f"python package {base}", set(files))
    trees: dict[str, ast.Module] = {}
    for mod, f in files.items():
        if f.suffix == ".py":
            trees[mod] = ast.parse(f.read_text(encoding="utf-8"), str(f))

    def package_of(mod: str) -> str:
        return mod if files[mod].name == "__init__.py" else mod.rpartition(".")[0]

    def from_base(mod: str, node: ast.ImportFrom) -> str:
        if node.level == 0:
            return node.module or ""
        pkg_parts = package_of(mod).split(".")
        pkg_parts = pkg_parts[:len(pkg_parts) - (node.level - 1)]
        return ".".join(pkg_parts + ([node.module] if node.module else []))

    bindings: dict[str, dict[str, str]] = {m: {} for m in files}
    for mod, tree in trees.items():
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                b = from_base(mod, node)
                for a in node.names:
                    if a.name != "*":
                        bindings[mod][a.asname or a.name] = f"{b}.{a.name}"
    defined: dict[str, set[str]] = {m: set() for m in files}
    for mod, tree in trees.items():
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                defined[mod].add(node.name)
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                for t in node.targets if isinstance(node, ast.Assign) else [node.target]:
                    if isinstance(t, ast.Name):
                        defined[mod].add(t.id)

    def resolve_py(dotted: str, depth: int = 0) -> str | None:
        if dotted in files:
            return dotted
        mod, _, name = dotted.rpartition(".")
        if mod not in files:
            return resolve_py(mod, depth) if mod else None
        if name not in defined[mod] and name in bindings[mod] and depth < 16:
            return resolve_py(bindings[mod][name], depth + 1) or mod
        return mod

    for mod, tree in trees.items():
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                b = from_base(mod, node)
                targets = [b if a.name == "*" else f"{b}.{a.name}" for a in node.names]
            for t in targets:
                if t == base or t.startswith(base + "."):
                    r = resolve_py(t)
                    if r is not None:
                        g.add(mod, r, f"{files[mod].relative_to(pkg.parent.parent)}:{node.lineno}")
    return g


# --------------------------------------------------------------------------- self-test


def self_test() -> int:
    """Runs the checker on small fixtures with known cycles; 0 when all agree."""
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)

        def write(rel: str, text: str) -> None:
            p = root / rel
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(text, encoding="utf-8")

        # A crate with one cycle (a <-> b, through a grouped use and `super::`)
        # and decoys: a facade re-exporting its children, comments, strings,
        # doc links, a test module, a root re-export, a binary.
        write("cyc/src/lib.rs", "pub mod a;\npub mod b;\npub mod c;\npub mod d;\n"
              "pub mod facade;\npub use a::A;\n")
        write("cyc/src/a.rs", "use crate::{b::{self, B}, d::D as Dee};\npub struct A;\n"
              "// use crate::c::nothing;\n")
        write("cyc/src/d.rs", "pub struct D;\n")
        write("cyc/src/b.rs", "pub struct B;\nfn f() -> super::a::A { super::a::A }\n")
        write("cyc/src/c.rs", "//! See [`A`](crate::b::B).\npub struct C;\n"
              "const S: &str = \"crate::a::A\";\nfn g() -> crate::A { crate::A }\n"
              "fn l<'a>(x: &'a str) -> char { let _ = x; '\"' }\n"
              "#[cfg(test)]\nmod tests { use crate::b::B; }\n")
        write("cyc/src/facade/mod.rs", "mod inner;\nmod other;\npub use inner::{I, J as K};\n"
              "pub use other::*;\n")
        write("cyc/src/facade/inner.rs", "pub struct I;\npub struct J;\n"
              "use super::O;\n")
        write("cyc/src/facade/other.rs", "pub struct O;\npub fn k() -> super::super::d::D { todo!() }\n")
        write("cyc/src/bin/tool.rs", "use cyc::b::B; mod x { use crate::y; }\n")
        g = rust_graph("cyc", root / "cyc/src")
        got = components(g)
        want = [["a", "b"]]
        ok = got == want
        print(f"rust fixture: cycles {got} (want {want})", file=sys.stderr)
        for e in [("c", "a"), ("a", "d"), ("facade::inner", "facade::other"),
                  ("facade::other", "d"), ("facade", "facade::inner")]:
            if e not in g.edges:
                print(f"  missing edge {e}", file=sys.stderr)
                ok = False
        for e in [("c", "b"), ("facade::inner", "facade"), ("facade::other", "facade")]:
            if e in g.edges:
                print(f"  spurious edge {e}: {g.edges[e]}", file=sys.stderr)
                ok = False
        # A crate whose only dependencies are one way: no cycle.
        write("ok/src/lib.rs", "mod x;\nmod y;\npub use x::X;\n")
        write("ok/src/x.rs", "use crate::y::Y;\npub struct X(Y);\n")
        write("ok/src/y.rs", "pub struct Y;\n/// [`X`](crate::X)\nfn f() {}\n")
        got = components(rust_graph("ok", root / "ok/src"))
        print(f"rust fixture without cycle: {got}", file=sys.stderr)
        ok &= got == []

        # A package with a cycle through a lazy import and a re-export, and one
        # without (the package re-exporting from its modules).
        write("py/pkg/__init__.py", "from .m1 import f\nfrom .m3 import h\n")
        write("py/pkg/m1.py", "from . import m2\ndef f():\n    return m2.g()\n")
        write("py/pkg/m2.py", "def g():\n    from pkg import f\n    return f\n")
        write("py/pkg/m3.py", "import pkg.m2\ndef h():\n    return 1\n")
        write("py/pkg/_ext.pyi", "def x() -> int: ...\n")
        g = python_graph(root / "py/pkg")
        got = components(g)
        want = [["pkg.m1", "pkg.m2"]]
        print(f"python fixture: cycles {got} (want {want})", file=sys.stderr)
        ok &= got == want
        ok &= ("pkg.m3", "pkg.m2") in g.edges
        # The printed report names the cycle and the lines.
        with tempfile.TemporaryFile("w+") as out:
            n = report(g, out)
            out.seek(0)
            text = out.read()
        ok &= n == 1 and "pkg.m1 -> pkg.m2 -> pkg.m1" in text and "m2.py:2" in text
        # A subpackage: `..` imports reach the parent package, a name its
        # `__init__` re-exports is a dependency on the module defining it, and
        # the facade alone makes no cycle.
        write("py/top/__init__.py", "")
        write("py/top/base.py", "def h():\n    return 1\n")
        write("py/top/sub/__init__.py", "from .a import A\nfrom .c import C\nfrom .d import D\n")
        write("py/top/sub/a.py", "from ..base import h\nA = h()\n")
        write("py/top/sub/b.py", "from . import a\nfrom ..sub import A\n")
        write("py/top/sub/c.py", "from ..sub import D\nC = 1\n")
        write("py/top/sub/d.py", "def D():\n    from .c import C\n    return C\n")
        g = python_graph(root / "py/top")
        got = components(g)
        want = [["top.sub.c", "top.sub.d"]]
        print(f"python subpackage fixture: cycles {got} (want {want})", file=sys.stderr)
        ok &= got == want
        ok &= ("top.sub.a", "top.base") in g.edges and ("top.sub.b", "top.sub.a") in g.edges
        ok &= ("top.sub.b", "top.sub") not in g.edges and ("top.sub", "top.sub.a") in g.edges
    print("self-test passed" if ok else "self-test FAILED", file=sys.stderr)
    return 0 if ok else 1


# --------------------------------------------------------------------------- main


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", type=Path, default=Path(__file__).resolve().parent.parent,
                    help="repository root (default: this script's)")
    ap.add_argument("--crate", action="append", default=[], metavar="NAME",
                    help="check this crate of crates/ only (repeatable; default: all)")
    ap.add_argument("--no-python", action="store_true", help="skip the Python package")
    ap.add_argument("--python-only", action="store_true", help="only the Python package")
    ap.add_argument("--self-test", action="store_true",
                    help="check the checker on fixtures with known cycles")
    args = ap.parse_args()
    if args.self_test:
        return self_test()
    crates_dir = args.root / "crates"
    names = sorted(p.name for p in crates_dir.iterdir() if (p / "src").is_dir())
    for c in args.crate:
        if c not in names:
            ap.error(f"--crate {c}: no such crate; expected one of {', '.join(names)}")
    selected = [] if args.python_only else (args.crate or names)
    cycles = 0
    for c in selected:
        cycles += report(rust_graph(c, crates_dir / c / "src"), sys.stdout)
    if not args.no_python and (args.python_only or not args.crate):
        pkg = args.root / "python" / "edccif"
        if not pkg.is_dir():
            ap.error(f"no Python package at {pkg}")
        cycles += report(python_graph(pkg), sys.stdout)
    return 1 if cycles else 0


if __name__ == "__main__":
    raise SystemExit(main())
