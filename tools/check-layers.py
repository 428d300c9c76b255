#!/usr/bin/env python3
"""No circle of files inside a source tree (server/kernel by default).

    tools/check-layers.py [-v] [DIR]   exit 0: no circle; 1: prints each circle
                                       (-v: every step inside each circle)

A module is foo.c with foo.h beside it (either may be missing), its
private header foo_internal.h and its SIMD lane code foo_lanes.h (a
plugin's lanes sit beside it: docs/adding-a-plugin.md) if it has them. Module A
depends on module B when a file of A
  - #includes a header of B ("..." includes resolved against the file's own
    directory, then against -I server, common, include), or
  - names a function or variable that a .c file of B defines (non-static):
    a header shared by several .c files (scene.h declaring functions of two
    files) does not hide who calls whom.
Calls through function pointers (a plugin's ops table, a hook in a struct)
are not dependencies: that is how a lower layer calls up without a circle.

A circle is a set of modules each reaching the others (a strongly connected
component of more than one module). For each, the script prints its
members and one shortest circle through them, each step with its reason
(the include line or the symbol named). Standard library only.
"""
import os
import re
import sys
from collections import deque

INCLUDE_DIRS = ("server", "common", "include")
INCLUDE_RE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')
TOKEN_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*|\S")
KEYWORDS_NOT_NAMES = {"__attribute__", "sizeof", "return", "if", "while", "for", "switch"}


