/*
 * kd_traverse_stream_lanes.h — the interleaved walk in SIMD lanes, written
 * once for 8 (AVX2) and 16 lanes (AVX-512): kd_traverse_stream8.c and
 * kd_traverse_stream16.c define KD_W, include simd_width.h and this
 * template (kd_stream_trace8, kd_stream_trace16). KD_W rays of a batch sit
 * in the KD_W lanes, each lane ITS OWN ray at ITS OWN node with its own
 * stack and interval (not a bundle: lanes never wait for each other). One
 * turn of the loop advances every lane by one step:
 *
 *   gather   each lane's node (split and bits: two KD_W-way gathers);
 *   step     the lanes at interior nodes take kd_traverse_single.c's node
 *            step as mask operations (near/far, the empty-child flags, the
 *            far entry scattered to the lane's stack when both are taken;
 *            AVX2 has no scatter: the pushing lanes store one by one);
 *   leaves   the lanes at leaves test their leaf one by one: closest-hit
 *            rays 8 triangles at a time whatever the leaf's size
 *            (kd_walk_leaf_w8: the single walk's triangle test and tie
 *            rule without its branch on the count), any-hit rays with the
 *            single walk's kd_walk_leaf (1, 4 or 8 at a time by the
 *            count: for them the 8-wide test of a short list cost more
 *            than the count's mispredicts, docs/TRAVERSAL.md);
 *   pops     lanes after a leaf or with no child to enter pop their stack
 *            (walk()'s pop: entries starting after kd_term_bound(best t)
 *            are dropped);
 *   refill   a finished lane writes its answer and takes the batch's next
 *            ray, so the lanes stay full until the batch runs dry (the
 *            rays are set up KD_W at a time, one per lane: ks_prepare); a ray
 *            that shares its origin with the ray before it starts at its
 *            entry on the origin's path, with the single walk's interval
 *            and pending entries there (kd_entry.h: the replayed levels
 *            count as visited nodes, so the work sums stay the walk's).
 *
 * Exact: per lane every float operation is the single walk's, in its
 * order (a = split - org, t_lo = (a - ss) * inv, t_hi = (a + ss) * inv,
 * max/min with the scalar ternaries' operand order, kd_term_bound's sum),
 * the same leaves are tested in the same order with the same [tmin, best
 * t], so t, u, v and prim are the single walk's bit for bit.
 *
 * On scenes of KD_STREAM_STAGE_MIN_BYTES and more (trees and triangles
 * that do not stay in the caches) a lane that reaches a leaf requests its
 * reference list, on its next turn the triangles, and tests them on the
 * turn after; and every lane's next node is requested as soon as it is
 * known.
 */
/* The includer includes kd_stream.h, kd_traverse_bundle.h and kd_walk.h
 * BEFORE defining KD_W: kd_walk.h instantiates the triangle tests at its own
 * widths, and kd_traverse_bundle.h would instantiate the bundle walk.
 *
 * The query kind is a compile-time constant as the width is: the includer
 * defines KS_ANY (1: any hit, kd_stream_any8 / 16; 0: closest hit,
 * kd_stream_hit8 / 16), and kd_stream_trace8 / 16 (kd_traverse_stream.c)
 * pick one per batch. Each instantiation has a translation unit of its
 * own (kd_traverse_stream{8,16}{,_any}.c): with both leaf tests in one
 * unit GCC stopped inlining kd_ntri_test8 into the closest-hit walk. */
#if !defined(KS_ANY) || (KS_ANY != 0 && KS_ANY != 1)
#error "define KS_ANY as 0 (closest hit) or 1 (any hit) before including kd_traverse_stream_lanes.h"
#endif

#undef KS_ALL
#undef KS_LOG2W
#define KS_ALL ((unsigned)((1u << KD_W) - 1)) /* every lane */
#define KS_LOG2W (KD_W == 16 ? 4 : 3)

