/* Thousands of films through the project's one EXR writer, each read back
 * bit for bit by two independent readers: OpenEXR Core (exr_read_image) and
 * OpenEXR's C++ library (Imf, tests/support/imf_read.cpp), which in Debian's
 * 3.1 decodes chunks and inflates ZIP data with its own code.
 *
 * Why: Debian's OpenEXR 3.1.5 Core writer, when a ZIP chunk compresses to
 * exactly as many bytes as the raw chunk, stores the zlib bytes, and every
 * reader takes a chunk of raw size as raw (OpenEXR issue #2306). About one
 * film in 200 then had a 16-line block of garbage. image_exr.c stores such
 * chunks raw; this test writes films of every size 1x1 .. 64x64, thin
 * strips up to 256x1, several value patterns (incompressible noise,
 * constants, gradients with noise at several scales, sparse spikes,
 * non-finite values), float32 and float16, and the rgb, luminance and
 * Stokes channel sets, half of them through exr_write_image and half
 * through exr_encode_image (the daemon's path), and counts the films
 * either reader gets wrong. RSW_EXR_STRESS_FILMS=N sets the film count
 * (default 4608: every size, then the strips) to measure the rate on more films. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../support/imf_read.h"
#include "../support/test.h"
#include "image_exr.h"

RSW_TEST_DEFINE_GLOBALS

static char tmpdir[256];

/* splitmix64: the film's parameters and samples from its index alone. */
static uint64_t mix(uint64_t *s) {
  uint64_t z = (*s += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}
static double unif(uint64_t *s) {
  return (double)(mix(s) >> 11) * 0x1p-53;
}

enum {
  PAT_NOISE_WIDE, /* random sign and exponent: incompressible */
  PAT_NOISE_UNIT, /* uniform in [0, 1) */
  PAT_CONSTANT,
  PAT_GRADIENT,
  PAT_GRAD_NOISE_1E6, /* gradient plus relative noise 1e-6, 1e-3, 1e-1 */
  PAT_GRAD_NOISE_1E3,
  PAT_GRAD_NOISE_1E1,
  PAT_RADIANCE,  /* a smooth positive lobe times (1 + 1% noise) */
  PAT_QUANTIZED, /* a few distinct values */
  PAT_SPARSE,    /* zeros with rare spikes */
  PAT_SPECIAL,   /* gradient with inf, -inf, NaN, subnormals, -0, huge */
  PAT_COUNT
};

static const char *pattern_name[PAT_COUNT] = {"noise-wide",    "noise-unit",    "constant",      "gradient",
                                              "gradient+1e-6", "gradient+1e-3", "gradient+1e-1", "radiance",
                                              "quantized",     "sparse",        "special"};

static float sample(int pat, uint64_t *s, const double g[3], int x, int y, int c) {
  double grad = g[0] + g[1] * x + g[2] * y + 0.25 * c;
  switch (pat) {
  case PAT_NOISE_WIDE: {
    double v = ldexp(1.0 + unif(s), (int)(mix(s) % 60) - 30);
    return (float)(mix(s) & 1 ? -v : v);
  }
  case PAT_NOISE_UNIT: return (float)unif(s);
  case PAT_CONSTANT: return (float)g[0];
  case PAT_GRADIENT: return (float)grad;
  case PAT_GRAD_NOISE_1E6: return (float)(grad * (1 + 1e-6 * (unif(s) - 0.5)));
  case PAT_GRAD_NOISE_1E3: return (float)(grad * (1 + 1e-3 * (unif(s) - 0.5)));
  case PAT_GRAD_NOISE_1E1: return (float)(grad * (1 + 1e-1 * (unif(s) - 0.5)));
  case PAT_RADIANCE: {
    double dx = (x - 20.0) / 17.0, dy = (y - 30.0) / 23.0;
    return (float)(0.05 * exp(-dx * dx - dy * dy) * (1 + 0.01 * (unif(s) - 0.5)) + 1e-3 * c);
  }
  case PAT_QUANTIZED: return (float)((int)(mix(s) % 5) * 0.125);
  case PAT_SPARSE: return mix(s) % 37 == 0 ? (float)(unif(s) * 1e4) : 0.0f;
  default: {
    static const float special[] = {INFINITY, -INFINITY, NAN, 0x1p-140f, -0x1p-130f, -0.0f, 3e38f, 1e-40f};
    uint64_t r = mix(s);
    return r % 5 == 0 ? special[(r >> 8) % 8] : (float)grad;
  }
  }
}

/* What a reader must give back for a written sample: the float itself, or
 * in float16 its nearest half (ties to even; overflow to inf), computed
 * here by the compiler's _Float16, not by the writer's own rounding. */
static float stored(float v, bool half) {
  return half ? (float)(_Float16)v : v;
}

static bool same_bits(float a, float b) {
  if (isnan(a) || isnan(b)) return isnan(a) && isnan(b);
  uint32_t ua, ub;
  memcpy(&ua, &a, 4);
  memcpy(&ub, &b, 4);
  return ua == ub;
}

typedef struct film {
  int w, h, nc, pat;
  bool half, in_memory;
  const char *const *names;
  float *data; /* HWC in names order */
} film;

static const char *const set_rgb[] = {"R", "G", "B"};
static const char *const set_y[] = {"Y"};
static const char *const set_stokes[] = {"S0", "S1", "S2", "S3"};

/* Film i: every size 1x1 .. 64x64 first (i < 4096), then strips up to
 * 256 x 1 and 256 x 2, then random sizes up to 64 x 64. */
static void make_film(int i, film *f) {
  uint64_t s = 0x5eed0000ULL + (uint64_t)i;
  if (i < 4096) {
    f->w = i % 64 + 1;
    f->h = i / 64 + 1;
  } else if (i < 4096 + 512) {
    f->w = (i - 4096) % 256 + 1;
    f->h = (i - 4096) / 256 + 1;
  } else {
    f->w = (int)(mix(&s) % 64) + 1;
    f->h = (int)(mix(&s) % 64) + 1;
  }
  f->pat = (int)(mix(&s) % PAT_COUNT);
  int set = (int)(mix(&s) % 3);
  f->names = set == 0 ? set_rgb : set == 1 ? set_y : set_stokes;
  f->nc = set == 0 ? 3 : set == 1 ? 1 : 4;
  f->half = mix(&s) & 1;
  f->in_memory = mix(&s) & 1;
  double g[3] = {unif(&s) * 2 - 0.5, (unif(&s) - 0.5) * 0.1, (unif(&s) - 0.5) * 0.1};
  size_t n = (size_t)f->w * f->h * f->nc;
  f->data = malloc(n * sizeof *f->data);
  for (int y = 0; y < f->h; y++)
    for (int x = 0; x < f->w; x++)
      for (int c = 0; c < f->nc; c++)
        f->data[((size_t)y * f->w + x) * f->nc + c] = sample(f->pat, &s, g, x, y, c);
}

/* Writes the film to path through the writer the film names. */
static bool write_film(const film *f, const char *path, char *msg, size_t msg_len) {
  rsw_err err = {0};
  if (!f->in_memory) {
    if (exr_write_image(path, f->w, f->h, f->nc, f->names, f->data, f->half, NULL, &err) == RSW_OK)
      return true;
    snprintf(msg, msg_len, "exr_write_image: %.400s", err.msg);
    return false;
  }
  void *bytes = NULL;
  size_t len = 0;
  if (exr_encode_image(f->w, f->h, f->nc, f->names, f->data, f->half, NULL, &bytes, &len, &err) != RSW_OK) {
    snprintf(msg, msg_len, "exr_encode_image: %.400s", err.msg);
    return false;
  }
  FILE *fp = fopen(path, "wb");
  bool ok = fp && fwrite(bytes, 1, len, fp) == len;
  if (fp) ok = fclose(fp) == 0 && ok;
  free(bytes);
  if (!ok) snprintf(msg, msg_len, "cannot write %.400s", path);
  return ok;
}

/* Samples of a decoded image (channels in file order, looked up by name)
 * that differ from what was written; -1 when the shape or names differ. */
static long count_wrong(const film *f, int w, int h, int nc, const char *const *file_names, const float *px) {
  if (w != f->w || h != f->h || nc != f->nc) return -1;
  int map[4];
  for (int c = 0; c < f->nc; c++) {
    map[c] = -1;
    for (int k = 0; k < nc; k++)
      if (strcmp(file_names[k], f->names[c]) == 0) map[c] = k;
    if (map[c] < 0) return -1;
  }
  long bad = 0;
  for (size_t p = 0; p < (size_t)w * h; p++)
    for (int c = 0; c < f->nc; c++)
      if (!same_bits(px[p * nc + map[c]], stored(f->data[p * f->nc + c], f->half))) bad++;
  return bad;
}

static void test_many_films_read_back_exactly(void) {
  const char *env = getenv("RSW_EXR_STRESS_FILMS");
  int n_films = env && atoi(env) > 0 ? atoi(env) : 4096 + 512;
  char path[512];
  snprintf(path, sizeof path, "%s/film.exr", tmpdir);
  int wrong_core = 0, wrong_imf = 0, disagree = 0, failed = 0, reported = 0;
  long per_pattern[PAT_COUNT] = {0};
  for (int i = 0; i < n_films; i++) {
    film f;
    make_film(i, &f);
    char msg[512] = "";
    bool ok = write_film(&f, path, msg, sizeof msg);
    exr_image core = {0};
    imf_image imf = {0};
    rsw_err err = {0};
    if (ok && exr_read_image(path, &core, &err) != RSW_OK) {
      snprintf(msg, sizeof msg, "Core read: %.400s", err.msg);
      ok = false;
    }
    if (ok && imf_read_float(path, &imf, msg, sizeof msg) != 0) ok = false;
    if (!ok) {
      failed++;
      if (reported++ < 5) CHECK(false, "film %d (%dx%dx%d): %s", i, f.w, f.h, f.nc, msg);
    } else {
      const char *imf_names[IMF_READ_MAX_CHANNELS];
      for (int c = 0; c < imf.n_channels; c++) imf_names[c] = imf.names[c];
      long bc = count_wrong(&f, core.width, core.height, core.n_channels,
                            (const char *const *)core.channel_names, core.data);
      long bi = count_wrong(&f, imf.width, imf.height, imf.n_channels, imf_names, imf.data);
      /* The two readers must agree with each other sample for sample too
       * (both give channels in the file's order). */
      bool agree = core.width == imf.width && core.height == imf.height && core.n_channels == imf.n_channels;
      for (size_t k = 0; agree && k < (size_t)core.width * core.height * core.n_channels; k++)
        agree = same_bits(core.data[k], imf.data[k]);
      wrong_core += bc != 0;
      wrong_imf += bi != 0;
      disagree += !agree;
      if (bc != 0 || bi != 0) per_pattern[f.pat]++;
      if ((bc != 0 || bi != 0 || !agree) && reported++ < 5)
        CHECK(false, "film %d: %dx%d %s %s %s via %s: %ld samples wrong through Core, %ld through Imf", i,
              f.w, f.h, f.names[0], f.half ? "float16" : "float32", pattern_name[f.pat],
              f.in_memory ? "exr_encode_image" : "exr_write_image", bc, bi);
    }
    exr_image_free(&core);
    free(imf.data);
    free(f.data);
    unlink(path);
  }
  printf("  %d films: corrupt through Core %d (%.2f per thousand), through Imf %d, readers disagree %d, "
         "failed %d\n",
         n_films, wrong_core, 1000.0 * wrong_core / n_films, wrong_imf, disagree, failed);
  for (int p = 0; p < PAT_COUNT; p++)
    if (per_pattern[p]) printf("    %s: %ld corrupt\n", pattern_name[p], per_pattern[p]);
  CHECK(wrong_core == 0 && wrong_imf == 0 && disagree == 0 && failed == 0,
        "%d of %d films corrupt (Core %d, Imf %d, disagree %d, failed %d)", wrong_core + failed, n_films,
        wrong_core, wrong_imf, disagree, failed);
}

int main(void) {
  const char *base = getenv("TMPDIR");
  snprintf(tmpdir, sizeof tmpdir, "%s/rsw_exr_stress_XXXXXX", base && *base ? base : "/tmp");
  if (!mkdtemp(tmpdir)) {
    perror("mkdtemp");
    return 1;
  }
  RSW_TEST_RUN(test_many_films_read_back_exactly);
  rmdir(tmpdir);
  RSW_TEST_END("test_image_exr_stress");
}
