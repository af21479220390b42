#!/usr/bin/env python3
"""List import loops between the files of each crate of the workspace.

    python3 scripts/architecture/import_loops.py [ROOT] [--edges]

For every `crates/*/src`, each file is one module (`lib.rs`/`main.rs` the crate root, `a.rs` and
`a/mod.rs` module `a`, `a/b.rs` module `a::b`). A file depends on the module where an item is
defined when its library code names the item through a `crate::`, `super::` or `self::` path (or
a path that starts with one of its child modules), in a `use` or in the code itself; a name
reached through a `use` or a re-export is followed to the file that defines it. Inline modules
count as their file; test modules (`#[cfg(test)] mod …`) are left out. Not dependencies: a
`pub use` of a descendant's item that the file's own code does not name (a parent publishing its
children), and a type named only as the type of an `impl` block (`impl` blocks of one type split
across files; method calls name no module). Comments and string literals are ignored.

Prints each loop (a strongly connected group of two or more files), its cycles of two and three
files (or its shortest cycle) with the `file:line: path` of each edge, and `N import loops`;
exits 1 when there is any. `--edges` prints every edge too.
"""

import bisect
import os
import re
import sys

IDENT = r"[A-Za-z_][A-Za-z0-9_]*"


def blank(src):
    """Replace comments, string and char literals by spaces (newlines kept)."""
    out, i, n = [], 0, len(src)

    def spaces(a, b):
        return "".join(ch if ch == "\n" else " " for ch in src[a:b])

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
            out.append(spaces(i, j))
            i = j
        elif (c in "rb" and re.match(r'(br|r)#*"', src[i:i + 10])
              and (i == 0 or not (src[i - 1].isalnum() or src[i - 1] == "_"))):
            m = re.match(r'(?:br|r)(#*)"', src[i:])
            close = '"' + m.group(1)
            j = src.find(close, i + len(m.group(0)))
            j = n if j < 0 else j + len(close)
            out.append(spaces(i, j))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(spaces(i, j))
            i = j
        elif c == "'":
            m = re.match(r"'(\\.[^']*|[^\\'])'", src[i:])
            if m:  # a char literal, not a lifetime
                out.append(" " * len(m.group(0)))
                i += len(m.group(0))
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def modules(src_dir):
    """Module path (tuple) of every `.rs` file under `src_dir`."""
    found = {}
    for dirpath, _, names in os.walk(src_dir):
        for name in names:
            if not name.endswith(".rs"):
                continue
            rel = os.path.relpath(os.path.join(dirpath, name), src_dir)
            parts = rel[:-3].split(os.sep)
            if parts in (["lib"], ["main"]):
                parts = []
            elif parts[-1] == "mod":
                parts = parts[:-1]
            found[tuple(parts)] = os.path.join(dirpath, name)
    return found


def expand(tree):
    """The paths of a use tree: `a::{b, c::{d as e}}` -> [a::b, a::c::d as e]."""
    tree = re.sub(r"\s*(::|\{|\}|,)\s*", r"\1", re.sub(r"\s+", " ", tree.strip()))
    k = tree.find("{")
    if k < 0:
        return [tree]
    head, inner = tree[:k], tree[k + 1:tree.rindex("}")]
    parts, level, start = [], 0, 0
    for j, c in enumerate(inner):
        if c == "{":
            level += 1
        elif c == "}":
            level -= 1
        elif c == "," and level == 0:
            parts.append(inner[start:j])
            start = j + 1
    parts.append(inner[start:])
    return [head + p for part in parts if part for p in expand(part)]


def imported_name(path):
    """The name a use path brings into scope (`a::b` -> b, `a::b as c` -> c, `a::b::self` -> b)."""
    segments = path.split(" as ")[-1].split("::")
    return segments[-2] if segments[-1] == "self" and len(segments) > 1 else segments[-1]


def absolute(scope, segments, known, inline):
    """`segments` (a path seen in inline module `scope` of file `module`) from the crate root, or
    None for a path into another crate."""
    here, first = list(scope), segments[0]
    if first == "crate":
        return segments[1:]
    if first in ("super", "self"):
        rest = list(segments)
        while rest and rest[0] in ("super", "self"):
            if rest.pop(0) == "super":
                here = here[:-1]
        return here + rest
    if tuple(here + [first]) in known or (tuple(here), first) in inline:
        return here + segments
    return None


