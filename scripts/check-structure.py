#!/usr/bin/env python3
"""Structure checks of the workspace's source files (run by scripts/test.sh).

1. No import cycle between the files of a crate. Per crate (every `*/src` of the workspace and
   the root package's `src/`), the files are the nodes of a graph; file A has an edge to file B
   when A names an item that B defines: through a `use` (plain or grouped, `crate::`,
   `super::`, `self::` or a child module's name), or a path in code (`crate::x::f()`,
   `super::Y`, `child::Z`). A path is followed through re-exports and imports (`pub use`,
   `pub(crate) use`, a parent's private `use` that its children see) to the file that defines
   the item, so a module that only re-exports its children's items depends on none of them. A
   `pub use` counts as a use of its target only where its own file names the item again.
   Left out: the crate root (`lib.rs`, `main.rs`: it holds the crate's `Error` that every
   module returns, and declares and re-exports every module, so it sits above and below all of
   them), test-only code (`#[cfg(test)]` items, such as `mod tests { … }`), comments and string
   literals. A child that uses its parent's items and a parent that uses its child's are a
   cycle like any other.
2. No file of `fit/src` over 700 lines.

Prints every cycle (each edge with the line that makes it) and every long file; exits 1 if
there is any.
"""
import os
import re
import sys

MAX_FIT_LINES = 700
IDENT = r"[A-Za-z_][A-Za-z0-9_]*"


def strip(src):
    """Source with comments, string and char literals blanked (newlines kept)."""
    out = []
    i, n = 0, len(src)
    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
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
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif re.match(r'(b?r#*")', src[i:i + 8]) and (i == 0 or not re.match(r"\w", src[i - 1])):
            m = re.match(r'b?r(#*)"', src[i:])
            end = '"' + m.group(1)
            j = src.find(end, i + len(m.group(0)))
            j = n if j < 0 else j + len(end)
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif c == '"' or (c == "b" and src.startswith('b"', i) and (i == 0 or not re.match(r"\w", src[i - 1]))):
            j = i + (2 if c == "b" else 1)
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            j += 1
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif c == "'":
            # A char literal ('x', '\n', '\u{1F600}') or a lifetime ('a): only the former ends in '.
            m = re.match(r"'(\\(u\{[0-9a-fA-F]+\}|x[0-9a-fA-F]{2}|.)|[^\\'\n])'", src[i:])
            if m:
                out.append(" " * len(m.group(0)))
                i += len(m.group(0))
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def matching_brace(s, i):
    """Index just past the brace block opening at s[i] == '{'."""
    depth = 0
    for j in range(i, len(s)):
        if s[j] == "{":
            depth += 1
        elif s[j] == "}":
            depth -= 1
            if depth == 0:
                return j + 1
    return len(s)


def drop_test_items(s):
    """Blanks every item under `#[cfg(test)]`; returns (code, names of test-only `mod x;`)."""
    test_mods = set()
    while True:
        m = re.search(r"#\s*\[\s*cfg\s*\(\s*test\s*\)\s*\]", s)
        if not m:
            return s, test_mods
        j = m.end()
        # The item ends at its first `;` or its first brace block, whichever comes first.
        semi, brace = s.find(";", j), s.find("{", j)
        if brace >= 0 and (semi < 0 or brace < semi):
            end = matching_brace(s, brace)
        else:
            end = (semi if semi >= 0 else len(s) - 1) + 1
            t = re.match(r"\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(" + IDENT + r")\s*;", s[j:end])
            if t:
                test_mods.add(t.group(1))
        s = s[: m.start()] + re.sub(r"[^\n]", " ", s[m.start():end]) + s[end:]


def parse_use_tree(text):
    """`a::b::{c, d::{e as f}, self, *}` → [(segments, bound name)], bound '*' for globs."""
    pos = 0
    toks = re.findall(r"::|\{|\}|,|\*|" + IDENT, text)

    def tree(prefix):
        nonlocal pos
        out = []
        segs = list(prefix)
        while pos < len(toks):
            t = toks[pos]
            if t == "::":
                pos += 1
            elif t == "{":
                pos += 1
                while pos < len(toks) and toks[pos] != "}":
                    out.extend(tree(segs))
                    if pos < len(toks) and toks[pos] == ",":
                        pos += 1
                pos += 1
                return out
            elif t in (",", "}"):
                break
            elif t == "*":
                pos += 1
                out.append((segs, "*"))
                return out
            elif t == "as":
                pos += 1
                alias = toks[pos]
                pos += 1
                out.append((segs, alias))
                return out
            else:
                segs = segs + [t]
                pos += 1
        if segs != list(prefix) or not out:
            if segs and segs[-1] == "self":
                segs = segs[:-1]
            if segs:
                out.append((segs, segs[-1]))
        return out

    return tree([])


