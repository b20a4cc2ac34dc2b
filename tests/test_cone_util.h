/*
 * test_cone_util.h — what the cone-shadow test programs share: small scenes
 * built from triangles (rectangles, random soups), the query with the
 * contract's defaults, a deterministic generator, and check_modes, which
 * holds KDR_SHADOW_CONE, KDR_SHADOW_RAYS and the cone walk forced on and
 * off to brute force sample by sample.
 *
 * The brute-force reference tests every triangle with core/kd_tri.h, so a
 * cone traversal that skips a leaf some sample enters shows up as a count
 * mismatch; the scenes are many small triangles so that most blocked
 * samples are blocked by one triangle only. Header-only (static inline) so
 * each test_cone*.c stays one translation unit with its own counter.
 */
#ifndef TEST_CONE_UTIL_H
#define TEST_CONE_UTIL_H

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "compare.h"
#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_tri.h"
#include "kdray.h"

/* ---- scenes ---------------------------------------------------------------- */

typedef struct tri_buf {
    float *v;
    size_t n, cap;
} tri_buf;

static inline void tb_add(tri_buf *b, const float t[9]) {
    if (b->n == b->cap) {
        b->cap = b->cap ? 2 * b->cap : 64;
        b->v = realloc(b->v, b->cap * 9 * sizeof(float));
        if (!b->v)
            abort();
    }
    memcpy(b->v + 9 * b->n++, t, 9 * sizeof(float));
}

/* Axis-aligned rectangle in the plane x_axis = c over [a0,a1] x [b0,b1]. */
static inline void tb_rect(tri_buf *b, int axis, float c, float a0, float a1, float b0,
                    float b1) {
    const int i = (axis + 1) % 3, j = (axis + 2) % 3;
    float p[4][3];
    const float ua[4] = {a0, a1, a1, a0}, ub[4] = {b0, b0, b1, b1};
    for (int q = 0; q < 4; q++) {
        p[q][axis] = c;
        p[q][i] = ua[q];
        p[q][j] = ub[q];
    }
    const float t0[9] = {p[0][0], p[0][1], p[0][2], p[1][0], p[1][1],
                         p[1][2], p[2][0], p[2][1], p[2][2]};
    const float t1[9] = {p[0][0], p[0][1], p[0][2], p[2][0], p[2][1],
                         p[2][2], p[3][0], p[3][1], p[3][2]};
    tb_add(b, t0);
    tb_add(b, t1);
}

static uint64_t rng_state;
static inline double rnd(void) {
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(rng_state >> 11) * 0x1p-53;
}

/* n small random triangles (edge ~size) inside [0, extent]^3. */
static inline void tb_soup(tri_buf *b, size_t n, float extent, float size) {
    for (size_t t = 0; t < n; t++) {
        float c[3], tri[9];
        for (int k = 0; k < 3; k++)
            c[k] = (float)(rnd() * extent);
        for (int j = 0; j < 9; j++)
            tri[j] = c[j % 3] + (float)((rnd() - 0.5) * size);
        tb_add(b, tri);
    }
}

static inline kdr_scene *build(const tri_buf *b) {
    kdr_build_opts o;
    kdr_scene *s = NULL;
    kdr_build_opts_default(&o);
    if (kdr_scene_build(b->v, b->n, &o, NULL, NULL, &s) != KDR_OK || !s) {
        fprintf(stderr, "scene build failed\n");
        exit(1);
    }
    return s;
}

static inline kdr_shadow_query make_query(const float *pts, size_t n,
                                   const kdr_sphere_light *lights, size_t nl,
                                   uint32_t samples) {
    kdr_shadow_query q = {0};
    q.n = n;
    q.points = pts;
    q.lights = lights;
    q.nlights = nl;
    q.samples = samples;
    q.seed = 7;
    q.offset = KDR_OFFSET_AUTO; /* the contract's default (API v1.1) */
    return q;
}

/* ---- the checks ------------------------------------------------------------ */

/* Lit-sample counts of (point, light) pairs by brute force over all
 * triangles with the core's triangle test. */
static inline uint32_t brute_lit(const kdr_scene *s, const tri_buf *b,
                          const kdr_shadow_query *q, size_t i, size_t l) {
    uint32_t lit = 0;
    (void)s;
    for (uint32_t k = 0; k < q->samples; k++) {
        kdr_ray r;
        if (kdr_shadow_ray(s, q, i, l, k, &r) != KDR_OK)
            return UINT32_MAX;
        lit += ref_occluded1(b->v, b->n, &r) ? 0u : 1u;
    }
    return lit;
}

