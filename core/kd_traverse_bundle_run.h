/*
 * kd_traverse_bundle_run.h — the batch driver of the omni-directional
 * bundle traversal, a template included after kd_traverse_bundle.h's (same
 * KD_W, simd_width.h convention) by kd_traverse_bundle4.c,
 * kd_traverse_bundle8.c and kd_traverse_bundle16.c. It cuts a batch into
 * chunks of KB_CHUNK rays (answering first the rays that cannot hit,
 * regrouping by direction),
 * gathers each KD_W of them into a bundle's lanes (rays a bundle cannot
 * take go alone through the single-ray walk), traces the bundle
 * (kb_trace), stores the lanes' answers, and sends incoherent stretches
 * through the interleaved walk (kd_stream_trace): chunks kd_batch_scattered
 * calls scattered, and the rest of a chunk, plus KB_FALLBACK_CHUNKS more,
 * whose first bundles' lane occupancy fell under KB_OCC_MIN. Any-hit
 * chunks whose rays' ends cluster (kd_batch_far_first: shadow rays toward a
 * light) walk far end first, in bundles and in the interleaved walk, where
 * the call's first such rays measured that order cheaper (kd_far_probe);
 * any-hit chunks whose ends spread (AO) walk far end first wherever they
 * go to the interleaved walk (kd_batch_scattered_any).
 */
#ifndef KD_W
#error "include kd_traverse_bundle.h's template (define KD_W) before kd_traverse_bundle_run.h"
#endif

#if KD_W == 16
/* 1 when ids[0..16) are 16 consecutive rays (the usual bundle: a chunk
 * that the order left alone, with every ray live) */
static inline int KD_WN(kb_consecutive)(const size_t *ids) {
    for (int j = 1; j < KD_W; j++)
        if (ids[j] != ids[0] + (size_t)j)
            return 0;
    return 1;
}

/* kb_gather's copy for 16 consecutive rays, a vector at a time (the same
 * floats: only where they are moved differs) */
KD_FN void KD_WN(kb_gather_run)(const kdr_ray_batch *rb, size_t i0, KD_WN(kb_bundle) *b) {
    VF v[3];
    f16_load3x16(rb->dir + 3 * i0, v);
    for (int k = 0; k < 3; k++)
        V(store)(b->dir[k], v[k]);
    if (rb->org_stride) {
        f16_load3x16(rb->org + 3 * i0, v);
        for (int k = 0; k < 3; k++)
            V(store)(b->org[k], v[k]);
    } else {
        for (int k = 0; k < 3; k++)
            V(store)(b->org[k], V(set1)(rb->org[k]));
    }
    const VF lo = !rb->tmin ? V(set1)(0.0f)
                  : rb->tmin_stride ? f16_loadu(rb->tmin + i0) : V(set1)(rb->tmin[0]);
    const VF hi = !rb->tmax ? V(set1)(INFINITY)
                  : rb->tmax_stride ? f16_loadu(rb->tmax + i0) : V(set1)(rb->tmax[0]);
    V(store)(b->tmin, lo);
    V(store)(b->best_t, hi);
}
#endif

/* Copies the rays ids[0..n) into the bundle's lanes (SoA). Lanes that
 * must be traced alone are returned in *alone; they and unused lanes hold
 * a harmless ray. */
