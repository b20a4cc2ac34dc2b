/*
 * kd_cone.c — the cone-shadow query (kdr_shadow_trace): visibility of
 * spherical lights from points, as the fraction of kdr_shadow_ray samples
 * whose segment reaches the light.
 *
 * KDR_SHADOW_RAYS traces every sample through the kd-tree (the reference).
 * KDR_SHADOW_CONE first asks a cheap test whether a point's cone walk can
 * pay (walk_pays: not below CONE_WALK_FROM samples, nor toward wide lights
 * below CONE_WALK_WIDE_FROM); when it cannot, the point's samples go
 * straight to any-hit bundles (kdr_trace_batch), chunked over consecutive
 * points below CONE_WALK_FROM. Otherwise it decides the (point, light) by
 * cones, from the whole light down to small groups of samples, and traces
 * only what no cone decides (runs of consecutive points first try to share
 * step 1's walk: trace_grouped, kd_cone_group.c):
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
 * kdr_shadow_trace_order takes the points as a list of indices: the j-th
 * point traced is order[j], which seeds its samples and names its slots,
 * so only the cost depends on the order (groups form among consecutive
 * points of the list).
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
    kd_cand_list gl; /* a group's list (trace_grouped) */
    kd_tri_pre *gpre; /* its triangles' cull data (GROUP_MAX_CANDS) */
    kdr_ray *rays;  /* the samples of one (point, light) */
    uint32_t *idx;  /* pending (not yet decided) samples */
    uint64_t *keys; /* Morton key << 12 | sample, for grouping */
    light_state *lights;
    float *borg, *bdir, *btmax; /* pending samples as a kdr_ray_batch */
    uint8_t *bhit;
    int wide;       /* AVX2 packets */
    kd_walk_policy policy;
    const size_t *order; /* non-NULL: the j-th point traced is order[j] */
    size_t first;        /* else it is first + j */
    kdr_shadow_stats st;
    kd_cells cells;
} shadow_ws;

/* ---- testing samples ----------------------------------------------------- */

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

/* A cone too busy to decide (its walk went over budget): the samples are
 * sorted along a Morton curve of the light's disc and packets of 4/8
 * neighbours walk their own narrow cones; when those would be wide, a few
 * closest hits learn blockers and the rest go through the tree in bundles
 * (kdr_trace_batch). */