/* Per-lane data the scalar parts use (leaf tests, answers). */
typedef struct KD_WN(ks_lane) {
    size_t id;
    float tmin;
    kd_walk_out o;
#if KS_ANY
    kd_ray_pre pre;    /* kd_walk_leaf's shear, one and four lanes */
    kd_ntri_pre4 pre4;
#else
    kd_ntri_pre8 pre8; /* the leaf test's shear, eight lanes (kd_walk_leaf_w8) */
#endif
} KD_WN(ks_lane);

/* The lanes' state: in registers (the vectors) and in memory (stacks of
 * {node, tn, tf} in lane columns: entry d of lane j is [d][j]). */
typedef struct KD_WN(ks_lanes) {
    VI node, sp, visits;
    VF tn, tf, org[3], inv[3], ss[3];
    unsigned act;  /* lanes holding a ray */
    unsigned refs; /* lanes whose leaf's reference list was requested last turn */
    unsigned tris; /* lanes whose leaf's triangles were requested last turn */
    _Alignas(sizeof(VF)) int32_t stk_node[KD_MAX_DEPTH][KD_W];
    _Alignas(sizeof(VF)) float stk_tn[KD_MAX_DEPTH][KD_W];
    _Alignas(sizeof(VF)) float stk_tf[KD_MAX_DEPTH][KD_W];
    KD_WN(ks_lane) lane[KD_W];
} KD_WN(ks_lanes);

/* The batch's next KD_W rays, set up together, one ray per lane
 * (ks_prepare): kd_walk_setup's interval, 1 / dir and signed slack, and
 * kd_ray_precompute's shear, in lane columns; ks_fill hands them out in
 * batch order. */
typedef struct KD_WN(ks_prep) {
    _Alignas(sizeof(VF)) float org[3][KD_W], dir[3][KD_W], tmin[KD_W], tmax[KD_W];
    _Alignas(sizeof(VF)) float inv[3][KD_W], ss[3][KD_W], tn[KD_W], tf[KD_W];
    _Alignas(sizeof(VF)) float sh[6][KD_W]; /* org[kx], org[ky], org[kz], sx, sy, sz */
    size_t id[KD_W];
    unsigned ok;                /* lanes whose ray is traced (set-up passed) */
    unsigned neg[3], kz[3], sw; /* sign of dir[k]; lanes with kz == k; kx, ky swapped */
    int n, at;                  /* rays prepared, next to hand out */
} KD_WN(ks_prep);

/* The batch being traced. */
typedef struct KD_WN(ks_src) {
    const kdr_scene *s;
    const kdr_ray_batch *b;
    const size_t *ids; /* NULL: rays first, first + 1, ... */
    size_t first, m, next;
    kdr_hits *out;
    kdr_trav_stats *stats;
    unsigned stage; /* all lanes when leaves are staged (large scenes) */
    kd_entry_cache *entry; /* rays of a shared origin start at their entry
                              (kd_entry.h) */
    int far;        /* any hit, KD_STREAM_FAR: each ray's cells back to front,
                       from the root (the origin's path leads to the near end) */
    KD_WN(ks_prep) prep;
} KD_WN(ks_src);

/* Writes lane l's answer and adds its stats. */
static void KD_WN(ks_finish)(const KD_WN(ks_lane) * l, int found,
                             const KD_WN(ks_src) * c) {
    const size_t i = l->id;
    if (c->stats) {
        c->stats->rays++;
        c->stats->nodes_visited += l->o.nodes;
        c->stats->tri_tests += l->o.tests;
    }
    if (KS_ANY) {
        c->out->hit[i] = (uint8_t)found;
        return;
    }
    c->out->t[i] = found ? l->o.t : -1.0f;
    c->out->prim[i] = found ? l->o.prim : -1;
    c->out->u[i] = found ? l->o.u : 0.0f;
    c->out->v[i] = found ? l->o.v : 0.0f;
}

/* Reads the batch's next rays (up to KD_W) into c->prep and sets them up,
 * lane by lane with the float operations of kd_walk_setup and
 * kd_ray_precompute on the same operands in the same order: the per-axis
 * steps are the same vector operations, and where kd_walk_setup reduces
 * across axes (the slack's max, the entry's max, the exit's min) it pairs
 * the axes as here, over values that are never NaN there. So every
 * traced ray's interval, 1 / dir, slack and shear are the single walk's
 * bits. Done once per KD_W rays instead of once per ray: the set-up was a
 * sixth of the walk's time on scenes that fit in the caches. */
