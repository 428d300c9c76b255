#!/bin/sh
# Wavelength sweep of a Lambertian plate with the raysweep CLI.
set -e
command -v raysweep >/dev/null || {
  echo "sweep.sh: raysweep is not on PATH: run 'make install' (see docs/building.md)" \
       "or export PATH=\"\$PWD/../../build/bin:\$PATH\" from docs/examples" >&2
  exit 127
}
SCENE=$(raysweep scene push plate.json)
raysweep sweep "$SCENE" --grid wavelength=400:700:50 --format json -o sweep \
  --set 'plate.bsdf.reflectance.value={"wavelengths": [400, 700], "values": [0.2, 0.8]}'
# sweep/index.jsonl: one line per film {"context", "sensor", "wavelength", ..., "file"}
sed 's/.*"wavelength":\([0-9.]*\).*"file":"\([^"]*\)".*/\1 \2/' sweep/index.jsonl |
  while read -r w file; do
    echo "$w $(sed 's/.*"data":\[\([^]]*\)\].*/\1/' "sweep/$file")"   # the film as JSON
  done
