#!/usr/bin/env bash
# The Python package (python/, docs/python.md) against real daemons:
#   - it installs offline exactly as README.md says, into a venv over
#     Debian's python3 (`python3 -m venv --system-site-packages .venv &&
#     .venv/bin/pip install --no-build-isolation ./python`, run on a copy of
#     python/ so the checkout gets no build/ or egg-info);
#   - tests/python/test_client.py (unittest) against a daemon, and a second
#     one started with --token-file: connect, load_file/load_dict with
#     uploads (the same scene ids as `raysweep scene push`), traverse and
#     update, render, sweep, futures, Ctrl-C, errors, the numpy-only path,
#     plugin failures in films' attrs and datasets;
#   - docs/python.md's example (docs/examples/sweep_rs.py) prints rho(lambda)/pi;
#   - the notebook docs/examples/python_quickstart.ipynb runs top to bottom
#     (jupyter nbconvert --execute, Debian's python3-nbconvert and
#     python3-ipykernel) in the venv's kernel, its cells' assertions
#     included, and its outputs hold the closed-form numbers.
# Ends with "test_python: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_python
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweep raysweepd
# Debian's python3 (numpy, xarray, netCDF4, nbconvert from `make deps`), not
# one earlier on PATH that lacks them.
py=${RSW_PYTHON:-/usr/bin/python3}
"$py" -c 'import numpy, xarray, netCDF4, venv' 2>/dev/null || {
  bad "$py cannot import numpy, xarray, netCDF4 and venv (make deps installs them)"
  finish
}
cd "$tmp" || exit 1
t0=$(date +%s.%N)
secs() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$1" "$(date +%s.%N)"; }