KD_FN void KD_WN(kb_gather)(const kdr_ray_batch *rb, const size_t *ids, int n,
                      KD_WN(kb_bundle) *b, int *alone) {
#if KD_W == 16
    if (n == KD_W && KD_WN(kb_consecutive)(ids)) {
        KD_WN(kb_gather_run)(rb, ids[0], b);
        V(store)(b->best_u, V(set1)(0.0f));
        V(store)(b->best_v, V(set1)(0.0f));
        V(store)((float *)b->best_prim, V(seti)(-1));
    } else
#endif
    for (int j = 0; j < KD_W; j++) {
        const size_t i = ids[j < n ? j : 0];
        const float *o = rb->org + rb->org_stride * i, *d = rb->dir + 3 * i;
        for (int k = 0; k < 3; k++) {
            b->org[k][j] = o[k];
            b->dir[k][j] = d[k];
        }
        b->tmin[j] = rb->tmin ? rb->tmin[rb->tmin_stride * i] : 0.0f;
        b->best_t[j] = rb->tmax ? rb->tmax[rb->tmax_stride * i] : INFINITY;
        b->best_u[j] = b->best_v[j] = 0.0f;
        b->best_prim[j] = -1;
    }
    /* a bundle takes finite (x - x == 0) rays with a non-zero direction, no
     * subnormal direction component, and
     * 0 <= tmin <= tmax (false for NaN): t >= 0 is what makes the paper's
     * "negative means behind" rule right; the others go alone */
    const VF zero = V(set1)(0.0f);
    const VF tiny = V(set1)(FLT_MIN), ntiny = V(set1)(-FLT_MIN);
    VF ok = V(le)(zero, V(load)(b->tmin)), nonzero = V(seti)(0);
    ok = V(and)(ok, V(le)(V(load)(b->tmin), V(load)(b->best_t)));
    for (int k = 0; k < 3; k++) {
        const VF o = V(load)(b->org[k]), d = V(load)(b->dir[k]);
        ok = V(and)(ok, V(and)(V(eq)(V(sub)(o, o), zero), V(eq)(V(sub)(d, d), zero)));
        /* a subnormal direction component (its reciprocal overflows): the
         * single walk decides how such a ray is traced (kd_traverse.h) */
        ok = V(and)(ok, V(or)(V(eq)(d, zero), V(or)(V(le)(tiny, d), V(le)(d, ntiny))));
        nonzero = V(or)(nonzero, V(andnot)(V(eq)(d, zero), V(seti)(-1)));
    }
    const int used = (1 << n) - 1, good = V(bits)(V(and)(ok, nonzero)) & used;
    b->lanes = good;
    *alone = used & ~good;
    for (int j = 0; j < KD_W; j++) /* a harmless ray where none is traced */
        if (!((good >> j) & 1)) {
            for (int k = 0; k < 3; k++)
                b->org[k][j] = 0.0f, b->dir[k][j] = 1.0f;
            b->tmin[j] = b->best_t[j] = 0.0f;
        }
}


/* Writes the results of rays [base, base+n) except the `alone` lanes. */
KD_FN void KD_WN(kb_store)(const KD_WN(kb_bundle) *b, const size_t *ids, int n, int alone,
                     kdr_query q, kdr_hits *out) {
    for (int j = 0; j < n; j++) {
        const size_t i = ids[j];
        if ((alone >> j) & 1)
            continue;
        if (q == KDR_ANY) {
            out->hit[i] = (uint8_t)((b->hit >> j) & 1);
            continue;
        }
        const int found = ((b->lanes >> j) & 1) && b->best_prim[j] >= 0;
        out->t[i] = found ? b->best_t[j] : -1.0f;
        out->prim[i] = found ? b->best_prim[j] : -1;
        out->u[i] = found ? b->best_u[j] : 0.0f;
        out->v[i] = found ? b->best_v[j] : 0.0f;
    }
}

KD_FN void KD_WN(kb_stats_add)(kdr_trav_stats *stats, const KD_WN(kb_bundle) *b, int n,
                         int alone) {
    if (!stats)
        return;
    stats->rays += (uint64_t)(n - kd_lane_count(alone));
    stats->nodes_visited += b->lane_steps;
    stats->tri_tests += b->tri_tests;
}

/* The interleaved walk over ids[0..m) (ids NULL: [first, first + m)),
 * front to back (order KB_ORDER_NEAR) or far end first (the others). */
KD_FN void KD_WN(kb_stream)(const kdr_scene *s, const kdr_ray_batch *rb,
                            const size_t *ids, size_t first, size_t m, kdr_query q,
                            int order, kdr_hits *out, kdr_trav_stats *stats) {
    if (order != KB_ORDER_NEAR)
        kd_stream_trace_far(s, rb, ids, first, m, q,
                            order == KB_ORDER_FAR_SPREAD &&
                                    s->stats.bytes >= KD_FAR_STAGE_MIN_BYTES
                                ? KD_STREAM_STAGE
                                : 0,
                            out, stats);
    else
        kd_stream_trace(s, rb, ids, first, m, q, out, stats);
}

