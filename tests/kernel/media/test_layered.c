/* media/layered.c media_layers_finish's packed copies (test_packed_copies);
 * media_layer_of's and media_layers_cum_in's clamps against their
 * branches (test_layer_of_clamps);
 * media_layers_sample_real_batch and
 * media_layers_transmittance_batch against media_layers_sample_real and
 * media_layers_transmittance, bit for bit, at every ISA this CPU runs
 * (media/layered_lanes.h: the setup's lanes): equal layers under an affine
 * to_world (the lanes), unequal layers and a projective to_world (the
 * scalar setup), one channel and three, over random rays from inside and
 * outside the box (level ones among them), random u and u at the quick
 * pass test's margin, batches of every length from 1 to past a chunk. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../server/kernel/core/rng.h"
#include "../../../server/kernel/media/layered.h"
#include "../../support/test.h"

RSW_TEST_DEFINE_GLOBALS

enum {
  NMAX = 300
};

/* n layers of an exponential profile (every 7th empty), nc channels
 * (one: the others copied, as piecewise does), equal or jittered
 * thicknesses, under xf. */
static bool layers_make(media_layers *L, const xform *xf, uint32_t n, int nc, bool equal, pcg32 *rng) {
  memset(L, 0, sizeof *L);
  if (!media_layers_alloc(L, n)) return false;
  L->to_world = xf;
  L->nc = nc;
  if (!equal) {
    L->uniform = false;
    for (uint32_t k = 1; k < n; k++) L->lay[k].z = (k + 0.8 * (pcg32_next_double(rng) - 0.5)) / n;
  }
  for (uint32_t k = 0; k < n; k++)
    for (int c = 0; c < 3; c++) {
      double s = k % 7 == 3 ? 0.0 : 4.0 * exp(-(double)k / (n / 6.0)) * (nc == 1 ? 1.0 : 1.0 + 0.5 * c);
      L->lay[k].sig[c] = s;
      L->alb[3 * k + c] = 0.3 + 0.2 * c;
    }
  media_layers_finish(L);
  return true;
}

typedef struct flights {
  int n;
  ray3 r[NMAX];
  double o[3][NMAX], d[3][NMAX], mint[NMAX], maxt[NMAX], u[NMAX];
  int ch[NMAX];
} flights;

/* n clipped flights through L's box; every 5th u at the quick pass test's
 * margin, a few ulp either side. */
static void flights_make(const media_layers *L, int n, pcg32 *rng, flights *F) {
  F->n = 0;
  while (F->n < n) {
    vec3 o = v3(-1.5 + 3 * pcg32_next_double(rng), -1.5 + 3 * pcg32_next_double(rng),
                -0.2 + 1.4 * pcg32_next_double(rng));
    double ct = 2 * pcg32_next_double(rng) - 1, ph = 6.283185307179586 * pcg32_next_double(rng);
    if (F->n % 11 == 5) ct = 0.0; /* level */
    double st = sqrt(1 - ct * ct);
    ray3 r = {o, v3(st * cos(ph), st * sin(ph), ct), 0, INFINITY};
    double mint, maxt;
    if (!media_box_clip_at(&L->box, &r, &mint, &maxt) || !(maxt > mint)) continue;
    if (F->n % 3 == 1) maxt = mint + (maxt - mint) * pcg32_next_double(rng);
    int i = F->n++;
    F->r[i] = r;
    F->o[0][i] = o.x, F->o[1][i] = o.y, F->o[2][i] = o.z;
    F->d[0][i] = r.d.x, F->d[1][i] = r.d.y, F->d[2][i] = r.d.z;
    F->mint[i] = mint, F->maxt[i] = maxt;
    F->ch[i] = (int)(3 * pcg32_next_double(rng));
    double u = pcg32_next_double(rng);
    if (i % 5 == 0) {
      media_flight f;
      media_flight_setup(L, &r, mint, maxt, F->ch[i], &f);
      double edge = f.total * MEDIA_LAYERS_PASS_MARGIN;
      if (edge > 0 && edge < 1) {
        u = edge;
        int steps = (int)(9 * pcg32_next_double(rng)) - 4;
        for (int q = 0; q < abs(steps); q++) u = nextafter(u, steps < 0 ? 0.0 : 1.0);
      }
    }
    F->u[i] = u;
  }
}

static bool same(const void *a, const void *b, size_t n) {
  return memcmp(a, b, n) == 0;
}

/* Each ISA's batch against the scalar flights of F; returns the lanes that
 * differ (and counts collisions and passes). */
