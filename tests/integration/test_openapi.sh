#!/usr/bin/env bash
# Keeps proto/openapi.yaml true: runs tests/openapi/check.mjs (validates the
# spec with a real OpenAPI 3.1 validator and compares its routes with those
# `$RSW_BIN_DIR/raysweepd routes` prints). Ends with the summary line
# "test_openapi: N passed, N failed" that tests/run.sh sums, also when the
# validator cannot run at all.
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
missing() {
  echo "FAIL deps: $1"
  echo "test_openapi: 0 passed, 1 failed"
  exit 1
}
command -v node >/dev/null || missing "node is not installed (it comes with the machine image)"
[ -d "$root/tests/openapi/node_modules" ] ||
  missing "tests/openapi/node_modules is missing: run \`make deps\` (npm ci --prefix tests/openapi)"
cd "$root" && exec node tests/openapi/check.mjs
