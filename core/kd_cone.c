/*
 * kd_cone.c — the cone-shadow query (kdr_shadow_trace): visibility of
 * spherical lights from points, as the fraction of kdr_shadow_ray samples
 * whose segment reaches the light.
 *
 * KDR_SHADOW_RAYS traces every sample through the kd-tree (the reference).
 * KDR_SHADOW_CONE first walks the tree with the cone of the whole light
 * (kd_cone_trav.c). No candidate: visibility 1, no rays (a decided cone).
 * A short list: every sample is tested against the list only. Too many (a
 * wide cone over a busy scene): the samples are sorted along a Morton curve
 * of the light's disc and cut into groups; each group's own narrow cone
 * walks the tree and its samples are tested against that list, or traced
 * through the tree when even the narrow cone is too busy.
 *
 * Exactness: every list holds all triangles any of its samples can touch,
 * every test is kd_tri_intersect over [tmin, tmax], and a hit on any
 * triangle is an occlusion whichever way it was found. So the last blocker
 * (kept per light, across samples and points) is always tried first, and
 * the visibility equals KDR_SHADOW_RAYS bit for bit.
 */
#include <stdlib.h>

#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_tri.h"

#define SHADOW_MAX_SAMPLES 4096u
/* Tuning (bench/bench_cone.c): budgets of the whole-light cone, above which
 * the samples are grouped, and of each group's cone, above which its
 * samples go through the tree one by one. */
#define CONE_MAX_CANDS 48u
#define CONE_MAX_NODES 384u
#define GROUP_SIZE 16u
#define GROUP_MAX_CANDS 32u
#define GROUP_MAX_NODES 256u
#define NO_PRIM UINT32_MAX

typedef struct shadow_ws {
    kd_cand_list cl;
    kdr_ray *rays;  /* the samples of one (point, light), grouped path */
    uint64_t *keys; /* Morton key << 12 | sample */
    uint32_t *last; /* last blocker per light */
    kdr_shadow_stats st;
} shadow_ws;

/* ---- testing one sample -------------------------------------------------- */

static int hits_tri(const kdr_scene *scene, const kd_ray_pre *pre,
                    const kdr_ray *r, uint32_t prim) {
    float t, u, v;
    return kd_tri_intersect(pre, scene->tris + 9 * (size_t)prim, r->tmin,
                            r->tmax, &t, &u, &v);
}

/* Occlusion of r by the candidates (cl non-NULL) or by the whole tree. */
static int sample_blocked(const kdr_scene *scene, const kdr_ray *r,
                          const kd_cand_list *cl, uint32_t *last,
                          kdr_shadow_stats *st) {
    kd_ray_pre pre;
    kd_ray_precompute(r->org, r->dir, &pre);
    st->rays_traced++;
    if (*last != NO_PRIM && hits_tri(scene, &pre, r, *last))
        return 1;
    if (!cl) {
        kdr_trav_stats ts = {0};
        const int hit = kdr_occluded1(scene, r, &ts);
        st->nodes_visited += ts.nodes_visited;
        return hit;
    }
    for (size_t j = 0; j < cl->n; j++) {
        if (hits_tri(scene, &pre, r, cl->v[j])) {
            *last = cl->v[j];
            return 1;
        }
    }
    return 0;
}

/* Lit samples among all of the frame's, each against cl (or the tree). */
static uint32_t lit_all(const kdr_scene *scene, const kd_shadow_frame *f,
                        uint32_t nsamples, const kd_cand_list *cl,
                        uint32_t *last, kdr_shadow_stats *st) {
    uint32_t lit = 0;
    for (uint32_t s = 0; s < nsamples; s++) {
        kdr_ray r;
        kd_shadow_frame_ray(f, s, nsamples, &r);
        lit += sample_blocked(scene, &r, cl, last, st) ? 0u : 1u;
    }
    return lit;
}

/* ---- grouped samples --------------------------------------------------------- */

