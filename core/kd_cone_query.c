/*
 * kd_cone_query.c — the cone-shadow query's driver (kdr_shadow_trace,
 * kdr_shadow_trace_order and their forced-policy forms for tests): checks
 * the query, then sends its points down one of three paths. Below
 * CONE_WALK_FROM samples (or with walks forced off) no cone walks: the
 * samples of consecutive points go through the tree (any hit) a chunk at
 * a time, in bundles or, at 1-2 samples on larger scenes, the interleaved
 * walk far end first (trace_unwalked, trace_chunk). From there on, runs of up to
 * GROUP_POINTS consecutive points toward one light share one walk of their
 * group's cone (trace_grouped, kd_cone_group.c) and each point judges that
 * list (kd_pair_visibility in kd_cone.c); a (point, light) pair whose walk
 * cannot pay (kd_walk_pays: a wide light below CONE_WALK_WIDE_FROM
 * samples) joins the same chunks as unwalked points instead. KDR_SHADOW_RAYS traces every
 * sample alone, point by point.
 *
 * kdr_shadow_trace_order takes the points as a list of indices: the j-th
 * point traced is order[j], which seeds its samples and names its slots,
 * so only the cost depends on the order (groups form among consecutive
 * points of the list).
 */
#include <stdlib.h>

#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_stream.h" /* kd_cpu_has_avx512, kd_stream_trace_far */
#include "kd_traverse_bundle.h"

/* The index of the j-th point traced: its samples' seed and its answers'
 * slots (kdr_shadow_trace_order passes points in its own order). */
static size_t point_at(const kd_shadow_ws *ws, size_t j) {
    return ws->order ? ws->order[j] : ws->first + j;
}

static int query_valid(const kdr_scene *scene, const kdr_shadow_query *q,
                       size_t first, size_t count, const float *visibility) {
    if (!scene || !q || !visibility || !q->points || !q->lights)
        return 0;
    if (q->nlights < 1 || q->samples < 1 || q->samples > KD_SHADOW_MAX_SAMPLES)
        return 0;
    return first <= q->n && count <= q->n - first;
}

/* One chunk of unwalked samples (n per point and light), any hit. At 1-2
 * samples on scenes of at least n x UNWALKED_STREAM_BYTES_PER_SAMPLE bytes
 * the interleaved walk, far end first: a bundle there would hold the
 * samples of 8-16 points a pixel apart, and the walk hides the larger
 * tree's memory latency. Else bundles, without kdr_trace_batch's fallback
 * to the interleaved walk: its tests (directions spread over 8 rays, the
 * lanes' occupancy) were tuned on AO rays and send a wide light's 1-8
 * samples there, where bundles trace them faster; on scenes of at least
 * UNWALKED_NARROW_MIN_BYTES, 8 lanes at most up to
 * UNWALKED_NARROW_MAX_SAMPLES samples (fewer points a bundle; kd_tune.h).
 * Above UNWALKED_ORDER_FROM samples a pair's samples arrive in
 * kd_shadow_disc_order
 * and the bundles take them as they come; below, each chunk's runs are
 * regrouped by direction (KB_SORT).
 * Every route returns the single-ray walk's answers. */
static void trace_chunk(const kdr_scene *scene, const kdr_ray_batch *b, size_t m,
                        uint32_t n, uint8_t *hit, kdr_trav_stats *ts) {
    kdr_hits out = {.hit = hit};
    const uint64_t bytes = scene->stats.bytes;
    if (scene->nodes && n <= UNWALKED_STREAM_MAX_SAMPLES &&
        bytes >= (uint64_t)n * UNWALKED_STREAM_BYTES_PER_SAMPLE) {
        kd_stream_trace_far(scene, b, NULL, 0, m, KDR_ANY, 0, &out, ts);
        return;
    }
    const int narrow = n <= UNWALKED_NARROW_MAX_SAMPLES && bytes >= UNWALKED_NARROW_MIN_BYTES;
    /* samples in kd_shadow_disc_order need no regrouping by direction */
    const int sort = n > UNWALKED_ORDER_FROM ? 0 : KB_SORT;
    kd_batch_bundles(scene, b, 0, m, KDR_ANY, sort | KB_LIVE | KB_FAR_AUTO,
                     narrow ? 8 : 16, &out, ts);
}