/* Traces rays ids[0..m) (ids NULL: [first, first + m)) through the
 * interleaved walk in the order `order` (KB_ORDER_*; probing: runs of
 * KD_FAR_PROBE_RAYS alternate the orders into fp until both are measured,
 * the rest takes kd_far_pick's): one fallback per bundle-sized group. */
KD_FN void KD_WN(kb_alone)(const kdr_scene *s, const kdr_ray_batch *rb,
                           const size_t *ids, size_t first, size_t m, kdr_query q,
                           int order, kd_far_probe *fp, kdr_hits *out,
                           kdr_trav_stats *stats) {
    size_t done = 0;
    if (order == KB_ORDER_PROBE)
        for (; done < m && kd_far_probing(fp); done += KD_FAR_PROBE_RAYS) {
            const size_t k = m - done < KD_FAR_PROBE_RAYS ? m - done : KD_FAR_PROBE_RAYS;
            const int far = kd_far_pick(fp);
            kdr_trav_stats st = {0, 0, 0, 0};
            KD_WN(kb_stream)(s, rb, ids ? ids + done : NULL, ids ? 0 : first + done, k, q,
                             far, out, &st);
            fp->work[far] += (double)(st.nodes_visited + st.tri_tests);
            fp->rays[far] += (double)st.rays;
            if (stats) {
                stats->rays += st.rays;
                stats->nodes_visited += st.nodes_visited;
                stats->tri_tests += st.tri_tests;
            }
        }
    if (done < m)
        KD_WN(kb_stream)(s, rb, ids ? ids + done : NULL, ids ? 0 : first + done, m - done,
                         q, order == KB_ORDER_PROBE ? kd_far_pick(fp) : order, out, stats);
    if (stats)
        stats->fallbacks += (uint64_t)((m + KD_W - 1) / KD_W);
}

/* Traces one chunk of rays (ids) in bundles of KD_W, any-hit lanes in the
 * order `order` (KB_ORDER_*; probing: each bundle takes kd_far_pick's order
 * and adds its work to fp). Returns 1 when the bundles so far (at least
 * KB_PROBE of them) turned out incoherent; the rest of the chunk then went
 * alone. */
KD_FN int KD_WN(kb_chunk)(const kdr_scene *s, const kdr_ray_batch *rb,
                    const size_t *ids, int m, kdr_query q, int flags, int order,
                    kd_far_probe *fp, kdr_hits *out, kdr_trav_stats *stats) {
    KD_WN(kb_bundle) b;
    kd_entry_cache ec;
    ec.have_path = ec.have_prev = 0;
    double used = 0.0, offered = 0.0; /* lane steps: taken / possible */
    b.scene_mag = KD_WN(kb_scene_mag)(s);
    for (int g = 0, k = 1; g < m; g += KD_W, k++) {
        const int n = m - g < KD_W ? m - g : KD_W;
        int alone;
        KD_WN(kb_gather)(rb, ids + g, n, &b, &alone);
        const int far = order == KB_ORDER_PROBE ? kd_far_pick(fp) : order;
        KD_WN(kb_trace)(s, &b, q == KDR_ANY, far, (flags & KB_ROOT) ? NULL : &ec);
        if (order == KB_ORDER_PROBE) {
            fp->work[far] += (double)(b.lane_steps + b.tri_tests);
            fp->rays[far] += (double)kd_lane_count(b.lanes);
        }
        KD_WN(kb_store)(&b, ids + g, n, alone, q, out);
        KD_WN(kb_stats_add)(stats, &b, n, alone);
        for (int j = 0; j < n; j++)
            if ((alone >> j) & 1)
                kd_batch_single(s, rb, ids[g + j], q, out, stats);
        /* occupancy among the lanes that entered the tree: lanes that
         * missed the scene (camera rays past a silhouette) cost nothing */
        used += (double)b.lane_steps;
        offered += (double)b.steps * kd_lane_count(b.lanes);
        if ((flags & KB_FALLBACK) && k >= KB_PROBE && used < KB_OCC_MIN * offered) {
            KD_WN(kb_alone)(s, rb, ids + g + n, 0, (size_t)(m - g - n), q, order, fp, out,
                            stats);
            return 1;
        }
    }
    return 0;
}