/* Spreads the low 16 bits of x to the even bits. */
static uint32_t spread_bits(uint32_t x) {
    x &= 0xffffu;
    x = (x | (x << 8)) & 0x00ff00ffu;
    x = (x | (x << 4)) & 0x0f0f0f0fu;
    x = (x | (x << 2)) & 0x33333333u;
    x = (x | (x << 1)) & 0x55555555u;
    return x;
}

/* Position of a direction on the light's disc, quantised to 16 bits. */
static uint32_t disc_coord(const kd_shadow_frame *f, const float *dir,
                           const double *b) {
    const double x = (dir[0] * b[0] + dir[1] * b[1] + dir[2] * b[2]) / f->sin_a;
    const double q = fmin(fmax(0.5 * (x + 1.0), 0.0), 1.0) * 65535.0;
    return (uint32_t)q;
}

static int cmp_u64(const void *a, const void *b) {
    const uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

/* The narrowest cone (around the mean direction) holding the group's
 * samples; returns 0 if it would be too wide to help. */
static int group_cone(const kdr_scene *scene, const kd_shadow_frame *f,
                      const kdr_ray *rays, const uint64_t *keys, uint32_t n,
                      kd_cone *c) {
    double axis[3] = {0, 0, 0}, len = 0.0, cos_min = 1.0;
    for (uint32_t j = 0; j < n; j++)
        for (int k = 0; k < 3; k++)
            axis[k] += rays[keys[j] & 0xfffu].dir[k];
    len = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    if (!(len > 0.0))
        return 0;
    for (int k = 0; k < 3; k++)
        axis[k] /= len;
    for (uint32_t j = 0; j < n; j++) {
        const float *d = rays[keys[j] & 0xfffu].dir;
        const double dl = sqrt((double)d[0] * d[0] + (double)d[1] * d[1] +
                               (double)d[2] * d[2]);
        cos_min = fmin(cos_min, (d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2]) / dl);
    }
    if (cos_min <= 0.1)
        return 0;
    kd_cone_init(c, scene, f, axis, sqrt((1.0 - cos_min) * (1.0 + cos_min)));
    return 1;
}

/* Lit samples when the whole-light cone was too busy. */
static int lit_grouped(const kdr_scene *scene, const kd_shadow_frame *f,
                       uint32_t nsamples, shadow_ws *ws, uint32_t *last,
                       uint32_t *lit) {
    for (uint32_t s = 0; s < nsamples; s++) {
        kdr_ray *r = &ws->rays[s];
        kd_shadow_frame_ray(f, s, nsamples, r);
        const uint64_t m = spread_bits(disc_coord(f, r->dir, f->b1)) |
                           spread_bits(disc_coord(f, r->dir, f->b2)) << 1;
        ws->keys[s] = m << 12 | s;
    }
    qsort(ws->keys, nsamples, sizeof *ws->keys, cmp_u64);
    *lit = 0;
    for (uint32_t g = 0; g < nsamples; g += GROUP_SIZE) {
        const uint32_t n = nsamples - g < GROUP_SIZE ? nsamples - g : GROUP_SIZE;
        const uint64_t *keys = ws->keys + g;
        kd_cone c;
        int rc = KD_CONE_OVER;
        if (group_cone(scene, f, ws->rays, keys, n, &c))
            rc = kd_cone_collect(scene, &c, &ws->cl, GROUP_MAX_CANDS,
                                 GROUP_MAX_NODES, &ws->st.nodes_visited);
        if (rc == KDR_ENOMEM)
            return rc;
        const kd_cand_list *cl = rc == KDR_OK ? &ws->cl : NULL;
        if (cl && cl->n == 0) {
            *lit += n;
            continue;
        }
        for (uint32_t j = 0; j < n; j++)
            *lit += sample_blocked(scene, &ws->rays[keys[j] & 0xfffu], cl, last,
                                   &ws->st) ? 0u : 1u;
    }
    return KDR_OK;
}

/* ---- one (point, light) ---------------------------------------------------- */

static int ws_reserve(shadow_ws *ws, uint32_t nsamples) {
    if (ws->rays)
        return KDR_OK;
    ws->rays = malloc(nsamples * sizeof *ws->rays);
    ws->keys = malloc(nsamples * sizeof *ws->keys);
    return ws->rays && ws->keys ? KDR_OK : KDR_ENOMEM;
}

