#!/usr/bin/env bash
# No circle of files inside server/kernel (issue 23: the kernel's layers).
# tools/check-layers.py counts both #include lines and the functions and
# variables a file names that another .c file defines; first it must catch
# circles made each way in small trees of its own, then find none in the
# kernel (printing the circle when it does).
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
check=$root/tools/check-layers.py
pass=0; fail=0
ok() { echo "ok   $1"; pass=$((pass + 1)); }
bad() { echo "FAIL $1"; [ -n "${2:-}" ] && echo "$2" | head -30; fail=$((fail + 1)); }
tmp=$(mktemp -d /tmp/rsw-layers-XXXXXX)
trap 'rm -rf "$tmp"' EXIT

# A circle of includes: a.c includes b.h, b.c includes a.h.
mkdir -p "$tmp/inc/sub"
printf 'void a(void);\n' > "$tmp/inc/a.h"
printf '#include "sub/b.h"\nvoid a(void) { b(); }\n' > "$tmp/inc/a.c"
printf 'void b(void);\n' > "$tmp/inc/sub/b.h"
printf '#include "../a.h"\nvoid b(void) {}\nstatic void c(void) { a(); }\n' > "$tmp/inc/sub/b.c"
out=$(python3 "$check" "$tmp/inc" 2>&1)
if [ $? -eq 1 ] && grep -q 'circle of 2 modules' <<<"$out" && grep -q 'includes "../a.h"' <<<"$out"; then
  ok "a circle of includes is found and printed"
else bad "a circle of includes is found and printed" "$out"; fi

# A circle through a shared header: api.h declares functions of two files
# (p.c and q.c); p calls q's, q calls p's. Includes alone see no circle.
mkdir -p "$tmp/shared"
printf 'void p(void);\nvoid q(void);\n' > "$tmp/shared/api.h"
printf '#include "api.h"\nvoid p(void) { q(); }\n' > "$tmp/shared/p.c"
printf '#include "api.h"\nvoid q(void) {}\nvoid q2(void) { p(); }\n' > "$tmp/shared/q.c"
out=$(python3 "$check" "$tmp/shared" 2>&1)
if [ $? -eq 1 ] && grep -q 'names q (defined in q.c)' <<<"$out" && grep -q 'names p (defined in p.c)' <<<"$out"; then
  ok "a circle through a shared header's functions is found"
else bad "a circle through a shared header's functions is found" "$out"; fi

# A circle through a header's inline function: common.h (no .c of its
# own) calls g() of g.c inline, and g.c includes common.h; a prototype
# after the inline function is no use.
mkdir -p "$tmp/inline"
printf 'static inline int twice(int x) { return 2 * x; }\nint g(int);\nstatic inline int h(int x) { return g(x); }\nint later(void);\n' > "$tmp/inline/common.h"
printf '#include "common.h"\nint g(int x) { return twice(x); }\n' > "$tmp/inline/g.c"
printf 'int later(void) { return 0; }\n' > "$tmp/inline/later.c"
printf '#include "later.h"\nint user(void) { return 1; }\n' > "$tmp/inline/user.c"
printf 'int user(void);\n' > "$tmp/inline/later.h"
out=$(python3 "$check" "$tmp/inline" 2>&1)
if [ $? -eq 1 ] && grep -q 'common.h names g (defined in g.c)' <<<"$out" && ! grep -q 'names later' <<<"$out"; then
  ok "a circle through a header's inline function is found; its prototypes are no use"
else bad "a circle through a header's inline function is found; its prototypes are no use" "$out"; fi

# A table of pasted names (plugin_##name) names what it pastes; a call
# through a function pointer and a static function of the same name are
# no dependency.
mkdir -p "$tmp/paste"
printf '#define X(n) extern const int plugin_##n;\nX(one)\nconst int *t[] = {&plugin_one};\nint reg(void) { return 0; }\n' > "$tmp/paste/registry.c"
printf 'int reg(void);\nconst int plugin_one = 1;\nint use(void) { return reg(); }\n' > "$tmp/paste/one.c"
printf 'static int reg(void) { return 1; }\nint (*hook)(void) = 0;\nint two(void) { return reg() + hook(); }\n' > "$tmp/paste/two.c"
out=$(python3 "$check" "$tmp/paste" 2>&1)
if [ $? -eq 1 ] && grep -q 'names plugin_one' <<<"$out" && ! grep -q '^ *two' <<<"$out"; then
  ok "pasted names count; a static function of the same name does not"
else bad "pasted names count; a static function of the same name does not" "$out"; fi

# A tree without a circle passes.
mkdir -p "$tmp/line"
printf 'int low(void);\n' > "$tmp/line/low.h"
printf '#include "low.h"\nint low(void) { return 1; }\n' > "$tmp/line/low.c"
printf '#include "low.h"\nint high(void) { return low(); }\n' > "$tmp/line/high.c"
out=$(python3 "$check" "$tmp/line" 2>&1)
if [ $? -eq 0 ] && grep -q '0 circles' <<<"$out"; then ok "a layered tree passes"
else bad "a layered tree passes" "$out"; fi

# The kernel.
out=$(cd "$root" && python3 "$check" server/kernel 2>&1)
if [ $? -eq 0 ]; then ok "no circle of files in server/kernel ($(tail -1 <<<"$out"))"
else bad "no circle of files in server/kernel" "$out"; fi

echo "test_layers: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
