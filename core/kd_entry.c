/*
 * kd_entry.c — the origin's path (kd_entry_path_init) and the batch driver
 * that traces runs of rays sharing an origin from their entry points
 * (kd_entry_trace). Why it is exact: kd_entry.h.
 */
#include <string.h>

#include "kd_entry.h"
#include "kd_stream.h"
#include "simd.h"

void kd_entry_path_init(const kdr_scene *s, const float org[3], kd_entry_path *p) {
    const kd_node *nodes = s->nodes, *n = nodes;
    int d = 0;
    /* the build splits only above depth KD_MAX_DEPTH, so d stays below it */
    while (!kd_is_leaf(n) && d < KD_MAX_DEPTH) {
        const int axis = kd_axis(n);
        const float split = n->u.split;
        /* an origin in the plane has no side: every ray with a direction
         * along this axis needs both children there (|a| is 0, under the
         * slack), so the path ends; so it does where the origin's child is
         * empty (a ray's walk never enters it) */
        if (org[axis] == split)
            break;
        const int above = org[axis] > split;
        if (above ? kd_above_empty(n) : kd_below_empty(n))
            break;
        p->node[d] = n;
        p->lv[d].split = split;
        p->lv[d].axis = (uint8_t)axis;
        p->lv[d].above = (uint8_t)above;
        p->lv[d].empty = (uint8_t)(kd_below_empty(n) | kd_above_empty(n) << 1);
        n = above ? nodes + kd_above(n) : n + 1;
        d++;
    }
    p->node[d] = n;
    p->depth = d;
    p->ax1 = p->ax2 = p->above_m = p->below_empty_m = p->above_empty_m = 0;
    for (int i = 0; i < d; i++) {
        const struct kd_entry_level *l = &p->lv[i];
        p->a[i] = l->split - org[l->axis]; /* the walk's a, bit for bit */
        p->ax1 |= (uint64_t)(l->axis == 1) << i;
        p->ax2 |= (uint64_t)(l->axis == 2) << i;
        p->above_m |= (uint64_t)l->above << i;
        p->below_empty_m |= (uint64_t)(l->empty & 1u) << i;
        p->above_empty_m |= (uint64_t)(l->empty >> 1) << i;
    }
    for (int i = d; i < d + 16; i++)
        p->a[i] = 0.0f; /* lanes past the path: masked off */
    p->wide = kd_cpu_has_avx512();
}

/* Levels [i, i + 16) at once, each lane with kd_entry_start_scalar's
 * operations: a from the path, ss and inv of the level's axis (blends of
 * broadcasts), t_lo = (a - ss) * inv, t_hi = (a + ss) * inv, the near
 * child is above where inv is negative (its sign is dir's, which is what
 * kd_walk_setup's neg holds), go_near = !(t_hi < tn) minus an empty near
 * child, go_far = !(t_lo > tf) minus an empty far child. A level stops the
 * vector scan when the walk needs anything but the path's child there (the
 * entry), or when the interval reaches the path's sibling but the sibling
 * is empty: only there does the walk clip its interval (near only with the
 * far child empty: tf = min(t_hi, tf); far only with the near child empty:
 * tn = max(t_lo, tn); elsewhere a single child means t_lo > tf or t_hi <
 * tn, and the same min / max leave the interval as it is). Such
 * a level is applied as the scalar replay does and the scan goes on after
 * it with the new interval. */
/* Levels [i, i + 16) against interval [n0, f0]: bit j of the result set
 * where level i + j stops the scan (kd_entry_find16), bit j of *clip where
 * that is an interval update rather than the entry. */
KD_AVX512 static inline unsigned stops16(const kd_entry_path *p, int i, const f16 inv[3],
                                         const f16 ssv[3], float n0, float f0,
                                         unsigned *clip, unsigned *path_near_out) {
    const int left = p->depth - i;
    const unsigned valid = left >= 16 ? 0xffffu : (1u << left) - 1u;
    const unsigned m1 = (unsigned)(p->ax1 >> i) & 0xffffu;
    const unsigned m2 = (unsigned)(p->ax2 >> i) & 0xffffu;
    const f16 iv = f16_selm(m2, inv[2], f16_selm(m1, inv[1], inv[0]));
    const f16 sv = f16_selm(m2, ssv[2], f16_selm(m1, ssv[1], ssv[0]));
    const f16 a = f16_loadu(p->a + i);
    const f16 t_lo = f16_mul(f16_sub(a, sv), iv);
    const f16 t_hi = f16_mul(f16_add(a, sv), iv);
    const unsigned ng = f16_signs(iv);
    const unsigned be = (unsigned)(p->below_empty_m >> i) & 0xffffu;
    const unsigned ae = (unsigned)(p->above_empty_m >> i) & 0xffffu;
    const unsigned near_empty = (ng & ae) | (~ng & be);
    const unsigned far_empty = (ng & be) | (~ng & ae);
    const unsigned raw_near = f16_nlt(valid, t_hi, f16_set1(n0));
    const unsigned raw_far = f16_ngt(valid, t_lo, f16_set1(f0));
    const unsigned go_near = raw_near & ~near_empty;
    const unsigned go_far = raw_far & ~far_empty;
    const unsigned path_near = ~((unsigned)(p->above_m >> i) ^ ng) & 0xffffu;
    const unsigned only = (go_near ^ go_far) & ~(go_near ^ path_near);
    /* the interval reaches the path's sibling but the sibling is empty:
     * the only levels where the walk's interval changes */
    *clip = only & ((path_near & raw_far) | (~path_near & raw_near)) & valid;
    *path_near_out = path_near;
    return (~only & valid) | *clip;
}