KD_TARGET __attribute__((noinline)) static void KD_WN(ks_prepare)(KD_WN(ks_src) * c) {
    KD_WN(ks_prep) *p = &c->prep;
    const kdr_ray_batch *b = c->b;
    int n = 0;
    for (; n < KD_W && c->next < c->m; n++, c->next++) { /* kd_batch_read */
        const size_t id = c->ids ? c->ids[c->next] : c->first + c->next;
        const float *o = b->org + b->org_stride * id, *d = b->dir + 3 * id;
        p->id[n] = id;
        for (int k = 0; k < 3; k++) {
            p->org[k][n] = o[k];
            p->dir[k][n] = d[k];
        }
        p->tmin[n] = b->tmin ? b->tmin[b->tmin_stride * id] : 0.0f;
        p->tmax[n] = b->tmax ? b->tmax[b->tmax_stride * id] : INFINITY;
    }
    for (int j = n; j < KD_W; j++) { /* unused lanes: a harmless ray */
        for (int k = 0; k < 3; k++)
            p->org[k][j] = p->dir[k][j] = 1.0f;
        p->tmin[j] = p->tmax[j] = 0.0f;
    }
    p->n = n;
    p->at = 0;
    const VF zero = V(set1)(0.0f), one = V(set1)(1.0f), sgn = V(set1)(-0.0f);
    const VF tmin = V(load)(p->tmin), tmax = V(load)(p->tmax);
    VF O[3], D[3], iv[3];
    unsigned ok = n == KD_W ? KS_ALL : (1u << n) - 1u, flat[3];
    ok &= (unsigned)V(bits)(V(le)(tmin, tmax));
    for (int k = 0; k < 3; k++) {
        O[k] = V(load)(p->org[k]);
        D[k] = V(load)(p->dir[k]);
        ok &= (unsigned)V(bits)(V(eq)(V(sub)(O[k], O[k]), zero)) &
              (unsigned)V(bits)(V(eq)(V(sub)(D[k], D[k]), zero));
        flat[k] = (unsigned)V(bits)(V(eq)(D[k], zero));
        iv[k] = V(div)(one, D[k]);
        p->neg[k] = V(signs)(D[k]);
    }
    ok &= ~(flat[0] & flat[1] & flat[2]);
    /* the slack: f4_hmax of (m0, m1, m2, 0) pairs (m0, m2) and (m1, 0) */
    const VF rm = V(set1)(c->s->root_mag);
    VF m[3];
    for (int k = 0; k < 3; k++)
        m[k] = V(max)(V(andnot)(sgn, O[k]), rm);
    const VF sl =
        V(mul)(V(max)(V(max)(m[0], m[2]), V(max)(m[1], zero)), V(set1)(KD_SLACK_REL));
    VF ent[3], ext[3];
    for (int k = 0; k < 3; k++) {
        V(store)(p->inv[k], iv[k]);
        V(store)(p->ss[k], V(xor)(sl, V(and)(iv[k], sgn)));
        const VF lo = V(sub)(V(set1)(c->s->root.min[k]), sl);
        const VF hi = V(add)(V(set1)(c->s->root.max[k]), sl);
        /* a flat axis only rejects an origin outside the grown slab */
        ok &= ~(flat[k] & (unsigned)V(bits)(V(or)(V(lt)(O[k], lo), V(gt)(O[k], hi))));
        const VF t0 = V(mul)(V(sub)(lo, O[k]), iv[k]);
        const VF t1 = V(mul)(V(sub)(hi, O[k]), iv[k]);
        ent[k] = V(max)(V(selm)(flat[k], V(set1)(-INFINITY), V(min)(t1, t0)), tmin);
        ext[k] = V(min)(V(selm)(flat[k], V(set1)(INFINITY), V(max)(t0, t1)), tmax);
    }
    /* f4_hmax / f4_hmin of (e0, e1, e2, tmin or tmax): (e0, e2), (e1, t) */
    const VF tn = V(max)(V(max)(ent[0], ent[2]), V(max)(ent[1], tmin));
    const VF tf = V(min)(V(min)(ext[0], ext[2]), V(min)(ext[1], tmax));
    V(store)(p->tn, tn);
    V(store)(p->tf, tf);
    p->ok = ok & (unsigned)V(bits)(V(le)(tn, tf));
    /* kd_ray_precompute: the dominant axis kz (first on ties), kx and ky
     * after it, swapped when dir[kz] < 0 */
    const VF ax = V(andnot)(sgn, D[0]), ay = V(andnot)(sgn, D[1]), az = V(andnot)(sgn, D[2]);
    const unsigned xy = (unsigned)V(bits)(V(le)(ay, ax)), xz = (unsigned)V(bits)(V(le)(az, ax)),
                   yz = (unsigned)V(bits)(V(le)(az, ay));
    const unsigned z0 = xy & xz, z1 = ~xy & yz, z2 = KS_ALL & ~(z0 | z1);
#undef KS_PICK
#define KS_PICK(m1, m2, A) V(selm)((m2), (A)[2], V(selm)((m1), (A)[1], (A)[0]))
    const VF dz = KS_PICK(z1, z2, D);
    const unsigned sw = (unsigned)V(bits)(V(lt)(dz, zero));
    /* kx = kz + 1 and ky = kz + 2 (mod 3), exchanged in the lanes of sw */
    const unsigned x1 = (~sw & z0) | (sw & z2), x2 = (~sw & z1) | (sw & z0);
    const unsigned y1 = (~sw & z2) | (sw & z0), y2 = (~sw & z0) | (sw & z1);
    const VF dx = KS_PICK(x1, x2, D), dy = KS_PICK(y1, y2, D);
    V(store)(p->sh[0], KS_PICK(x1, x2, O));
    V(store)(p->sh[1], KS_PICK(y1, y2, O));
    V(store)(p->sh[2], KS_PICK(z1, z2, O));
    V(store)(p->sh[3], V(div)(dx, dz));
    V(store)(p->sh[4], V(div)(dy, dz));
    V(store)(p->sh[5], V(div)(one, dz));
#undef KS_PICK
    p->kz[0] = z0, p->kz[1] = z1, p->kz[2] = z2;
    p->sw = sw;
}

