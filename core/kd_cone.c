/*
 * kd_cone.c — the cone-shadow query (kdr_shadow_trace): visibility of
 * spherical lights from points, as the fraction of kdr_shadow_ray samples
 * whose segment reaches the light.
 *
 * KDR_SHADOW_RAYS traces every sample through the kd-tree (the reference).
 * KDR_SHADOW_CONE, per (point, light):
 *  1. if the light's last blocker blocks sample 0 (umbra likely), every
 *     sample is first tested against that one triangle;
 *  below CONE_WALK_MIN_SAMPLES samples a cone that reaches no candidate
 *  (a walk stopped at the first one) is decided (visibility 1, no rays),
 *  else the rest go straight to
 *  the tree in one shared-origin batch (the full walk with its per-triangle
 *  cull costs more than it saves there); else
 *  2. the cone of the whole light walks the tree (kd_cone_trav.c) with a
 *     budget: no candidate gives visibility 1 with no rays (a decided cone),
 *     a short list is tested by packets of samples (kd_cone_packet.c);
 *  3. over budget, with sub-cones narrow enough: the samples are sorted
 *     along a Morton curve of the light's disc and packets of 4/8
 *     neighbours walk their own cones, testing leaves on the way;
 *  4. otherwise: a few closest hits learn blockers, the rest go through
 *     the tree in bundles (kdr_trace_batch).
 * A walk over budget makes the next points of that light skip step 2 for a
 * while (back-off): neighbouring points see the same busy cone.
 *
 * Exactness: every list holds all triangles any of its samples can touch,
 * every test is kd_tri_intersect over [tmin, tmax], and a hit on any
 * triangle is an occlusion whichever way it was found (so a blocker
 * learned at one point may be tried at any other). The visibility equals
 * KDR_SHADOW_RAYS bit for bit, whichever path was taken.
 */
#include <stdlib.h>

#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_tri.h"

#define SHADOW_MAX_SAMPLES 4096u
#define NO_PRIM UINT32_MAX

/* Per light, carried from point to point (points arrive in image order). */
typedef struct light_state {
    uint32_t last;    /* last blocker: tried first on the next samples */
    uint32_t backoff; /* points to skip after the next failed walk */
    uint32_t skip;    /* points still to skip */
} light_state;

typedef struct shadow_ws {
    kd_cand_list cl;
    kdr_ray *rays;  /* the samples of one (point, light) */
    uint32_t *idx;  /* pending (not yet decided) samples */
    uint64_t *keys; /* Morton key << 12 | sample, for grouping */
    light_state *lights;
    float *borg, *bdir, *btmax; /* pending samples as a kdr_ray_batch */
    uint8_t *bhit;
    int wide;       /* AVX2 packets */
    kdr_shadow_stats st;
} shadow_ws;

/* ---- testing samples ----------------------------------------------------- */

/* Of the samples idx[0..n), keeps in idx those the candidates do not block
 * (packets of 8); returns how many are kept. */
static uint32_t filter_by_list(const kdr_scene *scene, shadow_ws *ws,
                               uint32_t *idx, uint32_t n, const uint32_t *cands,
                               size_t ncand, uint32_t *last) {
    uint32_t kept = 0;
    for (uint32_t g = 0; g < n; g += 8) {
        const kdr_ray *lanes[8];
        const int m = (int)(n - g < 8 ? n - g : 8);
        for (int j = 0; j < m; j++)
            lanes[j] = &ws->rays[idx[g + j]];
        const int blocked = kd_cone_packet_blocked(scene, lanes, m, cands, ncand,
                                                   last, ws->wide);
        for (int j = 0; j < m; j++)
            if (!((blocked >> j) & 1))
                idx[kept++] = idx[g + j];
    }
    ws->st.rays_traced += n;
    return kept;
}

/* Lit samples among idx[0..n), each traced alone through the whole tree
 * with kdr_occluded1 (the reference mode). */
static uint32_t lit_by_rays(const kdr_scene *scene, shadow_ws *ws,
                            const uint32_t *idx, uint32_t n) {
    kdr_trav_stats ts = {0};
    uint32_t lit = 0;
    for (uint32_t j = 0; j < n; j++)
        lit += kdr_occluded1(scene, &ws->rays[idx[j]], &ts) ? 0u : 1u;
    ws->st.rays_traced += n;
    ws->st.nodes_visited += ts.nodes_visited;
    return lit;
}

/* The same answers through kdr_trace_batch, whose bundles share node steps
 * between samples of one point (equal to kdr_occluded1 ray by ray). */
