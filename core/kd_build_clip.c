/*
 * kd_build_clip.c — "perfect splits" for the SAH build (kd_build.h): a
 * triangle that straddles a split plane is clipped to the node's box and
 * then to either side of the plane, and its events in each child are the
 * bounds of what is left there. Clipping runs in double and rounds the
 * bounds of computed points outward, so a triangle is never left out of a
 * box it touches; when double clipping loses a sliver, the triangle's own
 * bounds cut to the box stand in (still conservative).
 */
#include <float.h>
#include <math.h>
#include <string.h>

#include "kd_build.h"
#include "simd.h"

#define KD_CLIP_AHEAD 8 /* straddlers prefetched ahead of the one clipped */

typedef struct cvert {
    double p[3];
    unsigned exact; /* bit k: p[k] is exactly a float of the input */
} cvert;

/* The point where edge a-b crosses the plane p[k] = c at t (clip_plane's
 * arithmetic). */
static inline void cross_point(const cvert *a, const cvert *b, double t, int k,
                               float c, cvert *v) {
    v->exact = 1u << k;
    for (int j = 0; j < 3; j++) {
        v->p[j] = a->p[j] + t * (b->p[j] - a->p[j]);
        if (j != k && a->p[j] == b->p[j])
            v->exact |= a->exact & b->exact & (1u << j);
    }
    v->p[k] = c;
}

/* Sutherland-Hodgman step: keeps the part where sign * (p[k] - c) >= 0. */
static int clip_plane(const cvert *in, int n, cvert *out, int k, float c,
                      double sign) {
    int m = 0;
    for (int i = 0; i < n; i++) {
        const cvert *a = &in[i], *b = &in[i + 1 < n ? i + 1 : 0];
        double da = sign * (a->p[k] - c), db = sign * (b->p[k] - c);
        if (da >= 0.0)
            out[m++] = *a;
        if ((da > 0.0 && db < 0.0) || (da < 0.0 && db > 0.0))
            cross_point(a, b, da / (da - db), k, c, &out[m++]);
    }
    return m;
}

