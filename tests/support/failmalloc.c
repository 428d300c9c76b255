/* failmalloc: make the Nth heap allocation fail, as curl's and redis's
 * test suites do, to check that every allocation failure in the process
 * ends in a clean error (tests/http/test_oom.c).
 *
 * How it hooks in: a build-time hook, not LD_PRELOAD. This file defines
 * malloc, calloc, realloc, reallocarray, strdup, strndup, posix_memalign,
 * aligned_alloc and memalign and is linked into the test binary itself
 * (and into build/tests/raysweepd-failmalloc). A definition in the
 * executable preempts libc's for every library of the process, exactly as
 * an LD_PRELOAD library would (glibc supports replacing malloc this way),
 * so allocations inside cJSON, expat, OpenEXR, Embree (C++ new included,
 * through libstdc++'s operator new), libmicrohttpd and libc itself are
 * counted. Why not LD_PRELOAD:
 *  - under ASan (make test SAN=1) a preloaded malloc either loses to
 *    ASan's own definitions (libasan must come first in the library list,
 *    and then its malloc wins) or trips ASan's "runtime does not come
 *    first" check; a definition in the executable comes before both, and
 *    forwards to ASan's allocator by its __interceptor_* names, so the
 *    same test runs in the SAN build with every access still checked;
 *  - no re-exec with an environment, no library search path to get right.
 * free() is not replaced: every block still comes from the real allocator
 * (glibc's through its __libc_* entry points, or ASan's), so the real
 * free() is the right one for it.
 *
 * Counting is off until armed, so the start-up of libc, the dynamic
 * loader, pthread and library constructors is never counted and never
 * fails:
 *  - in process: failmalloc_arm(n) right before the operation under test,
 *    failmalloc_disarm() right after (the test finds them with dlsym, or
 *    calls them directly when linked in);
 *  - a daemon (build/tests/raysweepd-failmalloc): with FAILMALLOC_N=n in
 *    its environment, SIGUSR1 arms it with n (the test sends it once the
 *    daemon is listening, so start-up is not counted), SIGUSR2 disarms it
 *    and appends "<allocations> <failed>" to FAILMALLOC_REPORT;
 *  - a command (raysweepd render): FAILMALLOC_N=n FAILMALLOC_AT_START=1
 *    arms it when main() is about to run (this file's constructor is the
 *    executable's, run after every library's), and the counts are written
 *    at exit (tests/integration/test_oom_cli.sh).
 * Armed with n >= 1, the nth allocation from then on (counted across all
 * threads) returns NULL with errno ENOMEM and every other one succeeds
 * (one failure per run: what a recovery path must survive). n = 0 only
 * counts. A thread may exclude itself (failmalloc_exclude_thread), so a
 * test driving a server in the same process does not fail its own
 * client-side allocations.
 *
 * This file is compiled without sanitizer instrumentation (its code may run
 * before ASan has initialised). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <execinfo.h>
#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#ifdef FAILMALLOC_ASAN
extern void *__interceptor_malloc(size_t);
extern void *__interceptor_calloc(size_t, size_t);
extern void *__interceptor_realloc(void *, size_t);
extern void *__interceptor_memalign(size_t, size_t);
#define REAL_MALLOC(n)      __interceptor_malloc(n)
#define REAL_CALLOC(n, m)   __interceptor_calloc(n, m)
#define REAL_REALLOC(p, n)  __interceptor_realloc(p, n)
#define REAL_MEMALIGN(a, n) __interceptor_memalign(a, n)
#else /* glibc's allocator under the names it exports for this purpose */
extern void *__libc_malloc(size_t);
extern void *__libc_calloc(size_t, size_t);
extern void *__libc_realloc(void *, size_t);
extern void *__libc_memalign(size_t, size_t);
#define REAL_MALLOC(n)      __libc_malloc(n)
#define REAL_CALLOC(n, m)   __libc_calloc(n, m)
#define REAL_REALLOC(p, n)  __libc_realloc(p, n)
#define REAL_MEMALIGN(a, n) __libc_memalign(a, n)
#endif

#define FM_EXPORT __attribute__((visibility("default"), used))

