#!/usr/bin/env bash
# Puts each test program where its subject lives (tests/README.md#layout):
# moves tests/{unit,validation,integration}/test_NAME.c to the folder the
# table below names (git mv), rewrites its relative #includes for the new
# depth, and rewrites every mention of the old path in the repository's
# text files. Program names (build/tests/test_NAME) do not change.
#
#   tools/test-layout.sh [-n]      (-n: print the moves, change nothing)
#
# Re-runnable: a test already in place is left alone. A test the table does
# not name goes to the folder of the kernel class whose plugin it is named
# after (test_rtls -> the folder of server/kernel/*/rtls.c), else it is
# listed and left where it is (the Makefile still builds and runs it; add a
# line to the table and run this again).
set -euo pipefail
cd "$(dirname "$0")/.."
dry=0
[ "${1:-}" = -n ] && dry=1

# test name            folder under tests/
table='
test_cmdline            common
test_scene_state        service
test_blendbsdf          kernel/bsdfs
test_bsdf               kernel/bsdfs
test_plugin_example     kernel/scene
test_eo_bsdf            kernel/bsdfs
test_eo_surfaces        kernel/bsdfs
test_mask               kernel/bsdfs
test_microfacet_albedo  kernel/bsdfs
test_plastic            kernel/bsdfs
test_area_light         kernel/emitters
test_envmap             kernel/emitters
test_point_spot         kernel/emitters
test_cameras            kernel/sensors
test_eo_sensors         kernel/sensors
test_sensors            kernel/sensors
test_film_quantities    kernel/films
test_rfilters           kernel/films
test_stokes             kernel/films
test_samplers           kernel/samplers
test_direct             kernel/integrators
test_wave               kernel/integrators
test_bitmap_ldr         kernel/textures
test_volume             kernel/volumes
test_phase              kernel/phase
test_dense_media        kernel/media
test_media              kernel/media
test_media_params       kernel/media
test_molecular_atmosphere kernel/media
test_cylinder           kernel/shapes
test_instancing         kernel/shapes
test_mesh_io            kernel/shapes
test_shape_ops          kernel/shapes
test_shapegroup_big     kernel/shapes
test_spawn              kernel/shapes
test_traceable          kernel/shapes
test_corpus             kernel/scene
test_params             kernel/scene
test_periodic_lamp      kernel/scene
test_periodic_sun       kernel/scene
test_update_reload      kernel/scene
test_xml_read           kernel/scene
test_isa                kernel/core
test_warp               kernel/core
test_simd               kernel/simd
test_env_plugins        kernel/extplugin
test_plugin_loader      kernel/extplugin
test_kapi               kernel
test_render_pool        kernel
test_render_stop        kernel
test_dataset_nc         common
test_exr_full           common
test_image_exr          common
test_image_exr_stress   common
test_bands              service
test_render_views       service
test_service            service
test_service_limits     service
test_service_wire       service
test_state_durable      service
test_state_service      service
test_templates          service
test_http               http
test_http_encode        http
test_http_limits        http
test_media_http         http
test_oom                http
test_client             client
test_spread             client
test_chi2               validation
test_eo_reference       validation
test_radiometry         validation
test_seed_scene         validation
test_translation        validation
test_cli                integration
'

folder_of() { # NAME -> folder, from the table or the plugin it is named after
  local f
  f=$(awk -v n="$1" '$1 == n { print $2 }' <<<"$table")
  if [ -z "$f" ]; then
    local src
    src=$(find server/kernel -name "${1#test_}.c" | head -n 1)
    [ -n "$src" ] && f=kernel/${src#server/kernel/} && f=${f%/*}
  fi
  echo "$f"
}

moves=()
left=()
for old in tests/unit/test_*.c tests/validation/test_*.c tests/integration/test_*.c; do
  [ -e "$old" ] || continue
  name=$(basename "$old" .c)
  dir=$(folder_of "$name")
  if [ -z "$dir" ]; then left+=("$old"); continue; fi
  new=tests/$dir/$name.c
  [ "$old" = "$new" ] && continue
  moves+=("$old $new")
done

for m in "${moves[@]}"; do
  set -- $m
  echo "$1 -> $2"
  [ $dry = 1 ] && continue
  mkdir -p "$(dirname "$2")"
  git mv "$1" "$2"
  # Relative #includes, resolved from the old folder, made relative to the new one.
  python3 - "$1" "$2" <<'PY'
import os, re, sys
old, new = sys.argv[1:3]
src = open(new).read()
def fix(m):
    target = os.path.normpath(os.path.join(os.path.dirname(old), m.group(2)))
    if not m.group(2).startswith("../") or not os.path.exists(target):
        return m.group(0)
    return m.group(1) + os.path.relpath(target, os.path.dirname(new)) + m.group(3)
out = re.sub(r'(#\s*include\s+")([^"]+)(")', fix, src)
if out != src:
    open(new, "w").write(out)
PY
done

if [ $dry = 0 ] && [ ${#moves[@]} -gt 0 ]; then
  # Every mention of an old path (docs, comments, scripts, the Makefile's
  # special link rules use $(call test_obj,NAME) and need none).
  sedargs=()
  for m in "${moves[@]}"; do
    set -- $m
    sedargs+=(-e "s#\\b$1\\b#$2#g")
  done
  git ls-files -z | grep -zv '^tests/fuzz/corpus/\|^tests/fuzz/crashes/' |
    xargs -0 grep -lIE 'tests/(unit|validation|integration)/test_[a-z0-9_]+\.c' 2>/dev/null |
    while read -r f; do [ -f "$f" ] && sed -i -E "${sedargs[@]}" "$f"; done
  rmdir tests/unit 2>/dev/null || true
fi

if [ ${#left[@]} -gt 0 ]; then
  echo "tools/test-layout.sh: no folder for these (add them to the table):" >&2
  printf '  %s\n' "${left[@]}" >&2
  exit 1
fi
