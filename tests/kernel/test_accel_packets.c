/* accel.c's packet queries against its one-ray queries, at every ISA and
 * packet width: packet_load hands Embree the floats fill_ray gives one
 * ray, bit for bit (seen through the query hook, accel_internal.h); the
 * packets' occlusion answers are the single queries', their hits too (bit
 * for bit where both find one primitive; Embree's packet and one-ray
 * traversals may break a tie of two primitives at one distance either
 * way), and every ISA's packets are the others', bit for bit. The rays
 * cover fill_ray's every branch: ordinary ones, origins beyond the clip
 * sphere, directions rescaled (long, short), negative tmin, tmax near
 * float's limit and infinite, and rays it refuses (NaN, zero direction,
 * tmax < tmin). Also accel_surface_error_at_n (compiled per ISA) against
 * accel_surface_error_at. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../server/kernel/accel_internal.h"
#include "../../server/kernel/core/isa.h"
#include "../../server/kernel/core/rng.h"
#include "../support/test.h"
#include "../support/tsup.h"

RSW_TEST_DEFINE_GLOBALS

/* The rays the hook saw, as 8 floats each (org, tnear, dir, tfar). */
enum {
  REC_MAX = 64
};
static float s_rec[REC_MAX][8];
static int s_nrec;

static void record(const struct RTCRay *const *rays, unsigned k, unsigned width, bool occluded) {
  (void)width, (void)occluded;
  for (unsigned i = 0; i < k && s_nrec < REC_MAX; i++, s_nrec++) {
    const struct RTCRay *r = rays[i];
    float f[8] = {r->org_x, r->org_y, r->org_z, r->tnear, r->dir_x, r->dir_y, r->dir_z, r->tfar};
    memcpy(s_rec[s_nrec], f, sizeof f);
  }
}

/* Ray i of a test set around the scene's box (centre c, radius R). */
static ray3 test_ray(pcg32 *g, vec3 c, double R, int i) {
  vec3 d = v3(2 * pcg32_next_double(g) - 1, 2 * pcg32_next_double(g) - 1, 2 * pcg32_next_double(g) - 1);
  if (!(v3_len(d) > 1e-3)) d = v3(0.3, -0.5, 0.8);
  d = v3_norm(d);
  vec3 q = v3(c.x + R * (2 * pcg32_next_double(g) - 1), c.y + R * (2 * pcg32_next_double(g) - 1),
              c.z + R * (2 * pcg32_next_double(g) - 1));
  ray3 r = {v3_fma(q, -2.0 * R, d), d, 0.0, INFINITY};
  switch (i % 13) {
  case 1: r.o = v3_fma(q, -1e6 * R, d); break;    /* beyond the clip sphere */
  case 2: r.d = v3_scale(d, 5000.0); break;       /* rescaled: long */
  case 3: r.d = v3_scale(d, 1e-5); break;         /* rescaled: short */
  case 4: r.tmin = -1.0, r.tmax = 3.0 * R; break; /* negative tmin, finite tmax */
  case 5: r.tmin = 0.5 * R; break;
  case 6: r.tmax = 2e38; break;               /* below 3e38: converted */
  case 7: r.tmax = 5e38; break;               /* from 3e38: infinite */
  case 8: r.o.y = NAN; break;                 /* refused */
  case 9: r.d = v3(0, 0, 0); break;           /* refused */
  case 10: r.tmin = 2.0, r.tmax = 1.0; break; /* refused */
  case 11: r.tmin = -0.0, r.tmax = 2.5 * R; break;
  case 12: r.o = v3_fma(q, -1e6 * R, d), r.d = v3_scale(d, 3000.0); break;
  default: break;
  }
  return r;
}

enum {
  BATCHES = 400
};

