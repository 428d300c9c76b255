#!/usr/bin/env bash
# The documentation is executable. Part 1 runs every shell block of
# README.md and docs/**/*.md against a real daemon on an ephemeral loopback
# port (tests/support/docs_check.py `run`: the rules for what runs, what is
# skipped and why, are in its header; blocks that copy a file are compared
# with it byte for byte), and checks that every curl in them and in
# docs/examples/*.sh fails on an HTTP error instead of saving the error
# body as a film. Part 2 runs the client examples of docs/client.md (docs/examples/: C with libraysweep, the
# raysweep CLI, curl, Python) against the real daemon on an ephemeral
# loopback port, so they cannot rot. Each must print the wavelengths 400,
# 450, ..., 700 nm and, for the plate of docs/examples/plate.json (a
# Lambertian rectangle lit at normal incidence with irradiance E = 1, seen by
# a `distant` sensor), the radiance
#   L(w) = rho(w) * E * cos(0) / pi,   rho(w) = 0.2 + 0.6 * (w - 400) / 300
# (the job-level tabulated reflectance, linear between its two points), to
# 1e-5 relative. docs/client.md must hold every example verbatim.
# Every docs/examples/*.sh runs (with build/bin on PATH), and sweep.sh says
# how to get raysweep on PATH when it is not.
# Environment: RSW_BIN_DIR (default build/bin: raysweepd, raysweep; the
# library is looked for in RSW_BIN_DIR/../lib), SAN=1 (the library is built
# with ASan+UBSan, so the C example is too). Ends with the summary line
# "test_docs_examples: N passed, N failed" that tests/run.sh sums.
set -u
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root" || exit 1
bin=${RSW_BIN_DIR:-build/bin}
case $bin in /*) ;; *) bin=$root/$bin ;; esac
lib=$(cd "$bin/.." && pwd)/lib
examples=$root/docs/examples

name=test_docs_examples
source "$root/tests/support/shtest.sh"
daemon=

# ---- the daemon ------------------------------------------------------------
"$bin/raysweepd" serve --listen 127.0.0.1:0 --port-file "$tmp/port" --data-root "$tmp" --threads 1 \
  >"$tmp/daemon.log" 2>&1 &
daemon=$!
pids+=("$daemon")
for _ in $(seq 100); do
  [ -s "$tmp/port" ] && break
  kill -0 "$daemon" 2>/dev/null || break
  sleep 0.1
done
if [ ! -s "$tmp/port" ]; then
  bad "daemon: no port file after 10 s: $(tail -n 5 "$tmp/daemon.log")"
  finish
fi
export RAYSWEEP_URL="http://127.0.0.1:$(cat "$tmp/port")"
unset RAYSWEEP_TOKEN

# ---- part 1: the shell blocks of README.md and docs/ -----------------------------
# (Before the client examples: the walk-through of docs/daemon.md starts
# from the daemon's default scene.) Under SAN=1 the library is built with ASan, so
# the blocks' `cc` links with the same flags (a shim first on PATH).
shim=()
if [ "${SAN:-}" = 1 ]; then
  mkdir -p "$tmp/shim"
  printf '#!/bin/sh\nexec /usr/bin/cc -fsanitize=address,undefined -fno-omit-frame-pointer "$@"\n' >"$tmp/shim/cc"
  chmod +x "$tmp/shim/cc"
  shim=(--path-prefix "$tmp/shim")
fi
python3 "$root/tests/support/docs_check.py" run --root "$root" --bin "$bin" --work "$tmp/blocks" \
  --url "$RAYSWEEP_URL" "${shim[@]}" >"$tmp/blocks.log" 2>&1
python3 "$root/tests/support/docs_check.py" curl-lint README.md $(find docs -name '*.md' | sort) docs/examples/*.sh \
  >>"$tmp/blocks.log" 2>&1
while IFS= read -r line; do
  case $line in
    PASS*) ok; [ -n "${RSW_VERBOSE:-}" ] && echo "$line" ;;
    SKIP*) echo "$line" ;;
    FAIL*) bad "${line#FAIL }" ;;
    *) bad "docs_check.py: $line" ;;
  esac
done <"$tmp/blocks.log"
rm -rf "$tmp/blocks"

# The checker itself catches broken documentation: a failing block, a
# skip marker without a reason, a block that differs from its file, a
# transcript whose output differs, a curl that would save an error body,
# and the README's old job example (plate.bsdf key, hdistant sensor).
cat >"$tmp/broken.md" <<'MD'
```sh
true
false
```

<!-- docs-test: skip -->
```sh
true
```

<!-- docs-test: file docs/examples/plate.json -->
```json
{"type": "scene"}
```

```sh
$ echo one; echo two
one
three
```

```sh
curl -s localhost:8350/v1/health/live -o live.txt
```

```sh
URL=localhost:8350
id() { sed -n 's/^{"id":"\([^"]*\)".*/\1/p'; }
PLATE=$(curl -sS --fail-with-body -X POST $URL/v1/scenes -H 'Content-Type: application/json' \
     --data-binary @proto/examples/hdistant_lambertian.json | id)