static uint32_t lit_busy(const kdr_scene *scene, const kd_shadow_frame *f,
                         shadow_ws *ws, uint32_t n, uint32_t *last) {
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
static int walk_pays(uint32_t nsamples, double sin_a, kd_walk_policy policy) {
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
static size_t cand_budget(uint32_t nsamples, light_state *ls) {
    if (ls->skip > 0) {
        ls->skip--;
        return 0;
    }
    if (nsamples < CONE_RAYS_BELOW)
        return 0;
    return nsamples < CONE_WALK_MIN_SAMPLES ? CONE_FEW_CANDS : CONE_MAX_CANDS;
}

static int visibility_by_cone(const kdr_scene *scene, const kd_shadow_frame *f,
                              uint32_t nsamples, shadow_ws *ws, light_state *ls,
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
    if (!walk_pays(nsamples, f->sin_a, ws->policy)) {
        /* a wide cone at moderate samples: straight to the bundles */
        make_samples(f, nsamples, ws);
        *vis = (float)lit_by_tree(scene, ws, ws->idx, nsamples) / (float)nsamples;
        return KDR_OK;
    }
    kd_cone_pair pr = {.scene = scene, .f = f, .n = nsamples, .wide = ws->wide,
                       .proofs = f->along == 0.0f, .last = ls->last,
                       .max_cands = cand_budget(nsamples, ls),
                       .group = group ? ws->gpre : NULL,
                       .ngroup = group ? group->n : 0};
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

/* ---- the query ----------------------------------------------------------- */

/* The index of the j-th point traced: its samples' seed and its answers'
 * slots (kdr_shadow_trace_order passes points in its own order). */
static size_t point_at(const shadow_ws *ws, size_t j) {
    return ws->order ? ws->order[j] : ws->first + j;
}

static int query_valid(const kdr_scene *scene, const kdr_shadow_query *q,
                       size_t first, size_t count, const float *visibility) {
    if (!scene || !q || !visibility || !q->points || !q->lights)
        return 0;
    if (q->nlights < 1 || q->samples < 1 || q->samples > SHADOW_MAX_SAMPLES)
        return 0;
    return first <= q->n && count <= q->n - first;
}

/* Points that do not walk their cones, a chunk at a time: the samples of
 * consecutive points (toward the same lights, from nearby surfaces: the
 * bundles stay coherent) go through the tree in one kdr_trace_batch, whose
 * set-up is then paid per chunk, not per point. */
static int trace_unwalked(const kdr_scene *scene, const kdr_shadow_query *q,
                          size_t count, float *visibility, shadow_ws *ws) {
    const uint32_t n = q->samples;
    const size_t per_point = (size_t)n * q->nlights;
    size_t step = UNWALKED_CHUNK_RAYS / per_point;
    step = step ? step : 1;
    const size_t cap = step * per_point;
    float *org = malloc(3 * cap * sizeof *org), *dir = malloc(3 * cap * sizeof *dir);
    float *tmax = malloc(cap * sizeof *tmax);
    uint8_t *hit = malloc(cap);
    int rc = org && dir && tmax && hit ? KDR_OK : KDR_ENOMEM;
    for (size_t j0 = 0; rc == KDR_OK && j0 < count; j0 += step) {
        const size_t j1 = count - j0 < step ? count : j0 + step;
        size_t m = 0;
        for (size_t j = j0; rc == KDR_OK && j < j1; j++)
            for (size_t l = 0; rc == KDR_OK && l < q->nlights; l++) {
                kd_shadow_frame f;
                rc = kd_shadow_frame_init(scene, q, point_at(ws, j), l, &f);
                for (uint32_t s = 0; rc == KDR_OK && s < n; s++, m++) {
                    kdr_ray r;
                    kd_shadow_frame_ray(&f, s, n, &r);
                    for (int k = 0; k < 3; k++) {
                        org[3 * m + k] = r.org[k];
                        dir[3 * m + k] = r.dir[k];
                    }
                    tmax[m] = r.tmax; /* tmin is 0 for every sample */
                }
            }
        if (rc != KDR_OK)
            break;
        kdr_ray_batch b = {.n = m, .org = org, .org_stride = 3, .dir = dir,
                           .tmax = tmax, .tmax_stride = 1};
        kdr_hits out = {.hit = hit};
        kdr_trav_stats ts = {0};
        rc = kdr_trace_batch(scene, &b, 0, m, KDR_ANY, KDR_TRAV_AUTO, &out, &ts);
        ws->st.rays_traced += m;
        ws->st.nodes_visited += ts.nodes_visited;
        for (size_t k = 0, pair = 0; rc == KDR_OK && k < m; k += n, pair++) {
            uint32_t lit = 0;
            for (uint32_t s = 0; s < n; s++)
                lit += hit[k + s] ? 0u : 1u;
            const size_t i = point_at(ws, j0 + pair / q->nlights);
            visibility[i * q->nlights + pair % q->nlights] = (float)lit / (float)n;
        }
    }
    free(org);
    free(dir);
    free(tmax);
    free(hit);
    return rc;
}

/* The group list of frames fs[0..n) (one light), in *gl: 1 if the group's
 * cone exists and its walk stayed within budget, else 0 (each point then
 * walks on its own). */
static int group_list(const kdr_scene *scene, const kd_shadow_frame *const *fs, size_t n,
                      uint32_t nsamples, shadow_ws *ws, kd_cand_list *gl, int *rc) {
    const double spread = ws->policy == KD_WALK_GROUPS ? 1.0 : GROUP_MAX_SPREAD;
    kd_cone gc;
    /* points that will not walk (walk_pays) gain only from an empty list,
     * rare where walks do not pay: no group walk for them */
    if (n < 2 || !walk_pays(nsamples, fs[0]->sin_a, ws->policy) ||
        !kd_group_cone(scene, fs, n, spread, &gc))
        return 0;
    const uint64_t max_nodes =
        GROUP_WALK_NODES_BASE + GROUP_WALK_NODES_PER_POINT * (uint64_t)n;
    /* no prism test here: each point's own cull has it, and most of what
     * it would drop (the surface under the points) kd_group_clear drops
     * for the group anyway (callgrind of the picture: -2.2% without it) */
    const int r = kd_cone_collect(scene, &gc, gl, GROUP_MAX_CANDS, max_nodes, 0,
                                  &ws->st.nodes_visited);
    if (r == KDR_ENOMEM)
        *rc = KDR_ENOMEM;
    if (r != KDR_OK)
        return 0;
    if (!ws->gpre && !(ws->gpre = malloc(GROUP_MAX_CANDS * sizeof *ws->gpre))) {
        *rc = KDR_ENOMEM;
        return 0;
    }
    for (size_t j = 0; j < gl->n; j++)
        kd_tri_pre_plane(&ws->gpre[j], scene->tris + 9 * (size_t)gl->v[j], gl->v[j]);
    /* the surfaces under the points (most of a list) are dropped here once
     * for the whole group instead of by each point's cull; gpre keeps the
     * rest (gl->n of them). None left: no segment of the group can touch a
     * triangle, and the whole group is lit. */
    kd_group_clear(fs, n, gc.band, ws->gpre, gl->n);
    size_t kept = 0;
    for (size_t j = 0; j < gl->n; j++)
        if (!ws->gpre[j].clear) {
            ws->gpre[kept] = ws->gpre[j];
            kd_tri_pre_sides(&ws->gpre[kept], scene->tris + 9 * (size_t)ws->gpre[kept].prim);
            kept++;
        }
    gl->n = kept;
    return 1;
}

/* Cone-mode points through shared walks: runs of up to GROUP_POINTS
 * consecutive points, light by light, share one walk of their group's cone
 * (kd_group_cone) when it exists; each point then judges that list. */
static int trace_grouped(const kdr_scene *scene, const kdr_shadow_query *q, size_t count,
                         float *visibility, shadow_ws *ws) {
    kd_shadow_frame fr[GROUP_POINTS];
    const kd_shadow_frame *fs[GROUP_POINTS];
    int rc = KDR_OK;
    for (size_t j0 = 0; rc == KDR_OK && j0 < count; j0 += GROUP_POINTS) {
        const size_t n = count - j0 < GROUP_POINTS ? count - j0 : GROUP_POINTS;
        for (size_t l = 0; rc == KDR_OK && l < q->nlights; l++) {
            for (size_t j = 0; rc == KDR_OK && j < n; j++) {
                rc = kd_shadow_frame_init(scene, q, point_at(ws, j0 + j), l, &fr[j]);
                fs[j] = &fr[j];
            }
            if (rc != KDR_OK)
                break;
            const int grouped = group_list(scene, fs, n, q->samples, ws, &ws->gl, &rc);
            for (size_t j = 0; rc == KDR_OK && j < n; j++)
                rc = visibility_by_cone(scene, &fr[j], q->samples, ws, &ws->lights[l],
                                        grouped ? &ws->gl : NULL,
                                        &visibility[point_at(ws, j0 + j) * q->nlights + l]);
        }
    }
    return rc;
}

static int trace_points(const kdr_scene *scene, const kdr_shadow_query *q, size_t count,
                        kdr_shadow_mode mode, float *visibility, shadow_ws *ws) {
    if (mode == KDR_SHADOW_CONE &&
        (ws->policy == KD_WALK_NEVER ||
         (ws->policy == KD_WALK_AUTO && q->samples < CONE_WALK_FROM)))
        return trace_unwalked(scene, q, count, visibility, ws);
    if (mode == KDR_SHADOW_CONE &&
        (ws->policy == KD_WALK_GROUPS || (ws->policy == KD_WALK_AUTO && GROUP_POINTS > 1)))
        return trace_grouped(scene, q, count, visibility, ws);
    for (size_t j = 0; j < count; j++) {
        const size_t i = point_at(ws, j);
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
                rc = visibility_by_cone(scene, &f, q->samples, ws, &ws->lights[l], NULL,
                                        vis);
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
    return kd_shadow_trace_policy(scene, q, first, count, mode, KD_WALK_AUTO,
                                  visibility, stats);
}

int kdr_shadow_trace_order(const kdr_scene *scene, const kdr_shadow_query *q,
                           const size_t *order, size_t count, kdr_shadow_mode mode,
                           float *visibility, kdr_shadow_stats *stats) {
    return kd_shadow_trace_order_policy(scene, q, order, count, mode, KD_WALK_AUTO,
                                        visibility, stats);
}

static int trace_query(const kdr_scene *scene, const kdr_shadow_query *q,
                       const size_t *order, size_t first, size_t count,
                       kdr_shadow_mode mode, kd_walk_policy policy, float *visibility,
                       kdr_shadow_stats *stats);

int kd_shadow_trace_policy(const kdr_scene *scene, const kdr_shadow_query *q,
                           size_t first, size_t count, kdr_shadow_mode mode,
                           kd_walk_policy policy, float *visibility,
                           kdr_shadow_stats *stats) {
    if (!query_valid(scene, q, first, count, visibility))
        return KDR_EINVAL;
    return trace_query(scene, q, NULL, first, count, mode, policy, visibility, stats);
}

int kd_shadow_trace_order_policy(const kdr_scene *scene, const kdr_shadow_query *q,
                                 const size_t *order, size_t count, kdr_shadow_mode mode,
                                 kd_walk_policy policy, float *visibility,
                                 kdr_shadow_stats *stats) {
    if (!query_valid(scene, q, 0, 0, visibility) || (count > 0 && !order))
        return KDR_EINVAL;
    for (size_t j = 0; j < count; j++)
        if (order[j] >= q->n)
            return KDR_EINVAL;
    return trace_query(scene, q, order, 0, count, mode, policy, visibility, stats);
}

static int trace_query(const kdr_scene *scene, const kdr_shadow_query *q,
                       const size_t *order, size_t first, size_t count,
                       kdr_shadow_mode mode, kd_walk_policy policy, float *visibility,
                       kdr_shadow_stats *stats) {
    if (mode != KDR_SHADOW_CONE && mode != KDR_SHADOW_RAYS)
        return KDR_EINVAL;
    if (policy != KD_WALK_AUTO && policy != KD_WALK_ALWAYS && policy != KD_WALK_NEVER &&
        policy != KD_WALK_GROUPS)
        return KDR_EINVAL;
    shadow_ws ws = {0};
    ws.policy = policy;
    ws.order = order;
    ws.first = first;
    ws.wide = kdr_cpu_has_avx2();
    ws.lights = malloc(q->nlights * sizeof *ws.lights);
    int rc = ws.lights ? KDR_OK : KDR_ENOMEM;
    for (size_t l = 0; rc == KDR_OK && l < q->nlights; l++)
        ws.lights[l] = (light_state){NO_PRIM, 0, 0};
    if (rc == KDR_OK)
        rc = trace_points(scene, q, count, mode, visibility, &ws);
    if (stats) {
        stats->cones_decided += ws.st.cones_decided;
        stats->rays_traced += ws.st.rays_traced;
        stats->nodes_visited += ws.st.nodes_visited;
    }
    free(ws.cl.v);
    free(ws.gl.v);
    free(ws.gpre);
    free(ws.rays);
    free(ws.idx);
    free(ws.keys);
    free(ws.borg);
    free(ws.bdir);
    free(ws.btmax);
    free(ws.bhit);
    free(ws.lights);
    kd_cells_free(&ws.cells);
    return rc;
}