static int compare(const media_layers *L, const flights *F, rsw_isa isa, long *hits, long *passes) {
  static double t[NMAX], tr[3][NMAX], pdf[3][NMAX];
  static int layer[NMAX];
  media_flight_batch b = {.n = F->n,
                          .o = {F->o[0], F->o[1], F->o[2]},
                          .d = {F->d[0], F->d[1], F->d[2]},
                          .mint = F->mint,
                          .maxt = F->maxt,
                          .u = F->u,
                          .channel = F->ch,
                          .t = t,
                          .layer = layer,
                          .tr = {tr[0], tr[1], tr[2]},
                          .pdf = {pdf[0], pdf[1], pdf[2]}};
  media_layers_sample_real_batch(isa, L, &b);
  medium m = {0};
  int differ = 0;
  for (int i = 0; i < F->n; i++) {
    medium_interaction mi, mb;
    memset(&mi, 0, sizeof mi);
    memset(&mb, 0, sizeof mb);
    color ctr, cpdf;
    media_layers_sample_real(L, &m, &F->r[i], F->mint[i], F->maxt[i], F->u[i], F->ch[i], &mi, &ctr, &cpdf);
    bool bad = !same(&mi.t, &t[i], sizeof t[i]);
    for (int c = 0; c < 3; c++) bad |= !same(&ctr.c[c], &tr[c][i], 8) || !same(&cpdf.c[c], &pdf[c][i], 8);
    if (isfinite(mi.t)) {
      ++*hits;
      bad |= layer[i] < 0 || layer[i] >= (int)L->n;
      if (!bad) {
        media_layers_collision(L, &m, &F->r[i], F->mint[i], t[i], layer[i], &mb);
        bad |= !same(&mi, &mb, sizeof mi);
      }
    } else {
      ++*passes;
      bad |= layer[i] != -1;
    }
    differ += bad;
  }
  /* The transmittances over the same intervals. */
  const double *o[3] = {F->o[0], F->o[1], F->o[2]}, *d[3] = {F->d[0], F->d[1], F->d[2]};
  double *const trp[3] = {tr[0], tr[1], tr[2]};
  media_layers_transmittance_batch(isa, L, F->n, o, d, F->mint, F->maxt, trp);
  for (int i = 0; i < F->n; i++) {
    color ct = media_layers_transmittance(L, &F->r[i], F->mint[i], F->maxt[i]);
    bool bad = false;
    for (int c = 0; c < 3; c++) bad |= !same(&ct.c[c], &tr[c][i], 8);
    differ += bad;
  }
  return differ;
}

static void run_case(const char *name, const xform *xf, uint32_t n, int nc, bool equal, bool want_lanes) {
  pcg32 rng;
  pcg32_seed(&rng, 11 + n + nc, 7);
  media_layers L;
  REQUIRE(layers_make(&L, xf, n, nc, equal, &rng), "%s: layers", name);
  CHECK((L.uniform && L.affine) == want_lanes, "%s: the %s setup expected", name,
        want_lanes ? "lanes'" : "scalar");
  static flights F;
  long hits = 0, passes = 0;
  int differ = 0, isas = 0;
  for (int rep = 0; rep < 40; rep++) {
    int len = rep < 20 ? rep + 1 : rep < 30 ? 60 + rep : NMAX; /* tails, a chunk and a bit, several chunks */
    flights_make(&L, len, &rng, &F);
    for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
      if (!rsw_isa_supported((rsw_isa)isa)) continue;
      int d = compare(&L, &F, (rsw_isa)isa, &hits, &passes);
      if (d)
        printf("  %s at %s: %d of %d flights or transmittances differ\n", name, rsw_isa_name((rsw_isa)isa), d,
               F.n);
      differ += d;
      isas += rep == 0;
    }
  }
  printf("  %s: %d ISAs, %ld collisions, %ld passes, %d differ\n", name, isas, hits, passes, differ);
  CHECK(isas >= 1, "%s: no ISA", name);
  CHECK(hits > 1000 && passes > 1000, "%s: both kinds of flight (%ld collisions, %ld passes)", name, hits,
        passes);
  CHECK(differ == 0, "%s: %d flights or transmittances differ from the scalar ones", name, differ);
  media_layers_free(&L);
}

/* The box of the atmosphere bench's kind: a slab wider than high, off the
 * origin. */
static xform slab_xform(void) {
  xform s = xf_scale(v3(2.0, 3.0, 0.7)), t = xf_translate(v3(-1.0, -1.5, 0.05));
  return xf_mul(&t, &s);
}

static void test_flight_batch_equal_layers(void) {
  xform xf = slab_xform();
  run_case("2400 equal layers, 1 channel", &xf, 2400, 1, true, true);
  run_case("97 equal layers, 3 channels", &xf, 97, 3, true, true);
  run_case("1 layer", &xf, 1, 1, true, true);
}

static void test_flight_batch_scalar_setup(void) {
  xform xf = slab_xform();
  run_case("300 unequal layers, 3 channels", &xf, 300, 3, false, false);
  /* A projective to_world (its inverse's last row is not 0 0 0 1). */
  const double m[4][4] = {{2, 0, 0, -1}, {0, 3, 0, -1.5}, {0, 0, 0.7, 0.05}, {0, 0, 0.01, 1}};
  xform proj;
  REQUIRE(xf_from_matrix(m, &proj), "projective to_world");
  run_case("projective, 200 equal layers", &proj, 200, 1, true, false);
}