# ---- install, as the README says ------------------------------------------------------
cp -r "$root/python" python
rm -rf python/build python/*.egg-info
if PATH=$(dirname "$py"):$PATH PIP_NO_INDEX=1 PIP_DISABLE_PIP_VERSION_CHECK=1 \
  bash -c 'python3 -m venv --system-site-packages .venv && .venv/bin/pip install --no-build-isolation ./python' \
  >install.log 2>&1; then ok; else
  bad "install: $(tail -n 5 install.log)"
  finish
fi
vpy=$tmp/.venv/bin/python
if "$vpy" -c 'import raysweep, sys; assert raysweep.__file__.startswith(sys.prefix), raysweep.__file__' \
  2>"$tmp/pyerr"; then ok; else bad "the venv does not import its own raysweep: $(tail -n 2 "$tmp/pyerr")"; fi
echo "test_python: install $(secs "$t0") s"

# ---- the package's tests ----------------------------------------------------------------
# With the SDK examples (tests/plugins), for the Stokes films' tests, and
# tests/support/plugins/failing_sky.c for the plugin failures'.
mkdir -p plugins && cp "$bin"/../plugins/*.so plugins/
need_cmd cc "to build the failing plugin"
cc -shared -fPIC -I "$root/include" -o plugins/failing_sky.so "$root/tests/support/plugins/failing_sky.c" || {
  bad "cannot build tests/support/plugins/failing_sky.c"
  finish
}
start_daemon "$tmp/d" --plugin-dir "$tmp/plugins"
[ -n "$started_port" ] || {
  bad "daemon did not start: $(tail -n 5 "$tmp/d/log")"
  finish
}
url=http://127.0.0.1:$started_port
head -c 24 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$tmp/token"
start_daemon "$tmp/d2" --token-file "$tmp/token"
url2=http://127.0.0.1:$started_port

t1=$(date +%s.%N)
RSW_STOKES=1 RSW_FAILING_SKY=1 RAYSWEEP_URL=$url RSW_TOKEN_URL=$url2 RSW_TOKEN=$(cat "$tmp/token") RSW_ROOT=$root RSW_BIN=$bin \
  "$vpy" "$root/tests/python/test_client.py" >client.log 2>&1
summary=$(grep -E '^test_client: [0-9]+ passed, [0-9]+ failed$' client.log)
if [ -n "$summary" ]; then
  read -r p f < <(sed -E 's/^test_client: ([0-9]+) passed, ([0-9]+) failed$/\1 \2/' <<<"$summary")
  pass=$((pass + p))
  [ "$f" -eq 0 ] || { fail=$((fail + f)); grep -E '^(FAIL|ERROR):|Error|assert' client.log | head -n 30; }
else
  bad "test_client.py printed no summary: $(tail -n 20 client.log)"
fi
echo "test_python: test_client.py $(secs "$t1") s"

# ---- docs/python.md's example (docs/examples/sweep_rs.py): rho(lambda)/pi ---------------------
mkdir -p ex && cp "$root/docs/examples/sweep_rs.py" "$root/docs/examples/plate.json" ex/
if (cd ex && RAYSWEEP_URL=$url "$vpy" sweep_rs.py) >ex/out 2>"$tmp/pyerr"; then ok; else
  bad "docs/examples/sweep_rs.py: $(tail -n 3 "$tmp/pyerr")"
fi
py "sweep_rs.py prints rho(lambda)/pi at 400..700 nm" '
import math, sys
rows = [l.split() for l in open(sys.argv[1]) if l.strip()]
assert [float(w) for w, _ in rows] == list(range(400, 701, 50)), rows
for w, v in rows:
    rho = 0.2 + 0.6 * (float(w) - 400) / 300
    assert abs(float(v) - rho / math.pi) < 1e-5, (w, v)
' ex/out

# ---- the notebook -----------------------------------------------------------------------
# The kernel is the venv's python (where raysweep is installed): a kernelspec
# of that name first on JUPYTER_PATH.
t2=$(date +%s.%N)
if "$vpy" -c 'import nbconvert, ipykernel' 2>/dev/null; then
  mkdir -p jupyter/kernels/python3
  printf '{"argv": ["%s", "-m", "ipykernel_launcher", "-f", "{connection_file}"], "display_name": "raysweep venv", "language": "python"}\n' \
    "$vpy" >jupyter/kernels/python3/kernel.json
  cp "$root/docs/examples/python_quickstart.ipynb" "$root/docs/examples/plate.json" .
  if RAYSWEEP_URL=$url JUPYTER_PATH=$tmp/jupyter PYDEVD_DISABLE_FILE_VALIDATION=1 \
    "$vpy" -m nbconvert --to notebook --execute --ExecutePreprocessor.timeout=120 \
    --output executed.ipynb python_quickstart.ipynb >nb.log 2>&1; then ok; else
    bad "the notebook failed: $(grep -E 'Error|error' nb.log | tail -n 8)"
  fi
  # Its outputs: the BRF series (rho(lambda) from 0.2 to 0.8) and the typo's hint.
  if [ -f executed.ipynb ]; then
    if "$vpy" - executed.ipynb <<'PY' 2>"$tmp/pyerr"; then ok; else bad "notebook outputs: $(tail -n 3 "$tmp/pyerr")"; fi
import json, sys
nb = json.load(open(sys.argv[1]))
text = []
for c in nb["cells"]:
    for o in c.get("outputs", []):
        assert o.get("output_type") != "error", o
        text.append("".join(o.get("text", "")) + "".join(o.get("data", {}).get("text/plain", "")))
out = "\n".join(text)
for want in ("did you mean 'plate.bsdf.reflectance.value'", "0.8", "xarray.Dataset", "succeeded"):
    assert want in out, (want, out[-2000:])
PY
  fi
else
  bad "nbconvert and ipykernel are needed for the notebook (make deps installs python3-nbconvert python3-ipykernel)"
fi
echo "test_python: notebook $(secs "$t2") s"
# Under `make test SAN=1` a sanitizer report in a daemon's log is a failure.
for d in d d2; do
  if grep -qE 'Sanitizer|runtime error:' "$tmp/$d/log"; then bad "$d: $(grep -m 3 -E 'Sanitizer|runtime error:' "$tmp/$d/log")"; else ok; fi
done
finish
