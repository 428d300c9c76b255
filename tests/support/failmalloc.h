/* failmalloc (failmalloc.c): fail the nth heap allocation of the process.
 * Only in binaries that link tests/support/failmalloc.c (test_oom,
 * raysweepd-failmalloc); see that file for how it hooks in. */
#ifndef RSW_TEST_FAILMALLOC_H
#define RSW_TEST_FAILMALLOC_H
#include <stdbool.h>

/* Count allocations from now on (every thread but excluded ones) and fail
 * the nth (1-based) with NULL/ENOMEM; n = 0: count only. */
void failmalloc_arm(long n);
/* Stop counting; returns the allocations counted since failmalloc_arm. */
long failmalloc_disarm(void);
/* Failures injected since failmalloc_arm (0 or 1). */
long failmalloc_failed(void);
/* The stack of the allocation that the last arm made to fail (nothing if
 * none), to fd (addresses in the executable as +offsets: addr2line -e BIN). */
void failmalloc_print_failure(int fd);
/* The same stack's return addresses into out[0..max); returns how many. */
int failmalloc_failure_stack(void **out, int max);
/* Which threads count (and so may fail): 0 all (the default), 1 only
 * the thread that arms, 2 all but that one. */
void failmalloc_side(int side);
/* Exclude (or include again) the calling thread's allocations. */
void failmalloc_exclude_thread(bool excluded);
/* While on, a target allocation made with Embree's code on the stack
 * succeeds and the next one fails instead (failmalloc.c says why). */
void failmalloc_skip_embree(bool on);
#endif
