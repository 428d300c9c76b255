#!/usr/bin/env bash
# Each plugin's tests are findable by its name (tests/README.md):
#  - every plugin registered in server/kernel/scene/registry.c is named by
#    at least one test, and tests/README.md's plugin index is current
#    (tools/test-index.py --check), each plugin with its source file;
#  - every test program sits in the folder tools/test-layout.sh gives it,
#    and none is left in the old tests/unit/;
#  - and the check catches a plugin no test names, and a stale index (a
#    negative control on a small tree of its own).
# Ends with "test_plugin_index: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_plugin_index
source "$(dirname "$0")/../support/shtest.sh"
cd "$root" || exit 1

if out=$(python3 tools/test-index.py --check 2>&1); then ok; else bad "tools/test-index.py --check: $out"; fi
# every plugin's source file is found (DEFINE_PLUGIN(name, ...) or const plugin plugin_name)
if grep -q '\[?\](\.\./?)' tests/README.md; then bad "plugins without their source in the index: $(grep -c '\[?\]' tests/README.md)"; else ok; fi

moves=$(tools/test-layout.sh -n 2>&1)
if [ -z "$moves" ]; then ok; else bad "test programs out of place (run tools/test-layout.sh): $moves"; fi
if ls tests/unit/test_*.c >/dev/null 2>&1; then bad "tests/unit/ still holds test programs"; else ok; fi

# Negative control: a registered plugin no test names, then a stale index.
t=$tmp/tree
mkdir -p "$t/server/kernel/scene" "$t/server/kernel/bsdfs" "$t/tests/kernel/bsdfs"
printf '#define PLUGINS(X) X(scene) X(fake_bsdf)\n// clang-format on\n' >"$t/server/kernel/scene/registry.c"
printf 'const plugin plugin_scene = {.name = "scene"};\n' >"$t/server/kernel/scene/scene.c"
printf 'const plugin plugin_fake_bsdf = {.name = "fake_bsdf"};\n' >"$t/server/kernel/bsdfs/fake_bsdf.c"
printf 'const char *s = "{\\"type\\": \\"scene\\"}";\n' >"$t/tests/kernel/bsdfs/test_other.c"
printf '# x\n<!-- plugin index: tools/test-index.py writes what follows -->\n<!-- end of plugin index -->\n' >"$t/tests/README.md"
python3 tools/test-index.py --root "$t" 2>/dev/null
out=$(python3 tools/test-index.py --root "$t" --check 2>&1)
rc=$?
if [ $rc -ne 0 ] && [[ $out == *"no test names: fake_bsdf"* ]] && [[ $out != *"not current"* ]]; then ok; else
  bad "a plugin without a test passed the check (rc $rc): $out"
fi
printf 'const char *s = "<bsdf type=\\"fake_bsdf\\"/>";\n' >"$t/tests/kernel/bsdfs/test_fake_bsdf.c"
out=$(python3 tools/test-index.py --root "$t" --check 2>&1)
rc=$?
if [ $rc -ne 0 ] && [[ $out == *"not current"* ]] && [[ $out != *"no test names"* ]]; then ok; else
  bad "a stale index passed the check (rc $rc): $out"
fi
python3 tools/test-index.py --root "$t"
if out=$(python3 tools/test-index.py --root "$t" --check 2>&1) && grep -q '`fake_bsdf`.*test_fake_bsdf.c' "$t/tests/README.md"; then ok; else
  bad "the rewritten index does not pass, or lacks fake_bsdf's test: $out"
fi
finish