class Crate:
    """The files of one crate, their imports and the modules their paths lead to."""

    def __init__(self, src):
        self.known = modules(src)
        self.test_only = set()
        self.files = {}
        for module, path in self.known.items():
            self.files[module] = scan(module, path)
            for child in self.files[module]["test_children"]:
                self.test_only.add(module + (child,))
        # What each module imports under each name (its `use` statements at file level).
        self.imports = {}
        for module, f in self.files.items():
            table = self.imports.setdefault(module, {})
            for scope, _, path, _ in f["uses"]:
                if tuple(scope) != module or path.endswith("*"):
                    continue
                seg = absolute(scope, split(path), self.known, f["inline"])
                if seg is not None:
                    table[imported_name(path)] = [s for s in seg if s != "self"]

    def locate(self, segments, depth=0):
        """The module holding the item `segments` (from the crate root) names, following imports
        and re-exports to where the item is defined."""
        segments = [s for s in segments if s not in ("*", "self")]
        for k in range(len(segments), -1, -1):
            module = tuple(segments[:k])
            if module in self.known:
                break
        else:
            return None
        if k < len(segments) and depth < 20:
            target = self.imports.get(module, {}).get(segments[k])
            if target is not None:
                found = self.locate(target + segments[k + 1:], depth + 1)
                if found is not None:
                    return found
        return module


def split(path):
    """The segments of a use path, its alias left out."""
    return [s for s in path.split(" as ")[0].split("::") if s]


def scan(module, path):
    """A file's `use` statements and the paths its code names, test modules left out."""
    code = blank(open(path, encoding="utf-8").read())
    line_starts = [0] + [k + 1 for k, ch in enumerate(code) if ch == "\n"]

    def line(pos):
        return bisect.bisect_right(line_starts, pos)

    # Inline modules as (start, end, scope, test) spans; `#[cfg(test)] mod x;` files.
    test_children = set(re.findall(r"#\[cfg\(test\)\]\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(" + IDENT
                                   + r")\s*;", code))
    openers = {}
    for m in re.finditer(r"(#\[cfg\(test\)\]\s*)?(?:pub(?:\([^)]*\))?\s+)?mod\s+(" + IDENT
                         + r")\s*\{", code):
        openers[m.end() - 1] = (m.group(2), bool(m.group(1)))
    spans, stack, depth = [], [], 0
    for k, ch in enumerate(code):
        if ch == "{":
            depth += 1
            if k in openers:
                name, test = openers[k]
                outer = stack[-1][2] if stack else list(module)
                stack.append((k, depth, outer + [name], test or (stack and stack[-1][3])))
        elif ch == "}":
            if stack and stack[-1][1] == depth:
                start, _, scope, test = stack.pop()
                spans.append((start, k, scope, test))
            depth -= 1
    inline = {(tuple(scope[:-1]), scope[-1]) for _, _, scope, _ in spans}

    def scope_at(pos):
        best, test = list(module), False
        for start, end, scope, is_test in spans:
            if start < pos < end and len(scope) > len(best):
                best, test = scope, is_test
        return best, test

    # Where `impl` blocks name their own type (`impl T`, `impl Trait for T`): naming a type only
    # to add methods to it is no dependency (`impl` blocks of one type split across files).
    impl_self = set()
    for m in re.finditer(r"(?m)^[ \t]*(?:unsafe\s+)?impl\b", code):
        k, level = m.end(), 0
        while k < len(code) and (level or code[k] not in "{;"):
            level += {"<": 1, ">": -1}.get(code[k], 0) if code[k - 1] != "-" else 0
            k += 1
        header, base = code[m.end():k], m.end()
        g = re.match(r"\s*<", header)
        if g:
            j, level = g.end(), 1
            while j < len(header) and level:
                level += {"<": 1, ">": -1}.get(header[j], 0) if header[j - 1] != "-" else 0
                j += 1
            header, base = header[j:], base + j
        header = re.split(r"\bwhere\b", header)[0]
        top = [f.start() for f in re.finditer(r"\bfor\b", header)]
        start = top[-1] + 3 if top else 0
        t = re.match(r"\s*&?\s*(?:mut\s+)?((?:" + IDENT + r"::)*)(" + IDENT + r")", header[start:])
        if t:
            impl_self.add(base + start + t.start(2))
    for start, end, _, test in spans:
        if test:
            code_test = code[start:end + 1]
            code = code[:start] + re.sub(r"[^\n]", " ", code_test) + code[end + 1:]

    uses, statements = [], list(re.finditer(r"\b(pub(?:\s*\([^)]*\))?\s+)?use\s+([^;]+);", code))
    rest = code
    for m in statements:
        rest = rest[:m.start()] + " " * (m.end() - m.start()) + rest[m.end():]
    rest = re.sub(r"\bmod\s+" + IDENT + r"\s*;", lambda m: " " * len(m.group(0)), rest)
    for m in statements:
        scope, test = scope_at(m.start())
        if not test:
            for p in expand(m.group(2)):
                uses.append((scope, line(m.start()), p, bool(m.group(1))))
    paths = []
    for m in re.finditer(r"(?<![A-Za-z0-9_:])((?:" + IDENT + r"::)+" + IDENT + r")", rest):
        scope, test = scope_at(m.start())
        last = m.end(1) - len(m.group(1).split("::")[-1])
        if not test and last not in impl_self:
            paths.append((scope, line(m.start()), m.group(1)))
    return {"uses": uses, "paths": paths, "rest": rest, "inline": inline,
            "test_children": test_children, "impl_self": impl_self}


