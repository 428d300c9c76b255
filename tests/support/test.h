/* Minimal test harness. Each test binary calls RSW_TEST_RUN(fn) for every
 * test function and ends main() with RSW_TEST_END(); the last line it
 * prints is "<binary>: N passed, N failed", which tests/run.sh sums into the
 * one closing line of `make test`.
 *
 * Inside a test: CHECK(cond, fmt, ...) records a failure with file:line and
 * continues; REQUIRE(cond, fmt, ...) records and returns from the test. */
#ifndef RSW_TEST_H
#define RSW_TEST_H

#include <math.h>
#include <stdio.h>
#include <string.h>

extern int rsw_test_failed_checks_;
extern int rsw_test_passed_;
extern int rsw_test_failed_;
extern const char *rsw_test_name_;

#define CHECK(cond, ...)                                                                                     \
  do {                                                                                                       \
    if (!(cond)) {                                                                                           \
      rsw_test_failed_checks_++;                                                                             \
      fprintf(stdout, "  FAIL %s (%s:%d): ", rsw_test_name_, __FILE__, __LINE__);                            \
      fprintf(stdout, __VA_ARGS__);                                                                          \
      fputc('\n', stdout);                                                                                   \
    }                                                                                                        \
  } while (0)

#define REQUIRE(cond, ...)                                                                                   \
  do {                                                                                                       \
    if (!(cond)) {                                                                                           \
      CHECK(cond, __VA_ARGS__);                                                                              \
      return;                                                                                                \
    }                                                                                                        \
  } while (0)

/* |a - b| <= rel * max(|a|, |b|) (or both zero). */
#define CHECK_REL(a, b, rel)                                                                                 \
  do {                                                                                                       \
    double a_ = (a), b_ = (b);                                                                               \
    double m_ = fabs(a_) > fabs(b_) ? fabs(a_) : fabs(b_);                                                   \
    CHECK(fabs(a_ - b_) <= (rel)*m_, "%s = %.17g vs %s = %.17g (rel %g)", #a, a_, #b, b_, (double)(rel));    \
  } while (0)

#define CHECK_ABS(a, b, tol)                                                                                 \
  do {                                                                                                       \
    double a_ = (a), b_ = (b);                                                                               \
    CHECK(fabs(a_ - b_) <= (tol), "%s = %.17g vs %s = %.17g (abs %g)", #a, a_, #b, b_, (double)(tol));       \
  } while (0)

#define RSW_TEST_RUN(fn)                                                                                     \
  do {                                                                                                       \
    rsw_test_name_ = #fn;                                                                                    \
    int before_ = rsw_test_failed_checks_;                                                                   \
    fn();                                                                                                    \
    if (rsw_test_failed_checks_ == before_) {                                                                \
      rsw_test_passed_++;                                                                                    \
      fprintf(stdout, "ok   %s\n", #fn);                                                                     \
    } else {                                                                                                 \
      rsw_test_failed_++;                                                                                    \
      fprintf(stdout, "FAIL %s\n", #fn);                                                                     \
    }                                                                                                        \
    fflush(stdout);                                                                                          \
  } while (0)

#define RSW_TEST_DEFINE_GLOBALS                                                                              \
  int rsw_test_failed_checks_ = 0;                                                                           \
  int rsw_test_passed_ = 0;                                                                                  \
  int rsw_test_failed_ = 0;                                                                                  \
  const char *rsw_test_name_ = "";

#define RSW_TEST_END(binary)                                                                                 \
  do {                                                                                                       \
    fprintf(stdout, "%s: %d passed, %d failed\n", binary, rsw_test_passed_, rsw_test_failed_);               \
    return rsw_test_failed_ ? 1 : 0;                                                                         \
  } while (0)

#endif
