/*
 * kd_build_sah.c — the split search of the SAH build (kd_build.h): one
 * sweep per axis over the node's sorted events, evaluating the surface
 * area heuristic at every distinct event position strictly inside the
 * node, with pbrt's empty-space bonus; triangles lying in a candidate
 * plane go to the cheaper side (left on ties).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "kd_build.h"

/* Counts stay below 2^30: the signed conversion is one instruction and
 * gives the same float as the unsigned one. */
static float sah_cost(const sah_ctx *c, float p, size_t nl, size_t nr) {
    float pl = 2.0f * (c->cap + (p - c->min) * c->perim) * c->inv_area;
    float pr = 2.0f * (c->cap + (c->max - p) * c->perim) * c->inv_area;
    float eb = (nl == 0 || nr == 0) ? 1.0f - c->bonus : 1.0f;
    return c->trav +
           c->isect * eb * (pl * (float)(int64_t)nl + pr * (float)(int64_t)nr);
}

/* Evaluates plane p with nl left, np planar, nr right; planar triangles go
 * to the cheaper side (left on ties). Without planar triangles both sides
 * cost the same: one evaluation. */
static void sah_try(const sah_ctx *c, int k, float p, size_t nl, size_t np,
                    size_t nr, kd_split *best) {
    float cl = sah_cost(c, p, nl + np, nr);
    float cr = np ? sah_cost(c, p, nl, nr + np) : cl;
    float cost = cl <= cr ? cl : cr;
    if (cost < best->cost) {
        best->cost = cost;
        best->axis = k;
        best->pos = p;
        best->planar_left = cl <= cr;
    }
}

/* The SAH terms of planes on axis k of box; 0 when the box is flat there
 * (or has no area), so no plane can split it. */
static int sah_init(const builder *b, const kdr_bounds *box, int k, sah_ctx *c) {
    const int a1 = (k + 1) % 3, a2 = (k + 2) % 3;
    const float d1 = box->max[a1] - box->min[a1], d2 = box->max[a2] - box->min[a2];
    *c = (sah_ctx){box->min[k], box->max[k], d1 * d2, d1 + d2, 0.0f,
                   b->o.isect_cost, b->o.trav_cost, b->o.empty_bonus};
    float area = 2.0f * (c->cap + (c->max - c->min) * c->perim);
    if (!(area > 0.0f) || !(c->max > c->min))
        return 0;
    c->inv_area = 1.0f / area;
    return 1;
}

/* Pass one of the sweep: every event writes the current group's entry and
 * a new group begins when the next key differs, without a branch on the
 * data (whether the next event shares the position is random: a loop that
 * stopped at each group's end mispredicted there about once a group). */
size_t kd_group_events(const kd_event *e, size_t n, const kd_groups *g) {
    size_t ng = 0;
    uint32_t ends = 0, planars = 0;
    for (size_t i = 0; i < n; i++) {
        const uint32_t key = ev_key(e[i]);
        const unsigned type = ev_type(e[i]);
        ends += type == EV_END;
        planars += type == EV_PLANAR;
        g->key[ng] = key;
        g->ends[ng] = ends;
        g->planars[ng] = planars;
        g->end[ng] = (uint32_t)(i + 1);
        const size_t next = i + 1 < n ? i + 1 : i;
        ng += (next == i) | (ev_key(e[next]) != key);
    }
    return ng;
}

/* Pass two: group j has pe end, pp planar and ps start events; left of its
 * plane lie the triangles that started (or lie) in earlier groups, right
 * of it those that have not ended there or before. */
void kd_eval_groups(const sah_ctx *c, int k, const kd_groups *g, size_t ng,
                    size_t ntri, kd_split *best) {
    uint32_t pend = 0, pplanar = 0, pidx = 0;
    for (size_t j = 0; j < ng; j++) {
        const size_t nl = pidx - pend;
        const size_t nr = ntri - g->ends[j] - g->planars[j];
        const size_t pp = g->planars[j] - pplanar;
        const float p = key_float(g->key[j]);
        if (p > c->min && p < c->max)
            sah_try(c, k, p, nl, pp, nr, best);
        pend = g->ends[j];
        pplanar = g->planars[j];
        pidx = g->end[j];
    }
}

/* One sweep in two passes: fold the events into groups, then evaluate the
 * groups (both passes 16 lanes at a time where AVX-512 runs). */
static void sweep_axis(const kdr_bounds *box, const builder *b, const ev_list *ev,
                       int k, const kd_groups *g, kd_split *best) {
    sah_ctx c;
    if (!sah_init(b, box, k, &c))
        return;
    if (b->avx512) {
        const size_t ng = kd_group_events_avx512(ev->e[k], ev->n[k], g);
        kd_eval_groups_avx512(&c, k, g, ng, ev->ntri, best);
    } else {
        const size_t ng = kd_group_events(ev->e[k], ev->n[k], g);
        kd_eval_groups(&c, k, g, ng, ev->ntri, best);
    }
}