/* Puts the batch's next traceable ray into lane j (rays that cannot be
 * traced or miss the root box are answered on the way, as kdr_intersect1
 * answers them); returns 0 when the batch is exhausted. */
KD_TARGET __attribute__((noinline)) static int
KD_WN(ks_fill)(KD_WN(ks_src) * c, KD_WN(ks_lanes) * w, int j) {
    const unsigned bit = (unsigned)(1u << j);
    KD_WN(ks_lane) *l = &w->lane[j];
    KD_WN(ks_prep) *p = &c->prep;
    for (;;) {
        if (p->at == p->n) {
            if (c->next >= c->m) return 0;
            KD_WN(ks_prepare)(c);
        }
        const int i = p->at++;
        l->id = p->id[i];
        l->o = (kd_walk_out){p->tmax[i], 0.0f, 0.0f, -1, 0, 0};
        if (!((p->ok >> i) & 1)) {
            KD_WN(ks_finish)(l, 0, c);
            continue;
        }
        const float org[3] = {p->org[0][i], p->org[1][i], p->org[2][i]};
        const float inv[3] = {p->inv[0][i], p->inv[1][i], p->inv[2][i]};
        const float ss[3] = {p->ss[0][i], p->ss[1][i], p->ss[2][i]};
        const unsigned neg[3] = {(p->neg[0] >> i) & 1, (p->neg[1] >> i) & 1,
                                 (p->neg[2] >> i) & 1};
        float tn = p->tn[i], tf = p->tf[i];
        kd_todo st[KD_MAX_DEPTH];
        int level = 0, sp = 0;
        const kd_node *n0 =
            c->far ? c->s->nodes
                   : kd_entry_for(c->s, c->entry, org, inv, ss, neg, &tn, &tf, &level, st, &sp);
        for (int d = 0; d < sp; d++) { /* the entries pushed above the entry */
            w->stk_node[d][j] = (int32_t)(st[d].node - c->s->nodes);
            w->stk_tn[d][j] = st[d].tn;
            w->stk_tf[d][j] = st[d].tf;
        }
        l->tmin = p->tmin[i];
        static const int8_t after[3][2][2] = {{{1, 2}, {2, 1}}, {{2, 0}, {0, 2}}, {{0, 1}, {1, 0}}};
        const int kz = (int)((p->kz[1] >> i) & 1) + 2 * (int)((p->kz[2] >> i) & 1);
        const int swp = (int)((p->sw >> i) & 1);
#if KS_ANY
        /* the ray's kd_ray_precompute (ks_prepare's shear) and its
         * kd_ntri_pre_init4 */
        for (int k = 0; k < 3; k++)
            l->pre.org[k] = org[k];
        l->pre.kx = after[kz][swp][0];
        l->pre.ky = after[kz][swp][1];
        l->pre.kz = kz;
        l->pre.sx = p->sh[3][i];
        l->pre.sy = p->sh[4][i];
        l->pre.sz = p->sh[5][i];
        kd_ntri_pre_init4(&l->pre, &l->pre4);
#else
        /* kd_ntri_pre_init8 of the ray's kd_ray_precompute */
        l->pre8.kx = after[kz][swp][0];
        l->pre8.ky = after[kz][swp][1];
        l->pre8.kz = kz;
        l->pre8.ox = f8_set1(p->sh[0][i]);
        l->pre8.oy = f8_set1(p->sh[1][i]);
        l->pre8.oz = f8_set1(p->sh[2][i]);
        l->pre8.sx = f8_set1(p->sh[3][i]);
        l->pre8.sy = f8_set1(p->sh[4][i]);
        l->pre8.sz = f8_set1(p->sh[5][i]);
#endif
        w->node = IV(put)(w->node, bit, (int32_t)(n0 - c->s->nodes));
        w->sp = IV(put)(w->sp, bit, sp);
        w->visits = IV(put)(w->visits, bit, level);
        w->tn = V(put)(w->tn, bit, tn);
        w->tf = V(put)(w->tf, bit, tf);
        for (int k = 0; k < 3; k++) {
            w->org[k] = V(put)(w->org[k], bit, org[k]);
            w->inv[k] = V(put)(w->inv[k], bit, inv[k]);
            w->ss[k] = V(put)(w->ss[k], bit, ss[k]);
        }
        return 1;
    }
}

