#!/usr/bin/env bash
# The public headers compile alone, warning-free, as C11 and as C++
# (include/raysweep/*.h promise this in their opening comments).
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
pass=0; fail=0
check() { # name, command...
  local name=$1; shift
  local out
  if out=$("$@" 2>&1); then
    echo "ok   $name"; pass=$((pass + 1))
  else
    echo "FAIL $name"; echo "$out" | head -20; fail=$((fail + 1))
  fi
}
CC=${CC:-cc}
for h in client.h status.h; do
  f="$root/include/raysweep/$h"
  check "$h as C11" "$CC" -std=c11 -Wall -Wextra -Wpedantic -Werror -fsyntax-only -x c "$f"
  check "$h as C++" g++ -std=c++11 -Wall -Wextra -Wpedantic -Werror -fsyntax-only -x c++ "$f"
done
# Through the include path a user of raysweep.pc gets (-I<prefix>/include).
src=$(mktemp /tmp/rsw-headers-XXXXXX.cc)
printf '#include <raysweep/client.h>\nint main() { rsw_client *c = nullptr; rsw_client_free(c); return (int)RSW_OK; }\n' > "$src"
check "client.h from C++ code" g++ -std=c++11 -Wall -Wextra -Werror -fsyntax-only -I"$root/include" "$src"
rm -f "$src"
echo "test_headers: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