static bool same_hit(const accel_hit *a, const accel_hit *b) {
  return memcmp(&a->t, &b->t, sizeof a->t) == 0 && a->shape == b->shape && a->sub == b->sub &&
         a->member == b->member && a->prim == b->prim && memcmp(&a->u, &b->u, sizeof a->u) == 0 &&
         memcmp(&a->v, &b->v, sizeof a->v) == 0 && memcmp(&a->ng, &b->ng, sizeof a->ng) == 0;
}

/* Packets of n rays (n = 16, 13, 5, 2) at every ISA and packet width
 * against the rays one at a time. */
static void check_scene(scene *s, const char *what) {
  REQUIRE(s, "%s loads", what);
  const accel *a = s->accel;
  vec3 c = v3_scale(v3_add(s->bbox_min, s->bbox_max), 0.5);
  double R = v3_len(v3_sub(s->bbox_max, c));
  rsw_isa was = rsw_isa_get();
  int isas = 0;
  long rays = 0, bad_floats = 0, bad_hits = 0, bad_occ = 0, hits = 0, ties = 0, bad_isa = 0;
  static accel_hit first_h[3][BATCHES][16];
  static bool first_hit[3][BATCHES][16];
  for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
    if (!rsw_isa_set((rsw_isa)isa)) continue;
    isas++;
    const int widths[] = {16, 8, 4};
    for (int wi = 0; wi < 3; wi++) {
      accel_set_packet_width(widths[wi]);
      pcg32 g;
      pcg32_seed(&g, 11, (uint64_t)wi);
      for (int batch = 0; batch < BATCHES; batch++) {
        const int sizes[] = {16, 13, 5, 2};
        int n = sizes[batch % 4];
        ray3 r[16];
        const ray3 *rp[16];
        for (int i = 0; i < n; i++) r[i] = test_ray(&g, c, R, batch * 16 + i), rp[i] = &r[i];
        /* One ray at a time: its floats and answers. */
        float one[16][8];
        bool one_ok[16], one_hit[16], one_occ[16];
        accel_hit one_h[16];
        for (int i = 0; i < n; i++) {
          s_nrec = 0;
          one_occ[i] = accel_occluded(a, &r[i]);
          one_ok[i] = s_nrec == 1;
          if (one_ok[i]) memcpy(one[i], s_rec[0], sizeof one[i]);
          one_hit[i] = accel_intersect(a, &r[i], &one_h[i]);
        }
        /* The packets: the same floats for the rays fill_ray takes. */
        s_nrec = 0;
        bool occ[16];
        accel_occluded_packet(a, rp, n, occ);
        int k = 0;
        for (int i = 0; i < n; i++) {
          if (!one_ok[i]) continue;
          if (k >= s_nrec || memcmp(one[i], s_rec[k], sizeof one[i]) != 0) bad_floats++;
          k++;
        }
        if (k != s_nrec) bad_floats++;
        accel_hit h[16];
        accel_hit *hp[16];
        bool hit[16];
        for (int i = 0; i < n; i++) hp[i] = &h[i];
        accel_intersect_packet(a, rp, n, hp, hit, batch % 2 == 0);
        for (int i = 0; i < n; i++) {
          rays++;
          hits += hit[i];
          bad_occ += occ[i] != one_occ[i];
          if (hit[i] != one_hit[i]) {
            bad_hits++;
          } else if (hit[i] && (h[i].shape != one_h[i].shape || h[i].prim != one_h[i].prim)) {
            /* Two primitives at one distance (a box on the floor, an edge
             * of two faces): Embree's packet and one-ray traversals may
             * pick either. */
            ties++;
            if (!(fabs(h[i].t - one_h[i].t) <= 1e-6 * fabs(one_h[i].t))) bad_hits++;
          } else if (hit[i] && !same_hit(&h[i], &one_h[i])) {
            bad_hits++;
          }
          /* And every ISA's packets are the first ISA's, bit for bit. */
          accel_hit *ref = &first_h[wi][batch][i];
          if (isas == 1) {
            *ref = h[i], first_hit[wi][batch][i] = hit[i];
          } else if (hit[i] != first_hit[wi][batch][i] || (hit[i] && !same_hit(&h[i], ref))) {
            bad_isa++;
          }
        }
      }
    }
  }
  accel_set_packet_width(0);
  rsw_isa_set(was);
  printf("  %s: %d ISAs, %ld rays, %ld hits, %ld ties\n", what, isas, rays, hits, ties);
  CHECK(isas >= 2, "%s: at least two ISAs (%d)", what, isas);
  CHECK(bad_floats == 0, "%s: %ld packets whose floats differ from fill_ray's", what, bad_floats);
  CHECK(bad_hits == 0, "%s: %ld packet hits differ from accel_intersect's", what, bad_hits);
  CHECK(ties <= rays / 100, "%s: %ld ties of %ld rays", what, ties, rays);
  CHECK(bad_isa == 0, "%s: %ld packet hits differ between ISAs", what, bad_isa);
  CHECK(bad_occ == 0, "%s: %ld packet occlusions differ from accel_occluded's", what, bad_occ);
  CHECK(hits > rays / 20, "%s: the rays meet the geometry (%ld of %ld)", what, hits, rays);
  scene_free(s);
}

