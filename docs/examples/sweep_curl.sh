#!/bin/sh
# Wavelength sweep of a Lambertian plate with curl (and sed to pick JSON fields).
set -e
URL=${RAYSWEEP_URL:-http://127.0.0.1:8350}
post() { curl -sSf -H 'Content-Type: application/json' "$@"; }
id() { sed -n 's/^{"id":"\([^"]*\)".*/\1/p'; }
SCENE=$(post "$URL/v1/scenes" --data-binary @plate.json | id)
CONTEXTS=$(for w in $(seq 400 50 700); do printf '{"id":"w%s","wavelength":%s},' $w $w; done)
JOB=$(post "$URL/v1/scenes/$SCENE/jobs" -d '{
  "params": {"plate.bsdf.reflectance.value": {"wavelengths": [400, 700], "values": [0.2, 0.8]}},
  "contexts": ['"${CONTEXTS%,}"']}' | id)
# Server-sent events until the job ends; the last one says how.
curl -sSfN "$URL/v1/jobs/$JOB/events" | grep -q '^data: {"state":"succeeded"'
for w in $(seq 400 50 700); do
  FILM=$(curl -sSf "$URL/v1/jobs/$JOB/results/w$w/camera")   # {..., "data": [value], ...}
  echo "$w $(echo "$FILM" | sed 's/.*"data":\[\([^]]*\)\].*/\1/')"
done