static uint32_t lit_by_tree(const kdr_scene *scene, shadow_ws *ws,
                            const uint32_t *idx, uint32_t n) {
    if (n < TREE_MIN_RAYS)
        return lit_by_rays(scene, ws, idx, n);
    for (uint32_t j = 0; j < n; j++) {
        const kdr_ray *r = &ws->rays[idx[j]];
        for (int k = 0; k < 3; k++) {
            ws->borg[3 * j + k] = r->org[k];
            ws->bdir[3 * j + k] = r->dir[k];
        }
        ws->btmax[j] = r->tmax; /* tmin is 0 for every sample */
    }
    kdr_ray_batch b = {.n = n, .org = ws->borg, .org_stride = 3, .dir = ws->bdir,
                       .tmax = ws->btmax, .tmax_stride = 1};
    kdr_hits out = {.hit = ws->bhit};
    kdr_trav_stats ts = {0};
    kdr_trace_batch(scene, &b, 0, n, KDR_ANY, KDR_TRAV_AUTO, &out, &ts);
    uint32_t lit = 0;
    for (uint32_t j = 0; j < n; j++)
        lit += ws->bhit[j] ? 0u : 1u;
    ws->st.rays_traced += n;
    ws->st.nodes_visited += ts.nodes_visited;
    return lit;
}

/* Drops the pending samples that the last blocker blocks. */
static uint32_t filter_by_last(const kdr_scene *scene, shadow_ws *ws,
                               uint32_t *idx, uint32_t n, uint32_t *last) {
    if (*last == NO_PRIM || n == 0)
        return n;
    const uint32_t cand = *last;
    const uint32_t kept = filter_by_list(scene, ws, idx, n, &cand, 1, last);
    ws->st.rays_traced -= n; /* counted when they are decided */
    return kept;
}

/* Before many samples of one point go through the tree: the closest hit of
 * the first pending one becomes the last blocker and removes every sample
 * it blocks (in umbra the others then cost one triangle test each); this
 * repeats up to LEARN_ROUNDS times and stops at the first sample that is
 * lit, which is then settled too. Returns the samples still pending. */
static uint32_t learn_blockers(const kdr_scene *scene, shadow_ws *ws,
                               uint32_t *idx, uint32_t n, uint32_t *last,
                               uint32_t *lit) {
    for (uint32_t round = 0; round < LEARN_ROUNDS && n >= LEARN_MIN; round++) {
        kdr_hit h;
        kdr_trav_stats ts = {0};
        const int hit = kdr_intersect1(scene, &ws->rays[idx[0]], &h, &ts);
        ws->st.nodes_visited += ts.nodes_visited;
        ws->st.rays_traced++;
        if (!hit) {
            ++*lit;
            idx[0] = idx[--n];
            break;
        }
        *last = (uint32_t)h.prim; /* blocks idx[0] too: same test, same interval */
        const uint32_t before = n;
        n = filter_by_last(scene, ws, idx, n, last);
        ws->st.rays_traced += before - n - 1;
    }
    return n;
}

/* ---- packets of neighbouring samples ------------------------------------------ */

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

/* Orders the pending samples along a Morton curve of the light's disc, so
 * that consecutive samples are close in direction. */
static void sort_pending(const kd_shadow_frame *f, shadow_ws *ws, uint32_t n) {
    for (uint32_t j = 0; j < n; j++) {
        const float *d = ws->rays[ws->idx[j]].dir;
        const uint64_t m = spread_bits(disc_coord(f, d, f->b1)) |
                           spread_bits(disc_coord(f, d, f->b2)) << 1;
        ws->keys[j] = m << 12 | ws->idx[j];
    }
    qsort(ws->keys, n, sizeof *ws->keys, cmp_u64);
    for (uint32_t j = 0; j < n; j++)
        ws->idx[j] = (uint32_t)(ws->keys[j] & 0xfffu);
}

/* The narrowest cone around the mean direction holding samples idx[0..n);
 * 0 if it would be wider than GROUP_MAX_ANGLE. */
static int group_cone(const kdr_scene *scene, const kd_shadow_frame *f,
                      const kdr_ray *rays, const uint32_t *idx, uint32_t n,
                      kd_cone *c) {
    double axis[3] = {0, 0, 0}, cos_min = 1.0;
    for (uint32_t j = 0; j < n; j++)
        for (int k = 0; k < 3; k++)
            axis[k] += rays[idx[j]].dir[k];
    const double len = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    if (!(len > 0.0))
        return 0;
    for (int k = 0; k < 3; k++)
        axis[k] /= len;
    for (uint32_t j = 0; j < n; j++) {
        const float *d = rays[idx[j]].dir;
        const double dl = sqrt((double)d[0] * d[0] + (double)d[1] * d[1] +
                               (double)d[2] * d[2]);
        cos_min = fmin(cos_min, (d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2]) / dl);
    }
    if (cos_min < cos(GROUP_MAX_ANGLE))
        return 0;
    kd_cone_init(c, scene, f, axis, sqrt((1.0 - cos_min) * (1.0 + cos_min)));
    return 1;
}

