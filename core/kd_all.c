/*
 * kd_all.c — every hit along a ray ("all", capped at max_hits, in (t, prim)
 * order) and the number of hits ("count", no cap), one ray at a time.
 *
 * What a hit is: triangle prim is hit by the ray when kd_tri_intersect
 * (core/kd_tri.h, the test every other traversal uses) accepts it with
 * tmin <= t <= tmax. Nothing else is merged or filtered: a ray through an
 * edge shared by two triangles is accepted by the watertight test for both
 * (edges count as inside), so it gives two hits at the same t; a ray through
 * a vertex shared by k triangles gives up to k hits; coincident triangles
 * each give a hit. Each triangle counts once, however many leaves reference
 * it: its test result depends only on the ray and the triangle, so the
 * copies found in other leaves are identical and are dropped.
 *
 * The walk is the single-ray walk's (kd_traverse_single.c) front-to-back
 * descent with the split convention and slack of kd_traverse.h, written
 * with the scalar forms of the ray set-up (kd_clip_root_slack), which that
 * file documents as the definition. Leaves test every reference over
 * [tmin, bound]: bound is tmax until max_hits hits are held, then the
 * max_hits-th t (a hit at that t with a smaller prim can still replace the
 * last one). A pending subtree is skipped once it starts past
 * kd_term_bound(bound), as for closest hits, so a capped walk stops early
 * and its answer is the first max_hits hits of the uncapped one.
 *
 * "count" keeps every accepted prim (duplicates included) in a buffer that
 * starts on the stack and moves to the heap past KD_COUNT_STACK entries,
 * then sorts (by insertion when few) and counts distinct prims.
 */
#include "kd_all.h"
#include "kd_stream.h"          /* kd_cpu_has_avx512 */
#include "kd_traverse_bundle.h" /* kd_batch_scattered */

/* The front-to-back walk over every leaf the ray passes (within the slack)
 * that can still hold a hit at or before the bound. */
static void walk(const kdr_scene *sc, const kdr_ray *r, all_sink *s) {
    if (!sc || !sc->nodes || !kd_ray_valid(r->org, r->dir, r->tmin, r->tmax)) return;
    float inv[3], ss[3], tn, tf;
    for (int k = 0; k < 3; k++)
        inv[k] = 1.0f / r->dir[k];
    const float slack = kd_ray_slack(sc, r->org);
    kd_signed_slack(slack, inv, ss);
    if (!kd_clip_root_slack(sc, r->org, r->dir, inv, slack, r->tmin, r->tmax, &tn, &tf))
        return;
    kd_ray_pre pre;
    kd_ray_precompute(r->org, r->dir, &pre);
    kd_ntri_pre4 pre4;
    kd_ntri_pre_init4(&pre, &pre4);
    const int avx2 = __builtin_cpu_supports("avx2") ? 1 : 0;
    uint32_t mb[KD_ALL_MBOX_SLOTS];
    if (all_use_mbox(sc, s->hits != NULL)) all_mbox_start(s, mb);
    kd_todo stack[KD_MAX_DEPTH];
    int sp = 0;
    const kd_node *nodes = sc->nodes, *n = nodes;
    for (;;) {
        while (n && !kd_is_leaf(n)) {
            s->nodes++;
            const int axis = kd_axis(n);
            const float a = n->u.split - r->org[axis];
            const float t_lo = (a - ss[axis]) * inv[axis];
            const float t_hi = (a + ss[axis]) * inv[axis];
            const int neg = signbit(inv[axis]) ? 1 : 0;
            const kd_node *below = n + 1, *above = nodes + kd_above(n);
            const kd_node *nearc = neg ? above : below, *farc = neg ? below : above;
            const int near_empty = neg ? kd_above_empty(n) : kd_below_empty(n);
            const int far_empty = neg ? kd_below_empty(n) : kd_above_empty(n);
            if (t_lo > tf) {
                n = near_empty ? NULL : nearc;
            } else if (t_hi < tn) {
                n = far_empty ? NULL : farc;
            } else if (far_empty) { /* both sides, or a NaN: the near one */
                n = nearc;
                tf = t_hi < tf ? t_hi : tf;
            } else if (near_empty) {
                n = farc;
                tn = t_lo > tn ? t_lo : tn;
            } else {
                stack[sp].node = farc;
                stack[sp].tn = t_lo > tn ? t_lo : tn;
                stack[sp].tf = tf;
                ++sp;
                n = nearc;
                tf = t_hi < tf ? t_hi : tf;
            }
        }
        if (n) {
            s->nodes++;
            test_leaf(sc, n, &pre, &pre4, avx2, r->tmin, s, sc->prefetch_leaves);
            if (s->oom) return;
        }
        const float bound = kd_term_bound(s->bound);
        do {
            if (sp == 0) return;
            --sp;
        } while (!(stack[sp].tn <= bound));
        n = stack[sp].node;
        tn = stack[sp].tn;
        tf = stack[sp].tf;
    }
}

