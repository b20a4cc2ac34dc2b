/*
 * kd_entry.c — the origin's path (kd_entry_path_init), the AVX-512 replay
 * of a ray's descent along it (kd_entry_descend16) and the per-batch path
 * cache of the interleaved walk's refill (kd_entry_for). Why it is exact:
 * kd_entry.h.
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
        if (org[axis] == split) break;
        const int above = org[axis] > split;
        if (above ? kd_above_empty(n) : kd_below_empty(n)) break;
        p->node[d] = n;
        p->sib[d] = above ? n + 1 : nodes + kd_above(n);
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

/* One block of levels [i, i + 16) for kd_entry_descend16, each lane with
 * kd_entry_descend_scalar's operations for its level, given the interval
 * [n0, f0] at level i. tn changes along the path only where the path's
 * child is the far one and the empty near child is reached (tn = max(t_lo,
 * tn)): such a level ends the block's scan (*clip) and is replayed alone.
 * Below it, tf at level j is the scalar loop's running min(t_hi, tf) over
 * the levels before j that take their near child: an exclusive scan of
 * min_ps(later, earlier), which is the ternary t_hi < tf ? t_hi : tf
 * (a NaN t_hi, which leaves tf as it is, enters as +inf, which does too;
 * on equal values the earlier one stays, so the bits are the loop's, -0
 * and +0 included, and the combination is associative), in 4 steps.
 * Returns the levels where the replay stops (path child not needed, or the
 * near sibling needed first) or clips; writes per lane the far entry's tn
 * and tf (*ftn, *ftf), the levels that push (*push) and tf after each
 * level (*after). */
KD_AVX512 static inline unsigned block16(const kd_entry_path *p, int i, const f16 inv[3],
                                         const f16 ssv[3], float n0, float f0,
                                         unsigned *clip, unsigned *push, f16 *ftn,
                                         f16 *ftf, f16 *after) {
    const int left = p->depth - i;
    const unsigned valid = left >= 16 ? 0xffffu : (1u << left) - 1u;
    const unsigned m1 = (unsigned)(p->ax1 >> i) & 0xffffu;
    const unsigned m2 = (unsigned)(p->ax2 >> i) & 0xffffu;
    const f16 iv = f16_selm(m2, inv[2], f16_selm(m1, inv[1], inv[0]));
    const f16 sv = f16_selm(m2, ssv[2], f16_selm(m1, ssv[1], ssv[0]));
    const f16 a = f16_loadu(p->a + i);
    const f16 t_lo = f16_mul(f16_sub(a, sv), iv);
    const f16 t_hi = f16_mul(f16_add(a, sv), iv);
    const unsigned ng = f16_signs(iv); /* dir's signs: kd_walk_setup's neg */
    const unsigned be = (unsigned)(p->below_empty_m >> i) & 0xffffu;
    const unsigned ae = (unsigned)(p->above_empty_m >> i) & 0xffffu;
    const unsigned near_empty = (ng & ae) | (~ng & be);
    const unsigned far_empty = (ng & be) | (~ng & ae);
    const unsigned path_near = ~((unsigned)(p->above_m >> i) ^ ng) & valid;
    const unsigned raw_near = f16_nlt(valid, t_hi, f16_set1(n0));
    const unsigned go_near = raw_near & ~near_empty;
    /* tf before each level: the exclusive scan of the near levels' t_hi */
    const f16 inf = f16_set1(INFINITY);
    f16 y = f16_selm(f16_ord(path_near, t_hi), t_hi, inf); /* a NaN: +inf */
    y = f16_min(y, f16_up(y, inf, 1));
    y = f16_min(y, f16_up(y, inf, 2));
    y = f16_min(y, f16_up(y, inf, 4));
    y = f16_min(y, f16_up(y, inf, 8));
    const f16 f0v = f16_set1(f0);
    const f16 tfv = f16_min(f16_up(y, inf, 1), f0v);
    const unsigned go_far = f16_ngt(valid, t_lo, tfv) & ~far_empty;
    *clip = ~path_near & raw_near & near_empty & go_far & valid;
    *push = path_near & go_near & go_far;
    *ftn = f16_max(t_lo, f16_set1(n0));
    *ftf = tfv;
    *after = f16_min(y, f0v);
    return ((path_near & ~go_near) | (~path_near & (go_near | ~go_far)) | *clip) & valid;
}

KD_AVX512 const kd_node *kd_entry_descend16(const kd_entry_path *p, const float inv[3],
                                            const float ss[3], float *tn, float *tf,
                                            int *level, kd_todo *stack, int *sp) {
    const f16 iv[3] = {f16_set1(inv[0]), f16_set1(inv[1]), f16_set1(inv[2])};
    const f16 sv[3] = {f16_set1(ss[0]), f16_set1(ss[1]), f16_set1(ss[2])};
    _Alignas(64) float ftn[16], ftf[16], aft[16];
    float n0 = *tn, f0 = *tf;
    int i = 0, k = 0;
    while (i < p->depth) {
        unsigned clip, push;
        f16 vtn, vtf, vaf;
        const unsigned stop =
            block16(p, i, iv, sv, n0, f0, &clip, &push, &vtn, &vtf, &vaf);
        const int left = p->depth - i;
        const int f = stop ? __builtin_ctz(stop) : (left < 16 ? left : 16);
        push &= (unsigned)((1u << f) - 1u); /* f <= 16: 1u << 16 is defined */
        if (push) {
            f16_store(ftn, vtn);
            f16_store(ftf, vtf);
            for (unsigned m = push; m; m &= m - 1) {
                const int j = __builtin_ctz(m);
                stack[k].node = p->sib[i + j];
                stack[k].tn = ftn[j];
                stack[k].tf = ftf[j];
                k++;
            }
        }
        if (f > 0) {
            f16_store(aft, vaf);
            f0 = aft[f - 1];
        }
        i += f;
        if (!stop) continue;
        if (!((clip >> f) & 1u)) break;
        /* the far child, its empty near sibling reached: tn moves */
        const struct kd_entry_level *l = &p->lv[i];
        const float tl = (p->a[i] - ss[l->axis]) * inv[l->axis];
        n0 = tl > n0 ? tl : n0;
        i++;
    }
    *tn = n0;
    *tf = f0;
    *level = i;
    *sp = k;
    return p->node[i];
}

const kd_node *kd_entry_for(const kdr_scene *s, kd_entry_cache *ec, const float org[3],
                            const float inv[3], const float ss[3], const unsigned neg[3],
                            float *tn, float *tf, int *level, kd_todo *stack, int *sp) {
    const size_t sz = 3 * sizeof(float);
    if (!(ec->have_path && memcmp(org, ec->path_org, sz) == 0)) {
        const int run = ec->have_prev && memcmp(org, ec->prev_org, sz) == 0;
        memcpy(ec->prev_org, org, sz);
        ec->have_prev = 1;
        if (!run) {
            *level = *sp = 0;
            return s->nodes;
        }
        kd_entry_path_init(s, org, &ec->path);
        memcpy(ec->path_org, org, sz);
        ec->have_path = 1;
    }
    return kd_entry_descend(&ec->path, org, inv, ss, neg, tn, tf, level, stack, sp);
}
