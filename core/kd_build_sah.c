/*
 * kd_build_sah.c — the split search of the SAH build (kd_build.h): one
 * sweep per axis over the node's sorted events, evaluating the surface
 * area heuristic at every distinct event position strictly inside the
 * node, with pbrt's empty-space bonus; triangles lying in a candidate
 * plane go to the cheaper side (left on ties).
 */
#include <math.h>

#include "kd_build.h"

typedef struct sah_ctx {
    float min, max;      /* node extent on the axis */
    float cap, perim;    /* child area = 2 (cap + len * perim) */
    float inv_area;      /* 1 / node area */
    float isect, trav, bonus;
} sah_ctx;

static float sah_cost(const sah_ctx *c, float p, size_t nl, size_t nr) {
    float pl = 2.0f * (c->cap + (p - c->min) * c->perim) * c->inv_area;
    float pr = 2.0f * (c->cap + (c->max - p) * c->perim) * c->inv_area;
    float eb = (nl == 0 || nr == 0) ? 1.0f - c->bonus : 1.0f;
    return c->trav + c->isect * eb * (pl * (float)nl + pr * (float)nr);
}

/* Evaluates plane p with nl left, np planar, nr right; planar triangles go
 * to the cheaper side (left on ties). */
static void sah_try(const sah_ctx *c, int k, float p, size_t nl, size_t np,
                    size_t nr, kd_split *best) {
    float cl = sah_cost(c, p, nl + np, nr);
    float cr = sah_cost(c, p, nl, nr + np);
    float cost = cl <= cr ? cl : cr;
    if (cost < best->cost) {
        best->cost = cost;
        best->axis = k;
        best->pos = p;
        best->planar_left = cl <= cr;
    }
}

static void sweep_axis(const builder *b, const kdr_bounds *box,
                       const ev_list *ev, int k, kd_split *best) {
    const int a1 = (k + 1) % 3, a2 = (k + 2) % 3;
    const float d1 = box->max[a1] - box->min[a1], d2 = box->max[a2] - box->min[a2];
    sah_ctx c = {box->min[k], box->max[k], d1 * d2, d1 + d2, 0.0f,
                 b->o.isect_cost, b->o.trav_cost, b->o.empty_bonus};
    float area = 2.0f * (c.cap + (c.max - c.min) * c.perim);
    if (!(area > 0.0f) || !(c.max > c.min))
        return;
    c.inv_area = 1.0f / area;
    const kd_event *e = ev->e[k];
    const size_t n = ev->n[k];
    size_t nl = 0, nr = ev->ntri;
    for (size_t i = 0; i < n;) {
        const uint32_t key = ev_key(e[i]);
        size_t pe = 0, pp = 0, ps = 0;
        do { /* one group: the events at this position */
            const unsigned type = ev_type(e[i]);
            pe += type == EV_END;
            pp += type == EV_PLANAR;
            ps += type == EV_START;
        } while (++i < n && ev_key(e[i]) == key);
        const float p = key_float(key);
        nr -= pp + pe;
        if (p > c.min && p < c.max)
            sah_try(&c, k, p, nl, pp, nr, best);
        nl += ps + pp;
    }
}

int kd_find_split(const builder *b, const kdr_bounds *box, const ev_list *ev,
                  kd_split *best) {
    best->axis = -1;
    best->pos = 0.0f;
    best->planar_left = 1;
    best->cost = INFINITY;
    for (int k = 0; k < 3; k++)
        sweep_axis(b, box, ev, k, best);
    return best->axis >= 0;
}
