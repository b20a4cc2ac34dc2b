/*
 * test_core_tri4.c — kd_ntri_test4 and kd_ntri_test8 (AVX2, when
 * the CPU has it) of core/kd_tri_ntri.h against kd_tri_intersect
 * (core/kd_tri.h), lane by lane, bit for bit: hit mask, t,
 * u = V / det and v = W / det. Triangles are random, share vertices and
 * edges with the ray's target (so edge functions are exactly 0 and the
 * double fallback runs), repeat across lanes, and rays have every dominant
 * axis and sign.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_tri_ntri.h"

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

/* Lane j of the wide test against the scalar test of tris[j]. */
static int lane_bad(const kd_ray_pre *pre, const float *tri, float tmin,
                    float tmax, int hit_lane, float t, float V, float W,
                    float d) {
    float st, su, sv;
    const int hit = kd_tri_intersect(pre, tri, tmin, tmax, &st, &su, &sv);
    if (hit != hit_lane)
        return 1;
    return hit && (!same(st, t) || !same(su, V / d) || !same(sv, W / d));
}

KD_AVX2 static int check8(const kd_ray_pre *pre, float tris[8][9], float tmin,
                          float tmax) {
    kd_ntri_pre8 pre8;
    kd_ntri_pre_init8(pre, &pre8);
    const float *rows[8];
    for (int j = 0; j < 8; j++)
        rows[j] = tris[j];
    f8 t8, V8, W8, d8;
    const int m = kd_ntri_test8(&pre8, rows, f8_set1(tmin), f8_set1(tmax),
                                    &t8, &V8, &W8, &d8);
    _Alignas(32) float t[8], V[8], W[8], d[8];
    f8_store(t, t8), f8_store(V, V8), f8_store(W, W8), f8_store(d, d8);
    int bad = 0;
    for (int j = 0; j < 8; j++)
        bad |= lane_bad(pre, tris[j], tmin, tmax, (m >> j) & 1, t[j], V[j], W[j],
                        d[j]);
    return bad;
}

static int check_round(int avx2) {
    float tris[8][9], org[3], dir[3];
    for (int j = 0; j < 8; j++)
        for (int k = 0; k < 9; k++)
            tris[j][k] = coord();
    if (rng & 2) /* lanes repeat others */
        for (int j = 3; j < 8; j += 4)
            memcpy(tris[j], tris[(rng >> 2) & 3], sizeof tris[j]);
    for (int k = 0; k < 3; k++) {
        org[k] = 2.0f * coord();
        dir[k] = (rng & 4) ? coord() - org[k] : rnd(); /* maybe at a grid point */
    }
    if (dir[0] == 0.0f && dir[1] == 0.0f && dir[2] == 0.0f)
        return 0;
    kd_ray_pre pre;
    kd_ntri_pre4 pre4;
    kd_ray_precompute(org, dir, &pre);
    kd_ntri_pre_init4(&pre, &pre4);
    const float tmin = (rng & 8) ? 0.0f : 0.25f, tmax = (rng & 16) ? 1e30f : 1.0f;
    const float *rows[4] = {tris[0], tris[1], tris[2], tris[3]};
    f4 t4, V4, W4, d4;
    const int m = kd_ntri_test4(&pre4, rows, f4_set1(tmin), f4_set1(tmax),
                                    &t4, &V4, &W4, &d4);
    _Alignas(16) float t[4], V[4], W[4], d[4];
    f4_store(t, t4), f4_store(V, V4), f4_store(W, W4), f4_store(d, d4);
    int bad = 0;
    for (int j = 0; j < 4; j++)
        bad |= lane_bad(&pre, tris[j], tmin, tmax, (m >> j) & 1, t[j], V[j], W[j],
                        d[j]);
    if (avx2)
        bad |= check8(&pre, tris, tmin, tmax) << 1;
    return bad;
}

int main(void) {
    const int avx2 = __builtin_cpu_supports("avx2") ? 1 : 0;
    int fails4 = 0, fails8 = 0;
    for (int i = 0; i < ROUNDS; i++) {
        const int bad = check_round(avx2);
        fails4 += bad & 1;
        fails8 += bad >> 1;
    }
    printf("test_core_tri4: %d (4 lanes) and %d (8 lanes%s) of %d rounds differ\n",
           fails4, fails8, avx2 ? "" : ", no AVX2: skipped", ROUNDS);
    return fails4 + fails8 != 0;
}