int kd_find_split(builder *b, const kdr_bounds *box, const ev_list *ev,
                  kd_split *best) {
    best->axis = -1;
    best->pos = 0.0f;
    best->planar_left = 1;
    best->cost = INFINITY;
    size_t need = ev->n[0];
    need = ev->n[1] > need ? ev->n[1] : need;
    need = ev->n[2] > need ? ev->n[2] : need;
    /* the groups live above the top of the worker's stack when there is
     * room (a task's first node sizes the stack for that); else in a
     * buffer of their own */
    kd_stack_reserve(b, 2 * (ev->n[0] + ev->n[1] + ev->n[2]));
    size_t stride = need + KD_GROUP_PAD;
    uint32_t *gm = kd_stack_scratch(b, 4 * stride * sizeof *gm);
    if (!gm && need > b->groups_cap) {
        size_t cap = b->groups_cap ? b->groups_cap : 4096;
        while (cap < need)
            cap *= 2;
        free(b->groups);
        const size_t bytes = 4 * (cap + KD_GROUP_PAD) * sizeof *b->groups;
        b->groups = b->huge ? kd_scratch_alloc(bytes) : malloc(bytes);
        b->groups_cap = b->groups ? cap : 0;
        if (!b->groups) {
            b->err = KDR_ENOMEM;
            return 0;
        }
    }
    if (!gm) {
        gm = b->groups;
        stride = b->groups_cap + KD_GROUP_PAD;
    }
    const kd_groups g = {gm, gm + stride, gm + 2 * stride, gm + 3 * stride};
    for (int k = 0; k < 3; k++)
        sweep_axis(box, b, ev, k, &g, best);
    return best->axis >= 0;
}

/* ---- binned nodes ------------------------------------------------------------ */

/* Plane p with nl triangles left and nr right; planar_left says where the
 * triangles lying in p were counted (the estimate has no planar count). */
static void bin_try(const sah_ctx *c, int k, float p, size_t nl, size_t nr,
                    int planar_left, kd_split *best) {
    if (!(p > c->min && p < c->max))
        return;
    const float cost = sah_cost(c, p, nl, nr);
    if (cost < best->cost) {
        best->cost = cost;
        best->axis = k;
        best->pos = p;
        best->planar_left = planar_left;
    }
}

/* Bin of x in [t0, t0 + KD_BINS / scale]; double, so a tiny extent cannot
 * overflow the scale. */
static inline int bin_of(float x, double t0, double scale) {
    const int i = (int)(((double)x - t0) * scale);
    return i < 0 ? 0 : i >= KD_BINS ? KD_BINS - 1 : i;
}

int kd_bin_split(const builder *b, const kdr_bounds *box, const kd_prims *p,
                 kd_split *best) {
    uint32_t lo[3][KD_BINS], hi[3][KD_BINS];
    double t0[3], scale[3];
    int binned[3];
    best->axis = -1;
    best->pos = 0.0f;
    best->planar_left = 1;
    best->cost = INFINITY;
    for (int k = 0; k < 3; k++) {
        t0[k] = p->tight.min[k];
        binned[k] = p->tight.max[k] > p->tight.min[k];
        scale[k] = binned[k] ? KD_BINS / ((double)p->tight.max[k] - t0[k]) : 0.0;
    }
    memset(lo, 0, sizeof lo);
    memset(hi, 0, sizeof hi);
    for (size_t i = 0; i < p->n; i++) {
        const kd_prim *q = &p->p[i];
        for (int k = 0; k < 3; k++) {
            lo[k][bin_of(q->lo[k], t0[k], scale[k])]++;
            hi[k][bin_of(q->hi[k], t0[k], scale[k])]++;
        }
    }
    for (int k = 0; k < 3; k++) {
        sah_ctx c;
        if (!sah_init(b, box, k, &c))
            continue;
        /* empty space below the triangles: all of them (and those lying in
         * the plane) on the right */
        bin_try(&c, k, p->tight.min[k], 0, p->n, 0, best);
        size_t nl = 0, nr = p->n;
        const double w = (double)p->tight.max[k] - t0[k];
        for (int i = 1; binned[k] && i < KD_BINS; i++) {
            nl += lo[k][i - 1];
            nr -= hi[k][i - 1];
            bin_try(&c, k, (float)(t0[k] + w * i / KD_BINS), nl, nr, 1, best);
        }
        bin_try(&c, k, p->tight.max[k], p->n, 0, 1, best);
    }
    return best->axis >= 0;
}
