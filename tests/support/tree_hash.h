/*
 * tree_hash.h — what kdray-tree-digest (tests/tree_digest.c) and
 * bench/ab_build.c share: a clock in milliseconds and the FNV-1a digests
 * of a built tree's node and reference arrays, the two arrays that must
 * be byte-identical across thread counts and across build changes that
 * claim to leave the tree alone. Header-only (bench/ab_build compiles
 * ab_build.c by itself, with -I tests/support). Needs kd_internal.h.
 */
#ifndef KDRAY_TESTS_TREE_HASH_H
#define KDRAY_TESTS_TREE_HASH_H

#include <stddef.h>
#include <stdint.h>
#include <time.h>

#include "kd_internal.h"

static inline double th_clock_ms(clockid_t id) {
    struct timespec ts;
    clock_gettime(id, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static inline uint64_t th_fnv1a(const void *p, size_t n) {
    const unsigned char *b = p;
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < n; i++) {
        h ^= b[i];
        h *= 1099511628211ull;
    }
    return h;
}

/* dig[0]: the nodes' digest, dig[1]: the references'. */
static inline void th_tree_digest(const kdr_scene *s, uint64_t dig[2]) {
    dig[0] = th_fnv1a(s->nodes, s->nnodes * sizeof *s->nodes);
    dig[1] = th_fnv1a(s->refs, s->nrefs * sizeof *s->refs);
}

#endif /* KDRAY_TESTS_TREE_HASH_H */