static atomic_bool g_armed;
static atomic_long g_target; /* fail allocation number g_target (0: none) */
static atomic_long g_count;  /* allocations since armed */
static atomic_long g_failed; /* failures injected since armed */
static _Thread_local bool t_excluded;
/* failmalloc_skip_embree(true): the target allocation, when Embree's code
 * is on the stack, succeeds and the next one fails instead (see there). */
static atomic_bool g_skip_embree;
/* The stack of the allocation made to fail, and whether it was on the
 * thread that armed (failmalloc_print_failure), so that a failure the run
 * did not survive (a hang: nothing else names the place) says where it
 * fell. */
static void *g_fail_bt[48];
static atomic_int g_fail_bt_n;
static atomic_bool g_fail_on_armer;
static _Thread_local bool t_armer;
/* failmalloc_side: 0 every thread, 1 only the arming thread, 2 every
 * thread but it. */
static atomic_int g_side;
/* FAILMALLOC_JITTER_US=N: while armed, one counted allocation in 4 first
 * sleeps 0..N microseconds (a hash of its number), so that the threads'
 * allocations interleave in orders a quiet machine does not give (hunting
 * a failure seen once under load; the order is still the count's). */
static long g_jitter_us;

/* Threads. pthread_create is wrapped (this definition preempts libc's, or
 * ASan's, which it calls) so that each new thread starts in a trampoline:
 *  - under ASan, a thread's allocations count only once its start routine
 *    runs: ASan sets the thread up first (pthread_getattr_np, its own
 *    bookkeeping), and an allocation failing there is a CHECK failure
 *    (abort) inside ASan by design, not a failure of the code under test;
 *  - threads that oneTBB starts (Embree's build workers) are excluded:
 *    Embree 3.13's parallel builders do not survive a std::bad_alloc
 *    thrown on a worker (the builder waits for that worker forever, or
 *    TBB terminates the process with missing_wait), a limitation of the
 *    library that no caller can handle, so failing there would only
 *    measure Embree. The thread that calls Embree takes part in the build
 *    too: there, an allocation inside a oneTBB task is not failed either
 *    (should_fail), as the std::bad_alloc it throws can leave a spin lock
 *    of Embree's held, and the next build, on any thread, spins on it
 *    forever (test_oom's d_scene_push under load, 2026-11-29: allocations
 *    1043-1048 failed inside tasks, then the push of run 1049 hung in
 *    rtcCommitScene, on a `pause` loop). Its failures outside the tasks
 *    still surface as RTC_ERROR_OUT_OF_MEMORY. */
static _Thread_local bool t_started;

typedef struct trampoline {
  void *(*fn)(void *);
  void *arg;
  bool excluded;
} trampoline;

static void *thread_start(void *p) {
  trampoline t = *(trampoline *)p;
  free(p);
  t_excluded = t.excluded;
  t_started = true;
  return t.fn(t.arg);
}

#ifdef FAILMALLOC_ASAN
extern int __interceptor_pthread_create(pthread_t *, const pthread_attr_t *, void *(*)(void *), void *);
#define REAL_PTHREAD_CREATE __interceptor_pthread_create
#define THREAD_COUNTS()     t_started
#else
typedef int (*pthread_create_fn)(pthread_t *, const pthread_attr_t *, void *(*)(void *), void *);
static pthread_create_fn real_pthread_create(void) {
  static _Atomic(pthread_create_fn) f;
  pthread_create_fn r = atomic_load(&f);
  if (!r) {
    r = (pthread_create_fn)dlsym(RTLD_NEXT, "pthread_create");
    atomic_store(&f, r);
  }
  return r;
}
#define REAL_PTHREAD_CREATE real_pthread_create()
#define THREAD_COUNTS()     true
#endif
#define MARK_STARTED() (t_started = true)

int pthread_create(pthread_t *th, const pthread_attr_t *attr, void *(*fn)(void *), void *arg) {
  trampoline *t = REAL_MALLOC(sizeof *t);
  if (!t) return EAGAIN;
  t->fn = fn, t->arg = arg;
  Dl_info di;
  t->excluded = dladdr(__builtin_return_address(0), &di) && di.dli_fname && strstr(di.dli_fname, "libtbb");
  int rc = REAL_PTHREAD_CREATE(th, attr, thread_start, t);
  if (rc) free(t);
  return rc;
}