def only_in_impl_headers(f, name):
    """True when the file's code names `name` and every time as the type of an `impl` block."""
    places = [m.end(1) - len(name) for m in re.finditer(r"(?<![A-Za-z0-9_])(" + re.escape(name)
                                                        + r")(?![A-Za-z0-9_])", f["rest"])]
    return bool(places) and all(p in f["impl_self"] for p in places)


def edges(crate):
    """(from module, to module, line, path) for every dependency of a file's library code."""
    out = []
    for module, f in crate.files.items():
        if module in crate.test_only or any(module[:k] in crate.test_only
                                            for k in range(len(module))):
            continue
        for scope, line, path, public in f["uses"]:
            seg = absolute(scope, split(path), crate.known, f["inline"])
            if seg is None:
                continue
            target = crate.locate(seg)
            if target is None:
                continue
            name = imported_name(path)
            if public and target[:len(scope)] == tuple(scope):
                # A re-export of a descendant's item: a dependency only where the code names it.
                if name == "*" or not re.search(r"\b" + re.escape(name) + r"\b", f["rest"]):
                    continue
            if only_in_impl_headers(f, name):
                continue
            out.append((module, target, line, "use " + re.sub(r"::self$", "", path)))
        for scope, line, path in f["paths"]:
            seg = absolute(scope, split(path), crate.known, f["inline"])
            if seg is None:
                continue
            target = crate.locate(seg)
            if target is not None:
                out.append((module, target, line, path))
    return out


def loops(graph):
    """Strongly connected components of two or more nodes (Tarjan)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]

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
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def shortest_cycles(graph, members):
    """For each edge inside a loop, the shortest cycle through it; each cycle once, shortest
    first."""
    cycles = set()
    for a in sorted(members):
        for b in sorted(graph.get(a, ()) & members):
            previous, queue = {b: None}, [b]
            while queue and a not in previous:
                v = queue.pop(0)
                for w in sorted(graph.get(v, ()) & members):
                    if w not in previous:
                        previous[w] = v
                        queue.append(w)
            path, v = [], a
            while v is not None:
                path.append(v)
                v = previous[v]
            cycle = [a] + list(reversed(path))[:-1]
            k = cycle.index(min(cycle))
            cycles.add(tuple(cycle[k:] + cycle[:k]))
    return [list(c) for c in sorted(cycles, key=lambda c: (len(c), c))]


def name(module):
    return "::".join(module) or "crate"


def main(argv):
    show_edges = "--edges" in argv
    args = [a for a in argv if not a.startswith("--")]
    root = args[0] if args else "."
    crates_dir = os.path.join(root, "crates")
    total = 0
    for crate in sorted(os.listdir(crates_dir)):
        src = os.path.join(crates_dir, crate, "src")
        if not os.path.isdir(src):
            continue
        crate_ = Crate(src)
        graph, evidence = {}, {}
        for module, target, line, text in edges(crate_):
            if target == module:
                continue
            graph.setdefault(module, set()).add(target)
            rel = os.path.relpath(crate_.known[module], root)
            evidence.setdefault((module, target), f"{rel}:{line}: {text}")
        if show_edges:
            for (a, b), where in sorted(evidence.items()):
                print(f"{crate}: {name(a)} -> {name(b)}    ({where})")
        for group in loops(graph):
            total += 1
            print(f"{crate}: loop among {', '.join(name(m) for m in group)}")
            cycles = shortest_cycles(graph, set(group))
            shown = [c for c in cycles if len(c) <= 3] or cycles[:1]
            for cycle in shown:
                print("    " + " -> ".join(name(m) for m in cycle + [cycle[0]]))
                for a, b in zip(cycle, cycle[1:] + [cycle[0]]):
                    print(f"        {evidence[(a, b)]}")
            if len(shown) < len(cycles):
                print(f"    and {len(cycles) - len(shown)} longer cycles (--edges lists every edge)")
    print(f"{total} import loops")
    return 1 if total else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
