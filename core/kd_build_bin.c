/*
 * kd_build_bin.c — the binned top of the SAH build (kd_build.h). Nodes with
 * more than exact_max triangles carry a plain array of prims (triangle
 * number and its bounds inside the node) instead of three sorted event
 * lists: their plane comes from min-max bins (kd_build_sah.c), so the
 * large top levels cost one linear pass each and need no global sort.
 * A split sends each prim left, right, or (a straddler) to both sides with
 * its bounds clipped to each child, by the same rules and the same
 * clipping as the exact path. Once a node is small enough its prims become
 * sorted event lists and the exact sweep takes over.
 *
 * Prim arrays stay in triangle-number order (the root is built in that
 * order and partitions are stable), so the events made from them sort
 * stably into the same order as the exact path's keys.
 */
#include <math.h>
#include <stdlib.h>

#include "kd_build.h"
#include "kd_traverse.h"

/* Below this many events a node's lists are sorted by comparison; the radix
 * sort's histograms cost more than that. Same order either way: keys are
 * unique. */
#define RADIX_MIN 4096

static void tight_reset(kdr_bounds *t) {
    for (int k = 0; k < 3; k++) {
        t->min[k] = INFINITY;
        t->max[k] = -INFINITY;
    }
}

static void tight_add(kdr_bounds *t, const float lo[3], const float hi[3]) {
    for (int k = 0; k < 3; k++) {
        t->min[k] = lo[k] < t->min[k] ? lo[k] : t->min[k];
        t->max[k] = hi[k] > t->max[k] ? hi[k] : t->max[k];
    }
}

int kd_root_prims(const float *tris, size_t ntris, size_t nvalid, kd_prims *out) {
    out->p = malloc((nvalid ? nvalid : 1) * sizeof *out->p);
    out->n = 0;
    tight_reset(&out->tight);
    if (!out->p)
        return KDR_ENOMEM;
    for (size_t i = 0; i < ntris; i++) {
        const float *t = tris + 9 * i;
        if (kd_tri_degenerate(t))
            continue;
        kd_prim *q = &out->p[out->n++];
        for (int k = 0; k < 3; k++) {
            q->lo[k] = min3(t[k], t[3 + k], t[6 + k]);
            q->hi[k] = max3(t[k], t[3 + k], t[6 + k]);
        }
        q->tri = (uint32_t)i;
        tight_add(&out->tight, q->lo, q->hi);
    }
    return KDR_OK;
}

/* The side of a prim (kd_build_events.c's classify, for bounds instead of
 * events): touching the plane from one side keeps it on that side; lying
 * in the plane sends it where the split says. */
static inline int prim_side(const kd_prim *q, int k, float pos, int planar_left) {
    if (q->lo[k] == q->hi[k] && q->lo[k] == pos)
        return planar_left ? SIDE_LEFT : SIDE_RIGHT;
    if (q->hi[k] <= pos)
        return SIDE_LEFT;
    if (q->lo[k] >= pos)
        return SIDE_RIGHT;
    return SIDE_BOTH;
}

static void put(kd_prims *c, const float lo[3], const float hi[3], uint32_t tri) {
    kd_prim *q = &c->p[c->n++];
    for (int k = 0; k < 3; k++) {
        q->lo[k] = lo[k];
        q->hi[k] = hi[k];
    }
    q->tri = tri;
    tight_add(&c->tight, lo, hi);
}

int kd_bin_partition(const builder *b, const kdr_bounds *box, const kd_split *s,
                     const kdr_bounds cbox[2], const kd_prims *in, kd_prims out[2]) {
    const int k = s->axis;
    size_t cap[2] = {0, 0};
    for (size_t i = 0; i < in->n; i++) {
        const int sd = prim_side(&in->p[i], k, s->pos, s->planar_left);
        cap[0] += sd != SIDE_RIGHT;
        cap[1] += sd != SIDE_LEFT;
    }
    for (int side = 0; side < 2; side++) {
        out[side].p = malloc((cap[side] ? cap[side] : 1) * sizeof(kd_prim));
        out[side].n = 0;
        tight_reset(&out[side].tight);
    }
    if (!out[0].p || !out[1].p) {
        free(out[0].p);
        free(out[1].p);
        out[0].p = out[1].p = NULL;
        return KDR_ENOMEM;
    }
    for (size_t i = 0; i < in->n; i++) {
        const kd_prim *q = &in->p[i];
        const int sd = prim_side(q, k, s->pos, s->planar_left);
        if (sd != SIDE_BOTH) {
            put(&out[sd == SIDE_RIGHT], q->lo, q->hi, q->tri);
            continue;
        }
        kdr_bounds bb[2];
        const unsigned sides =
            kd_clip_tri(b->tris + 9 * (size_t)q->tri, box, k, s->pos, cbox, bb);
        for (int side = 0; side < 2; side++)
            if (sides & (1u << side))
                put(&out[side], bb[side].min, bb[side].max, q->tri);
    }
    for (int side = 0; side < 2; side++)
        if (out[side].n == 0)
            out[side].tight = cbox[side];
    return KDR_OK;
}

int kd_prims_to_events(const kd_prims *p, ev_list *ev, kd_event **block, int avx512) {
    const size_t per = 2 * p->n + 1;
    /* three lists, then room for the radix sort's scratch */
    kd_event *m = malloc(4 * per * sizeof *m);
    memset(ev, 0, sizeof *ev);
    *block = m;
    if (!m)
        return KDR_ENOMEM;
    for (int k = 0; k < 3; k++)
        ev->e[k] = m + (size_t)k * per;
    for (size_t i = 0; i < p->n; i++) {
        const kd_prim *q = &p->p[i];
        const kdr_bounds bb = {{q->lo[0], q->lo[1], q->lo[2]},
                               {q->hi[0], q->hi[1], q->hi[2]}};
        ev_add(ev->e, ev->n, &bb, q->tri);
    }
    for (int k = 0; k < 3; k++) {
        if (ev->n[k] < RADIX_MIN)
            kd_sort_events(ev->e[k], ev->n[k], avx512);
        else
            kd_radix_sort(ev->e[k], m + 3 * per, ev->n[k]);
    }
    ev->ntri = p->n;
    return KDR_OK;
}