def strip_comments_and_strings(text):
    """C source with comments, string and char literals blanked (newlines kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c == "/" and i + 1 < n and text[i + 1] == "*":
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("\n" * text.count("\n", i, j) or " ")
            i = j
        elif c == "/" and i + 1 < n and text[i + 1] == "/":
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(c + c)
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def split_preprocessor(text):
    """(code without preprocessor lines, the preprocessor lines joined)."""
    code, pp = [], []
    cont = False
    for line in text.split("\n"):
        if cont or line.lstrip().startswith("#"):
            pp.append(line)
            cont = line.endswith("\\")
            code.append("")
        else:
            code.append(line)
    return "\n".join(code), "\n".join(pp)


def top_level_definitions(code):
    """Names of the non-static functions and variables a .c file defines."""
    toks = TOKEN_RE.findall(code)
    defs = set()
    decl = []  # tokens of the current top-level declaration
    i, n = 0, len(toks)

    def skip_braces(k):  # toks[k] == "{": index after the matching "}"
        depth = 0
        while k < n:
            if toks[k] == "{":
                depth += 1
            elif toks[k] == "}":
                depth -= 1
                if depth == 0:
                    return k + 1
            k += 1
        return n

    def name_before(tokens, stop):
        """Last identifier before index `stop`, skipping [..] and attributes."""
        k = stop - 1
        while k >= 0:
            t = tokens[k]
            if t == "]":
                while k >= 0 and tokens[k] != "[":
                    k -= 1
            elif re.match(r"[A-Za-z_]", t) and t not in KEYWORDS_NOT_NAMES:
                return t
            k -= 1
        return None

    def is_static(tokens):
        return "static" in tokens or "extern" in tokens or "typedef" in tokens

    while i < n:
        t = toks[i]
        if t == "{":
            if "=" in decl:  # an initialised variable
                if not is_static(decl):
                    nm = name_before(decl, decl.index("="))
                    if nm:
                        defs.add(nm)
                i = skip_braces(i)
                while i < n and toks[i] != ";":
                    i += 1
                decl = []
                i += 1
                continue
            if "(" in decl and decl[0] not in ("struct", "union", "enum", "typedef"):
                if not is_static(decl):
                    k = decl.index("(")
                    while k > 0 and decl[k - 1] == "__attribute__":
                        k = decl.index("(", k + 1)
                    nm = name_before(decl, k)
                    if nm:
                        defs.add(nm)
                i = skip_braces(i)
                decl = []
                continue
            i = skip_braces(i)  # a struct/enum body: the declaration goes on
            decl.append("{}")
            continue
        if t == ";":
            if decl and not is_static(decl) and "(" not in decl and decl[-1] != "{}":
                if not (decl[0] in ("struct", "union", "enum") and len(decl) <= 2):
                    stop = decl.index("=") if "=" in decl else len(decl)
                    nm = name_before(decl, stop)
                    if nm:
                        defs.add(nm)
            elif decl and "=" in decl and not is_static(decl):
                nm = name_before(decl, decl.index("="))
                if nm and "(" not in decl[: decl.index("=")]:
                    defs.add(nm)
            decl = []
            i += 1
            continue
        decl.append(t)
        i += 1
    return defs


def header_uses(code):
    """Names a header uses: everything but its top-level prototypes and
    extern declarations (declaring a function is no use of it; an inline
    function calling it is)."""
    kept = []
    decl = []
    depth = 0
    for t in TOKEN_RE.findall(code):
        if depth > 0:
            kept.append(t)
            depth += t == "{"
            depth -= t == "}"
            continue
        if t == "{":
            kept.extend(decl)
            decl = []
            depth = 1
        elif t == ";":
            prototype = "(" in decl and "=" not in decl and decl[0] != "typedef"
            if not prototype and decl[:1] != ["extern"]:
                kept.extend(decl)
            decl = []
        else:
            decl.append(t)
    kept.extend(decl)
    return {t for t in kept if re.match(r"[A-Za-z_]", t)}


def module_of(root, path):
    """foo.c, foo.h, foo's private header foo_internal.h and its lanes
    foo_lanes.h: module foo."""
    m = os.path.splitext(os.path.relpath(path, root))[0]
    if path.endswith(".h"):
        for suffix in ("_internal", "_lanes"):
            if m.endswith(suffix):
                return m[: -len(suffix)]
    return m


def build_graph(root):
    root = os.path.abspath(root)
    repo = os.path.dirname(os.path.dirname(root)) if os.path.basename(os.path.dirname(root)) == "server" else None
    files = []
    for d, dirs, fs in os.walk(root):
        dirs.sort()
        for f in sorted(fs):
            if f.endswith((".c", ".h")):
                files.append(os.path.join(d, f))
    info = {}
    for f in files:
        with open(f, errors="replace") as fh:
            raw = fh.read()
        includes = [m.group(1) for m in map(INCLUDE_RE.match, raw.split("\n")) if m]
        code, pp = split_preprocessor(strip_comments_and_strings(raw))
        if f.endswith(".h"):
            names = header_uses(code) | set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", pp))
        else:
            names = set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", code + "\n" + pp))
        # Token pasting (a table of plugin_##name): any name of the file
        # with the pasted prefix or suffix may be named.
        for pre in re.findall(r"([A-Za-z_][A-Za-z0-9_]*)\s*##", pp):
            names |= {pre + w for w in names}
        for suf in re.findall(r"##\s*([A-Za-z0-9_]+)", pp):
            names |= {w + suf for w in list(names)}
        defs = top_level_definitions(code) if f.endswith(".c") else set()
        own = set(re.findall(r"\bstatic\b[^;{=]*?\b([A-Za-z_][A-Za-z0-9_]*)\s*[\[(=;]", code))
        info[f] = (includes, names, defs, own)
    definer = {}
    for f, (_, _, defs, _) in info.items():
        for s in defs:
            definer.setdefault(s, set()).add(f)
    graph = {}  # module -> {module: reason}
    for f, (includes, names, defs, own) in info.items():
        m = module_of(root, f)
        edges = graph.setdefault(m, {})
        bases = [os.path.dirname(f)]
        if repo:
            bases += [os.path.join(repo, d) for d in INCLUDE_DIRS]
        for inc in includes:
            for b in bases:
                p = os.path.normpath(os.path.join(b, inc))
                if os.path.exists(p):
                    if p.startswith(root + os.sep):
                        t = module_of(root, p)
                        if t != m:
                            edges.setdefault(t, '%s includes "%s"' % (os.path.relpath(f, root), inc))
                    break
        for s in sorted(names - defs - own):
            for g in definer.get(s, ()):
                t = module_of(root, g)
                if t != m:
                    edges.setdefault(t, "%s names %s (defined in %s)" % (os.path.relpath(f, root), s,
                                                                         os.path.relpath(g, root)))
    return graph


def strongly_connected(graph):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(100000)

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


def shortest_circle(graph, comp):
    """One shortest circle through comp[0], inside comp."""
    members = set(comp)
    start = comp[0]
    prev = {start: None}
    q = deque([start])
    while q:
        v = q.popleft()
        for w in sorted(graph.get(v, ())):
            if w not in members:
                continue
            if w == start:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                path.reverse()
                return path + [start]
            if w not in prev:
                prev[w] = v
                q.append(w)
    return [start]


def main():
    args = sys.argv[1:]
    verbose = "-v" in args
    args = [a for a in args if a != "-v"]
    root = args[0] if args else "server/kernel"
    if not os.path.isdir(root):
        print("check-layers: no directory %s" % root, file=sys.stderr)
        return 2
    graph = build_graph(root)
    comps = strongly_connected(graph)
    for comp in comps:
        print("circle of %d modules in %s: %s" % (len(comp), root, " ".join(comp)))
        path = shortest_circle(graph, comp)
        for a, b in zip(path, path[1:]):
            print("  %s -> %s: %s" % (a, b, graph[a][b]))
        if verbose:
            print("  every step inside it:")
            for a in comp:
                for b in sorted(graph[a]):
                    if b in comp:
                        print("    %s -> %s: %s" % (a, b, graph[a][b]))
    print("check-layers: %d modules, %d circles" % (len(graph), len(comps)))
    return 1 if comps else 0


if __name__ == "__main__":
    sys.exit(main())
