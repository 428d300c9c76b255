#!/usr/bin/env bash
# Keeps proto/openapi.yaml true: runs tests/openapi/check.py (validates the
# spec against the OpenAPI 3.1 schema with python3-jsonschema, resolves every
# $ref, checks every example against its schema, and compares the routes
# with those `$RSW_BIN_DIR/raysweepd routes` prints). Then feeds the checker
# broken copies of the spec, each of which it must reject: a check that
# cannot fail proves nothing. Ends with "test_openapi: N passed, N failed",
# also when the checker cannot run at all.
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
# Debian's python3, which has Debian's python3-yaml and python3-jsonschema
# (`make deps`), whatever python3 comes first in PATH.
py=${RSW_PYTHON:-/usr/bin/python3}
if [ ! -x "$py" ]; then
  echo "FAIL deps: $py is not installed: run \`make deps\`"
  echo "test_openapi: 0 passed, 1 failed"
  exit 1
fi
cd "$root"
out=$("$py" tests/openapi/check.py 2>&1)
rc=$?
echo "$out" | grep -v '^test_openapi: '
line=$(echo "$out" | grep -E '^test_openapi: [0-9]+ passed, [0-9]+ failed$' | tail -n 1)
if [ -z "$line" ]; then
  echo "FAIL check.py: exited $rc without a summary line"
  echo "test_openapi: 0 passed, 1 failed"
  exit 1
fi
pass=$(echo "$line" | sed -E 's/.*: ([0-9]+) passed.*/\1/')
fail=$(echo "$line" | sed -E 's/.*, ([0-9]+) failed/\1/')
[ "$rc" -ne 0 ] && [ "$fail" -eq 0 ] && fail=1

# ---- the checker rejects what it must ----------------------------------------
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# mutant NAME CHECK SED-SCRIPT: the spec edited by SED-SCRIPT must make CHECK fail.
mutant() {
  local name=$1 want=$2 script=$3
  sed -e "$script" proto/openapi.yaml >"$tmp/$name.yaml"
  if cmp -s proto/openapi.yaml "$tmp/$name.yaml"; then
    echo "FAIL reject_$name: the edit did not change the spec (fix the test)"; fail=$((fail + 1)); return
  fi
  local o
  o=$(RSW_OPENAPI_SPEC="$tmp/$name.yaml" "$py" tests/openapi/check.py 2>&1)
  if echo "$o" | grep -q "^FAIL $want: "; then
    echo "ok   reject_$name"; pass=$((pass + 1))
  else
    echo "FAIL reject_$name: check.py did not fail $want:"; echo "$o" | sed 's/^/    /' | head -n 20
    fail=$((fail + 1))
  fi
}
# Not an OpenAPI 3.1 document: an unknown field of an operation.
mutant unknown_field spec_validate '0,/operationId:/s/operationId:/operationIdd:/'
# A $ref to a schema that does not exist.
mutant dangling_ref spec_dereference '0,/\$ref: .#\/components\/schemas\/Problem./s//$ref: "#\/components\/schemas\/Problemm"/'
# A misspelt JSON Schema keyword inside a component schema.
mutant schema_typo schemas_compile '0,/minimum: 1}/s//minimun: 1}/'
# A route that raysweepd does not serve.
mutant extra_route routes_served 's|^  /v1/health/ready:|  /v1/health/readyy:|'
# An example that does not match its schema: the first `spp:` example value.
mutant bad_example examples_valid '0,/^\( *\)spp: [0-9][0-9]*$/s//\1spp: "many"/'
# A duplicate key is an error, not last-one-wins.
mutant duplicate_key spec_parse '0,/^info:/s//info:\n  title: twice/'

echo "test_openapi: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