/* Lane j's pop (walk()'s): returns 0 when its stack holds nothing that
 * starts at or before kd_term_bound(best t), i.e. the ray is done. */
KD_FN int KD_WN(ks_pop)(KD_WN(ks_lanes) * w, int j, const int32_t *spv) {
    const unsigned bit = (unsigned)(1u << j);
    const int sp =
        kd_lane_pop_depth(&w->stk_tn[0][0], KD_W, j, spv[j], kd_term_bound(w->lane[j].o.t));
    if (sp < 0) return 0;
    w->node = IV(put)(w->node, bit, w->stk_node[sp][j]);
    w->tn = V(put)(w->tn, bit, w->stk_tn[sp][j]);
    w->tf = V(put)(w->tf, bit, w->stk_tf[sp][j]);
    w->sp = IV(put)(w->sp, bit, sp);
    return 1;
}

/* The lanes' leaves and pops; finished lanes answer and refill. */
KD_FN void KD_WN(ks_settle)(KD_WN(ks_src) * c, KD_WN(ks_lanes) * w, unsigned leaf,
                            unsigned pop) {
    const kdr_scene *s = c->s;
    _Alignas(sizeof(VF)) int32_t nv[KD_W], spv[KD_W], vis[KD_W];
    IV(store)(nv, w->node);
    IV(store)(spv, w->sp);
    unsigned done = 0, found = 0;
    for (unsigned mm = leaf; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        KD_WN(ks_lane) *l = &w->lane[j];
#if KS_ANY
        const int hit = kd_walk_leaf(s, s->nodes + nv[j], &l->pre, &l->pre4, l->tmin, 1, 1,
                                     &l->o);
#else
        const int hit = kd_walk_leaf_w8(s, s->nodes + nv[j], &l->pre8, l->tmin, 0, &l->o);
#endif
        if (hit) {
            done |= (unsigned)(1u << j);
            found |= (unsigned)(1u << j);
        } else {
            pop |= (unsigned)(1u << j);
        }
    }
    for (unsigned mm = pop; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        if (!KD_WN(ks_pop)(w, j, spv)) {
            done |= (unsigned)(1u << j);
            found |= (unsigned)((w->lane[j].o.prim >= 0) << j);
        }
    }
    if (!done) return;
    IV(store)(vis, w->visits);
    for (unsigned mm = done; mm; mm &= mm - 1) {
        const int j = __builtin_ctz(mm);
        w->lane[j].o.nodes = (uint64_t)vis[j];
        KD_WN(ks_finish)(&w->lane[j], (found >> j) & 1, c);
        if (!KD_WN(ks_fill)(c, w, j)) w->act &= (unsigned)~(1u << j);
    }
}