static int visibility_by_cone(const kdr_scene *scene, const kd_shadow_frame *f,
                              uint32_t nsamples, shadow_ws *ws, uint32_t *last,
                              float *vis) {
    kd_cone c;
    uint32_t lit = 0;
    kd_cone_init(&c, scene, f, NULL, 0.0);
    int rc = kd_cone_collect(scene, &c, &ws->cl, CONE_MAX_CANDS, CONE_MAX_NODES,
                             &ws->st.nodes_visited);
    if (rc == KDR_OK && ws->cl.n == 0) {
        ws->st.cones_decided++;
        *vis = 1.0f;
        return KDR_OK;
    }
    if (rc == KDR_OK) {
        lit = lit_all(scene, f, nsamples, &ws->cl, last, &ws->st);
    } else if (rc == KD_CONE_OVER && nsamples >= 2 * GROUP_SIZE) {
        rc = ws_reserve(ws, nsamples);
        if (rc == KDR_OK)
            rc = lit_grouped(scene, f, nsamples, ws, last, &lit);
    } else if (rc == KD_CONE_OVER) {
        lit = lit_all(scene, f, nsamples, NULL, last, &ws->st);
        rc = KDR_OK;
    }
    if (rc != KDR_OK)
        return rc;
    *vis = (float)lit / (float)nsamples;
    return KDR_OK;
}

/* ---- the query ----------------------------------------------------------- */

static int query_valid(const kdr_scene *scene, const kdr_shadow_query *q,
                       size_t first, size_t count, const float *visibility) {
    if (!scene || !q || !visibility || !q->points || !q->lights)
        return 0;
    if (q->nlights < 1 || q->samples < 1 || q->samples > SHADOW_MAX_SAMPLES)
        return 0;
    return first <= q->n && count <= q->n - first;
}

static int trace_points(const kdr_scene *scene, const kdr_shadow_query *q,
                        size_t first, size_t count, kdr_shadow_mode mode,
                        float *visibility, shadow_ws *ws) {
    for (size_t i = first; i < first + count; i++) {
        for (size_t l = 0; l < q->nlights; l++) {
            kd_shadow_frame f;
            float *vis = &visibility[i * q->nlights + l];
            int rc = kd_shadow_frame_init(scene, q, i, l, &f);
            if (rc == KDR_OK && mode == KDR_SHADOW_RAYS) {
                uint32_t none = NO_PRIM;
                *vis = (float)lit_all(scene, &f, q->samples, NULL, &none, &ws->st) /
                       (float)q->samples;
            } else if (rc == KDR_OK) {
                rc = visibility_by_cone(scene, &f, q->samples, ws, &ws->last[l], vis);
            }
            if (rc != KDR_OK)
                return rc;
        }
    }
    return KDR_OK;
}

int kdr_shadow_trace(const kdr_scene *scene, const kdr_shadow_query *q,
                     size_t first, size_t count, kdr_shadow_mode mode,
                     float *visibility, kdr_shadow_stats *stats) {
    if (!query_valid(scene, q, first, count, visibility))
        return KDR_EINVAL;
    if (mode != KDR_SHADOW_CONE && mode != KDR_SHADOW_RAYS)
        return KDR_EINVAL;
    shadow_ws ws = {0};
    ws.last = malloc(q->nlights * sizeof *ws.last);
    int rc = ws.last ? KDR_OK : KDR_ENOMEM;
    for (size_t l = 0; rc == KDR_OK && l < q->nlights; l++)
        ws.last[l] = NO_PRIM;
    if (rc == KDR_OK)
        rc = trace_points(scene, q, first, count, mode, visibility, &ws);
    if (stats) {
        stats->cones_decided += ws.st.cones_decided;
        stats->rays_traced += ws.st.rays_traced;
        stats->nodes_visited += ws.st.nodes_visited;
    }
    free(ws.cl.v);
    free(ws.rays);
    free(ws.keys);
    free(ws.last);
    return rc;
}