/* The next float toward -infinity (finite input). */
static inline float step_down(float f) {
    uint32_t u;
    if (f == 0.0f)
        return -FLT_TRUE_MIN;
    memcpy(&u, &f, sizeof u);
    u = f > 0.0f ? u - 1 : u + 1;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* Clips tri to box (only against the planes its bounds cross) into out[];
 * returns the vertex count, 0 when nothing is left. */
static int clip_to_box(const float *tri, const kdr_bounds *box, cvert out[16]) {
    cvert tmp[16];
    cvert *buf[2] = {out, tmp};
    int n = 3, cur = 0;
    for (int i = 0; i < 3; i++) {
        for (int k = 0; k < 3; k++)
            out[i].p[k] = tri[3 * i + k];
        out[i].exact = 7u;
    }
    for (int k = 0; k < 3 && n > 0; k++) {
        if (min3(tri[k], tri[3 + k], tri[6 + k]) < box->min[k]) {
            n = clip_plane(buf[cur], n, buf[cur ^ 1], k, box->min[k], 1.0);
            cur ^= 1;
        }
        if (n > 0 && max3(tri[k], tri[3 + k], tri[6 + k]) > box->max[k]) {
            n = clip_plane(buf[cur], n, buf[cur ^ 1], k, box->max[k], -1.0);
            cur ^= 1;
        }
    }
    if (cur)
        memcpy(out, tmp, (size_t)n * sizeof *out);
    return n;
}

/* Fallback when double clipping loses a sliver: the triangle's bounds cut
 * to the box (still conservative). */
static int tri_bounds_in_box(const float *tri, const kdr_bounds *box,
                             kdr_bounds *out) {
    for (int k = 0; k < 3; k++) {
        float lo = min3(tri[k], tri[3 + k], tri[6 + k]);
        float hi = max3(tri[k], tri[3 + k], tri[6 + k]);
        out->min[k] = lo > box->min[k] ? lo : box->min[k];
        out->max[k] = hi < box->max[k] ? hi : box->max[k];
        if (out->min[k] > out->max[k])
            return 0;
    }
    return 1;
}

/* The float bounds a clipped vertex adds: a computed coordinate rounded
 * one float outward, an input one as it is. */
static inline void vert_bounds(const cvert *v, float lo[3], float hi[3]) {
    for (int j = 0; j < 3; j++) {
        const float f = (float)v->p[j];
        const int ex = (v->exact >> j) & 1u;
        lo[j] = ex ? f : step_down(f);
        hi[j] = ex ? f : -step_down(-f);
    }
}

/* The plane p[k] = c splits the polygon in[0..n): the bounds of the part
 * with p[k] <= c go to lo[0], hi[0], of the part with p[k] >= c to lo[1],
 * hi[1] (INFINITY / -INFINITY where a part is empty). The same vertices
 * and crossing points (the same arithmetic, edge a-b in polygon order) as
 * clipping to each side (Sutherland-Hodgman) and bounding the two polygons,
 * without writing them: their bounds are a min and max over their
 * vertices, in any order. With the sign flipped, da, db and da - db only
 * change sign (IEEE negation and subtraction are exact under it), so t and
 * a crossing point are the same bits for either side. */
static void clip_bounds_both(const cvert *in, int n, int k, float c, float lo[2][3],
                             float hi[2][3]) {
    for (int s = 0; s < 2; s++)
        for (int j = 0; j < 3; j++) {
            lo[s][j] = INFINITY;
            hi[s][j] = -INFINITY;
        }
    for (int i = 0; i < n; i++) {
        const cvert *a = &in[i], *b = &in[i + 1 < n ? i + 1 : 0];
        const double da = a->p[k] - c, db = b->p[k] - c;
        float vlo[3], vhi[3];
        vert_bounds(a, vlo, vhi);
        const int in0 = da <= 0.0, in1 = da >= 0.0;
        for (int j = 0; j < 3; j++) {
            const float l0 = in0 ? vlo[j] : INFINITY, h0 = in0 ? vhi[j] : -INFINITY;
            const float l1 = in1 ? vlo[j] : INFINITY, h1 = in1 ? vhi[j] : -INFINITY;
            lo[0][j] = l0 < lo[0][j] ? l0 : lo[0][j];
            hi[0][j] = h0 > hi[0][j] ? h0 : hi[0][j];
            lo[1][j] = l1 < lo[1][j] ? l1 : lo[1][j];
            hi[1][j] = h1 > hi[1][j] ? h1 : hi[1][j];
        }
        if ((da > 0.0 && db < 0.0) || (da < 0.0 && db > 0.0)) {
            cvert v;
            cross_point(a, b, da / (da - db), k, c, &v);
            vert_bounds(&v, vlo, vhi);
            for (int s = 0; s < 2; s++)
                for (int j = 0; j < 3; j++) {
                    lo[s][j] = vlo[j] < lo[s][j] ? vlo[j] : lo[s][j];
                    hi[s][j] = vhi[j] > hi[s][j] ? vhi[j] : hi[s][j];
                }
        }
    }
}

/* The sides a straddler goes to, from its halves' clipped bounds lo[side],
 * hi[side] (x, y, z): each half's bounds limited to its child's box cbox
 * into bb; a side that keeps a non-empty box, or whose box holds the
 * triangle's own bounds there (tri_bounds_in_box), is taken. Shared by the
 * scalar and the AVX-512 clipping; inlined in both (as a call it cost the
 * build 20-25 %: bench/ab_build, haus, clearcoat, 2CylinderEngine). */
static inline __attribute__((always_inline)) unsigned
halves_sides(const float *tri, const float *const lo[2], const float *const hi[2],
             const kdr_bounds cbox[2], kdr_bounds bb[2]) {
    unsigned sides = 0;
    for (int side = 0; side < 2; side++) {
        int ok = 1;
        for (int k = 0; k < 3; k++) {
            bb[side].min[k] = lo[side][k] > cbox[side].min[k] ? lo[side][k] : cbox[side].min[k];
            bb[side].max[k] = hi[side][k] < cbox[side].max[k] ? hi[side][k] : cbox[side].max[k];
            ok &= bb[side].min[k] <= bb[side].max[k];
        }
        if (ok || tri_bounds_in_box(tri, &cbox[side], &bb[side]))
            sides |= 1u << side;
    }
    return sides;
}

/* The bounds of the parts of tri inside cbox[0] and cbox[1], the halves of
 * box split at pos on axis; bit s of the result is set when side s keeps
 * something. The triangle is clipped to the node's box once, then that
 * polygon is split by the plane (clip_bounds_both). */
unsigned kd_clip_tri(const float *tri, const kdr_bounds *box, int axis, float pos,
                     const kdr_bounds cbox[2], kdr_bounds bb[2]) {
    cvert poly[16];
    float lo[2][3], hi[2][3];
    const int n = clip_to_box(tri, box, poly);
    clip_bounds_both(poly, n, axis, pos, lo, hi);
    const float *const l2[2] = {lo[0], lo[1]}, *const h2[2] = {hi[0], hi[1]};
    return halves_sides(tri, l2, h2, cbox, bb);
}

/* ---- the same clipping, a vertex per AVX vector (AVX-512 CPUs) ---------- */

/* kd_clip_tri's arithmetic with a vertex's three doubles in lanes 0-2 of
 * one vector (lane 3 zero) and its exact bits beside it: the crossing point
 * a + t * (b - a) is the same three IEEE operations per lane as
 * cross_point's (no FMA: -ffp-contract=off), coordinate k is set to c, and
 * a lane is exact when a's and b's are equal and both exact. The rounding
 * to float bounds is step_down's on 4 lanes. Same bounds bit for bit. */
typedef struct vpoly {
    __m256d p[16];
    unsigned ex[16];
} vpoly;

KD_AVX512 static int vclip_plane(const vpoly *in, int n, vpoly *out, int k, float c,
                                 double sign) {
    int m = 0;
    const __m256d cv = _mm256_set1_pd((double)c);
    for (int i = 0; i < n; i++) {
        const int j = i + 1 < n ? i + 1 : 0;
        const double *pa = (const double *)&in->p[i], *pb = (const double *)&in->p[j];
        const double da = sign * (pa[k] - c), db = sign * (pb[k] - c);
        if (da >= 0.0) {
            out->p[m] = in->p[i];
            out->ex[m++] = in->ex[i];
        }
        if ((da > 0.0 && db < 0.0) || (da < 0.0 && db > 0.0)) {
            const __m256d a = in->p[i], b = in->p[j];
            const __m256d t = _mm256_set1_pd(da / (da - db));
            const __m256d v = _mm256_add_pd(a, _mm256_mul_pd(t, _mm256_sub_pd(b, a)));
            const unsigned eq = _mm256_cmp_pd_mask(a, b, _CMP_EQ_OQ);
            out->p[m] = _mm256_mask_blend_pd((__mmask8)(1u << k), v, cv);
            out->ex[m++] = (1u << k) | (in->ex[i] & in->ex[j] & eq & 7u & ~(1u << k));
        }
    }
    return m;
}

/* Lower and upper float bounds of a vertex (lanes 0-2): exact lanes as they
 * are, others one float outward (step_down and -step_down(-f)). */
KD_AVX512 static inline void vvert_bounds(__m256d p, unsigned ex, __m128 *lo, __m128 *hi) {
    const __m128 f = _mm256_cvtpd_ps(p);
    const __m128i u = _mm_castps_si128(f), one = _mm_set1_epi32(1);
    const __mmask8 gt = _mm_cmp_ps_mask(f, _mm_setzero_ps(), _CMP_GT_OQ);
    const __mmask8 z = _mm_cmp_ps_mask(f, _mm_setzero_ps(), _CMP_EQ_OQ);
    const __m128i plus = _mm_add_epi32(u, one), minus = _mm_sub_epi32(u, one);
    __m128i down = _mm_mask_blend_epi32(gt, plus, minus);
    __m128i up = _mm_mask_blend_epi32(gt, minus, plus);
    down = _mm_mask_blend_epi32(z, down, _mm_set1_epi32((int)0x80000001u));
    up = _mm_mask_blend_epi32(z, up, one);
    *lo = _mm_castsi128_ps(_mm_mask_blend_epi32((__mmask8)ex, down, u));
    *hi = _mm_castsi128_ps(_mm_mask_blend_epi32((__mmask8)ex, up, u));
}

KD_AVX512 unsigned kd_clip_tri_avx512(const float *tri, const kdr_bounds *box, int axis,
                                     float pos, const kdr_bounds cbox[2], kdr_bounds bb[2]) {
    vpoly buf[2];
    int n = 3, cur = 0;
    for (int i = 0; i < 3; i++) {
        buf[0].p[i] = _mm256_set_pd(0.0, tri[3 * i + 2], tri[3 * i + 1], tri[3 * i]);
        buf[0].ex[i] = 7u;
    }
    for (int k = 0; k < 3 && n > 0; k++) {
        if (min3(tri[k], tri[3 + k], tri[6 + k]) < box->min[k]) {
            n = vclip_plane(&buf[cur], n, &buf[cur ^ 1], k, box->min[k], 1.0);
            cur ^= 1;
        }
        if (n > 0 && max3(tri[k], tri[3 + k], tri[6 + k]) > box->max[k]) {
            n = vclip_plane(&buf[cur], n, &buf[cur ^ 1], k, box->max[k], -1.0);
            cur ^= 1;
        }
    }
    const vpoly *in = &buf[cur];
    __m128 lo0 = _mm_set1_ps(INFINITY), hi0 = _mm_set1_ps(-INFINITY);
    __m128 lo1 = lo0, hi1 = hi0;
    for (int i = 0; i < n; i++) {
        const int j = i + 1 < n ? i + 1 : 0;
        const double *pa = (const double *)&in->p[i], *pb = (const double *)&in->p[j];
        const double da = pa[axis] - pos, db = pb[axis] - pos;
        __m128 vlo, vhi;
        vvert_bounds(in->p[i], in->ex[i], &vlo, &vhi);
        const __mmask8 m0 = da <= 0.0 ? 0xf : 0, m1 = da >= 0.0 ? 0xf : 0;
        lo0 = _mm_mask_blend_ps(m0 & _mm_cmp_ps_mask(vlo, lo0, _CMP_LT_OQ), lo0, vlo);
        hi0 = _mm_mask_blend_ps(m0 & _mm_cmp_ps_mask(vhi, hi0, _CMP_GT_OQ), hi0, vhi);
        lo1 = _mm_mask_blend_ps(m1 & _mm_cmp_ps_mask(vlo, lo1, _CMP_LT_OQ), lo1, vlo);
        hi1 = _mm_mask_blend_ps(m1 & _mm_cmp_ps_mask(vhi, hi1, _CMP_GT_OQ), hi1, vhi);
        if ((da > 0.0 && db < 0.0) || (da < 0.0 && db > 0.0)) {
            const __m256d a = in->p[i], b = in->p[j];
            const __m256d t = _mm256_set1_pd(da / (da - db));
            const __m256d v = _mm256_add_pd(a, _mm256_mul_pd(t, _mm256_sub_pd(b, a)));
            const unsigned eq = _mm256_cmp_pd_mask(a, b, _CMP_EQ_OQ);
            const __m256d vk =
                _mm256_mask_blend_pd((__mmask8)(1u << axis), v, _mm256_set1_pd((double)pos));
            const unsigned ex =
                (1u << axis) | (in->ex[i] & in->ex[j] & eq & 7u & ~(1u << axis));
            vvert_bounds(vk, ex, &vlo, &vhi);
            lo0 = _mm_mask_blend_ps(_mm_cmp_ps_mask(vlo, lo0, _CMP_LT_OQ), lo0, vlo);
            hi0 = _mm_mask_blend_ps(_mm_cmp_ps_mask(vhi, hi0, _CMP_GT_OQ), hi0, vhi);
            lo1 = _mm_mask_blend_ps(_mm_cmp_ps_mask(vlo, lo1, _CMP_LT_OQ), lo1, vlo);
            hi1 = _mm_mask_blend_ps(_mm_cmp_ps_mask(vhi, hi1, _CMP_GT_OQ), hi1, vhi);
        }
    }
    float lo[2][4], hi[2][4];
    _mm_storeu_ps(lo[0], lo0);
    _mm_storeu_ps(hi[0], hi0);
    _mm_storeu_ps(lo[1], lo1);
    _mm_storeu_ps(hi[1], hi1);
    const float *const l2[2] = {lo[0], lo[1]}, *const h2[2] = {hi[0], hi[1]};
    return halves_sides(tri, l2, h2, cbox, bb);
}

/* Clips the straddlers to both child boxes; their new events go to
 * add[0..2] (left) and add[3..5] (right), sorted. */
void kd_clip_both(builder *b, size_t nboth, const kdr_bounds *box,
                  const kd_split *s, const kdr_bounds cbox[2], kd_event *add[6],
                  size_t nadd[6], size_t ntri[2]) {
    for (size_t i = 0; i < nboth; i++) {
        /* the straddlers are scattered over the triangle array (36 bytes
         * each, often two cache lines): fetch a few ahead, their loads
         * were a fifth of the clipping time */
        if (i + KD_CLIP_AHEAD < nboth) {
            const float *next = b->tris + 9 * (size_t)b->both[i + KD_CLIP_AHEAD];
            __builtin_prefetch(next);
            __builtin_prefetch(next + 8);
        }
        const float *tri = b->tris + 9 * (size_t)b->both[i];
        kdr_bounds bb[2];
        const unsigned sides =
            b->avx512 ? kd_clip_tri_avx512(tri, box, s->axis, s->pos, cbox, bb)
                      : kd_clip_tri(tri, box, s->axis, s->pos, cbox, bb);
        for (int side = 0; side < 2; side++) {
            if (sides & (1u << side)) {
                ev_add(add + 3 * side, nadd + 3 * side, &bb[side], b->both[i]);
                ntri[side]++;
            }
        }
    }
    for (int k = 0; k < 6; k++)
        kd_sort_events(add[k], nadd[k], b->avx512);
}