/* One turn: every active lane takes one step. */
KD_FN void KD_WN(ks_turn)(KD_WN(ks_src) * c, KD_WN(ks_lanes) * w) {
    const kdr_scene *s = c->s;
    const VI one = IV(set1)(1), three = IV(set1)(3);
    const unsigned act = w->act;
    const VI node = w->node;
    const VF tn = w->tn, tf = w->tf;
    /* the node: split (word 0) and bits (word 1) of kd_node[node] */
    const VI bits = IV(gather8)(three, act, node, (const int32_t *)s->nodes + 1);
    const VF split = V(gather8)(V(set1)(0.0f), act, node, s->nodes);
    w->visits = IV(add_in)(act & ~w->refs & ~w->tris, w->visits, one);
    const VI axis = IV(and)(bits, three);
    const unsigned at_leaf = IV(eq)(act, axis, three);
    /* staged leaves: references requested on the turn that reaches the
     * leaf, triangles on the next (the references are then in the cache,
     * so the requests cost no miss), the test on the one after */
    const unsigned get_refs = at_leaf & ~w->refs & ~w->tris & c->stage;
    const unsigned get_tris = at_leaf & w->refs;
    const unsigned leaf = at_leaf & ~get_refs & ~get_tris;
    w->refs = get_refs;
    w->tris = get_tris;
    const unsigned inner = act & ~at_leaf;
    /* descend()'s step, lane by lane as masks */
    const unsigned ax1 = IV(eq)(KS_ALL, axis, one),
                   ax2 = IV(eq)(KS_ALL, axis, IV(set1)(2));
    const VF o = V(selm)(ax2, w->org[2], V(selm)(ax1, w->org[1], w->org[0]));
    const VF iv = V(selm)(ax2, w->inv[2], V(selm)(ax1, w->inv[1], w->inv[0]));
    const VF ss = V(selm)(ax2, w->ss[2], V(selm)(ax1, w->ss[1], w->ss[0]));
    const VF a = V(sub)(split, o);
    const VF t_lo = V(mul)(V(sub)(a, ss), iv);
    const VF t_hi = V(mul)(V(add)(a, ss), iv);
    const unsigned neg = V(signs)(iv); /* the near child is above */
    const VI below = IV(add)(node, one), above = IV(srl)(bits, 4);
    const VI nearc = IV(selm)(neg, above, below), farc = IV(selm)(neg, below, above);
    const unsigned below_empty = IV(test)(bits, IV(set1)(4));
    const unsigned above_empty = IV(test)(bits, IV(set1)(8));
    const unsigned near_empty = (neg & above_empty) | (~neg & below_empty);
    const unsigned far_empty = (neg & below_empty) | (~neg & above_empty);
    /* kd_traverse_stream.c's branch-free form of the five cases */
    const unsigned go_near = V(nlt)(inner & ~near_empty, t_hi, tn);
    const unsigned go_far = V(ngt)(inner & ~far_empty, t_lo, tf);
    const unsigned push = go_near & go_far;
    const VF far_tn = V(max)(t_lo, tn), near_tf = V(min)(t_hi, tf);
    const unsigned moved = go_near | go_far;
    /* far end first (any hit): the same intervals, the far child entered
     * and the near one stacked */
    const int far_first = KS_ANY && c->far;
    if (push) {
        const VI slot = IV(add)(IV(sll)(w->sp, KS_LOG2W), IV(iota)());
        IV(scatter)(&w->stk_node[0][0], push, slot, far_first ? nearc : farc);
        V(scatter)(&w->stk_tn[0][0], push, slot, far_first ? tn : far_tn);
        V(scatter)(&w->stk_tf[0][0], push, slot, far_first ? near_tf : tf);
        w->sp = IV(add_in)(push, w->sp, one);
    }
    if (far_first) {
        w->node = IV(selm)(moved, IV(selm)(go_far, farc, nearc), node);
        w->tn = V(selm)(go_far, far_tn, tn);
        w->tf = V(selm)(go_near & ~go_far, near_tf, tf);
    } else {
        w->node = IV(selm)(moved, IV(selm)(go_near, nearc, farc), node);
        w->tn = V(selm)(go_far & ~go_near, far_tn, tn);
        w->tf = V(selm)(go_near, near_tf, tf);
    }
    if (c->stage) {
        _Alignas(sizeof(VF)) int32_t nv[KD_W];
        IV(store)(nv, w->node);
        for (unsigned mm = moved; mm; mm &= mm - 1)
            __builtin_prefetch(s->nodes + nv[__builtin_ctz(mm)]);
        for (unsigned mm = get_refs; mm; mm &= mm - 1) {
            const kd_node *n = s->nodes + nv[__builtin_ctz(mm)];
            kd_prefetch_refs(s, n);
        }
        for (unsigned mm = get_tris; mm; mm &= mm - 1) {
            const kd_node *n = s->nodes + nv[__builtin_ctz(mm)];
            kd_prefetch_tris(s, s->refs + n->u.first, kd_count(n));
        }
    }
    const unsigned pop = inner & ~moved;
    if (leaf | pop) KD_WN(ks_settle)(c, w, leaf, pop);
}