int kdr_intersect_all1(const kdr_scene *scene, const kdr_ray *ray, uint32_t max_hits,
                       kdr_hit *hits, uint32_t *nhits, kdr_trav_stats *stats) {
    if (nhits) *nhits = 0;
    if (!scene || !ray || !hits || !nhits || max_hits == 0 ||
        max_hits > KDR_MAX_HITS_LIMIT)
        return KDR_EINVAL;
    all_sink s = {.hits = hits, .cap = max_hits, .bound = ray->tmax};
    walk(scene, ray, &s);
    add_stats(stats, &s);
    *nhits = s.n;
    return KDR_OK;
}

int kdr_count1(const kdr_scene *scene, const kdr_ray *ray, uint32_t *count,
               kdr_trav_stats *stats) {
    if (count) *count = 0;
    if (!scene || !ray || !count) return KDR_EINVAL;
    uint32_t local[KD_COUNT_STACK];
    all_sink s = {.prims = local, .pcap = KD_COUNT_STACK, .bound = ray->tmax};
    walk(scene, ray, &s);
    add_stats(stats, &s);
    const uint32_t distinct = all_distinct(&s);
    if (s.oom) return KDR_ENOMEM;
    *count = distinct;
    return KDR_OK;
}

static int batch_ok(const kdr_ray_batch *b, size_t first, size_t count) {
    if (!b || !b->org || !b->dir) return 0;
    if (b->org_stride != 0 && b->org_stride != 3) return 0;
    if ((b->tmin && b->tmin_stride > 1) || (b->tmax && b->tmax_stride > 1)) return 0;
    return first <= b->n && count <= b->n - first;
}

/* Which walk a chunk of a batch takes: the interleaved one on scenes of
 * KD_ALL_STREAM_MIN_BYTES and more, where it hides the loads of nodes,
 * references and triangles that miss the caches; on AVX-512 CPUs from
 * KD_ALL_LANES_MIN_BYTES (its lanes form: a camera's chunks of
 * 2CylinderEngine 1.09x, bench/ab set ball16); on smaller scenes only
 * for chunks kd_batch_scattered calls scattered (own origins, directions
 * spread: bench_queries' random rays), where it beat one ray at a time
 * (random batches 1.15-1.35x on duck and 2CylinderEngine, 0.95-1.16x on
 * haus) while coherent chunks (a camera's rays) lost with it: those, and
 * on small scenes every chunk that is not scattered, walk one ray at a
 * time (docs/TRAVERSAL.md, "All hits and counts"). */
static int all_interleave(const kdr_scene *sc, const kdr_ray_batch *b, size_t first,
                          size_t count) {
    if (count < 2 || !sc->nodes) return 0;
    return sc->stats.bytes >= KD_ALL_STREAM_MIN_BYTES ||
           (sc->stats.bytes >= KD_ALL_LANES_MIN_BYTES && kd_cpu_has_avx512()) ||
           kd_batch_scattered(sc, b, first, count);
}

