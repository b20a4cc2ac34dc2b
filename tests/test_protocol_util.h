/*
 * test_protocol_util.h — what test_protocol.c (requests) and
 * test_protocol_encode.c (codecs and answers) share: the seeded generator,
 * bit-exact float comparison and base64 of a raw buffer. Header-only
 * (static inline) so each program stays one translation unit with its own
 * check.h counter.
 */
#ifndef TEST_PROTOCOL_UTIL_H
#define TEST_PROTOCOL_UTIL_H

#include <stdint.h>
#include <string.h>

#include "check.h"
#include "kdr_protocol.h"
#include "test_util.h"

static uint64_t rng_state = 0x243f6a8885a308d3ull;
static inline uint64_t rng(void) { return xorshift64(&rng_state); }

static inline int same_bits(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

/* kdr_base64_encode of p[0..n), NUL-terminated, malloc'd. */
static inline char *b64_of(const void *p, size_t n) {
    char *s = xmalloc(kdr_base64_encoded_len(n) + 1);
    s[kdr_base64_encode(p, n, s)] = '\0';
    return s;
}

#endif
