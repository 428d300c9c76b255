#include "tsup.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

scene *tsup_load(const char *text, const char *variant) {
  rsw_err err = {0};
  scene *s = NULL;
  scene_load_opts o = {.size = sizeof o, .variant = variant};
  const char *c = text;
  while (*c == ' ' || *c == '\n') c++;
  if (scene_load_memory(text, strlen(text), "test-scene", *c == '<', &o, &s, &err)) {
    char buf[1200];
    printf("  scene load failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return NULL;
  }
  return s;
}

scene *tsup_load_file(const char *path, const char *variant) {
  rsw_err err = {0};
  scene *s = NULL;
  scene_load_opts o = {.size = sizeof o, .variant = variant};
  if (scene_load_file(path, &o, &s, &err)) {
    char buf[1200];
    printf("  scene load failed: %s\n", rsw_err_format(&err, buf, sizeof buf));
    return NULL;
  }
  return s;
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