KD_AVX512 const kd_node *kd_entry_find16(const kd_entry_path *p, const float inv[3],
                                         const float ss[3], float *tn, float *tf,
                                         int *level) {
    const f16 iv[3] = {f16_set1(inv[0]), f16_set1(inv[1]), f16_set1(inv[2])};
    const f16 sv[3] = {f16_set1(ss[0]), f16_set1(ss[1]), f16_set1(ss[2])};
    float n0 = *tn, f0 = *tf;
    int i = 0;
    for (;;) {
        /* every block from level i, without a branch between them; the
         * first stop is the entry unless it is an interval update */
        uint64_t stop = 0, clip = 0, near = 0;
        for (int b = i; b < p->depth; b += 16) {
            unsigned c, pn;
            const unsigned st = stops16(p, b, iv, sv, n0, f0, &c, &pn);
            stop |= (uint64_t)st << (b - i);
            clip |= (uint64_t)c << (b - i);
            near |= (uint64_t)pn << (b - i);
        }
        if (!stop) {
            i = p->depth;
            break;
        }
        const int f = __builtin_ctzll(stop);
        i += f;
        if (!((clip >> f) & 1u))
            break;
        const struct kd_entry_level *l = &p->lv[i];
        const float th = (p->a[i] + ss[l->axis]) * inv[l->axis];
        const float tl = (p->a[i] - ss[l->axis]) * inv[l->axis];
        if ((near >> f) & 1u)
            f0 = th < f0 ? th : f0;
        else
            n0 = tl > n0 ? tl : n0;
        i++;
    }
    *tn = n0;
    *tf = f0;
    *level = i;
    return p->node[i];
}

const kd_node *kd_entry_for(const kdr_scene *s, kd_entry_cache *ec, const float org[3],
                            const float inv[3], const float ss[3], const unsigned neg[3],
                            float *tn, float *tf, int *level) {
    const size_t sz = 3 * sizeof(float);
    if (!(ec->have_path && memcmp(org, ec->path_org, sz) == 0)) {
        const int run = ec->have_prev && memcmp(org, ec->prev_org, sz) == 0;
        memcpy(ec->prev_org, org, sz);
        ec->have_prev = 1;
        if (!run) {
            *level = 0;
            return s->nodes;
        }
        kd_entry_path_init(s, org, &ec->path);
        memcpy(ec->path_org, org, sz);
        ec->have_path = 1;
    }
    return kd_entry_start(&ec->path, org, inv, ss, neg, tn, tf, level);
}

/* Origin of ray i (stride 0: every ray shares b->org). */
static inline const float *org_of(const kdr_ray_batch *b, size_t i) {
    return b->org + b->org_stride * i;
}

void kd_entry_trace(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                    size_t count, kdr_query q, kdr_hits *out, kdr_trav_stats *stats) {
    kd_entry_path path;
    const float *cur = NULL;
    for (size_t i = first; i < first + count; i++) {
        const float *o = org_of(b, i);
        if (!cur || (o != cur && memcmp(o, cur, 3 * sizeof(float)) != 0)) {
            kd_entry_path_init(s, o, &path);
            cur = o;
        }
        kdr_ray r;
        for (int k = 0; k < 3; k++) {
            r.org[k] = cur[k];
            r.dir[k] = b->dir[3 * i + k];
        }
        r.tmin = b->tmin ? b->tmin[b->tmin_stride * i] : 0.0f;
        r.tmax = b->tmax ? b->tmax[b->tmax_stride * i] : INFINITY;
        if (q == KDR_ANY) {
            out->hit[i] = (uint8_t)kd_entry_occluded1(s, &path, &r, stats);
            continue;
        }
        kdr_hit h;
        kd_entry_intersect1(s, &path, &r, &h, stats);
        out->t[i] = h.t;
        out->prim[i] = h.prim;
        out->u[i] = h.u;
        out->v[i] = h.v;
    }
}
