/* raysweepd: the radiometric computation daemon.
 *
 *   raysweepd render SCENE [-D name=value]... [--sensor ID] [--spp N]
 *                          [--seed S] [--wavelength NM] [--threads N]
 *                          [--variant mono|rgb] -o OUT.exr
 *   raysweepd version
 *
 * Subcommands are a const table (redis' command table). Bad input exits
 * non-zero with a message naming the flag, file or document place. */
#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kernel/image_exr.h"
#include "kernel/render.h"
#include "kernel/scene/scene.h"
#include "raysweep/status.h"

#define RSW_VERSION "0.1.0"
#define MAX_DEFINES 256

typedef struct command {
  const char *name;
  const char *usage;
  int (*run)(int argc, char **argv);
} command;

static int usage_error(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static int usage_error(const char *cmd, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "raysweepd %s: ", cmd);
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  va_end(ap);
  return 2;
}

static bool parse_u64(const char *s, unsigned long long max, unsigned long long *out) {
  if (!s || !*s || *s == '-' || *s == '+') return false;
  char *end;
  errno = 0;
  unsigned long long v = strtoull(s, &end, 10);
  if (errno || *end || v > max) return false;
  *out = v;
  return true;
}

static bool parse_pos_double(const char *s, double *out) {
  if (!s || !*s) return false;
  char *end;
  errno = 0;
  double v = strtod(s, &end);
  if (errno || *end || !(v > 0) || !isfinite(v)) return false;
  *out = v;
  return true;
}

static int cmd_render(int argc, char **argv) {
  const char *scene_path = NULL, *out_path = NULL, *sensor_id = NULL, *variant_name = NULL;
  scene_define defines[MAX_DEFINES];
  size_t n_defines = 0;
  unsigned long long spp = 0, seed = 0, threads = 0;
  double wavelength = 0;
  int rc = 1;
  scene *sc = NULL;
  film_image img = {0};
#define USAGE(...)                                                                                           \
  do {                                                                                                       \
    rc = usage_error("render", __VA_ARGS__);                                                                 \
    goto out;                                                                                                \
  } while (0)
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    const char *val = i + 1 < argc ? argv[i + 1] : NULL;
    if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0) {
      if (!val) USAGE("%s needs a file name", a);
      out_path = val, i++;
    } else if (strcmp(a, "--sensor") == 0) {
      if (!val) USAGE("%s needs a sensor id or index", a);
      sensor_id = val, i++;
    } else if (strcmp(a, "--spp") == 0) {
      if (!parse_u64(val, 1ull << 31, &spp) || spp == 0)
        USAGE("--spp needs a positive integer (got '%s')", val ? val : "");
      i++;
    } else if (strcmp(a, "--seed") == 0) {
      if (!parse_u64(val, ULLONG_MAX, &seed)) USAGE("--seed needs a non-negative integer (got '%s')", val ? val : "");
      i++;
    } else if (strcmp(a, "--threads") == 0) {
      if (!parse_u64(val, 256, &threads) || threads == 0)
        USAGE("--threads needs an integer in [1, 256] (got '%s')", val ? val : "");
      i++;
    } else if (strcmp(a, "--wavelength") == 0) {
      if (!parse_pos_double(val, &wavelength))
        USAGE("--wavelength needs a positive number of nm (got '%s')", val ? val : "");
      i++;
    } else if (strcmp(a, "--variant") == 0) {
      if (!val) USAGE("%s needs mono or rgb", a);
      variant_name = val, i++;
    } else if (strncmp(a, "-D", 2) == 0) {
      const char *def = a[2] ? a + 2 : val;
      if (!a[2]) i++;
      const char *eq = def ? strchr(def, '=') : NULL;
      if (!def || !eq || eq == def) USAGE("-D needs name=value (got '%s')", def ? def : "");
      if (n_defines == MAX_DEFINES) USAGE("too many -D definitions (at most %d)", MAX_DEFINES);
      char *name = strndup(def, (size_t)(eq - def));
      if (!name) USAGE("%s", "out of memory");
      defines[n_defines].name = name;
      defines[n_defines].value = eq + 1;
      n_defines++;
    } else if (a[0] == '-' && a[1]) {
      USAGE("unknown option '%s'", a);
    } else if (!scene_path) {
      scene_path = a;
    } else {
      USAGE("unexpected argument '%s' (one scene file per render)", a);
    }
  }
