#include "tsup.h"

#include "../../server/kernel/media/majorant_grid.h"

#include "../../server/kernel/core/rng.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

scene *tsup_load(const char *text, const char *variant_name) {
  rsw_err err = {0};
  scene *s = NULL;
  scene_load_opts o = {.size = sizeof o, .variant = variant_name};
  const char *c = text;
  while (*c == ' ' || *c == '\n') c++;
  if (scene_load_memory(text, strlen(text), "test-scene", *c == '<', &o, &s, &err)) {
    char buf[1200];
    printf("  scene load failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return NULL;
  }
  return s;
}

bool tsup_refused(const char *fmt, const char *object_json) {
  char buf[4096];
  snprintf(buf, sizeof buf, fmt, object_json);
  rsw_err err = {0};
  scene *s = NULL;
  rsw_status st = scene_load_memory(buf, strlen(buf), "bad.json", false, NULL, &s, &err);
  bool refused = st != RSW_OK && !s && err.code == st;
  scene_free(s);
  return refused;
}

scene *tsup_load_file(const char *path, const char *variant_name) {
  rsw_err err = {0};
  scene *s = NULL;
  scene_load_opts o = {.size = sizeof o, .variant = variant_name};
  if (scene_load_file(path, &o, &s, &err)) {
    char buf[1200];
    printf("  scene load failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return NULL;
  }
  return s;
}

char *tsup_read_file(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *t = n >= 0 ? malloc((size_t)n + 1) : NULL;
  if (t && fread(t, 1, (size_t)n, f) != (size_t)n) {
    free(t);
    t = NULL;
  }
  fclose(f);
  if (t) t[n] = '\0', *len = (size_t)n;
  return t;
}

bool tsup_render(scene *s, uint32_t spp, uint64_t seed, int threads, film_image *out) {
  rsw_err err = {0};
  render_opts o = {.size = sizeof o, .spp = spp, .seed = seed, .threads = threads};
  if (render_sensor(s, &o, out, NULL, &err)) {
    char buf[1200];
    printf("  render failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return false;
  }
  return true;
}

void tsup_stats(const film_image *img, int c, double *mean, double *sem) {
  size_t n = (size_t)img->width * img->height;
  double s = 0, s2 = 0;
  for (size_t i = 0; i < n; i++) {
    double v = img->data[i * img->channels + c];
    s += v;
    s2 += v * v;
  }
  *mean = s / n;
  double var = n > 1 ? (s2 - s * s / n) / (n - 1) : 0;
  *sem = sqrt(fmax(var, 0) / n);
}

void sb_printf(sbuf *b, const char *fmt, ...) {
  for (;;) {
    va_list ap;
    va_start(ap, fmt);
    int k = vsnprintf(b->p ? b->p + b->n : NULL, b->p ? b->cap - b->n : 0, fmt, ap);
    va_end(ap);
    if (k < 0) {
      fprintf(stderr, "sb_printf: bad format\n");
      abort();
    }
    if (b->p && b->n + (size_t)k < b->cap) {
      b->n += (size_t)k;
      return;
    }
    size_t cap = b->cap ? 2 * b->cap : 65536;
    while (cap < b->n + (size_t)k + 1) cap *= 2;
    char *p = realloc(b->p, cap);
    if (!p) {
      fprintf(stderr, "sb_printf: out of memory (%zu bytes)\n", cap);
      abort();
    }
    b->p = p;
    b->cap = cap;
  }
}

void tsup_random_leaves(double (*m)[16], int n, uint64_t seed, uint64_t stream, double half, double z0,
                        double dz, double radius) {
  pcg32 g;
  pcg32_seed(&g, seed, stream);
  for (int i = 0; i < n; i++) {
    double x = -half + 2 * half * pcg32_next_double(&g), y = -half + 2 * half * pcg32_next_double(&g);
    double z = z0 + dz * pcg32_next_double(&g);
    vec3 nn = v3_norm(v3(pcg32_next_double(&g) - 0.5, pcg32_next_double(&g) - 0.5, 0.6));
    frame f = frame_from_normal(nn);
    vec3 c[3] = {f.s, f.t, f.n};
    double *q = m[i];
    for (int k = 0; k < 3; k++) {
      q[0 * 4 + k] = radius * c[k].x;
      q[1 * 4 + k] = radius * c[k].y;
      q[2 * 4 + k] = radius * c[k].z;
    }
    q[3] = x, q[7] = y, q[11] = z;
    q[12] = q[13] = q[14] = 0, q[15] = 1;
  }
}

/* The dense slab of tests/kernel/media/test_dense_media.c: z in [0, 1], 200 x 200 wide (the light spreads about one
 * thickness sideways) holding medium med, over a black ground at
 * z = -0.5, under a sun of irradiance 1 at zenith angle th0. Sensor 0: a
 * distantflux above the slab, aimed at a 2 x 2 patch of its top; sensor 1:
 * one below it (its hemisphere around -z), aimed at a patch of its bottom,
 * its rays starting 0.25 under it (above the ground). Each has a 1 x 1
 * film: its pixel is the radiosity leaving the patch. */
char *tsup_dense_slab(const char *integ, const char *med, double th0) {
  sbuf b = {0};
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"integrator\": %s,"
      " \"slab\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"},"
      "   \"interior\": %s,"
      "   \"to_world\": [{\"scale\": [100, 100, 0.5]}, {\"translate\": [0, 0, 0.5]}]},"
      " \"ground\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0},"
      "   \"to_world\": [{\"scale\": 200}, {\"translate\": [0, 0, -0.5]}]},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [%.17g, 0, %.17g], \"irradiance\": 1},"
      " \"up\": {\"type\": \"distantflux\","
      "   \"target\": {\"type\": \"rectangle\", \"to_world\": [{\"translate\": [0, 0, 1]}]},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}},"
      " \"down\": {\"type\": \"distantflux\", \"ray_offset\": 0.25,"
      "   \"to_world\": [{\"rotate\": {\"axis\": [1, 0, 0], \"angle\": 180}}],"
      "   \"target\": {\"type\": \"rectangle\"},"
      "   \"film\": {\"type\": \"hdrfilm\", \"width\": 1, \"height\": 1, \"rfilter\": {\"type\": \"box\"}}}}",
      integ, med, sin(th0), -cos(th0));
  return b.p;
}

char *tsup_cloud_scene(int res, const char *extremum, int spp) {
  sbuf b = {0};
  sb_printf(
      &b,
      "{\"type\": \"scene\", \"integrator\": {\"type\": \"volpath\", \"max_depth\": -1},"
      " \"s\": {\"type\": \"hdistant\", \"sampler\": {\"type\": \"independent\", \"sample_count\": %d},"
      "  \"film\": {\"type\": \"hdrfilm\", \"width\": 16, \"height\": 16}},"
      " \"sun\": {\"type\": \"directional\", \"direction\": [0.5, 0, -0.8660254037844386], \"irradiance\": "
      "1},"
      " \"ground\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"diffuse\", \"reflectance\": 0.3},"
      "  \"to_world\": [{\"scale\": 3}, {\"translate\": [0, 0, -1]}]},"
      " \"box\": {\"type\": \"cube\", \"bsdf\": {\"type\": \"null\"}, \"interior\": {\"type\": \"ref\", "
      "\"id\": \"cloud\"}},"
      " \"cloud\": {\"type\": \"heterogeneous\", \"albedo\": 0.95, \"phase\": {\"type\": \"hg\", \"g\": "
      "0.85}, %s"
      "  \"sigma_t\": {\"type\": \"gridvolume\", \"filter_type\": \"nearest\", \"shape\": [%d, %d, %d],"
      "   \"to_world\": [{\"translate\": [-0.5, -0.5, -0.5]}, {\"scale\": 2}], \"data\": [",
      spp, extremum, res, res, res);
  for (int z = 0; z < res; z++)
    for (int y = 0; y < res; y++)
      for (int x = 0; x < res; x++) {
        double px = -1 + 2 * (x + 0.5) / res - 0.2, py = -1 + 2 * (y + 0.5) / res + 0.1,
               pz = -1 + 2 * (z + 0.5) / res;
        double q = (px * px + py * py + pz * pz) / (0.45 * 0.45);
        sb_printf(&b, "%s%.6g", x + y + z ? ", " : "", q < 1 ? 40 * (1 - q) : 0.0);
      }
  sb_printf(&b, "]}}}");
  return b.p;
}

bool tsup_build_plugin(const char *src, const char *name, char *dir) {
  snprintf(dir, 64, "/tmp/rsw-plugin-XXXXXX");
  if (!mkdtemp(dir)) {
    printf("  mkdtemp: cannot make a directory for plugin %s\n", name);
    return false;
  }
  char path[160], cmd[1024], inc[512];
  snprintf(path, sizeof path, "%s/%s.c", dir, name);
  FILE *f = fopen(path, "w");
  if (!f || fputs(src, f) < 0) {
    if (f) fclose(f);
    printf("  cannot write %s\n", path);
    return false;
  }
  fclose(f);
  const char *td = getenv("RSW_TEST_DIR");
  snprintf(inc, sizeof inc, "%s/../include", td && *td ? td : "tests");
  snprintf(cmd, sizeof cmd, "cc -std=c11 -Wall -Wextra -Werror -shared -fPIC -I '%s' -o '%s/%s.so' '%s'", inc,
           dir, name, path);
  if (system(cmd) != 0) {
    printf("  could not build plugin %s: %s\n", name, cmd);
    return false;
  }
  return true;
}

void tsup_remove_dir(const char *dir) {
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  if (system(cmd)) fprintf(stderr, "could not remove %s\n", dir);
}

static double walk_urand(uint64_t *x) {
  *x ^= *x << 13, *x ^= *x >> 7, *x ^= *x << 17;
  return (double)(*x >> 11) * 0x1p-53;
}

void tsup_walk_check(const medium *m, vec3 lo, vec3 hi, int n, uint64_t *rng, tsup_walk_stats *st) {
  *st = (tsup_walk_stats){0};
  for (int k = 0; k < n; k++) {
    vec3 o = v3(lo.x + (hi.x - lo.x) * walk_urand(rng), lo.y + (hi.y - lo.y) * walk_urand(rng),
                lo.z + (hi.z - lo.z) * walk_urand(rng));
    double z = 2 * walk_urand(rng) - 1, ph = 2 * 3.14159265358979323846 * walk_urand(rng),
           r = sqrt(fmax(0, 1 - z * z));
    ray3 ray = {o, v3(r * cos(ph), r * sin(ph), z), 0, INFINITY};
    double mint, maxt;
    if (!m->ops->intersect_aabb(m, &ray, &mint, &maxt) || !(mint < maxt)) continue;
    track_walk w;
    if (!m->ops->majorant_walk(m, &ray, mint, maxt, true, &w)) continue;
    st->rays++;
    st->radial += w.radial;
    double a = mint;
    for (int guard = 0; guard < 100000; guard++) {
      double b = w.b < INFINITY ? w.b : maxt;
      st->order += b < a - 1e-12;
      for (int q = 0; q < 64 && b - a > 1e-9; q++) {
        medium_interaction mi = {.medium = m, .t = a + (b - a) * (1e-9 + (1 - 2e-9) * walk_urand(rng))};
        mi.p = v3_fma(ray.o, mi.t, ray.d);
        mi.majorant = col1(w.mu);
        m->ops->coefficients(m, &mi);
        double smax = col_max(mi.sigma_t),
               smin = fmin(mi.sigma_t.c[0], fmin(mi.sigma_t.c[1], mi.sigma_t.c[2]));
        bool out = smax > w.mu || smin < w.ctl;
        if (out && st->bad < 5)
          printf("    t %.17g in [%.17g, %.17g] at (%.9g, %.9g, %.9g): sigma_t %g..%g outside [%g, %g]\n",
                 mi.t, a, b, mi.p.x, mi.p.y, mi.p.z, smin, smax, w.ctl, w.mu);
        st->bad += out;
      }
      st->pieces++;
      if (w.b == INFINITY) break;
      a = w.b;
      track_walk_next(&w);
    }
  }
}

bool tsup_pixel_estimate(scene *s, uint32_t spp, int reps, double *mean, double *se) {
  double sum = 0, sum2 = 0;
  for (int r = 1; r <= reps; r++) {
    film_image img;
    if (!tsup_render(s, spp, (uint64_t)r, 0, &img)) return false;
    double v = img.data[0];
    film_image_free(&img);
    sum += v, sum2 += v * v;
  }
  *mean = sum / reps;
  *se = sqrt(fmax(sum2 / reps - *mean * *mean, 0) / (reps - 1));
  return true;
}
