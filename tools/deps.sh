#!/usr/bin/env bash
# Install the Debian packages raysweep builds and tests with, when missing.
# Costs one dpkg-query when everything is present; runs `apt-get update`
# once before installing. Node.js/npm come with the machine image: Debian's
# npm package conflicts with them, so it is never installed here.
set -euo pipefail
pkgs=(build-essential pkg-config libembree-dev libopenexr-dev libmicrohttpd-dev
      libcjson-dev libcurl4-openssl-dev libexpat1-dev libssl-dev curl python3)
missing=()
for p in "${pkgs[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "deps: installing ${missing[*]}" >&2
  SUDO=""
  if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
fi
# The OpenAPI validator of tests/openapi (pinned by its package-lock.json).
# A failed install only warns: test_openapi then fails and says why.
root=$(cd "$(dirname "$0")/.." && pwd)
if command -v npm >/dev/null && [ ! -d "$root/tests/openapi/node_modules" ]; then
  echo "deps: npm ci --prefix tests/openapi" >&2
  npm ci --prefix "$root/tests/openapi" --no-audit --no-fund >&2 ||
    echo "deps: npm ci failed; test_openapi will fail until tests/openapi/node_modules exists" >&2
fi