/* True when this allocation is to fail. */
static bool should_fail(void) {
  if (!atomic_load_explicit(&g_armed, memory_order_relaxed) || t_excluded || !THREAD_COUNTS()) return false;
  int side = atomic_load_explicit(&g_side, memory_order_relaxed);
  if (side && (side == 1) != t_armer) return false;
  long n = atomic_fetch_add(&g_count, 1) + 1;
  if (g_jitter_us > 0) {
    uint64_t h = (uint64_t)n * 0x9e3779b97f4a7c15ull;
    h ^= h >> 29;
    if ((h & 3) == 0) {
      long us = (long)((h >> 8) % (uint64_t)(g_jitter_us + 1));
      struct timespec ts = {us / 1000000, (us % 1000000) * 1000};
      nanosleep(&ts, NULL);
    }
  }
  if (n != atomic_load(&g_target)) return false;
  /* Not inside a oneTBB task (libtbb on the stack: Embree's parallel
   * build running on the thread that called it; see the threads above),
   * nor, with failmalloc_skip_embree, anywhere in Embree: the next
   * allocation fails instead. */
  void *b[64];
  int k = backtrace(b, 64);
  bool embree = atomic_load(&g_skip_embree);
  for (int q = 0; q < k; q++) {
    Dl_info di;
    if (dladdr(b[q], &di) && di.dli_fname &&
        (strstr(di.dli_fname, "libtbb") || (embree && strstr(di.dli_fname, "libembree")))) {
      atomic_fetch_add(&g_target, 1);
      return false;
    }
  }
  atomic_store(&g_fail_bt_n, backtrace(g_fail_bt, 48));
  atomic_store(&g_fail_on_armer, t_armer);
  atomic_fetch_add(&g_failed, 1);
  return true;
}

FM_EXPORT void failmalloc_arm(long n) {
  MARK_STARTED();
  atomic_store(&g_armed, false);
  /* backtrace() loads libgcc's unwinder (an allocation, a lock) at its
   * first call: made here, unarmed, not inside an allocation made to fail. */
  static atomic_bool warm;
  if (!atomic_exchange(&warm, true)) {
    void *b[4];
    backtrace(b, 4);
  }
  t_armer = true;
  atomic_store(&g_fail_bt_n, 0);
  atomic_store(&g_count, 0);
  atomic_store(&g_failed, 0);
  atomic_store(&g_target, n);
  atomic_store(&g_armed, true);
}

/* Stops counting; returns the allocations counted since arming. */
FM_EXPORT long failmalloc_disarm(void) {
  atomic_store(&g_armed, false);
  return atomic_load(&g_count);
}

/* Failures injected since the last arm (0 or 1). */
FM_EXPORT long failmalloc_failed(void) {
  return atomic_load(&g_failed);
}

FM_EXPORT void failmalloc_print_failure(int fd) {
  int n = atomic_load(&g_fail_bt_n);
  if (n <= 0) return;
  dprintf(fd, "  the allocation made to fail, on %s:\n",
          atomic_load(&g_fail_on_armer) ? "the thread that armed failmalloc" : "another thread");
  backtrace_symbols_fd(g_fail_bt, n, fd);
}

FM_EXPORT int failmalloc_failure_stack(void **out, int max) {
  int n = atomic_load(&g_fail_bt_n);
  if (n > max) n = max;
  for (int i = 0; i < n; i++) out[i] = g_fail_bt[i];
  return n;
}

FM_EXPORT void failmalloc_side(int side) {
  atomic_store(&g_side, side);
}

FM_EXPORT void failmalloc_exclude_thread(bool excluded) {
  t_excluded = excluded;
}

/* Embree 3.13 does not survive an allocation failing inside a commit of a
 * scene it has built before (rtcCommitScene after a transform update, and
 * the commit that restores the old state): the process heap is corrupted
 * afterwards ("corrupted double-linked list" in a later malloc, 3 runs of 4
 * of the daemon's PATCH sweep; none of 4 with this on), with nothing of
 * ours freed or written in between. Like the TBB worker exclusion above, a
 * limitation no caller can handle; an operation that would only measure it
 * turns this on. */