class Crate:
    def __init__(self, src):
        self.src = src
        self.files = {}  # module path (tuple) → file path
        self.children = {}  # module → set of child module names (files)
        self.aliases = {}  # module → {name: (absolute segments, visibility, line)}
        self.globs = {}  # module → [absolute segments]
        self.code = {}  # module → stripped code
        self.uses = {}  # module → [(absolute segments, bound, public, line)]
        self.root = None
        for name in ("lib.rs", "main.rs"):
            if os.path.exists(os.path.join(src, name)):
                self.root = ()
                self.load((), os.path.join(src, name))
                break

    def module_dir(self, mod, path):
        base = os.path.basename(path)
        if base in ("lib.rs", "main.rs", "mod.rs"):
            return os.path.dirname(path)
        return path[:-3]

    def load(self, mod, path):
        self.files[mod] = path
        raw = open(path, encoding="utf-8").read()
        code, test_mods = drop_test_items(strip(raw))
        self.code[mod] = code
        self.children[mod] = set()
        d = self.module_dir(mod, path)
        for m in re.finditer(r"(?<![\w:])mod\s+(" + IDENT + r")\s*;", code):
            name = m.group(1)
            if name in test_mods:
                continue
            for cand in (os.path.join(d, name + ".rs"), os.path.join(d, name, "mod.rs")):
                if os.path.exists(cand):
                    self.children[mod].add(name)
                    self.load(mod + (name,), cand)
                    break
        self.aliases[mod] = {}
        self.globs[mod] = []
        self.uses[mod] = []
        for m in re.finditer(r"(?<![\w:])((?:pub\s*(?:\([^)]*\))?\s*)?)use\s+([^;]*);", code):
            public = bool(m.group(1).strip())
            line = code.count("\n", 0, m.start()) + 1
            for segs, bound in parse_use_tree(m.group(2)):
                ab = self.absolute(mod, segs)
                if ab is None:
                    continue  # another crate (std, ptm_format, …)
                if bound == "*":
                    self.globs[mod].append(ab)
                else:
                    self.aliases[mod][bound] = (ab, public, line)
                self.uses[mod].append((ab, bound, public, line))

    def absolute(self, mod, segs):
        """Segments of a path written in `mod`, from the crate root; None for another crate."""
        if not segs:
            return None
        first = segs[0]
        if first == "crate":
            return ["crate"] + segs[1:]
        if first in ("self", "super"):
            base = list(mod)
            rest = list(segs)
            while rest and rest[0] in ("self", "super"):
                if rest[0] == "super":
                    base = base[:-1]
                rest = rest[1:]
            return ["crate"] + base + rest
        if first in self.children.get(mod, ()):
            return ["crate"] + list(mod) + list(segs)
        return None

    def resolve(self, segs, depth=0):
        """The module (file) that defines what the absolute path `segs` names."""
        assert segs[0] == "crate"
        mod = ()
        rest = segs[1:]
        while rest:
            seg = rest[0]
            if seg in self.children.get(mod, ()):
                mod = mod + (seg,)
                rest = rest[1:]
                continue
            alias = self.aliases.get(mod, {}).get(seg)
            if alias and depth < 20:
                target = alias[0]
                if target[1:] == list(mod) + [seg]:
                    return mod  # `use self::x` of an item defined here
                return self.resolve(target + rest[1:], depth + 1)
            for g in self.globs.get(mod, []):
                if depth < 20 and g[1:] != list(mod):
                    got = self.resolve(g + rest, depth + 1)
                    if got != tuple(g[1:]) or seg in self.defined(tuple(g[1:])):
                        return got
            return mod
        return mod

    def defined(self, mod):
        code = self.code.get(mod, "")
        return set(re.findall(
            r"\b(?:fn|struct|enum|trait|type|const|static|union|macro_rules!)\s+(" + IDENT + ")", code))

    def edges(self):
        """module → {module it depends on: (line, what)}."""
        out = {m: {} for m in self.files}
        for mod, code in self.code.items():
            def add(target, line, what):
                if target != mod and target != self.root and target in self.files:
                    out[mod].setdefault(target, (line, what))
            # Code outside `use` items, for inline paths and for what a `pub use` is used for.
            body = re.sub(r"(?<![\w:])(?:pub\s*(?:\([^)]*\))?\s*)?use\s+[^;]*;",
                          lambda m: re.sub(r"[^\n]", " ", m.group(0)), code)
            for ab, bound, public, line in self.uses[mod]:
                if public and bound != "*" and not re.search(r"(?<![\w])" + re.escape(bound) + r"\b", body):
                    continue  # a re-export its own file does not use
                add(self.resolve(ab), line, "use " + "::".join(ab))
            first = r"(?:crate|super|self|" + "|".join(
                sorted(self.children[mod] | set(self.aliases[mod]))) + ")" if (
                self.children[mod] or self.aliases[mod]) else r"(?:crate|super|self)"
            for m in re.finditer(r"(?<![\w:])(" + first + r"(?:\s*::\s*" + IDENT + r")+)", body):
                segs = re.split(r"\s*::\s*", m.group(1))
                if segs[0] in self.aliases[mod] and segs[0] not in self.children[mod]:
                    ab = self.aliases[mod][segs[0]][0] + segs[1:]
                else:
                    ab = self.absolute(mod, segs)
                if ab is None:
                    continue
                line = code.count("\n", 0, m.start()) + 1
                add(self.resolve(ab), line, "::".join(segs))
        return out

    def rel(self, mod):
        return os.path.relpath(self.files[mod])


