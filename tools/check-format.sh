#!/usr/bin/env bash
# The C sources against .clang-format (Debian's clang-format):
#   tools/check-format.sh        report every file clang-format would change
#                                (--dry-run --Werror); exit 1 if there is one
#   tools/check-format.sh --fix  reformat them in place (`make format`)
# Both act on the same files: every .c and .h under server, client, include
# and tests.
set -euo pipefail
cd "$(dirname "$0")/.."
command -v clang-format >/dev/null || { echo "check-format: clang-format is not installed: run make deps" >&2; exit 1; }
mapfile -t files < <(find server client include tests -name '*.[ch]' -type f | sort)
[ ${#files[@]} -gt 0 ] || { echo "check-format: no C sources found" >&2; exit 1; }
if [ "${1:-}" = --fix ]; then
  exec clang-format -i --style=file "${files[@]}"
fi
rc=0
out=$(clang-format --dry-run --Werror --style=file "${files[@]}" 2>&1) || rc=$?
mapfile -t bad < <(grep -E '^[^:]+:[0-9]+:[0-9]+: error: code should be clang-formatted' <<<"$out" | cut -d: -f1 | uniq)
if [ "$rc" -ne 0 ] && [ ${#bad[@]} -eq 0 ]; then
  echo "check-format: clang-format failed:" >&2; head -n 20 <<<"$out" >&2; exit 1
fi
if [ ${#bad[@]} -gt 0 ]; then
  printf 'check-format: not formatted: %s\n' "${bad[@]}" >&2
  echo "check-format: ${#bad[@]} of ${#files[@]} files differ from .clang-format (clang-format $(clang-format --version | grep -o '[0-9][0-9.]*' | head -n 1)); run make format" >&2
  exit 1
fi
echo "check-format: ${#files[@]} files formatted"
