#!/usr/bin/env python3
"""Checks that the documentation is executable and agrees with the programs.

Used by tests/integration/test_docs_examples.sh and test_usage.sh. Every
mode prints one line per check, "PASS what", "FAIL what: why" or
"SKIP what: reason", which the calling script counts.

  docs_check.py run --root R --bin B --work W --url U [--path-prefix D] [FILE.md...]
      Runs every shell block of the Markdown files (default: README.md and
      docs/**/*.md) against the daemon at U; see RULES below.
  docs_check.py links ROOT FILE.md...
      Every relative link of the files ([text](path#anchor)) names a file
      or directory inside ROOT, and an anchor names a heading of the
      Markdown file it points to.
  docs_check.py citations ROOT FILE...
      No file cites a path outside the repository (the reference notes the
      project was written from, or a machine's own directories), and every
      "docs/<page>.md", "docs/<page>.md#anchor" or "README.md#<anchor>" a
      file mentions exists.
  docs_check.py curl-lint FILE...
      Every curl command in the shell blocks of FILE (Markdown) or in FILE
      (a shell script) fails on an HTTP error (see curl_fails).
  docs_check.py usage PROG FILE.md...
      Prints PROG's usage entries of the files' usage blocks (plain ```
      blocks whose lines start with "PROG "), one per line, normalised.
  docs_check.py man PROG PAGE.1
      The same for the .SH SYNOPSIS of a man page.
  docs_check.py help-entry PROG
      Reads `PROG ... --help` output on stdin; prints its usage entry.
  docs_check.py listing PROG
      Reads `PROG --help` on stdin; prints the command words it lists.

RULES for fenced blocks in Markdown (the visible rules the brief asks for):
  * A block tagged sh, bash, shell or console is run, unless
      - the nearest non-blank line above it is
        <!-- docs-test: skip: REASON -->   (REASON is required and printed), or
        <!-- docs-test: file PATH -->      (the block must equal the file PATH
                                            byte for byte, and the test runs
                                            the file itself), or
      - one of its commands is a build/bootstrap command (build_rule below:
        `make` with no target or only deps/all/run/test/bench/format/clean,
        any *bootstrap* program, tools/deps.sh, apt-get, docker, sudo): the project is already
        built, and `make run` would start a second daemon on the default
        port. The block is reported as SKIP with the command.
  * Any other block with a `file PATH` marker (C, JSON, Python) must equal
    PATH byte for byte.
  * Each runnable block runs on its own, in a fresh `bash -e` (so any failing
    command fails the block), from a copy of the repository (W/repo, with
    build/ linked to the built tree), with HOME=W/home, build/bin first on
    PATH (and python3 = RSW_PYTHON, default /usr/bin/python3, before it),
    RAYSWEEP_URL=U, and "localhost:8350" / "127.0.0.1:8350" replaced by
    the test daemon's address. Files written by one block stay for the next,
    as in a terminal; variables do not.
  * A block whose lines start with "$ " is a transcript: each "$ " command
    (with "\\" continuations) is run, and the lines after it, whitespace
    collapsed, must be its stdout, where a line "..." stands for any lines.
"""
import os
import re
import shutil
import subprocess
import sys

RUN_LANGS = {"sh", "bash", "shell", "console"}
MARKER = re.compile(r"^\s*<!--\s*docs-test:\s*(skip|file)\s*:?\s*(.*?)\s*-->\s*$")
MAKE_BUILD_TARGETS = {"deps", "all", "run", "test", "bench", "format", "clean"}