/* Both modes against brute force, pair by pair; returns cones decided. */
static inline uint64_t check_modes(const char *label, const kdr_scene *s,
                            const tri_buf *b, const kdr_shadow_query *q) {
    const size_t m = q->n * q->nlights;
    float *vc = malloc(m * sizeof *vc), *vr = malloc(m * sizeof *vr);
    kdr_shadow_stats sc = {0}, sr = {0};
    CHECK(kdr_shadow_trace(s, q, 0, q->n, KDR_SHADOW_CONE, vc, &sc) == KDR_OK,
          "%s cone", label);
    CHECK(kdr_shadow_trace(s, q, 0, q->n, KDR_SHADOW_RAYS, vr, &sr) == KDR_OK,
          "%s rays", label);
    /* the walk forced on, off and shared by groups: the same answers, bit
     * for bit */
    const kd_walk_policy forced[3] = {KD_WALK_ALWAYS, KD_WALK_NEVER, KD_WALK_GROUPS};
    static const char *const forced_name[3] = {"on", "off", "grouped"};
    for (int k = 0; k < 3; k++) {
        float *vf = malloc(m * sizeof *vf);
        kdr_shadow_stats sf = {0};
        CHECK(kd_shadow_trace_policy(s, q, 0, q->n, KDR_SHADOW_CONE, forced[k], vf,
                                     &sf) == KDR_OK,
              "%s policy %d", label, (int)forced[k]);
        CHECK(memcmp(vf, vr, m * sizeof *vf) == 0, "%s: walk %s differs from rays",
              label, forced_name[k]);
        if (k == 1)
            CHECK(sf.cones_decided == 0 && sf.rays_traced == (uint64_t)m * q->samples,
                  "%s walk off traces every sample", label);
        free(vf);
    }
    int bad = 0;
    for (size_t i = 0; i < q->n && bad < 5; i++) {
        for (size_t l = 0; l < q->nlights; l++) {
            const uint32_t lit = brute_lit(s, b, q, i, l);
            const float want = (float)lit / (float)q->samples;
            const float c = vc[i * q->nlights + l], r = vr[i * q->nlights + l];
            if (c != want || r != want) {
                bad++;
                CHECK(0, "%s point %zu light %zu: cone %.6f rays %.6f brute %.6f",
                      label, i, l, c, r, want);
            }
        }
    }
    CHECK(sr.cones_decided == 0 && sr.rays_traced == (uint64_t)m * q->samples,
          "%s rays-mode stats", label);
    printf("%-28s pairs %5zu decided %5llu rays cone %8llu rays %8llu\n", label,
           m, (unsigned long long)sc.cones_decided,
           (unsigned long long)sc.rays_traced, (unsigned long long)sr.rays_traced);
    free(vc);
    free(vr);
    return sc.cones_decided;
}

/* Split planes (axis, position) of interior nodes spread over the node
 * array: the root's big planes and deep ones between small cells. */
static inline size_t tree_splits(const kdr_scene *s, int *axis, float *pos, size_t max) {
    size_t n = 0;
    const size_t step = s->nnodes / (2 * max) + 1;
    for (size_t j = 0; j < s->nnodes && n < max; j += step) {
        while (j < s->nnodes && kd_is_leaf(&s->nodes[j]))
            j++;
        if (j < s->nnodes) {
            axis[n] = kd_axis(&s->nodes[j]);
            pos[n++] = s->nodes[j].u.split;
        }
    }
    return n;
}

/* Any orthonormal basis (b1, b2) of the plane normal to the unit vector a. */
static inline void unit_basis(const double a[3], double b1[3], double b2[3]) {
    const double t[3] = {fabs(a[0]) < 0.6 ? 1.0 : 0.0, fabs(a[0]) < 0.6 ? 0.0 : 1.0, 0.0};
    b1[0] = a[1] * t[2] - a[2] * t[1];
    b1[1] = a[2] * t[0] - a[0] * t[2];
    b1[2] = a[0] * t[1] - a[1] * t[0];
    const double l = sqrt(b1[0] * b1[0] + b1[1] * b1[1] + b1[2] * b1[2]);
    for (int k = 0; k < 3; k++)
        b1[k] /= l;
    b2[0] = a[1] * b1[2] - a[2] * b1[1];
    b2[1] = a[2] * b1[0] - a[0] * b1[2];
    b2[2] = a[0] * b1[1] - a[1] * b1[0];
}

#endif