static uint32_t popcount8(int m) {
    uint32_t c = 0;
    for (; m; m &= m - 1)
        c++;
    return c;
}

/* Lit samples of one packet idx[0..n) (reordered in place). */
static void lit_group(const kdr_scene *scene, const kd_shadow_frame *f,
                      shadow_ws *ws, uint32_t *idx, uint32_t n, uint32_t *last,
                      uint32_t *lit) {
    const uint32_t n0 = n;
    n = filter_by_last(scene, ws, idx, n, last);
    ws->st.rays_traced += n0 - n;
    if (n == 0)
        return;
    kd_cone c;
    if (!group_cone(scene, f, ws->rays, idx, n, &c)) {
        *lit += lit_by_tree(scene, ws, idx, n);
        return;
    }
    const kdr_ray *lanes[8];
    for (uint32_t j = 0; j < n; j++)
        lanes[j] = &ws->rays[idx[j]];
    int open = 0;
    const int blocked = kd_cone_packet_walk(scene, &c, lanes, (int)n,
                                            GROUP_MAX_NODES, last,
                                            &ws->st.nodes_visited, &open, ws->wide);
    ws->st.rays_traced += n - popcount8(open);
    *lit += popcount8(((1 << n) - 1) & ~blocked & ~open);
    uint32_t rest[8], nrest = 0;
    for (uint32_t j = 0; j < n; j++)
        if ((open >> j) & 1)
            rest[nrest++] = idx[j];
    *lit += lit_by_tree(scene, ws, rest, nrest);
}

/* ---- one (point, light) ---------------------------------------------------- */

static int ws_reserve(shadow_ws *ws, uint32_t nsamples) {
    if (ws->rays)
        return KDR_OK;
    ws->rays = malloc(nsamples * sizeof *ws->rays);
    ws->idx = malloc(nsamples * sizeof *ws->idx);
    ws->keys = malloc(nsamples * sizeof *ws->keys);
    ws->borg = malloc(3 * nsamples * sizeof *ws->borg);
    ws->bdir = malloc(3 * nsamples * sizeof *ws->bdir);
    ws->btmax = malloc(nsamples * sizeof *ws->btmax);
    ws->bhit = malloc(nsamples);
    return ws->rays && ws->idx && ws->keys && ws->borg && ws->bdir && ws->btmax &&
                   ws->bhit
               ? KDR_OK
               : KDR_ENOMEM;
}

static void make_samples(const kd_shadow_frame *f, uint32_t n, shadow_ws *ws) {
    for (uint32_t s = 0; s < n; s++) {
        kd_shadow_frame_ray(f, s, n, &ws->rays[s]);
        ws->idx[s] = s;
    }
}

/* 1 if the last blocker also blocks sample 0: the point is probably in
 * umbra, and testing every sample against it first is worth it. */
static int umbra_likely(const kdr_scene *scene, const kd_shadow_frame *f,
                        uint32_t n, uint32_t last) {
    kdr_ray r;
    kd_ray_pre pre;
    float t, u, v;
    if (last == NO_PRIM)
        return 0;
    kd_shadow_frame_ray(f, 0, n, &r);
    kd_ray_precompute(r.org, r.dir, &pre);
    return kd_tri_intersect(&pre, scene->tris + 9 * (size_t)last, r.tmin, r.tmax,
                            &t, &u, &v);
}

/* Lit samples once the whole-light cone was walked (rc, ws->cl). */
static int lit_after_walk(const kdr_scene *scene, const kd_shadow_frame *f,
                          shadow_ws *ws, int rc, uint32_t n, uint32_t *last,
                          uint32_t *lit) {
    const uint32_t n0 = n;
    if (rc == KDR_OK) {
        *lit = filter_by_list(scene, ws, ws->idx, n, ws->cl.v, ws->cl.n, last);
        return KDR_OK;
    }
    const uint32_t width = ws->wide ? 8u : 4u;
    /* a packet covers about width/n of the light's disc */
    if (asin(f->sin_a) * sqrt((double)width / n) > GROUP_MAX_ANGLE) {
        *lit = 0;
        n = filter_by_last(scene, ws, ws->idx, n, last);
        ws->st.rays_traced += n0 - n;
        n = learn_blockers(scene, ws, ws->idx, n, last, lit);
        *lit += lit_by_tree(scene, ws, ws->idx, n);
        return KDR_OK;
    }
    sort_pending(f, ws, n);
    *lit = 0;
    for (uint32_t g = 0; g < n; g += width)
        lit_group(scene, f, ws, ws->idx + g, n - g < width ? n - g : width, last,
                  lit);
    return KDR_OK;
}

