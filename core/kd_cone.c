/*
 * kd_cone.c — one (point, light) of the cone-shadow query: visibility of a
 * spherical light from a point, as the fraction of kdr_shadow_ray samples
 * whose segment reaches the light. Which points take which path, in what
 * order and in which groups is kd_cone_query.c's (kdr_shadow_trace).
 *
 * KDR_SHADOW_RAYS traces every sample through the kd-tree (the reference:
 * kd_pair_visibility_rays). KDR_SHADOW_CONE (kd_pair_visibility) first
 * asks a cheap test whether the point's cone walk can pay (kd_walk_pays:
 * not below CONE_WALK_FROM samples, nor toward wide lights below
 * CONE_WALK_WIDE_FROM); when it cannot, the point's samples go straight to
 * any-hit bundles (kdr_trace_batch). Otherwise it decides the (point,
 * light) by cones, from the whole light down to small groups of samples,
 * and traces only what no cone decides (a group's shared walk, when the
 * caller made one, replaces step 1's walk: kd_cone_group.c):
 *  1. Candidates: the cone of the whole light walks the kd-tree with a
 *     budget (kd_cone_trav.c); every triangle its cull keeps is judged by
 *     a proof against the float triangle test (kd_cone_proof.c, which needs
 *     the fixed start a normal gives): it misses every sample segment
 *     (dropped: a point's own surface, a triangle beside the cone), covers
 *     them all (umbra: visibility 0, no samples), or may do either (a
 *     candidate).
 *  2. No candidate left: visibility 1, no samples (the contract's decided
 *     cone).
 *  3. Refinement (kd_cone_cells.c): the samples split into four cells of
 *     their parameters, each with its own cone, judged against the parent's
 *     candidates the same way: lit, umbra, or split again; cells of a few
 *     samples test them in packets against their candidates.
 *  4. A busy cone (the walk over budget): the samples are sorted along a
 *     Morton curve of the light's disc and packets of 4/8 neighbours walk
 *     their own cones, or, where those would be wide, a few closest hits
 *     learn blockers and the rest go through the tree in bundles
 *     (kdr_trace_batch). A busy cone makes the next points of that light
 *     skip step 1 for a while (back-off): neighbours see the same busy
 *     cone.
 *
 * Exactness: a cell is decided only by proofs made against the float
 * arithmetic of kd_tri_intersect (or, without normals, by the walk's cull,
 * which keeps every triangle a segment could touch); every list holds all
 * triangles its samples can touch; every test is kd_tri_intersect over
 * [tmin, tmax]; and a hit on any triangle is an occlusion however it was
 * found. The visibility equals KDR_SHADOW_RAYS bit for bit, whichever path
 * was taken.
 */
#include <stdlib.h>

#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_tri.h"

/* ---- testing samples ----------------------------------------------------- */

/* Lit samples among idx[0..n), each traced alone through the whole tree
 * with kdr_occluded1 (the reference mode). */