def blocks(path):
    """Yield (line, lang, text, directive, arg) for each fenced block."""
    lines = open(path, encoding="utf-8").read().split("\n")
    i = 0
    while i < len(lines):
        m = re.match(r"^(\s*)(```+)\s*([A-Za-z0-9_+-]*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = m.group(1), m.group(2), m.group(3).lower()
        start = i
        body = []
        i += 1
        while i < len(lines) and not re.match(r"^\s*" + fence + r"\s*$", lines[i]):
            body.append(lines[i][len(indent):] if lines[i].startswith(indent) else lines[i])
            i += 1
        i += 1
        directive = arg = None
        k = start - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        if k >= 0:
            mm = MARKER.match(lines[k])
            if mm:
                directive, arg = mm.group(1), mm.group(2)
        yield start + 1, lang, "\n".join(body) + "\n", directive, arg


def logical_lines(text):
    """Shell lines with backslash-newline continuations joined."""
    out, cur = [], ""
    for line in text.split("\n"):
        if line.endswith("\\"):
            cur += line[:-1] + " "
        else:
            out.append(cur + line)
            cur = ""
    if cur:
        out.append(cur)
    return out


def commands(text):
    """The simple commands of a block, split at ;, &&, ||, | and & (quotes
    are not parsed: good enough to spot a command word)."""
    for line in logical_lines(text):
        code = re.sub(r"(^|\s)#.*$", "", line)
        for cmd in re.split(r"&&|\|\||[;|&()]|\$\(", code):
            if cmd.strip():
                yield cmd.strip()


def build_rule(text):
    """The first build/bootstrap command of a block, or None."""
    for cmd in commands(text):
        words = cmd.split()
        while words and re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", words[0]):
            words = words[1:]
        if words[:1] in (["sudo"], ["su"]):
            return cmd  # never run anything as root from a test
        if not words:
            continue
        w0 = words[0]
        if w0 in ("make", "./make"):  # ./make: the bootstrap wrapper of make
            targets = [w for w in words[1:] if not w.startswith("-") and "=" not in w]
            if all(t in MAKE_BUILD_TARGETS for t in targets):
                return cmd
        elif "bootstrap" in os.path.basename(w0) or w0 in ("tools/deps.sh", "apt-get", "apt", "docker"):
            return cmd
    return None


def curl_fails(segment):
    """True when a curl command line fails on HTTP errors (-f, --fail,
    --fail-with-body, or a short-option cluster with f such as -sSf)."""
    return re.search(r"(^|\s)(--fail(-with-body)?|-[A-Za-z]*f[A-Za-z]*)(?=\s|$)", segment) is not None


def curl_problems(text):
    bad = []
    for line in logical_lines(text):
        code = re.sub(r"(^|\s)#.*$", "", line)
        for m in re.finditer(r"(^|[\s|;&(`])curl\s", code):
            seg = re.split(r"[|;&)`]", code[m.start(0) + len(m.group(1)):])[0]
            if not curl_fails(seg):
                bad.append(seg.strip())
    return bad


def norm(s):
    return " ".join(s.split())


def match_transcript(expected, actual):
    """expected: normalised lines with "..." wildcards; actual: lines."""
    if not expected:
        return not actual
    if expected[0] == "...":
        return any(match_transcript(expected[1:], actual[i:]) for i in range(len(actual) + 1))
    return bool(actual) and actual[0] == expected[0] and match_transcript(expected[1:], actual[1:])


def transcript(text):
    """[(command, [expected output lines])] of a "$ " block."""
    items = []
    lines = text.rstrip("\n").split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("$ "):
            cmd = line[2:]
            while cmd.endswith("\\") and i + 1 < len(lines):
                i += 1
                cmd = cmd + "\n" + lines[i]
            items.append((cmd, []))
        elif items:
            items[-1][1].append(norm(line))
        i += 1
    return items


def make_sandbox(root, bin_dir, work):
    repo = os.path.join(work, "repo")
    home = os.path.join(work, "home")
    if os.path.exists(repo):
        shutil.rmtree(repo)
    os.makedirs(home, exist_ok=True)
    ignore = shutil.ignore_patterns(".git", "build", "build-san", "node_modules")
    # copy2 keeps modification times, so make sees the built tree up to date.
    shutil.copytree(root, repo, symlinks=True, ignore=ignore)
    built = os.path.dirname(os.path.abspath(bin_dir))
    for name in ("build", "build-san"):
        os.symlink(built, os.path.join(repo, name))
    return repo, home


def block_env(bin_dir, home, url):
    env = {k: v for k, v in os.environ.items()
           if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL", "MAKEOVERRIDES", "RAYSWEEP_TOKEN")}
    env["HOME"] = home
    env["PATH"] = os.path.abspath(bin_dir) + os.pathsep + env.get("PATH", "/usr/bin:/bin")
    env["RAYSWEEP_URL"] = url
    return env


def run_blocks(args):
    opts, files = {}, []
    it = iter(args)
    for a in it:
        if a.startswith("--"):
            opts[a[2:]] = next(it)
        else:
            files.append(a)
    root = os.path.abspath(opts["root"])
    if not files:
        files = [os.path.join(root, "README.md")]
        for d, _, names in sorted(os.walk(os.path.join(root, "docs"))):
            files += [os.path.join(d, n) for n in sorted(names) if n.endswith(".md")]
    hostport = re.sub(r"^https?://", "", opts["url"]).rstrip("/")
    repo, home = make_sandbox(root, opts["bin"], opts["work"])
    env = block_env(opts["bin"], home, opts["url"])
    # python3 in a block is Debian's (python3-xarray, python3-netcdf4 from
    # `make deps`), not one earlier on PATH that lacks them; RSW_PYTHON
    # names another, as in test_dataset.sh.
    py = os.environ.get("RSW_PYTHON", "/usr/bin/python3")
    if os.path.isfile(py):
        pybin = os.path.join(opts["work"], "pybin")
        os.makedirs(pybin, exist_ok=True)
        link = os.path.join(pybin, "python3")
        if not os.path.lexists(link):
            os.symlink(py, link)
        env["PATH"] = pybin + os.pathsep + env["PATH"]
    if "path-prefix" in opts:
        env["PATH"] = opts["path-prefix"] + os.pathsep + env["PATH"]
    timeout = int(opts.get("timeout", "300"))
    n_run = 0
    for path in files:
        rel = os.path.relpath(path, root)
        for line, lang, text, directive, arg in blocks(path):
            where = f"{rel}:{line}"
            if directive == "skip":
                if arg:
                    print(f"SKIP {where}: {arg}")
                else:
                    print(f"FAIL {where}: a docs-test skip marker needs a reason")
                continue
            if directive == "file":
                target = os.path.join(root, arg)
                if not os.path.isfile(target):
                    print(f"FAIL {where}: docs-test file {arg} does not exist")
                elif open(target, encoding="utf-8").read() != text:
                    print(f"FAIL {where}: the block differs from {arg} (copy the file into the page)")
                else:
                    print(f"PASS {where}: equals {arg}")
                continue
            if lang not in RUN_LANGS:
                continue
            rule = build_rule(text)
            if rule:
                print(f"SKIP {where}: build/bootstrap command `{rule}` (rule build_rule in {os.path.relpath(__file__, root)})")
                continue
            text = re.sub(r"\b(localhost|127\.0\.0\.1):8350\b", hostport, text)
            n_run += 1
            if any(l.startswith("$ ") for l in text.split("\n")):
                run_transcript(where, text, repo, env, timeout)
            else:
                run_script(where, text, repo, env, timeout)
    if n_run == 0:
        print("FAIL no runnable shell block found in " + ", ".join(os.path.relpath(f, root) for f in files))


def run_script(where, text, cwd, env, timeout):
    try:
        p = subprocess.run(["bash", "-e", "-c", text], cwd=cwd, env=env, capture_output=True,
                           timeout=timeout, text=True, errors="replace")
    except subprocess.TimeoutExpired:
        print(f"FAIL {where}: still running after {timeout} s")
        return
    if p.returncode != 0:
        tail = " | ".join((p.stderr.strip() or p.stdout.strip()).split("\n")[-6:])
        print(f"FAIL {where}: exit {p.returncode}: {tail}")
    else:
        print(f"PASS {where}: ran")


def run_transcript(where, text, cwd, env, timeout):
    for cmd, expected in transcript(text):
        first = cmd.split("\n")[0]
        try:
            p = subprocess.run(["bash", "-e", "-c", cmd], cwd=cwd, env=env, capture_output=True,
                               timeout=timeout, text=True, errors="replace")
        except subprocess.TimeoutExpired:
            print(f"FAIL {where}: `{first}` still running after {timeout} s")
            continue
        if p.returncode != 0:
            tail = " | ".join(p.stderr.strip().split("\n")[-6:])
            print(f"FAIL {where}: `{first}` exit {p.returncode}: {tail}")
            continue
        actual = [norm(l) for l in p.stdout.rstrip("\n").split("\n")] if p.stdout.strip() else []
        if not match_transcript(expected, actual):
            got = " / ".join(actual[:4])
            print(f"FAIL {where}: `{first}` printed other lines than the page shows (first: {got})")
        else:
            print(f"PASS {where}: `{first}` prints what the page shows")


def curl_lint(files):
    for path in files:
        if path.endswith(".md"):
            chunks = [(f"{path}:{l}", t) for l, lang, t, _, _ in blocks(path) if lang in RUN_LANGS]
        else:
            chunks = [(path, open(path, encoding="utf-8").read())]
        for where, text in chunks:
            for seg in curl_problems(text):
                print(f"FAIL {where}: curl without --fail-with-body/-f would save an error body: {seg[:80]}")
            if "curl" in text and not curl_problems(text):
                print(f"PASS {where}: every curl fails on HTTP errors")


def slugs(path):
    """The anchors of a Markdown file's headings, as GitHub makes them:
    lower case, punctuation but - and _ dropped, spaces to -, a repeated
    heading suffixed -1, -2, ..."""
    seen, out, fence = {}, set(), False
    for line in open(path, encoding="utf-8").read().split("\n"):
        if re.match(r"^\s*```", line):
            fence = not fence
            continue
        m = None if fence else re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        s = re.sub(r"[^\w\- ]", "", m.group(1).replace("`", "").lower()).replace(" ", "-")
        n = seen.get(s, 0)
        seen[s] = n + 1
        out.add(s if n == 0 else f"{s}-{n}")
    return out


def links(root, files):
    root = os.path.abspath(root)
    for path in files:
        path = os.path.abspath(path)
        rel = os.path.relpath(path, root)
        fence, bad = False, 0
        for no, line in enumerate(open(path, encoding="utf-8").read().split("\n"), 1):
            if re.match(r"^\s*```", line):
                fence = not fence
            if fence:
                continue
            for m in re.finditer(r"\]\(([^)\s]+)\)", line):
                target = m.group(1)
                if re.match(r"^[a-z]+:", target):
                    continue
                file, _, anchor = target.partition("#")
                dest = os.path.normpath(os.path.join(os.path.dirname(path), file)) if file else path
                if not (dest == root or dest.startswith(root + os.sep)):
                    print(f"FAIL {rel}:{no}: link {target} leaves the repository")
                    bad += 1
                elif not os.path.exists(dest):
                    print(f"FAIL {rel}:{no}: link {target}: {os.path.relpath(dest, root)} does not exist")
                    bad += 1
                elif anchor and dest.endswith(".md") and anchor not in slugs(dest):
                    print(f"FAIL {rel}:{no}: link {target}: no heading #{anchor} in {os.path.relpath(dest, root)}")
                    bad += 1
        if not bad:
            print(f"PASS {rel}: every link resolves")


# Paths outside the repository that files have cited (spelled in pieces so
# that this file does not match itself).
OUTSIDE = re.compile("|".join([r"kernel-" + r"behavior", r"(?<![\w.])(?:\.\./)+" + r"shared/",
                               r"/" + r"work/", r"(?<![\w/.-])" + r"shared/(?:seeds|reference|notes)/"]))


def citations(root, files):
    root = os.path.abspath(root)
    for path in files:
        rel = os.path.relpath(path, root)
        try:
            text = open(path, encoding="utf-8").read()
        except (UnicodeDecodeError, IsADirectoryError):
            continue
        bad = 0
        for no, line in enumerate(text.split("\n"), 1):
            m = OUTSIDE.search(line)
            if m:
                print(f"FAIL {rel}:{no}: cites a path outside the repository: {line.strip()[:100]}")
                bad += 1
            for m in re.finditer(r"(?<![\w/.-])README\.md#([\w-]+)", line):
                if m.group(1) not in slugs(os.path.join(root, "README.md")):
                    print(f"FAIL {rel}:{no}: cites README.md#{m.group(1)}: no such heading")
                    bad += 1
            for m in re.finditer(r"(?<![\w/.-])docs/([\w-]+\.md)(?:#([\w-]+))?", line):
                page = os.path.join(root, "docs", m.group(1))
                if not os.path.isfile(page):
                    print(f"FAIL {rel}:{no}: cites docs/{m.group(1)}, which does not exist")
                    bad += 1
                elif m.group(2) and m.group(2) not in slugs(page):
                    print(f"FAIL {rel}:{no}: cites docs/{m.group(1)}#{m.group(2)}: no such heading")
                    bad += 1
        if not bad and ("docs/" in text or "README.md#" in text):
            print(f"PASS {rel}: its citations exist")


def entries(lines, prog):
    """Usage entries: a line starting with "PROG " and the indented lines
    after it; "# comments" dropped, whitespace collapsed."""
    out = []
    for line in lines:
        code = line.split(" #", 1)[0].rstrip()
        if code.startswith(prog + " "):
            out.append(code)
        elif out and code.startswith(" ") and code.strip():
            out[-1] += " " + code
    return [norm(e) for e in out]


def command_words(entry, prog):
    """The lower-case words after PROG: "raysweep scene push FILE" -> "scene push"."""
    words = []
    for w in entry.split()[1:]:
        if re.fullmatch(r"[a-z]+", w):
            words.append(w)
        else:
            break
    return " ".join(words)


def usage_from_readme(prog, path):
    res = []
    for _, lang, text, _, _ in blocks(path):
        if lang:
            continue
        lines = text.split("\n")
        if not any(l.startswith(prog + " ") for l in lines):
            continue
        res += entries(lines, prog)
    return res


def usage_from_man(prog, path):
    src = open(path, encoding="utf-8").read().split("\n")
    try:
        i = src.index(".SH SYNOPSIS")
    except ValueError:
        return []
    lines = []
    for line in src[i + 1:]:
        if line.startswith(".SH"):
            break
        if line.startswith("."):
            continue
        line = re.sub(r"\\f[BIRP]", "", line).replace("\\-", "-").replace("\\(em", "--").replace("\\e", "\\")
        lines.append(line)
    return entries(lines, prog)


def main():
    if len(sys.argv) < 2:
        print(__doc__)
        return 2
    mode, args = sys.argv[1], sys.argv[2:]
    if mode == "run":
        run_blocks(args)
    elif mode == "links":
        links(args[0], args[1:])
    elif mode == "citations":
        citations(args[0], args[1:])
    elif mode == "curl-lint":
        curl_lint(args)
    elif mode == "usage":
        for path in args[1:]:
            for e in usage_from_readme(args[0], path):
                print(e)
    elif mode == "man":
        prog, path = args
        for e in usage_from_man(prog, path):
            print(e)
    elif mode == "help-entry":
        prog = args[0]
        lines, out = sys.stdin.read().split("\n"), []
        for line in lines:
            if line.startswith("usage: "):
                out.append(line[len("usage: "):])
            elif out and line.strip():
                out.append(line)
            elif out:
                break
        print(norm(" ".join(out)))
    elif mode == "listing":
        prog = args[0]
        for line in sys.stdin.read().split("\n"):
            if line.startswith("  " + prog + " "):
                words = command_words(norm(line), prog)
                if words:
                    print(words)
    elif mode == "words":
        prog = args[0]
        for line in sys.stdin.read().split("\n"):
            if line.strip():
                print(command_words(line, prog))
    else:
        print(__doc__)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
