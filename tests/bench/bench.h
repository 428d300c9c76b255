/* What the make-bench programs measure with: clocks, medians, threads. */
#ifndef RSW_BENCH_H
#define RSW_BENCH_H

#include <stdlib.h>
#include <time.h>
#include <unistd.h>

static inline double bench_clock_s(clockid_t id) {
  struct timespec ts;
  clock_gettime(id, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
/* Wall time. */
static inline double bench_wall_s(void) {
  return bench_clock_s(CLOCK_MONOTONIC);
}
/* This thread's CPU time: a thread the shared machine descheduled does
 * not count against the code. */
static inline double bench_thread_cpu_s(void) {
  return bench_clock_s(CLOCK_THREAD_CPUTIME_ID);
}
/* CPU time of the whole process (every render thread). */
static inline double bench_process_cpu_s(void) {
  return bench_clock_s(CLOCK_PROCESS_CPUTIME_ID);
}

static inline int bench_cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return x < y ? -1 : x > y;
}
/* Median of v[0..n) (n >= 1; the mean of the middle two for even n).
 * Sorts v. */
static inline double bench_median(double *v, size_t n) {
  qsort(v, n, sizeof *v, bench_cmp_double);
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* Render threads: RSW_BENCH_THREADS, else every online core. */
static inline int bench_threads(void) {
  const char *e = getenv("RSW_BENCH_THREADS");
  int t = e ? atoi(e) : 0;
  if (t <= 0) t = (int)sysconf(_SC_NPROCESSORS_ONLN);
  return t < 1 ? 1 : t;
}

#endif
