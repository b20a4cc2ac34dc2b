/*
 * test_core_tri4.c — kd_tri4_intersect (core/kd_tri_multi.h) against
 * kd_tri_intersect (core/kd_tri.h), lane by lane, bit for bit: hit mask, t,
 * u = V / det and v = W / det. Triangles are random, share vertices and
 * edges with the ray's target (so edge functions are exactly 0 and the
 * double fallback runs), repeat across lanes, and rays have every dominant
 * axis and sign.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_tri_multi.h"

#define ROUNDS 200000

static uint64_t rng = 0x9e3779b97f4a7c15ull;
static float rnd(void) { /* in [-1, 1) */
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (float)((rng >> 40) & 0xffffff) * 0x1p-23f - 1.0f;
}

/* Vertex coordinates on a coarse grid half the time, so that rays through
 * grid points hit vertices and edges exactly. */
static float coord(void) {
    const float x = rnd();
    return (rng & 1) ? (float)(int)(x * 4.0f) * 0.25f : x;
}

static int same(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

static int check_round(void) {
    float tris[4][9], org[3], dir[3];
    for (int j = 0; j < 4; j++)
        for (int k = 0; k < 9; k++)
            tris[j][k] = coord();
    if (rng & 2) /* a lane repeats another */
        memcpy(tris[3], tris[(rng >> 2) & 3], sizeof tris[3]);
    for (int k = 0; k < 3; k++) {
        org[k] = 2.0f * coord();
        dir[k] = (rng & 4) ? coord() - org[k] : rnd(); /* maybe at a grid point */
    }
    if (dir[0] == 0.0f && dir[1] == 0.0f && dir[2] == 0.0f)
        return 0;
    kd_ray_pre pre;
    kd_ray_pre4 pre4;
    kd_ray_precompute(org, dir, &pre);
    kd_ray_pre4_init(&pre, &pre4);
    const float tmin = (rng & 8) ? 0.0f : 0.25f, tmax = (rng & 16) ? 1e30f : 1.0f;
    const float *rows[4] = {tris[0], tris[1], tris[2], tris[3]};
    f4 t4, V4, W4, d4;
    const int m = kd_tri4_intersect(&pre4, rows, f4_set1(tmin), f4_set1(tmax),
                                    &t4, &V4, &W4, &d4);
    _Alignas(16) float t[4], V[4], W[4], d[4];
    f4_store(t, t4), f4_store(V, V4), f4_store(W, W4), f4_store(d, d4);
    int bad = 0;
    for (int j = 0; j < 4; j++) {
        float st, su, sv;
        const int hit = kd_tri_intersect(&pre, tris[j], tmin, tmax, &st, &su, &sv);
        if (hit != ((m >> j) & 1))
            bad = 1;
        else if (hit && (!same(st, t[j]) || !same(su, V[j] / d[j]) ||
                         !same(sv, W[j] / d[j])))
            bad = 1;
    }
    return bad;
}

int main(void) {
    int fails = 0;
    for (int i = 0; i < ROUNDS; i++)
        fails += check_round();
    printf("test_core_tri4: %d of %d rounds differ\n", fails, ROUNDS);
    return fails != 0;
}