#undef KS_ENTRY
#if KS_ANY
#define KS_ENTRY KD_WN(kd_stream_any)
#else
#define KS_ENTRY KD_WN(kd_stream_hit)
#endif

KD_TARGET void KS_ENTRY(const kdr_scene *s, const kdr_ray_batch *b, const size_t *ids,
                        size_t first, size_t m, int flags, kdr_hits *out,
                        kdr_trav_stats *stats) {
    const int stage =
        (flags & KD_STREAM_STAGE) || s->stats.bytes >= KD_STREAM_STAGE_MIN_BYTES;
    kd_entry_cache ec;
    ec.have_path = ec.have_prev = 0;
    KD_WN(ks_src) c; /* field by field: prep is written before it is read */
    c.s = s, c.b = b, c.ids = ids, c.first = first, c.m = m, c.next = 0;
    c.out = out, c.stats = stats, c.stage = stage ? KS_ALL : 0, c.entry = &ec;
    c.far = KS_ANY && (flags & KD_STREAM_FAR);
    c.prep.n = c.prep.at = 0;
    KD_WN(ks_lanes) w;
    w.node = w.sp = w.visits = IV(set1)(0);
    w.tn = w.tf = V(set1)(0.0f);
    for (int k = 0; k < 3; k++)
        w.org[k] = w.inv[k] = w.ss[k] = V(set1)(0.0f);
    w.act = w.refs = w.tris = 0;
    for (int j = 0; j < KD_W; j++)
        if (KD_WN(ks_fill)(&c, &w, j)) w.act |= (unsigned)(1u << j);
    while (w.act)
        KD_WN(ks_turn)(&c, &w);
}
