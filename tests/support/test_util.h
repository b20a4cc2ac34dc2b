/*
 * test_util.h — the two helpers nearly every protocol test and benchmark
 * program wrote again for itself: an allocation that cannot return NULL
 * (a test that runs out of memory stops with exit status 2, which ctest
 * reports as a failure, rather than crashing on a NULL) and the xorshift64
 * step behind each program's seeded generator. Each program keeps its own
 * state and seed, so its inputs are the same as before the helpers moved
 * here. Header-only (static inline): one copy per test program.
 */
#ifndef KDRAY_TESTS_TEST_UTIL_H
#define KDRAY_TESTS_TEST_UTIL_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

/* malloc that exits (status 2) instead of returning NULL; n 0 is 1 byte. */
static inline void *xmalloc(size_t n) {
    void *p = malloc(n ? n : 1);
    if (!p) {
        fprintf(stderr, "out of memory (%zu bytes)\n", n);
        exit(2);
    }
    return p;
}

/* Marsaglia's xorshift64 (13, 7, 17): advances *state, returns it. */
static inline uint64_t xorshift64(uint64_t *state) {
    uint64_t x = *state;
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    return *state = x;
}

#endif