JOB=$(curl -sS --fail-with-body -X POST $URL/v1/scenes/$PLATE/jobs -H 'Content-Type: application/json' -d '{
  "params": {"plate.bsdf.reflectance.value": {"wavelengths": [400, 700], "values": [0.2, 0.8]}},
  "contexts": [{"id": "w450", "wavelength": 450}]}' | id)
curl -sS --fail-with-body -N $URL/v1/jobs/$JOB/events
```

```sh
URL=localhost:8350
id() { sed -n 's/^{"id":"\([^"]*\)".*/\1/p'; }
PLATE=$(curl -sS --fail-with-body -X POST $URL/v1/scenes -H 'Content-Type: application/json' \
     --data-binary @proto/examples/hdistant_lambertian.json | id)
JOB=$(curl -sS --fail-with-body -X POST $URL/v1/scenes/$PLATE/jobs -H 'Content-Type: application/json' -d '{
  "params": {"surface.bsdf.reflectance.value": {"wavelengths": [400, 700], "values": [0.2, 0.8]}},
  "contexts": [{"id": "w450", "wavelength": 450}]}' | id)
curl -sS --fail-with-body -N $URL/v1/jobs/$JOB/events >/dev/null
curl -sSf $URL/v1/jobs/$JOB/results/w450/hdistant -H 'Accept: image/x-exr' -o w450.exr
```
MD
{
  python3 "$root/tests/support/docs_check.py" run --root "$root" --bin "$bin" --work "$tmp/broken" \
    --url "$RAYSWEEP_URL" "${shim[@]}" "$tmp/broken.md"
  python3 "$root/tests/support/docs_check.py" curl-lint "$tmp/broken.md"
} >"$tmp/broken.log" 2>&1
rm -rf "$tmp/broken"
for want in "broken.md:1: exit 1" "broken.md:7: a docs-test skip marker needs a reason" \
  "broken.md:12: the block differs from docs/examples/plate.json" \
  "broken.md:16: \`echo one; echo two\` printed other lines" "broken.md:22: curl without" \
  "broken.md:26: exit 22: curl: (22) The requested URL returned error: 422" \
  "broken.md:37: exit 22: curl: (22) The requested URL returned error: 404"; do
  if grep '^FAIL' "$tmp/broken.log" | grep -qF "$want"; then ok; else
    bad "docs_check.py did not report '$want': $(tr '\n' ' ' <"$tmp/broken.log" | head -c 800)"
  fi
done

# The expected output, "wavelength value" per line.
awk 'BEGIN { for (w = 400; w <= 700; w += 50) printf "%d %.9g\n", w, (0.2 + 0.6 * (w - 400) / 300) / 3.141592653589793 }' \
  >"$tmp/expected"

# check NAME FILE: FILE (an example's stdout) holds exactly the expected
# wavelengths, in any order, each with the expected value to 1e-5 relative.
check() {
  local name=$1 out=$2 msg
  msg=$(sort -n "$out" | awk -v exp_file="$tmp/expected" '
    BEGIN { n = 0; while ((getline line < exp_file) > 0) { split(line, f, " "); ew[n] = f[1]; ev[n] = f[2]; n++ } }
    NF != 2 || $1 !~ /^[0-9.]+$/ { print "line " NR " is not \"wavelength value\": " $0; bad = 1; exit }
    { i = NR - 1
      if (i >= n) { print "extra line: " $0; bad = 1; exit }
      if ($1 + 0 != ew[i] + 0) { print "wavelength " $1 ", expected " ew[i]; bad = 1; exit }
      d = ($2 - ev[i]) / ev[i]; if (d < 0) d = -d
      if (d > 1e-5) { print "at " $1 " nm: " $2 ", expected " ev[i] " (rho/pi; relative error " d ")"; bad = 1; exit } }
    END { if (!bad && NR != n) print NR " lines, expected " n }')
  if [ -n "$msg" ]; then bad "$name: $msg"; else ok; fi
}

# run NAME CMD...: runs an example with a time limit in a fresh copy of
# docs/examples (the examples read plate.json from the current directory and
# may write there); its stdout goes to $tmp/NAME.out.
run() {
  local name=$1 rc
  shift
  rm -rf "$tmp/work" && cp -R "$examples" "$tmp/work" || { bad "$name: cannot copy docs/examples"; return 1; }
  (cd "$tmp/work" && timeout 120 "$@") >"$tmp/$name.out" 2>"$tmp/$name.err"
  rc=$?
  if [ "$rc" -ne 0 ]; then
    bad "$name: exit $rc: $(tail -n 5 "$tmp/$name.err")"
    return 1
  fi
  ok
  check "$name" "$tmp/$name.out"
}

# ---- C with libraysweep -------------------------------------------------------
cflags=(-std=c11 -Wall -Wextra -Werror -pedantic)
[ "${SAN:-}" = 1 ] && cflags+=(-fsanitize=address,undefined -fno-omit-frame-pointer)
syslibs=(-lcurl -lcjson -lexpat -lcrypto -lOpenEXRCore -lnetcdf -lpng16 -lm -lpthread)
if [ ! -f "$lib/libraysweep.a" ]; then
  bad "sweep.c: $lib/libraysweep.a is missing (build the library first)"
elif ! cc "${cflags[@]}" -I"$root/include" "$examples/sweep.c" "$lib/libraysweep.a" "${syslibs[@]}" \
  -o "$tmp/sweep" 2>"$tmp/cc.err"; then
  bad "sweep.c does not compile against include/ and libraysweep.a: $(head -n 20 "$tmp/cc.err")"
else
  ok
  run sweep.c "$tmp/sweep"
fi
# The way docs/client.md builds it: `make install PREFIX=...` (headers, .a, .so,
# raysweep.pc), then pkg-config. (The make variables of a `make test` that
# runs this script are dropped, so the inner make is a plain one.)
if env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make -s -C "$root" install PREFIX="$tmp/prefix" SAN="${SAN:-}" \
  >"$tmp/install.log" 2>&1; then
  ok
  if cc "${cflags[@]}" "$examples/sweep.c" \
    $(PKG_CONFIG_PATH="$tmp/prefix/lib/pkgconfig" pkg-config --cflags --libs raysweep) \
    -Wl,-rpath,"$tmp/prefix/lib" -o "$tmp/sweep_pc" 2>"$tmp/cc_pc.err"; then
    ok
    run sweep.c-pkg-config "$tmp/sweep_pc"
  else
    bad "sweep.c does not build with pkg-config --cflags --libs raysweep: $(head -n 20 "$tmp/cc_pc.err")"
  fi
else
  bad "make install PREFIX=$tmp/prefix: $(tail -n 10 "$tmp/install.log")"
fi

# ---- every shell example (the raysweep CLI, curl), and Python ---------------------
if [ ! -x "$bin/raysweep" ]; then
  bad "$bin/raysweep is missing (build the CLI first)"
fi
for f in "$examples"/*.sh; do
  run "$(basename "$f")" env PATH="$bin:$PATH" sh "./$(basename "$f")"
done
run sweep.py python3 ./sweep.py
# Without raysweep on PATH, sweep.sh says how to get it (not "raysweep: not found").
mkdir -p "$tmp/nocli/bin" && cp -R "$examples" "$tmp/nocli/work"
for t in sed cat curl; do ln -s "$(command -v $t)" "$tmp/nocli/bin/$t"; done
(cd "$tmp/nocli/work" && PATH=$tmp/nocli/bin "$(command -v sh)" ./sweep.sh) >/dev/null 2>"$tmp/nocli.err"
rc=$?
if [ "$rc" -ne 0 ] && grep -q "make install" "$tmp/nocli.err"; then ok; else
  bad "sweep.sh without raysweep on PATH: exit $rc, '$(head -c 200 "$tmp/nocli.err")' (want a hint to make install)"
fi

# ---- the outputs agree with each other -------------------------------------------
# (Each was checked against rho/pi above; here the four lists must also name
# the same wavelengths, so no example silently drops a context.)
ref=
for f in "$tmp"/*.out; do
  [ -s "$f" ] || continue
  cut -d' ' -f1 "$f" | sort -n >"$f.w"
  if [ -z "$ref" ]; then ref=$f.w; elif cmp -s "$ref" "$f.w"; then ok; else
    bad "$(basename "$f" .out) prints other wavelengths than $(basename "${ref%.w}" .out)"
  fi
done

# ---- docs/client.md holds every example verbatim ------------------------------------
readme=$(<"$root/docs/client.md")
for f in plate.json sweep.c sweep.sh sweep_curl.sh sweep.py dataset.py; do
  if [ ! -f "$examples/$f" ]; then bad "docs/examples/$f is missing"; continue; fi
  text=$(<"$examples/$f")
  if [[ $readme == *"$text"* ]]; then ok; else bad "docs/client.md does not contain docs/examples/$f verbatim"; fi
done

finish
