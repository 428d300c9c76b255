#!/usr/bin/env bash
# tools/build-peer.sh DIR: build the peer that `make bench`'s peer line
# (tests/bench/bench_peer.py) compares raysweep with: Mitsuba 3 as
# Eradiate's fork (github.com/eradiate/mitsuba3: hdistant, rpv and the
# piecewise medium are there), its `mitsuba` command with the variants
# llvm_rgb, scalar_rgb and scalar_mono, Embree on, no Python, into
# DIR/build. Needs the network, git, cmake, ninja and g++ (Debian 12:
# apt install git cmake ninja-build g++), and libLLVM at run time for
# llvm_rgb (Debian 12: libllvm14). About 1.5 CPU-hours.
#
#   tools/build-peer.sh ~/peer
#   RSW_PEER_MITSUBA=~/peer/build/mitsuba make bench
#
# Embree is built for AVX2 and AVX-512 only (the x86 machines we measure
# on) and without curves (no scene of the comparison has them), which
# shortens the build and changes nothing the scenes use.
set -eu
dir=${1:?usage: tools/build-peer.sh DIR}
# What the build and llvm_rgb need, checked before the clone (an hour in,
# a missing libLLVM would only show when llvm_rgb first runs).
for t in git cmake ninja g++; do
  command -v "$t" >/dev/null || { echo "build-peer: $t not found (Debian 12: apt install git cmake ninja-build g++)" >&2; exit 1; }
done
if [ -z "${DRJIT_LIBLLVM_PATH:-}" ] && ! ldconfig -p 2>/dev/null | grep -q 'libLLVM'; then
  echo "build-peer: libLLVM not found, which llvm_rgb loads at run time (Debian 12: apt install libllvm14, or set DRJIT_LIBLLVM_PATH)" >&2
  exit 1
fi
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
if [ ! -d "$dir/src/.git" ]; then
  git clone --recursive https://github.com/eradiate/mitsuba3 "$dir/src"
fi
ext="$dir/src/ext/CMakeLists.txt"
sed -i -E 's/(EMBREE_ISA_SSE42|EMBREE_ISA_AVX)( +)ON CACHE/\1\2OFF CACHE/' "$ext"
sed -i -E 's/(EMBREE_GEOMETRY_CURVE|EMBREE_BACKFACE_CULLING_CURVES)( +)ON  CACHE/\1\2OFF CACHE/' "$ext"
# Without the autodiff variants Mitsuba does not link drjit-extra, which
# llvm_rgb's loops call (ad_loop): link it whenever the JIT is on.
sed -i 's/^if (MI_ENABLE_AUTODIFF)$/if (MI_ENABLE_JIT OR MI_ENABLE_AUTODIFF)/' "$dir/src/src/core/CMakeLists.txt"
mkdir -p "$dir/build"
cd "$dir/build"
# (Mitsuba's headers include nanobind's intrusive counter even without Python.)
cmake -G Ninja -DCMAKE_BUILD_TYPE=Release -DMI_ENABLE_PYTHON=OFF -DDRJIT_ENABLE_PYTHON=OFF \
  -DMI_ENABLE_EMBREE=ON -DCMAKE_CXX_FLAGS="-I$dir/src/ext/nanobind/include" ../src >/dev/null
# The variants (the first configure wrote mitsuba.conf with its defaults).
sed -i -E '/"enabled": \[/{n;s/.*/        "scalar_mono", "scalar_rgb", "llvm_rgb"/}' mitsuba.conf
cmake . >/dev/null
# Only what the comparison's scenes load: the command and these plugins.
ninja mitsuba-bin copy-resources hdistant path directional rectangle roughconductor hdrfilm box gaussian \
  independent stratified perspective diffuse area cube piecewise_volpath piecewise rpv blendphase rayleigh \
  hg gridvolume null uniform srgb d65 regular irregular constvolume merge extremum_global extremum_grid extremum_spherical tabphase tabphase_irregular multiphase isotropic
echo "built: RSW_PEER_MITSUBA=$dir/build/mitsuba make bench"