#undef USAGE
  if (!scene_path) {
    rc = usage_error("render", "missing the scene file%s", "");
    goto out;
  }
  if (!out_path) {
    rc = usage_error("render", "missing -o OUT.exr%s", "");
    goto out;
  }
  rsw_err err = {0};
  char msg[1200];
  scene_load_opts lo = {.size = sizeof lo, .variant = variant_name, .defines = defines, .n_defines = n_defines};
  if (scene_load_file(scene_path, &lo, &sc, &err)) {
    fprintf(stderr, "raysweepd render: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  size_t sensor_index = 0;
  if (sensor_id) {
    if (!scene_find_sensor(sc, sensor_id, &sensor_index)) {
      fprintf(stderr, "raysweepd render: --sensor: no sensor '%s' in %s (", sensor_id, scene_path);
      for (size_t i = 0; i < sc->n_sensors; i++)
        fprintf(stderr, "%s%s", i ? ", " : "sensors: ", sc->sensors[i]->base.id);
      fprintf(stderr, "%s)\n", sc->n_sensors ? "" : "the scene has none");
      goto out;
    }
  }
  render_opts ro = {.size = sizeof ro, .sensor = sensor_index, .spp = (uint32_t)spp, .seed = seed,
                    .wavelength = wavelength, .threads = (int)threads};
  render_result_stats rs;
  if (render_sensor(sc, &ro, &img, &rs, &err)) {
    fprintf(stderr, "raysweepd render: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  if (rs.invalid_samples)
    fprintf(stderr, "raysweepd render: warning: %llu samples were NaN or infinite and were dropped\n",
            (unsigned long long)rs.invalid_samples);
  if (film_image_write_exr(&img, out_path, sc->sensors[sensor_index]->base.id, &err)) {
    fprintf(stderr, "raysweepd render: %s\n", rsw_err_format(&err, msg, sizeof msg));
    goto out;
  }
  fprintf(stderr, "raysweepd render: wrote %s (%dx%d, %u spp, %.3f s, %d threads)\n", out_path, img.width,
          img.height, img.spp, rs.wall_s, rs.threads);
  rc = 0;
out:
  film_image_free(&img);
  scene_free(sc);
  for (size_t i = 0; i < n_defines; i++) free((char *)defines[i].name);
  return rc;
}

static int cmd_version(int argc, char **argv) {
  (void)argc, (void)argv;
  printf("raysweepd %s (variants: mono, rgb)\n", RSW_VERSION);
  return 0;
}

static int cmd_serve(int argc, char **argv) {
  (void)argc, (void)argv;
  fprintf(stderr, "raysweepd serve: the HTTP daemon is not part of this build yet; use 'raysweepd render'\n");
  return 2;
}

static const command commands[] = {
    {"render", "render SCENE [-D name=value]... [--sensor ID] [--spp N] [--seed S] [--wavelength NM] "
               "[--threads N] [--variant mono|rgb] -o OUT.exr",
     cmd_render},
    {"serve", "serve", cmd_serve},
    {"version", "version", cmd_version},
};

static void usage(FILE *f) {
  fprintf(f, "usage:\n");
  for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++) fprintf(f, "  raysweepd %s\n", commands[i].usage);
}

int main(int argc, char **argv) {
  if (argc < 2) {
    usage(stderr);
    return 2;
  }
  if (strcmp(argv[1], "-h") == 0 || strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "help") == 0) {
    usage(stdout);
    return 0;
  }
  for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
    if (strcmp(argv[1], commands[i].name) == 0) return commands[i].run(argc - 1, argv + 1);
  fprintf(stderr, "raysweepd: unknown command '%s'\n", argv[1]);
  usage(stderr);
  return 2;
}