static void test_packets_match_single_rays(void) {
  accel_set_query_hook(record);
  check_scene(tsup_load_file("proto/examples/cornell_box.json", NULL), "cornell");
  check_scene(tsup_load_file("proto/examples/hdistant_seed.xml", NULL), "seed");
  accel_set_query_hook(NULL);
}

/* accel_surface_error_at_n at every ISA: accel_surface_error_at's bits. */
static void test_surface_error_n(void) {
  scene *s = tsup_load_file("proto/examples/cornell_box.json", NULL);
  REQUIRE(s, "cornell loads");
  rsw_isa was = rsw_isa_get();
  pcg32 g;
  pcg32_seed(&g, 5, 9);
  enum {
    M = 67
  };
  double px[M], py[M], pz[M], nx[M], ny[M], nz[M], out[M + 1];
  long bad = 0, checked = 0;
  int isas = 0;
  for (size_t si = 0; si < s->n_shapes; si++) {
    const shape *sh = s->shapes[si];
    double t[8];
    accel_surface_error_terms(s->accel, sh->index, &sh->to_world, t);
    for (int j = 0; j < M; j++) {
      px[j] = 600 * pcg32_next_double(&g) - 50, py[j] = 600 * pcg32_next_double(&g) - 50;
      pz[j] = 600 * pcg32_next_double(&g) - 300;
      nx[j] = 2 * pcg32_next_double(&g) - 1, ny[j] = 2 * pcg32_next_double(&g) - 1;
      nz[j] = 2 * pcg32_next_double(&g) - 1;
    }
    const double *p[3] = {px, py, pz}, *n[3] = {nx, ny, nz};
    isas = 0;
    for (int isa = 0; isa < RSW_ISA__COUNT; isa++) {
      if (!rsw_isa_set((rsw_isa)isa)) continue;
      isas++;
      out[M] = -1.0;
      accel_surface_error_at_n(t, &sh->to_world, M, p, n, out);
      for (int j = 0; j < M; j++) {
        double want =
            accel_surface_error_at(t, &sh->to_world, v3(px[j], py[j], pz[j]), v3(nx[j], ny[j], nz[j]));
        bad += memcmp(&want, &out[j], sizeof want) != 0;
        checked++;
      }
      bad += out[M] != -1.0;
    }
  }
  rsw_isa_set(was);
  CHECK(isas >= 2, "at least two ISAs (%d)", isas);
  CHECK(checked > 1000, "lanes checked (%ld)", checked);
  CHECK(bad == 0, "%ld of %ld lanes differ from accel_surface_error_at (or past m written)", bad, checked);
  scene_free(s);
}

int main(void) {
  RSW_TEST_RUN(test_packets_match_single_rays);
  RSW_TEST_RUN(test_surface_error_n);
  RSW_TEST_END("test_accel_packets");
}