/* (point, light) pairs whose samples go through the tree without a cone
 * walk, gathered a chunk at a time: the samples of pairs added one after
 * the other (consecutive points toward the same lights, from nearby
 * surfaces: the bundles stay coherent) go through the tree in one call
 * (trace_chunk), whose set-up is then paid per chunk, not per pair. */
typedef struct unwalked {
    uint32_t n;      /* samples per pair */
    size_t cap;      /* rays per chunk: a whole number of pairs */
    size_t m, pairs; /* rays and pairs pending */
    float *org, *dir, *tmax;
    uint8_t *hit;
    size_t *slot; /* the visibility index of each pending pair */
    uint32_t *order; /* the samples of a pair in the order they are traced
                        (kd_shadow_disc_order), NULL: 0..n-1 */
} unwalked;

static int unwalked_init(unwalked *u, uint32_t n) {
    size_t per_chunk = UNWALKED_CHUNK_RAYS / n;
    per_chunk = per_chunk ? per_chunk : 1;
    *u = (unwalked){.n = n, .cap = per_chunk * n};
    u->org = malloc(3 * u->cap * sizeof *u->org);
    u->dir = malloc(3 * u->cap * sizeof *u->dir);
    u->tmax = malloc(u->cap * sizeof *u->tmax);
    u->hit = malloc(u->cap);
    u->slot = malloc(per_chunk * sizeof *u->slot);
    if (!u->org || !u->dir || !u->tmax || !u->hit || !u->slot)
        return KDR_ENOMEM;
    if (n <= UNWALKED_ORDER_FROM)
        return KDR_OK;
    u->order = malloc(n * sizeof *u->order);
    return u->order ? kd_shadow_disc_order(n, u->order) : KDR_ENOMEM;
}

static void unwalked_free(unwalked *u) {
    free(u->org);
    free(u->dir);
    free(u->tmax);
    free(u->hit);
    free(u->slot);
    free(u->order);
}

/* Traces the pending pairs and writes their visibilities. */
static void unwalked_flush(const kdr_scene *scene, unwalked *u, float *visibility,
                           kd_shadow_ws *ws) {
    if (u->m == 0)
        return;
    kdr_ray_batch b = {.n = u->m, .org = u->org, .org_stride = 3, .dir = u->dir,
                       .tmax = u->tmax, .tmax_stride = 1};
    kdr_trav_stats ts = {0};
    trace_chunk(scene, &b, u->m, u->n, u->hit, &ts);
    ws->st.rays_traced += u->m;
    ws->st.nodes_visited += ts.nodes_visited;
    for (size_t pair = 0; pair < u->pairs; pair++) {
        uint32_t lit = 0;
        for (uint32_t s = 0; s < u->n; s++)
            lit += u->hit[pair * u->n + s] ? 0u : 1u;
        visibility[u->slot[pair]] = (float)lit / (float)u->n;
    }
    u->m = u->pairs = 0;
}

/* Adds the samples of the pair of frame f, whose visibility goes to
 * visibility[slot]; traces the chunk first when it is full. */
static void unwalked_add(const kdr_scene *scene, unwalked *u, const kd_shadow_frame *f,
                         size_t slot, float *visibility, kd_shadow_ws *ws) {
    if (u->m + u->n > u->cap)
        unwalked_flush(scene, u, visibility, ws);
    const uint32_t n = u->n;
    float *org = u->org + 3 * u->m, *dir = u->dir + 3 * u->m, *tmax = u->tmax + u->m;
    kdr_ray r[64];
    for (uint32_t s0 = 0; s0 < n; s0 += 64) {
        const uint32_t m = n - s0 < 64 ? n - s0 : 64;
        kd_shadow_frame_rays(f, u->order ? u->order + s0 : NULL, s0, m, n, r);
        for (uint32_t j = 0; j < m; j++) {
            const uint32_t s = s0 + j;
            for (int k = 0; k < 3; k++) {
                org[3 * s + k] = r[j].org[k];
                dir[3 * s + k] = r[j].dir[k];
            }
            tmax[s] = r[j].tmax; /* tmin is 0 for every sample */
        }
    }
    u->m += n;
    u->slot[u->pairs++] = slot;
}

/* Points that do not walk their cones (below CONE_WALK_FROM samples, or
 * walks forced off), a chunk at a time. */