static uint32_t lit_by_rays(const kdr_scene *scene, kd_shadow_ws *ws,
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
static uint32_t lit_by_tree(const kdr_scene *scene, kd_shadow_ws *ws,
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
static uint32_t filter_by_last(const kdr_scene *scene, kd_shadow_ws *ws,
                               uint32_t *idx, uint32_t n, uint32_t *last) {
    if (*last == KD_NO_PRIM || n == 0)
        return n;
    /* one triangle: the scalar test; a packet's set-up (shears of 8 rays
     * transposed into lanes) costs several times one test */
    const float *tri = scene->tris + 9 * (size_t)*last;
    uint32_t kept = 0;
    for (uint32_t j = 0; j < n; j++) {
        const kdr_ray *r = &ws->rays[idx[j]];
        kd_ray_pre pre;
        float t, u, v;
        kd_ray_precompute(r->org, r->dir, &pre);
        if (!kd_tri_intersect(&pre, tri, r->tmin, r->tmax, &t, &u, &v))
            idx[kept++] = idx[j];
    }
    return kept;
}

/* Before many samples of one point go through the tree: the closest hit of
 * the first pending one becomes the last blocker and removes every sample
 * it blocks (in umbra the others then cost one triangle test each); this
 * repeats up to LEARN_ROUNDS times and stops at the first sample that is
 * lit, which is then settled too. Returns the samples still pending. */
static uint32_t learn_blockers(const kdr_scene *scene, kd_shadow_ws *ws,
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

/* Up to this many pending samples sort_pending sorts by insertion. */
#define SORT_INSERT_MAX 128u

static int cmp_u64(const void *a, const void *b) {
    const uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

/* Orders the pending samples along a Morton curve of the light's disc, so
 * that consecutive samples are close in direction. */
static void sort_pending(const kd_shadow_frame *f, kd_shadow_ws *ws, uint32_t n) {
    for (uint32_t j = 0; j < n; j++) {
        const float *d = ws->rays[ws->idx[j]].dir;
        const uint64_t m = spread_bits(disc_coord(f, d, f->b1)) |
                           spread_bits(disc_coord(f, d, f->b2)) << 1;
        ws->keys[j] = m << 12 | ws->idx[j];
    }
    if (n <= SORT_INSERT_MAX) {
        /* a point's few dozen keys: insertion sort, without qsort's
         * merge buffers and calls per comparison (the keys are distinct,
         * so the order is the same) */
        for (uint32_t j = 1; j < n; j++) {
            const uint64_t k = ws->keys[j];
            uint32_t i = j;
            for (; i > 0 && ws->keys[i - 1] > k; i--)
                ws->keys[i] = ws->keys[i - 1];
            ws->keys[i] = k;
        }
    } else {
        qsort(ws->keys, n, sizeof *ws->keys, cmp_u64);
    }
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
                      kd_shadow_ws *ws, uint32_t *idx, uint32_t n, uint32_t *last,
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

static int ws_reserve(kd_shadow_ws *ws, uint32_t nsamples) {
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

static void make_samples(const kd_shadow_frame *f, uint32_t n, kd_shadow_ws *ws) {
    kd_shadow_frame_rays(f, NULL, 0, n, n, ws->rays);
    for (uint32_t s = 0; s < n; s++)
        ws->idx[s] = s;
}

/* A cone too busy to decide (its walk went over budget): the samples are
 * sorted along a Morton curve of the light's disc and packets of 4/8
 * neighbours walk their own narrow cones; when those would be wide, a few
 * closest hits learn blockers and the rest go through the tree in bundles
 * (kdr_trace_batch). */
static uint32_t lit_busy(const kdr_scene *scene, const kd_shadow_frame *f,
                         kd_shadow_ws *ws, uint32_t n, uint32_t *last) {
    uint32_t lit = 0;
    make_samples(f, n, ws);
    const uint32_t width = ws->wide ? 8u : 4u;
    /* a packet covers about width/n of the light's disc */
    if (asin(f->sin_a) * sqrt((double)width / n) > GROUP_MAX_ANGLE) {
        uint32_t m = filter_by_last(scene, ws, ws->idx, n, last);
        ws->st.rays_traced += n - m;
        m = learn_blockers(scene, ws, ws->idx, m, last, &lit);
        return lit + lit_by_tree(scene, ws, ws->idx, m);
    }
    sort_pending(f, ws, n);
    for (uint32_t g = 0; g < n; g += width)
        lit_group(scene, f, ws, ws->idx + g, n - g < width ? n - g : width, last, &lit);
    return lit;
}

/* The cheap test: does a point with this many samples toward a light of
 * this angular size (sin_a = r / D) walk its whole light's cone? Below
 * CONE_WALK_FROM samples never (no cone set-up either: the query's points
 * then go through trace_unwalked in chunks); wide cones (penumbra-heavy:
 * the walk goes over budget, and a decided cone is rare) only from
 * CONE_WALK_WIDE_FROM samples on. */
int kd_walk_pays(uint32_t nsamples, double sin_a, kd_walk_policy policy) {
    if (policy != KD_WALK_AUTO)
        return policy == KD_WALK_ALWAYS || policy == KD_WALK_GROUPS;
    if (nsamples < CONE_WALK_FROM)
        return 0;
    return sin_a <= CONE_WIDE_SIN || nsamples >= CONE_WALK_WIDE_FROM;
}

/* The whole light's candidate budget for a point that walks: a full one,
 * a couple at few samples, or none (the walk then only looks for an empty
 * cone, stopping at the first candidate) below CONE_RAYS_BELOW samples
 * (forced walks only: the cheap test sends such points to bundles) and
 * while the light backs off after busy cones. */
static size_t cand_budget(uint32_t nsamples, kd_light_state *ls) {
    if (ls->skip > 0) {
        ls->skip--;
        return 0;
    }
    if (nsamples < CONE_RAYS_BELOW)
        return 0;
    return nsamples < CONE_WALK_MIN_SAMPLES ? CONE_FEW_CANDS : CONE_MAX_CANDS;
}

int kd_pair_visibility(const kdr_scene *scene, const kd_shadow_frame *f,
                       uint32_t nsamples, kd_shadow_ws *ws, kd_light_state *ls,
                       const kd_cand_list *group, float *vis) {
    uint32_t lit = 0;
    const uint64_t traced = ws->st.rays_traced;
    int rc = ws_reserve(ws, nsamples);
    if (rc != KDR_OK)
        return rc;
    if (group && group->n == 0) {
        /* the group's cone reaches no triangle but those kd_group_clear
         * showed harmless: every segment is unblocked */
        ws->st.cones_decided++;
        *vis = 1.0f;
        return KDR_OK;
    }
    if (!kd_walk_pays(nsamples, f->sin_a, ws->policy)) {
        /* a wide cone at moderate samples: straight to the bundles */
        make_samples(f, nsamples, ws);
        *vis = (float)lit_by_tree(scene, ws, ws->idx, nsamples) / (float)nsamples;
        return KDR_OK;
    }
    kd_cone_pair pr = {.scene = scene, .f = f, .n = nsamples, .wide = ws->wide,
                       .wide16 = ws->wide16,
                       .proofs = f->along == 0.0f, .last = ls->last,
                       .max_cands = cand_budget(nsamples, ls),
                       .group = group ? ws->gpre : NULL,
                       .ngroup = group ? group->n : 0,
                       .gsoa = group && ws->gsoa.f ? &ws->gsoa : NULL};
    /* every tmax is the float of (near side - along) >= D - r - along */
    pr.tmax_lo = ((f->dist - f->radius) - (double)f->along) * (1.0 - 0x1p-22);
    rc = kd_cells_lit(&ws->cells, &pr, &lit);
    ls->last = pr.last;
    ws->st.rays_traced += pr.st.rays_traced;
    ws->st.nodes_visited += pr.st.nodes_visited;
    if (rc == KD_CONE_OVER && pr.max_cands == CONE_MAX_CANDS) {
        ls->backoff = ls->backoff * 2 + 1 > WALK_BACKOFF_MAX ? WALK_BACKOFF_MAX
                                                             : ls->backoff * 2 + 1;
        ls->skip = ls->backoff;
    } else if (rc == KDR_OK && pr.max_cands == CONE_MAX_CANDS) {
        ls->backoff = 0;
    }
    if (rc == KD_CONE_OVER) {
        lit = lit_busy(scene, f, ws, nsamples, &ls->last);
        rc = KDR_OK;
    }
    ws->st.cones_decided += rc == KDR_OK && ws->st.rays_traced == traced;
    *vis = (float)lit / (float)nsamples;
    return rc;
}

int kd_pair_visibility_rays(const kdr_scene *scene, const kd_shadow_frame *f,
                            uint32_t nsamples, kd_shadow_ws *ws, float *vis) {
    const int rc = ws_reserve(ws, nsamples);
    if (rc != KDR_OK)
        return rc;
    make_samples(f, nsamples, ws);
    *vis = (float)lit_by_rays(scene, ws, ws->idx, nsamples) / (float)nsamples;
    return KDR_OK;
}

void kd_shadow_ws_free(kd_shadow_ws *ws) {
    free(ws->cl.v);
    free(ws->gl.v);
    free(ws->gpre);
    free(ws->gsoa.f);
    free(ws->gsoa.prim);
    free(ws->rays);
    free(ws->idx);
    free(ws->keys);
    free(ws->borg);
    free(ws->bdir);
    free(ws->btmax);
    free(ws->bhit);
    free(ws->lights);
    kd_cells_free(&ws->cells);
}