FM_EXPORT void failmalloc_skip_embree(bool on) {
  atomic_store(&g_skip_embree, on);
}

void *malloc(size_t n) {
  if (should_fail()) {
    errno = ENOMEM;
    return NULL;
  }
  return REAL_MALLOC(n);
}

void *calloc(size_t n, size_t m) {
  if (should_fail()) {
    errno = ENOMEM;
    return NULL;
  }
  return REAL_CALLOC(n, m);
}

void *realloc(void *p, size_t n) {
  /* realloc(p, 0) frees: not an allocation that can fail. */
  if ((n || !p) && should_fail()) {
    errno = ENOMEM;
    return NULL;
  }
  return REAL_REALLOC(p, n);
}

void *reallocarray(void *p, size_t n, size_t m) {
  size_t b;
  if (__builtin_mul_overflow(n, m, &b)) {
    errno = ENOMEM;
    return NULL;
  }
  return realloc(p, b);
}

char *strdup(const char *s) {
  size_t n = strlen(s) + 1;
  char *d = malloc(n);
  if (d) memcpy(d, s, n);
  return d;
}

char *strndup(const char *s, size_t max) {
  size_t n = strnlen(s, max);
  char *d = malloc(n + 1);
  if (d) {
    memcpy(d, s, n);
    d[n] = '\0';
  }
  return d;
}

void *memalign(size_t align, size_t n) {
  if (should_fail()) {
    errno = ENOMEM;
    return NULL;
  }
  return REAL_MEMALIGN(align, n);
}

int posix_memalign(void **out, size_t align, size_t n) {
  if (align < sizeof(void *) || (align & (align - 1))) return EINVAL;
  if (should_fail()) return ENOMEM;
  void *p = REAL_MEMALIGN(align, n);
  if (!p) return ENOMEM;
  *out = p;
  return 0;
}

void *aligned_alloc(size_t align, size_t n) {
  return memalign(align, n);
}

/* ---- daemons: armed and disarmed by signals ---------------------------------- */

static long g_env_n;
static const char *g_report;

static void on_arm_signal(int sig) {
  (void)sig;
  failmalloc_arm(g_env_n);
}

/* Only async-signal-safe calls: the counts as decimal text, one write(). */
static void on_disarm_signal(int sig) {
  (void)sig;
  long v[2] = {failmalloc_disarm(), failmalloc_failed()};
  char buf[64];
  size_t len = 0;
  for (int k = 0; k < 2; k++) {
    char d[24];
    int nd = 0;
    unsigned long u = v[k] < 0 ? 0 : (unsigned long)v[k];
    do d[nd++] = (char)('0' + u % 10), u /= 10;
    while (u);
    while (nd) buf[len++] = d[--nd];
    buf[len++] = k ? '\n' : ' ';
  }
  if (!g_report) return;
  int fd = open(g_report, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) return;
  ssize_t w = write(fd, buf, len);
  (void)w;
  close(fd);
}

/* FAILMALLOC_AT_START: armed from main() on (a command that runs and
 * exits, e.g. raysweepd render); "<allocations> <failed>" is written to
 * FAILMALLOC_REPORT at exit. */
static void report_at_exit(void) {
  on_disarm_signal(0);
}

__attribute__((constructor)) static void failmalloc_init(void) {
  const char *j = getenv("FAILMALLOC_JITTER_US");
  if (j) g_jitter_us = atol(j);
  const char *e = getenv("FAILMALLOC_N");
  if (!e) return;
  g_env_n = atol(e);
  g_report = getenv("FAILMALLOC_REPORT");
  /* FAILMALLOC_SKIP_EMBREE=1: as failmalloc_skip_embree(true). */
  if (getenv("FAILMALLOC_SKIP_EMBREE")) atomic_store(&g_skip_embree, true);
  if (getenv("FAILMALLOC_AT_START")) {
    /* This constructor is the executable's: every library's ran before. */
    atexit(report_at_exit);
    failmalloc_arm(g_env_n);
    return;
  }
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  sa.sa_handler = on_arm_signal;
  sigaction(SIGUSR1, &sa, NULL);
  sa.sa_handler = on_disarm_signal;
  sigaction(SIGUSR2, &sa, NULL);
}
