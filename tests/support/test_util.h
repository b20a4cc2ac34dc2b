/*
 * test_util.h — the two helpers nearly every protocol test and benchmark
 * program wrote again for itself: an allocation that cannot return NULL
 * (a test that runs out of memory stops with exit status 2, which ctest
 * reports as a failure, rather than crashing on a NULL) and the xorshift64
 * step behind each program's seeded generator (and the CBOR head writer
 * of the hand-built CBOR bodies). Each program keeps its own
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

/* The head of a CBOR data item (RFC 8949, 3): major type `major` with
 * argument v in the shortest form, written to h; returns its length (1, 2,
 * 3, 5 or 9). The bodies of test_exec and bench_e2e are written by hand
 * with it (the protocol tests use libcbor's encoders, cbor_body.h). */
static inline size_t cbor_head(unsigned char h[9], unsigned major, uint64_t v) {
    if (v < 24) {
        h[0] = (unsigned char)(major << 5 | v);
        return 1;
    }
    const int bytes = v < 256 ? 1 : v < 65536 ? 2 : v < (1ull << 32) ? 4 : 8;
    h[0] = (unsigned char)(major << 5 | (bytes == 1   ? 24
                                         : bytes == 2 ? 25
                                         : bytes == 4 ? 26
                                                      : 27));
    for (int k = 0; k < bytes; k++)
        h[1 + k] = (unsigned char)(v >> (8 * (bytes - 1 - k)));
    return 1 + (size_t)bytes;
}

#endif