/* The whole-light walk, unless the back-off says it would fail again. */
static int walk_light(const kdr_scene *scene, const kd_shadow_frame *f,
                      shadow_ws *ws, uint32_t pending, light_state *ls) {
    if (ls->skip > 0) {
        ls->skip--;
        return KD_CONE_OVER;
    }
    kd_cone c;
    kd_cone_init(&c, scene, f, NULL, 0.0);
    const int rc = kd_cone_collect(scene, &c, &ws->cl, CONE_MAX_CANDS,
                                   CONE_NODES_BASE + CONE_NODES_PER_SAMPLE * pending,
                                   &ws->st.nodes_visited);
    if (rc == KD_CONE_OVER) {
        ls->backoff = ls->backoff * 2 + 1 > WALK_BACKOFF_MAX ? WALK_BACKOFF_MAX
                                                             : ls->backoff * 2 + 1;
        ls->skip = ls->backoff;
    } else {
        ls->backoff = 0;
    }
    return rc;
}

/* Below CONE_WALK_MIN_SAMPLES: the whole-light cone walks the tree only
 * until its first candidate (max_cands 0: the walk stops at the first
 * triangle the cull keeps). A cone that reaches none is decided, visibility
 * exactly 1 with no rays, as the contract requires of a point whose cone
 * reaches no occluder. Returns 1 for such a cone, 0 otherwise (and
 * KDR_ENOMEM through *rc). */
static int cone_in_empty_space(const kdr_scene *scene, const kd_shadow_frame *f,
                               shadow_ws *ws, uint64_t max_nodes, int *rc) {
    kd_cone c;
    kd_cone_init(&c, scene, f, NULL, 0.0);
    const int r = kd_cone_collect(scene, &c, &ws->cl, 0, max_nodes,
                                  &ws->st.nodes_visited);
    *rc = r == KDR_ENOMEM ? KDR_ENOMEM : KDR_OK;
    return r == KDR_OK && ws->cl.n == 0; /* over budget: not decided */
}

static int visibility_by_cone(const kdr_scene *scene, const kd_shadow_frame *f,
                              uint32_t nsamples, shadow_ws *ws, light_state *ls,
                              float *vis) {
    uint32_t pending = nsamples, lit = 0;
    int made = 0, rc = ws_reserve(ws, nsamples);
    if (rc != KDR_OK)
        return rc;
    if (umbra_likely(scene, f, nsamples, ls->last)) {
        make_samples(f, nsamples, ws);
        made = 1;
        pending = filter_by_last(scene, ws, ws->idx, nsamples, &ls->last);
        ws->st.rays_traced += nsamples - pending;
    }
    if (pending > 0 && nsamples < CONE_WALK_MIN_SAMPLES) {
        if (cone_in_empty_space(scene, f, ws,
                                CONE_NODES_BASE + CONE_NODES_PER_SAMPLE * pending,
                                &rc)) {
            ws->st.cones_decided += !made;
            lit = pending;
        } else if (rc == KDR_OK) {
            if (!made)
                make_samples(f, nsamples, ws);
            lit = lit_by_tree(scene, ws, ws->idx, pending);
        }
    } else if (pending > 0) {
        rc = walk_light(scene, f, ws, pending, ls);
        if (rc == KDR_ENOMEM)
            return rc;
        if (rc == KDR_OK && ws->cl.n == 0) {
            ws->st.cones_decided += !made;
            lit = pending;
        } else {
            if (!made)
                make_samples(f, nsamples, ws);
            rc = lit_after_walk(scene, f, ws, rc, pending, &ls->last, &lit);
        }
    }
    *vis = (float)lit / (float)nsamples;
    return rc;
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
                rc = ws_reserve(ws, q->samples);
                if (rc == KDR_OK) {
                    make_samples(&f, q->samples, ws);
                    *vis = (float)lit_by_rays(scene, ws, ws->idx, q->samples) /
                           (float)q->samples;
                }
            } else if (rc == KDR_OK) {
                rc = visibility_by_cone(scene, &f, q->samples, ws, &ws->lights[l], vis);
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
    ws.wide = kdr_cpu_has_avx2();
    ws.lights = malloc(q->nlights * sizeof *ws.lights);
    int rc = ws.lights ? KDR_OK : KDR_ENOMEM;
    for (size_t l = 0; rc == KDR_OK && l < q->nlights; l++)
        ws.lights[l] = (light_state){NO_PRIM, 0, 0};
    if (rc == KDR_OK)
        rc = trace_points(scene, q, first, count, mode, visibility, &ws);
    if (stats) {
        stats->cones_decided += ws.st.cones_decided;
        stats->rays_traced += ws.st.rays_traced;
        stats->nodes_visited += ws.st.nodes_visited;
    }
    free(ws.cl.v);
    free(ws.rays);
    free(ws.idx);
    free(ws.keys);
    free(ws.borg);
    free(ws.bdir);
    free(ws.btmax);
    free(ws.bhit);
    free(ws.lights);
    return rc;
}