/* The batch driver: chunks of KB_CHUNK rays, regrouped by direction, then
 * bundles of KD_W; incoherent stretches through the interleaved walk (see
 * KB_OCC_MIN and kd_batch_scattered). */
KD_FN void KD_WN(kb_run)(const kdr_scene *s, const kdr_ray_batch *rb, size_t first,
                         size_t count, kdr_query q, int flags, kdr_hits *out,
                         kdr_trav_stats *stats) {
    size_t ids[KB_CHUNK];
    const size_t end = first + count;
    /* any hit: the order of a chunk's walks: far end first everywhere
     * (KB_FAR), or measured (kd_far_probe) where kd_batch_far_first says
     * the ends cluster (KB_FAR_AUTO) */
    const int far_all = q == KDR_ANY && (flags & KB_FAR);
    const int far_auto = q == KDR_ANY && (flags & KB_FAR_AUTO) && !far_all;
    kd_far_probe fp = {{0.0, 0.0}, {0.0, 0.0}};
    for (size_t base = first; base < end;) {
        /* a stretch of scattered chunks, or the chunks after a failed
         * probe, in one call: the walk's lanes stay full longer */
        size_t alone = base;
        if (flags & KB_FALLBACK)
            while (alone < end) {
                const size_t n = end - alone < KB_CHUNK ? end - alone : KB_CHUNK;
                if (!(far_auto ? kd_batch_scattered_any(s, rb, alone, n)
                               : kd_batch_scattered(s, rb, alone, n)))
                    break;
                alone += n;
            }
        if (alone > base) {
            /* clustered ends: the probe decides; spread ends (AO): far
             * end first (KD_FAR_RUNS_MIN_BYTES) */
            const size_t probe = alone - base < KB_CHUNK ? alone - base : KB_CHUNK;
            const int ends = far_auto ? kd_batch_far_first(s, rb, NULL, base, probe)
                                      : KB_ENDS_NONE;
            const int order = far_all                    ? KB_ORDER_FAR
                              : ends == KB_ENDS_CLUSTER ? KB_ORDER_PROBE
                              : ends == KB_ENDS_SPREAD  ? KB_ORDER_FAR_SPREAD
                              : ends == KB_ENDS_LONG    ? KB_ORDER_FAR
                                                        : KB_ORDER_NEAR;
            KD_WN(kb_alone)(s, rb, NULL, base, alone - base, q, order, &fp, out, stats);
            base = alone;
            continue;
        }
        const size_t c = end - base < KB_CHUNK ? end - base : KB_CHUNK;
        /* rays that cannot hit are answered before ordering: they would
         * cost the sort, a bundle slot and a single-ray call each */
        int m = (int)c;
        if (flags & KB_LIVE)
            m = (int)kd_batch_live(rb, base, c, q, out, stats, ids);
        else
            for (size_t i = 0; i < c; i++)
                ids[i] = base + i;
        /* the order only regroups rays within runs of one origin: where
         * every bundle already holds whole runs it would only permute
         * lanes (the walk is the same for any lane order), so its
         * direction spread (a division per ray) is skipped */
        if (!(flags & KB_SORT) || !kd_batch_runs_fit(rb, ids, (size_t)m, KD_W))
            kd_batch_order(rb, (size_t)m, (flags & KB_SORT) != 0, ids);
        base += c;
        /* in bundles only clustered ends are offered the far order: AO
         * bundles keep their origin's path replay (KD_FAR_RUNS_MIN_BYTES) */
        const int order =
            far_all ? KB_ORDER_FAR
            : far_auto && m > 0 && kd_batch_far_first(s, rb, ids, 0, (size_t)m) == KB_ENDS_CLUSTER
                ? KB_ORDER_PROBE
                : KB_ORDER_NEAR;
        if (m > 0 && KD_WN(kb_chunk)(s, rb, ids, m, q, flags, order, &fp, out, stats)) {
            const size_t skip = end - base < KB_FALLBACK_CHUNKS * KB_CHUNK
                                    ? end - base
                                    : KB_FALLBACK_CHUNKS * KB_CHUNK;
            if (skip)
                KD_WN(kb_alone)(s, rb, NULL, base, skip, q, order, &fp, out, stats);
            base += skip;
        }
    }
}