static int trace_unwalked(const kdr_scene *scene, const kdr_shadow_query *q,
                          size_t count, float *visibility, kd_shadow_ws *ws) {
    unwalked u;
    int rc = unwalked_init(&u, q->samples);
    for (size_t j = 0; rc == KDR_OK && j < count; j++)
        for (size_t l = 0; rc == KDR_OK && l < q->nlights; l++) {
            kd_shadow_frame f;
            const size_t i = point_at(ws, j);
            rc = kd_shadow_frame_init(scene, q, i, l, &f);
            if (rc == KDR_OK)
                unwalked_add(scene, &u, &f, i * q->nlights + l, visibility, ws);
        }
    if (rc == KDR_OK)
        unwalked_flush(scene, &u, visibility, ws);
    unwalked_free(&u);
    return rc;
}

#define GROUP_NONE 0   /* no group: each point walks on its own */
#define GROUP_LIST 1   /* the group's list is in *gl */
#define GROUP_SPREAD 2 /* no group cone (too spread out): worth a split */

/* The group list of frames fs[0..n) (one light), in *gl: GROUP_LIST if
 * the group's cone exists and its walk stayed within budget, GROUP_SPREAD
 * if the cone does not exist, else GROUP_NONE. */
static int group_list(const kdr_scene *scene, const kd_shadow_frame *const *fs, size_t n,
                      uint32_t nsamples, kd_shadow_ws *ws, kd_cand_list *gl, int *rc) {
    const double spread = ws->policy == KD_WALK_GROUPS ? 1.0 : GROUP_MAX_SPREAD;
    kd_cone gc;
    /* points that will not walk (kd_walk_pays) gain only from an empty list,
     * rare where walks do not pay: no group walk for them */
    if (n < 2 || !kd_walk_pays(nsamples, fs[0]->sin_a, ws->policy))
        return GROUP_NONE;
    if (!kd_group_cone(scene, fs, n, spread, &gc))
        return GROUP_SPREAD;
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
    if (ws->wide && !ws->gsoa.f) {
        ws->gsoa.cap = (GROUP_MAX_CANDS + 3) & ~3u;
        ws->gsoa.f = malloc(KD_SOA_FIELDS * ws->gsoa.cap * sizeof *ws->gsoa.f);
        ws->gsoa.prim = malloc(ws->gsoa.cap * sizeof *ws->gsoa.prim);
        if (!ws->gsoa.f || !ws->gsoa.prim) {
            *rc = KDR_ENOMEM;
            return 0;
        }
    }
    if (ws->wide)
        kd_tri_soa_fill(&ws->gsoa, ws->gpre, kept);
    return 1;
}

/* Splits sel[0..m) (indices into fr) in two at the middle of the apexes'
 * box along its longest side; returns the size of the first part, 0 if
 * the apexes coincide. */
static size_t split_by_apex(const kd_shadow_frame *fr, size_t *sel, size_t m) {
    float lo[3], hi[3];
    for (int k = 0; k < 3; k++)
        lo[k] = hi[k] = fr[sel[0]].apex[k];
    for (size_t j = 1; j < m; j++)
        for (int k = 0; k < 3; k++) {
            const float a = fr[sel[j]].apex[k];
            lo[k] = a < lo[k] ? a : lo[k];
            hi[k] = a > hi[k] ? a : hi[k];
        }
    int ax = 0;
    for (int k = 1; k < 3; k++)
        if (hi[k] - lo[k] > hi[ax] - lo[ax])
            ax = k;
    const float mid = lo[ax] + 0.5f * (hi[ax] - lo[ax]);
    size_t front = 0;
    for (size_t j = 0; j < m; j++) /* stable: each part keeps the list's order */
        if (fr[sel[j]].apex[ax] <= mid) {
            const size_t v = sel[j];
            for (size_t i = j; i > front; i--)
                sel[i] = sel[i - 1];
            sel[front++] = v;
        }
    return front < m ? front : 0;
}

/* The points sel[0..m) of one run toward light l: one group list for all
 * of them if their group's cone exists; if it does not (the run straddles
 * a depth step or two surfaces), the run is cut in two by position and
 * each part tries again (up to GROUP_SPLITS times); else each point walks
 * on its own. */