/* What media_layers_finish packs for the flights (cum: the search's C_k
 * per channel; lay[k].alb0 and gray_alb: a collision's albedo from the
 * layer's own line) agrees with the layers, and a collision's
 * coefficients are sigma_t alb per channel whether the albedo is gray or
 * not, before and after one layer's albedo turns chromatic (finish again,
 * as a parameter update does). */
static void test_packed_copies(void) {
  xform xf = slab_xform();
  pcg32 rng;
  pcg32_seed(&rng, 7, 3);
  media_layers L;
  REQUIRE(layers_make(&L, &xf, 240, 3, true, &rng), "layers");
  for (int round = 0; round < 3; round++) {
    for (uint32_t k = 0; k < L.n; k++)
      for (int c = 0; c < 3; c++) L.alb[3 * k + c] = round == 0 ? 0.2 + 0.5 * c : 0.6;
    if (round == 2) L.alb[3 * 17 + 2] = 0.25;
    media_layers_finish(&L);
    CHECK(L.gray_alb == (round == 1), "round %d: gray_alb %d", round, L.gray_alb);
    int bad = 0;
    for (int c = 0; c < 3; c++)
      for (uint32_t k = 0; k <= L.n; k++) bad += L.cum[(size_t)c * (L.n + 1) + k] != L.lay[k].cum[c];
    for (uint32_t k = 0; k < L.n; k++) {
      bad += L.lay[k].alb0 != L.alb[3 * k];
      medium_interaction mi = {0};
      media_layers_fill(&L, (int)k, &mi);
      for (int c = 0; c < 3; c++) bad += mi.sigma_s.c[c] != L.lay[k].sig[c] * L.alb[3 * k + c];
    }
    CHECK(bad == 0, "round %d: %d packed values or coefficients differ from the layers'", round, bad);
  }
  media_layers_free(&L);
}

/* media_layer_of's equal layers (a clamp of z n to [0, n - 1] in
 * minsd and maxsd) and media_layers_cum_in's clamp of z to [0, 1] against
 * the branches they replace, at the edges (signed zeros, NaN, infinities,
 * the layers' boundaries and the doubles beside them) and at random z,
 * for n = 1, 2, 7, 2,400. */
static int layer_of_ref(uint32_t n, double z) {
  double f = z * n;
  if (!(f > 0)) return 0;
  if (f >= n) return (int)n - 1;
  return (int)f;
}

static void test_layer_of_clamps(void) {
  const uint32_t ns[] = {1, 2, 7, 2400};
  pcg32 rng;
  pcg32_seed(&rng, 0x1a7e5, 11);
  int bad = 0, badc = 0, checked = 0;
  for (int in = 0; in < 4; in++) {
    uint32_t n = ns[in];
    media_layers L = {.n = n, .nd = n, .uniform = true};
    pw_layer lay[2] = {{.cum = {0.25}, .sig = {3.0}, .z = 0.125}};
    L.lay = lay;
    double zs[16 + 4 * 2401 + 4096];
    int nz = 0;
    const double edge[] = {0.0,      -0.0,      1.0,       -1.0,       NAN, -NAN,
                           INFINITY, -INFINITY, 0x1p-1074, -0x1p-1074, 2.0, 0.5};
    for (int i = 0; i < 12; i++) zs[nz++] = edge[i];
    for (uint32_t k = 0; k <= n; k++) {
      double z = (double)k / n;
      zs[nz++] = z, zs[nz++] = nextafter(z, -1.0), zs[nz++] = nextafter(z, 2.0);
    }
    for (int i = 0; i < 4096; i++) zs[nz++] = 1.2 * pcg32_next_double(&rng) - 0.1;
    for (int i = 0; i < nz; i++) {
      double z = zs[i];
      bad += media_layer_of(&L, z) != layer_of_ref(n, z);
      double zc = z < 0.0 ? 0.0 : z > 1.0 ? 1.0 : z, ref = lay[0].cum[0] + lay[0].sig[0] * (zc - lay[0].z);
      double got = media_layers_cum_in(&L, 0, 0, z);
      badc += memcmp(&got, &ref, sizeof got) != 0;
      checked++;
    }
  }
  CHECK(bad == 0 && badc == 0, "%d layers and %d C(z) of %d differ from the branches", bad, badc, checked);
}

int main(void) {
  RSW_TEST_RUN(test_flight_batch_equal_layers);
  RSW_TEST_RUN(test_flight_batch_scalar_setup);
  RSW_TEST_RUN(test_packed_copies);
  RSW_TEST_RUN(test_layer_of_clamps);
  RSW_TEST_END("test_layered");
}
