/* film_angle_list (common/film_io.h): the text of the raysweep:zenith_deg
 * and raysweep:azimuth_deg attributes (and of the JSON meta's lists) is
 * "%.9g" joined by ',' whether or not it comes from the cache of the last
 * angles formatted: checked against an independent formatting for cache
 * misses, hits, two arrays taking turns, arrays that differ in their last
 * value only, films too large to be cached, and four threads taking turns
 * on two arrays at once. film_exr_encode gives the same bytes for the same
 * film however often it is asked, and other bytes for other angles. */
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../support/test.h"
#include "film_io.h"

RSW_TEST_DEFINE_GLOBALS

/* The list as film_io.h documents it, formatted here without film_io. */
static char *reference_list(const double *angles, size_t n, int k) {
  char *s = malloc(n * 32 + 1);
  size_t len = 0;
  s[0] = '\0';
  for (size_t i = 0; i < n; i++)
    len += (size_t)sprintf(s + len, i ? ",%.9g" : "%.9g", angles[2 * i + (size_t)k]);
  return s;
}

/* n pixels of angles that need every part of %.9g: negatives, integers,
 * tiny and huge magnitudes, values that round at the 9th digit. */
static double *make_angles(size_t n, double shift) {
  double *a = malloc(2 * n * sizeof *a);
  for (size_t i = 0; i < n; i++) {
    a[2 * i] = 0.123456789123 * (double)(i % 731) + shift;
    a[2 * i + 1] = (i % 5 == 0)   ? -359.99999999 + (double)i
                   : (i % 7 == 0) ? 1e-300 * (double)i
                                  : 180.0 - shift;
  }
  return a;
}

/* film_angle_list(a, n, k) equals the reference, and *len_out its length. */
static bool list_ok(const double *a, size_t n, int k) {
  size_t len = 12345;
  char *got = film_angle_list(a, n, k, &len);
  char *want = reference_list(a, n, k);
  bool ok = got && strcmp(got, want) == 0 && len == strlen(want);
  if (!ok)
    fprintf(stdout, "  n %zu k %d: got %.60s... (len %zu), want %.60s...\n", n, k, got ? got : "(null)", len,
            want);
  free(got);
  free(want);
  return ok;
}

static void test_lists_hit_and_miss(void) {
  enum {
    N = 7 * 5
  };
  double *a = make_angles(N, 0), *b = make_angles(N, 1.5);
  /* a first (a miss), then a again (a hit), both lists, with no length
   * asked for as well. */
  CHECK(list_ok(a, N, 0) && list_ok(a, N, 1) && list_ok(a, N, 0), "a: miss then hits");
  char *nolen = film_angle_list(a, N, 1, NULL);
  char *want = reference_list(a, N, 1);
  CHECK(nolen && strcmp(nolen, want) == 0, "without len_out");
  free(nolen);
  free(want);
  /* Two arrays of one size taking turns: each gets its own text. */
  for (int r = 0; r < 4; r++)
    CHECK(list_ok(b, N, r & 1) && list_ok(a, N, r & 1), "turn %d: a and b apart", r);
  /* The same array but its last value: not served a's text. */
  double last = a[2 * N - 1];
  a[2 * N - 1] = last + 1e-6;
  CHECK(list_ok(a, N, 1), "a with its last azimuth changed");
  a[2 * N - 1] = last;
  CHECK(list_ok(a, N, 1), "a again");
  /* A shorter film sharing a's first pixels. */
  CHECK(list_ok(a, N - 1, 0) && list_ok(a, N, 0), "a prefix of a, then a");
  /* A film beyond the cache (more than 65536 pixels): formatted each time. */
  size_t big = 300 * 300;
  double *c = make_angles(big, 2.25);
  CHECK(list_ok(c, big, 0) && list_ok(c, big, 1) && list_ok(a, N, 0), "a 300x300 film, then a");
  free(a);
  free(b);
  free(c);
}

typedef struct turns {
  const double *a, *b;
  size_t n;
  int bad;
} turns;

static void *take_turns(void *arg) {
  turns *t = arg;
  for (int r = 0; r < 200; r++) {
    const double *x = (r & 1) ? t->a : t->b;
    if (!list_ok(x, t->n, r % 3 == 0)) t->bad++;
  }
  return NULL;
}

/* Four threads at once (the daemon's HTTP workers encode films
 * concurrently): every answer is that of its own angles. */
static void test_threads(void) {
  enum {
    N = 16 * 16,
    T = 4
  };
  double *a = make_angles(N, 0.5), *b = make_angles(N, 3.0);
  pthread_t th[T];
  turns t[T];
  for (int i = 0; i < T; i++) {
    t[i] = (turns){.a = a, .b = b, .n = N};
    pthread_create(&th[i], NULL, take_turns, &t[i]);
  }
  int bad = 0;
  for (int i = 0; i < T; i++) {
    pthread_join(th[i], NULL);
    bad += t[i].bad;
  }
  CHECK(bad == 0, "%d of %d lists wrong under 4 threads", bad, 200 * T);
  free(a);
  free(b);
}

static bool has(const void *hay, size_t n, const char *needle) {
  return memmem(hay, n, needle, strlen(needle)) != NULL;
}

static void test_exr_encode_same_bytes(void) {
  enum {
    W = 6,
    H = 4
  };
  float px[W * H];
  for (int i = 0; i < W * H; i++) px[i] = 0.25f * (float)i;
  const char *names[] = {"Y"};
  double *a = make_angles(W * H, 0), *b = make_angles(W * H, 7.0);
  film_exr_info info = film_exr_info_none();
  info.sensor = "hdistant";
  info.variant = "mono";
  info.wavelength_nm = 550;
  info.angles = a;
  void *p1 = NULL, *p2 = NULL, *p3 = NULL;
  size_t n1 = 0, n2 = 0, n3 = 0;
  rsw_err err = {0};
  REQUIRE(film_exr_encode(W, H, 1, names, px, false, &info, &p1, &n1, &err) == RSW_OK, "encode: %s", err.msg);
  REQUIRE(film_exr_encode(W, H, 1, names, px, false, &info, &p2, &n2, &err) == RSW_OK, "encode again");
  CHECK(n1 == n2 && memcmp(p1, p2, n1) == 0, "the same film twice: the same bytes");
  char *za = reference_list(a, W * H, 0), *zb = reference_list(b, W * H, 0);
  CHECK(has(p1, n1, za), "a's zenith list in the header");
  info.angles = b;
  REQUIRE(film_exr_encode(W, H, 1, names, px, false, &info, &p3, &n3, &err) == RSW_OK, "encode with b");
  CHECK(has(p3, n3, zb) && !has(p3, n3, za), "b's film carries b's list, not a's");
  free(za);
  free(zb);
  free(p1);
  free(p2);
  free(p3);
  free(a);
  free(b);
}

int main(void) {
  RSW_TEST_RUN(test_lists_hit_and_miss);
  RSW_TEST_RUN(test_threads);
  RSW_TEST_RUN(test_exr_encode_same_bytes);
  RSW_TEST_END("test_film_io");
}