def sccs(graph):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
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

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def crates(root):
    out = []
    for d in sorted(os.listdir(root)):
        src = os.path.join(root, d, "src")
        if d not in ("target",) and not d.startswith(".") and os.path.isdir(src):
            if os.path.exists(os.path.join(root, d, "Cargo.toml")):
                out.append(src)
    if os.path.isdir(os.path.join(root, "src")):
        out.append(os.path.join(root, "src"))
    return out


SELF_TEST = {
    # name: ({file: source}, cycles expected as sorted module lists)
    "a child and its parent that use each other": ({
        "lib.rs": "pub mod p;\n",
        "p.rs": "mod c;\npub fn helper() {}\npub fn run() { c::work() }\n",
        "p/c.rs": "pub fn work() { super::helper() }\n",
    }, [["p", "p::c"]]),
    "a facade that only re-exports, a grouped use, a re-export followed": ({
        "lib.rs": "mod a;\nmod b;\npub use a::A;\n",
        "a.rs": "use crate::b::{self, B as Bee};\npub struct A(Bee);\n"
                "pub fn f() { b::g() }\n",
        "b.rs": "mod inner;\npub use inner::B;\npub fn g() {}\n"
                "#[cfg(test)]\nmod tests { use crate::a::f; }\n",
        "b/inner.rs": "pub struct B;\n// crate::a::f in a comment\n"
                      "pub fn h() -> &'static str { \"crate::a::f\" }\n",
    }, []),
    "an item reached through the root's re-export": ({
        "lib.rs": "mod x;\nmod y;\npub use y::Y;\n",
        "x.rs": "pub fn fx(_: crate::Y) {}\n",
        "y.rs": "pub struct Y;\nfn fy() { crate::x::fx(Y) }\n",
    }, [["x", "y"]]),
}


def self_test():
    """The checker on small crates whose cycles are known: it must find exactly those."""
    import tempfile
    bad = 0
    for name, (files, want) in SELF_TEST.items():
        with tempfile.TemporaryDirectory() as d:
            for rel, text in files.items():
                os.makedirs(os.path.dirname(os.path.join(d, rel)), exist_ok=True)
                with open(os.path.join(d, rel), "w", encoding="utf-8") as f:
                    f.write(text)
            c = Crate(d)
            got = [["::".join(m) for m in comp]
                   for comp in sccs({m: set(e) for m, e in c.edges().items()})]
            if sorted(got) != sorted(want):
                print(f"check-structure self-test {name!r}: found {got}, expected {want}")
                bad += 1
    return bad


def main():
    root = os.path.relpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    failures = self_test()
    for src in crates(root):
        c = Crate(src)
        if c.root is None:
            continue
        g = c.edges()
        for comp in sccs({m: set(e) for m, e in g.items()}):
            failures += 1
            names = " ↔ ".join(c.rel(m) for m in comp)
            print(f"import cycle in {os.path.relpath(src)}: {names}")
            for a in comp:
                for b in comp:
                    if b in g[a]:
                        line, what = g[a][b]
                        print(f"    {c.rel(a)}:{line} → {c.rel(b)} ({what})")
    fit = os.path.join(root, "fit", "src")
    for dp, _, fns in os.walk(fit):
        for f in sorted(fns):
            if f.endswith(".rs"):
                p = os.path.join(dp, f)
                lines = sum(1 for _ in open(p, encoding="utf-8"))
                if lines > MAX_FIT_LINES:
                    failures += 1
                    print(f"{os.path.relpath(p)}: {lines} lines; fit/src files are at most "
                          f"{MAX_FIT_LINES} (split it along a seam, see ARCHITECTURE.md)")
    if failures:
        print(f"check-structure: {failures} problem(s)")
        return 1
    print("check-structure: no import cycle in any crate, no fit/src file over "
          f"{MAX_FIT_LINES} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