/* The interleaved walk stages leaves (kd_all_stream.h) by itself on scenes
 * of KD_STREAM_STAGE_MIN_BYTES and more; scattered chunks of smaller
 * scenes ask for it from KD_ALL_STAGE_MIN_BYTES. */
static int all_stage(const kdr_scene *sc) {
    return sc->stats.bytes >= KD_ALL_STAGE_MIN_BYTES ? KD_ALL_STAGE : 0;
}

/* Rays [first, first + count) of a batch into out, walk chosen per chunk of
 * KB_CHUNK rays; buf: KD_ALL_RAYS * max_hits entries of scratch, or NULL
 * (no memory for it: one ray at a time). */
static void all_chunk(const kdr_scene *scene, const kdr_ray_batch *batch, size_t first,
                      size_t count, uint32_t max_hits, kdr_hit *buf, kdr_hit *local,
                      kdr_all_hits *out, kdr_trav_stats *stats) {
    if (buf && all_interleave(scene, batch, first, count)) {
        kd_all_stream(scene, batch, first, count, max_hits, buf, out, NULL, all_stage(scene),
                      stats);
        return;
    }
    for (size_t i = first; i < first + count; i++) {
        kdr_ray r;
        uint32_t nh = 0;
        all_batch_ray(batch, i, &r);
        kdr_intersect_all1(scene, &r, max_hits, local, &nh, stats);
        all_put_list(out, i, max_hits, local, nh);
    }
}

int kdr_all_batch(const kdr_scene *scene, const kdr_ray_batch *batch, size_t first,
                  size_t count, uint32_t max_hits, kdr_all_hits *out,
                  kdr_trav_stats *stats) {
    if (!scene || !batch_ok(batch, first, count) || !out || !out->nhits || !out->t ||
        !out->prim || !out->u || !out->v || max_hits == 0 ||
        max_hits > KDR_MAX_HITS_LIMIT)
        return KDR_EINVAL;
    kdr_hit local[KDR_MAX_HITS_LIMIT];
    /* the interleaved walk's lists: on the stack when small, else on the
     * heap; without memory, ray by ray */
    const size_t need = (size_t)KD_ALL_RAYS * max_hits;
    kdr_hit *buf = need <= KDR_MAX_HITS_LIMIT ? local : malloc(need * sizeof *buf);
    kdr_hit one[KDR_MAX_HITS_LIMIT];
    for (size_t c = first; c < first + count; c += KB_CHUNK) {
        const size_t m = first + count - c < KB_CHUNK ? first + count - c : KB_CHUNK;
        all_chunk(scene, batch, c, m, max_hits, buf, one, out, stats);
    }
    if (buf != local) free(buf);
    return KDR_OK;
}

int kdr_count_batch(const kdr_scene *scene, const kdr_ray_batch *batch, size_t first,
                    size_t count, uint32_t *counts, kdr_trav_stats *stats) {
    if (!scene || !batch_ok(batch, first, count) || !counts) return KDR_EINVAL;
    int rc = KDR_OK;
    for (size_t c = first; c < first + count; c += KB_CHUNK) {
        const size_t m = first + count - c < KB_CHUNK ? first + count - c : KB_CHUNK;
        if (all_interleave(scene, batch, c, m)) {
            const int r = kd_all_stream(scene, batch, c, m, 0, NULL, NULL, counts,
                                         all_stage(scene), stats);
            if (r != KDR_OK) rc = r;
            continue;
        }
        for (size_t i = c; i < c + m; i++) {
            kdr_ray r;
            all_batch_ray(batch, i, &r);
            const int rr = kdr_count1(scene, &r, &counts[i], stats);
            if (rr != KDR_OK) return rr;
        }
    }
    return rc;
}
