#!/usr/bin/env python3
"""The plugin index of tests/README.md: for every plugin registered in
server/kernel/scene/registry.c, the test programs and scripts that exercise
it, found by name in their sources: a scene object of that type
("type": "NAME" in JSON, type="NAME" in XML, also inside C strings), the
plugin's symbol (plugin_NAME), or a scene file of proto/ or docs/ the test
names whose objects have that type.

  tools/test-index.py          rewrite the index in tests/README.md
  tools/test-index.py --check  exit 1 when a registered plugin has no test
                               (listing them) or the index is not current
  --root DIR                   index the tree at DIR, not this repository

tests/integration/test_plugin_index.sh runs --check in make test.
"""
import os
import re
import sys

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
if "--root" in sys.argv[1:]:  # another tree (the negative control of the test)
    ROOT = os.path.abspath(sys.argv[sys.argv.index("--root") + 1])
README = os.path.join(ROOT, "tests", "README.md")
BEGIN = "<!-- plugin index: tools/test-index.py writes what follows -->"
END = "<!-- end of plugin index -->"
SHOWN = 6  # tests listed per plugin, the most specific first
SKIP = {"support", "fuzz", "bench", "corpus", "data", "plugins", "cluster", "fresh", "openapi"}


def plugins():
    src = open(os.path.join(ROOT, "server/kernel/scene/registry.c")).read()
    body = src[src.index("#define PLUGINS(X)"):src.index("clang-format on")]
    return re.findall(r"\bX\((\w+)\)", body)


def plugin_file(name):
    pat = re.compile(r"\bconst plugin plugin_%s\b|^DEFINE_PLUGIN\(%s\b" % (re.escape(name), re.escape(name)),
                     re.M)
    for d, _, files in sorted(os.walk(os.path.join(ROOT, "server/kernel"))):
        for f in sorted(files):
            p = os.path.join(d, f)
            if f.endswith(".c") and pat.search(open(p, errors="replace").read()):
                return os.path.relpath(p, ROOT)
    return None


def tests():
    out = []
    top = os.path.join(ROOT, "tests")
    for d, dirs, files in os.walk(top):
        if os.path.relpath(d, top).split(os.sep)[0] in SKIP:
            dirs[:] = []
            continue
        dirs.sort()
        for f in files:
            # (test_plugin_index.sh, the check itself, names made-up plugins.)
            if f.startswith("test_") and f.endswith((".c", ".sh", ".py")) and f != "test_plugin_index.sh":
                out.append(os.path.relpath(os.path.join(d, f), ROOT))
    return sorted(out)


def scene_types(text):
    """The plugin types a source or scene file names."""
    q = r'\\?"'
    types = set(re.findall(r'%stype%s\s*:\s*%s([A-Za-z_]\w*)%s' % (q, q, q, q), text))
    types |= set(re.findall(r'\btype\s*=\s*%s([A-Za-z_]\w*)%s' % (q, q), text))
    types |= set(re.findall(r"\bplugin_([a-z_]\w*)\b", text))
    if re.search(r"<scene\b", text) or re.search(r"\bscene_(load|from)\w*\(", text):
        types.add("scene")
    return types


def referenced_files(text):
    refs = set()
    for m in re.finditer(r"((?:proto|docs)/[\w./-]+\.(?:json|xml))", text):
        p = os.path.join(ROOT, m.group(1))
        if os.path.isfile(p):
            refs.add(p)
    return refs


def index():
    found = {}
    for t in tests():
        text = open(os.path.join(ROOT, t), errors="replace").read()
        types = scene_types(text)
        for ref in referenced_files(text):
            types |= scene_types(open(ref, errors="replace").read())
        for ty in types:
            found.setdefault(ty, []).append((t, len(types)))
    lines = ["| plugin | source | tests |", "|---|---|---|"]
    missing = []
    for name in plugins():
        src = plugin_file(name) or "?"
        # The most specific first: those in the plugin's own folder
        # (tests/kernel/<class>/), then those naming the fewest types.
        home = "tests/kernel/" + os.path.dirname(src.replace("server/kernel/", "")) + "/"
        ts = [t for t, _ in sorted(found.get(name, []), key=lambda e: (not e[0].startswith(home), e[1], e[0]))]
        if not ts:
            missing.append(name)
        cell = ", ".join("[%s](%s)" % (os.path.basename(t), os.path.relpath(t, "tests")) for t in ts[:SHOWN])
        if len(ts) > SHOWN:
            cell += " and %d more" % (len(ts) - SHOWN)
        cell = cell or "**none**"
        lines.append("| `%s` | [%s](../%s) | %s |" % (name, src.replace("server/kernel/", ""), src, cell))
    return "\n".join(lines) + "\n", missing


def main():
    table, missing = index()
    text = open(README).read()
    i, j = text.find(BEGIN), text.find(END)
    if i < 0 or j < i:
        sys.exit("tools/test-index.py: tests/README.md lacks the index markers")
    new = text[: i + len(BEGIN)] + "\n" + table + text[j:]
    if "--check" in sys.argv[1:]:
        bad = 0
        if missing:
            print("registered plugins no test names: " + " ".join(missing))
            bad = 1
        if new != text:
            print("tests/README.md's plugin index is not current: run tools/test-index.py")
            bad = 1
        sys.exit(bad)
    if new != text:
        open(README, "w").write(new)
    if missing:
        print("registered plugins no test names: " + " ".join(missing), file=sys.stderr)


if __name__ == "__main__":
    main()