static int trace_run(const kdr_scene *scene, const kdr_shadow_query *q, size_t j0, size_t l,
                     const kd_shadow_frame *fr, size_t *sel, size_t m, int splits,
                     float *visibility, kd_shadow_ws *ws) {
    const kd_shadow_frame *fs[GROUP_POINTS];
    int rc = KDR_OK;
    for (size_t j = 0; j < m; j++)
        fs[j] = &fr[sel[j]];
    const int g = group_list(scene, fs, m, q->samples, ws, &ws->gl, &rc);
    if (rc != KDR_OK)
        return rc;
    if (g == GROUP_SPREAD && splits > 0 && m >= 2 * GROUP_SPLIT_MIN) {
        const size_t h = split_by_apex(fr, sel, m);
        if (h >= GROUP_SPLIT_MIN && m - h >= GROUP_SPLIT_MIN) {
            rc = trace_run(scene, q, j0, l, fr, sel, h, splits - 1, visibility, ws);
            if (rc == KDR_OK)
                rc = trace_run(scene, q, j0, l, fr, sel + h, m - h, splits - 1, visibility,
                               ws);
            return rc;
        }
    }
    for (size_t j = 0; rc == KDR_OK && j < m; j++)
        rc = kd_pair_visibility(scene, &fr[sel[j]], q->samples, ws, &ws->lights[l],
                                g == GROUP_LIST ? &ws->gl : NULL,
                                &visibility[point_at(ws, j0 + sel[j]) * q->nlights + l]);
    return rc;
}

/* Cone-mode points through shared walks: runs of up to GROUP_POINTS
 * consecutive points, light by light, share one walk of their group's cone
 * (kd_group_cone) when it exists (trace_run); each point then judges that
 * list. */
static int trace_grouped(const kdr_scene *scene, const kdr_shadow_query *q, size_t count,
                         float *visibility, kd_shadow_ws *ws) {
    kd_shadow_frame fr[GROUP_POINTS];
    size_t sel[GROUP_POINTS];
    /* pairs whose walk does not pay (a wide light below
     * CONE_WALK_WIDE_FROM samples) are traced as the unwalked points are,
     * a chunk of pairs per call, not one call per pair; none when every
     * walk is forced */
    unwalked u = {0};
    int rc = ws->policy == KD_WALK_AUTO ? unwalked_init(&u, q->samples) : KDR_OK;
    for (size_t j0 = 0; rc == KDR_OK && j0 < count; j0 += GROUP_POINTS) {
        const size_t n = count - j0 < GROUP_POINTS ? count - j0 : GROUP_POINTS;
        for (size_t l = 0; rc == KDR_OK && l < q->nlights; l++) {
            size_t m = 0;
            for (size_t j = 0; rc == KDR_OK && j < n; j++) {
                rc = kd_shadow_frame_init(scene, q, point_at(ws, j0 + j), l, &fr[j]);
                if (rc != KDR_OK)
                    break;
                if (u.cap && !kd_walk_pays(q->samples, fr[j].sin_a, ws->policy))
                    unwalked_add(scene, &u, &fr[j], point_at(ws, j0 + j) * q->nlights + l,
                                 visibility, ws);
                else
                    sel[m++] = j;
            }
            if (rc == KDR_OK && m > 0)
                rc = trace_run(scene, q, j0, l, fr, sel, m, GROUP_SPLITS, visibility, ws);
        }
    }
    if (rc == KDR_OK && u.cap)
        unwalked_flush(scene, &u, visibility, ws);
    unwalked_free(&u);
    return rc;
}

static int trace_points(const kdr_scene *scene, const kdr_shadow_query *q, size_t count,
                        kdr_shadow_mode mode, float *visibility, kd_shadow_ws *ws) {
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
                rc = kd_pair_visibility_rays(scene, &f, q->samples, ws, vis);
            } else if (rc == KDR_OK) {
                rc = kd_pair_visibility(scene, &f, q->samples, ws, &ws->lights[l], NULL,
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
    kd_shadow_ws ws = {0};
    ws.policy = policy;
    ws.order = order;
    ws.first = first;
    ws.wide = kdr_cpu_has_avx2();
    ws.wide16 = ws.wide && kd_cpu_has_avx512();
    ws.lights = malloc(q->nlights * sizeof *ws.lights);
    int rc = ws.lights ? KDR_OK : KDR_ENOMEM;
    for (size_t l = 0; rc == KDR_OK && l < q->nlights; l++)
        ws.lights[l] = (kd_light_state){KD_NO_PRIM, 0, 0};
    if (rc == KDR_OK)
        rc = trace_points(scene, q, count, mode, visibility, &ws);
    if (stats) {
        stats->cones_decided += ws.st.cones_decided;
        stats->rays_traced += ws.st.rays_traced;
        stats->nodes_visited += ws.st.nodes_visited;
    }
    kd_shadow_ws_free(&ws);
    return rc;
}
