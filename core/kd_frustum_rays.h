/*
 * kd_frustum_rays.h — the rays of the frustum traversal (part of the
 * kd_frustum_trav.h template, included by it after its types): building a
 * tile's ray groups (directions from the tabulated camera terms, the
 * shear of the watertight test, the tile's direction interval and root
 * interval), the per-group box test and termination bounds, and writing
 * the results out by pixel.
 */

/* ---- tile set-up ---------------------------------------------------------- */

static size_t kf_groups_per_tile(uint32_t tile) {
    return (size_t)((tile + KF_BW - 1) / KF_BW) * ((tile + 1) / 2);
}

/* Lanes set in 4- or 8-bit masks. */
static inline int kf_popcount(int bits) {
    return (int)((0x4332322132212110ull >> (4 * (bits & 15))) & 15) +
           (int)((0x4332322132212110ull >> (4 * ((bits >> 4) & 15))) & 15);
}

/* The shear of kd_ray_precompute for a whole group at once, when its rays
 * share the dominant axis and its sign (nearly always in a small block):
 * the same divisions, so the same bits. Returns 0 when lanes disagree. */
KD_TARGET static int kf_pre_uniform(const kf_ctx *c, kf_group *g, const VF d[3]) {
    const VF sign = V(set1)(-0.0f), zero = V(set1)(0.0f);
    const VF ax = V(andnot)(sign, d[0]), ay = V(andnot)(sign, d[1]),
             az = V(andnot)(sign, d[2]);
    const VF ge_xy = V(le)(ay, ax);
    const int b0 = V(bits)(V(and)(ge_xy, V(le)(az, ax)));
    const int b1 = V(bits)(V(andnot)(ge_xy, V(le)(az, ay)));
    const int kz = b0 == KF_FULL ? 0 : b1 == KF_FULL ? 1 : (b0 | b1) == 0 ? 2 : -1;
    if (kz < 0)
        return 0;
    int kx = kz + 1 == 3 ? 0 : kz + 1, ky = kx + 1 == 3 ? 0 : kx + 1;
    const int neg = V(bits)(V(lt)(d[kz], zero));
    if (neg != 0 && neg != KF_FULL)
        return 0;
    if (neg) {
        const int tmp = kx;
        kx = ky;
        ky = tmp;
    }
    KD_WN(kd_nray_pre) *p = &g->pre;
    p->ox = V(set1)(c->b->eye[kx]);
    p->oy = V(set1)(c->b->eye[ky]);
    p->oz = V(set1)(c->b->eye[kz]);
    p->sx = V(div)(d[kx], d[kz]);
    p->sy = V(div)(d[ky], d[kz]);
    p->sz = V(div)(V(set1)(1.0f), d[kz]);
    p->kx0 = V(seti)(kx == 0 ? -1 : 0);
    p->kx1 = V(seti)(kx == 1 ? -1 : 0);
    p->ky0 = V(seti)(ky == 0 ? -1 : 0);
    p->ky1 = V(seti)(ky == 1 ? -1 : 0);
    p->kz0 = V(seti)(kz == 0 ? -1 : 0);
    p->kz1 = V(seti)(kz == 1 ? -1 : 0);
    p->uniform = 1;
    p->kx = kx;
    p->ky = ky;
    p->kz = kz;
    return 1;
}

/* Per-lane scalar precomputation, for blocks whose rays shear differently. */
KD_TARGET static void kf_pre_mixed(const kf_ctx *c, kf_group *g, const VF d[3]) {
    _Alignas(32) float dd[3][KD_W];
    kd_ray_pre pre[KD_W];
    for (int a = 0; a < 3; a++)
        V(store)(dd[a], d[a]);
    for (int j = 0; j < KD_W; j++) {
        const float dir[3] = {dd[0][j], dd[1][j], dd[2][j]};
        kd_ray_precompute(c->b->eye, dir, &pre[j]);
    }
    KD_WN(kd_nray_pre_init)(&g->pre, pre, KF_FULL, 0);
}

/* Fills group g with the KF_BW x 2 block at (x, y), clipped to [.., x1) x
 * [.., y1): clipped-off lanes repeat a pixel of the block (so the block
 * still shears uniformly) but are never live nor written. Widens the
 * tile's direction interval. */
KD_TARGET static void kf_group_init(kf_ctx *c, kf_group *g, uint32_t x, uint32_t y,
                         uint32_t x1, uint32_t y1, VF dmin[3], VF dmax[3]) {
    _Alignas(32) float sxa[KD_W], sya[KD_W];
    const size_t W = c->cam->width;
    if (x + KF_BW <= x1 && y + 2 <= y1) { /* whole block: no clipping */
        for (int j = 0; j < KD_W; j++) {
            const uint32_t px = x + (uint32_t)(j % KF_BW), py = y + (uint32_t)(j / KF_BW);
            sxa[j] = c->sx_tab[px];
            sya[j] = c->sy_tab[py];
            g->pix[j] = (int32_t)((size_t)py * W + px);
        }
        g->live = KF_FULL;
    } else {
        g->live = 0;
        for (int j = 0; j < KD_W; j++) {
            const uint32_t px = x + (uint32_t)(j % KF_BW), py = y + (uint32_t)(j / KF_BW);
            const int in = px < x1 && py < y1;
            const uint32_t cx = px < x1 ? px : x1 - 1, cy = py < y1 ? py : y1 - 1;
            sxa[j] = c->sx_tab[cx];
            sya[j] = c->sy_tab[cy];
            g->pix[j] = in ? (int32_t)((size_t)py * W + px) : -1;
            g->live |= in << j;
        }
    }
    const VF sx = V(load)(sxa), sy = V(load)(sya);
    VF d[3];
    for (int a = 0; a < 3; a++) {
        d[a] = V(add)(V(add)(V(set1)(c->b->f[a]), V(mul)(sx, V(set1)(c->b->r[a]))),
                      V(mul)(sy, V(set1)(c->b->u[a])));
        dmin[a] = V(min)(dmin[a], d[a]);
        dmax[a] = V(max)(dmax[a], d[a]);
        V(store)(g->inv[a], V(div)(V(set1)(1.0f), d[a]));
    }
    if (!kf_pre_uniform(c, g, d))
        kf_pre_mixed(c, g, d);
    V(store)(g->t, V(set1)(INFINITY));
    V(store)(g->u, V(set1)(0.0f));
    V(store)(g->v, V(set1)(0.0f));
    V(store)((float *)g->prim, V(seti)(KF_NO_PRIM));
    g->term = INFINITY;
}

/* Box [lo, hi] relative to the eye, padded outward and never 0 (a zero
 * times an infinite 1/dir would give NaN). */
static void kf_rel_box(const kf_ctx *c, const float lo[3], const float hi[3],
                       float rlo[3], float rhi[3]) {
    for (int a = 0; a < 3; a++) {
        rlo[a] = (lo[a] - c->b->eye[a]) - c->pad;
        rhi[a] = (hi[a] - c->b->eye[a]) + c->pad;
        if (rlo[a] == 0.0f)
            rlo[a] = -FLT_MIN;
        if (rhi[a] == 0.0f)
            rhi[a] = FLT_MIN;
    }
}

/* Slab test of a group's rays against a relative box, over t >= 0: the
 * lanes whose ray may meet it, with their entry and exit distances. */
KD_TARGET static int kf_group_box(const kf_group *g, const float rlo[3],
                       const float rhi[3], VF *tnear, VF *tfar) {
    VF tn = V(set1)(0.0f), tf = V(set1)(INFINITY);
    for (int a = 0; a < 3; a++) {
        const VF inv = V(load)(g->inv[a]);
        const VF t0 = V(mul)(V(set1)(rlo[a]), inv);
        const VF t1 = V(mul)(V(set1)(rhi[a]), inv);
        tn = V(max)(tn, V(min)(t0, t1));
        tf = V(min)(tf, V(max)(t0, t1));
    }
    *tnear = tn;
    *tfar = tf;
    return V(bits)(V(le)(tn, tf));
}

/* kd_term_bound of four t values, same operations. */
KD_TARGET static VF kf_termv(VF t) {
    const VF abs_t = V(andnot)(V(set1)(-0.0f), t);
    return V(add)(V(add)(t, V(mul)(abs_t, V(set1)(0x1p-18f))), V(set1)(FLT_MIN));
}

KD_TARGET static void kf_group_update_term(kf_ctx *c, kf_group *g) {
    _Alignas(32) float tb[KD_W];
    float m = -INFINITY;
    if (c->q == KDR_ANY) {
        g->term = g->live ? INFINITY : -INFINITY;
        return;
    }
    V(store)(tb, kf_termv(V(load)(g->t)));
    for (int j = 0; j < KD_W; j++)
        if ((g->live >> j) & 1)
            m = kf_maxf(m, tb[j]);
    g->term = m;
}

KD_TARGET static void kf_tile_update_term(kf_ctx *c, kf_tile *ft) {
    float m = -INFINITY;
    for (size_t k = 0; k < ft->ng; k++)
        m = kf_maxf(m, c->groups[ft->g0 + k].term);
    ft->term = m;
}

KD_TARGET static float kf_hmin(VF v) {
    _Alignas(32) float x[KD_W];
    V(store)(x, v);
    float m = x[0];
    for (int j = 1; j < KD_W; j++)
        m = kf_minf(m, x[j]);
    return m;
}
KD_TARGET static float kf_hmax(VF v) {
    _Alignas(32) float x[KD_W];
    V(store)(x, v);
    float m = x[0];
    for (int j = 1; j < KD_W; j++)
        m = kf_maxf(m, x[j]);
    return m;
}

/* Builds tile k's groups in lane l; clips its rays to the root box (rays
 * that miss it stop searching: every triangle lies inside). */
KD_TARGET static void kf_tile_init(kf_ctx *c, int l, size_t k) {
    kf_tile *ft = &c->ft[l];
    const uint32_t T = c->tile, W = c->cam->width, H = c->cam->height;
    const size_t tiles_x = ((size_t)W + T - 1) / T;
    const uint32_t x0 = (uint32_t)(k % tiles_x) * T, y0 = (uint32_t)(k / tiles_x) * T;
    const uint32_t x1 = W - x0 < T ? W : x0 + T, y1 = H - y0 < T ? H : y0 + T;
    VF dmin[3], dmax[3], tn = V(set1)(INFINITY), tf = V(set1)(-INFINITY);
    float rlo[3], rhi[3];
    for (int a = 0; a < 3; a++) {
        dmin[a] = V(set1)(INFINITY);
        dmax[a] = V(set1)(-INFINITY);
    }
    ft->g0 = (size_t)l * c->gpt;
    ft->ng = 0;
    ft->nrays = (x1 - x0) * (y1 - y0);
    kf_rel_box(c, c->s->root.min, c->s->root.max, rlo, rhi);
    for (uint32_t y = y0; y < y1; y += 2) {
        for (uint32_t x = x0; x < x1; x += KF_BW) {
            kf_group *g = &c->groups[ft->g0 + ft->ng++];
            VF vn, vf;
            kf_group_init(c, g, x, y, x1, y1, dmin, dmax);
            g->live &= kf_group_box(g, rlo, rhi, &vn, &vf);
            const VF live = V(bitmask)(g->live);
            tn = V(min)(tn, V(sel)(live, vn, V(set1)(INFINITY)));
            tf = V(max)(tf, V(sel)(live, vf, V(set1)(-INFINITY)));
            if (!g->live)
                g->term = -INFINITY;
        }
    }
    for (int a = 0; a < 3; a++) {
        ft->dmin[a] = kf_hmin(dmin[a]);
        ft->dmax[a] = kf_hmax(dmax[a]);
    }
    ft->tn = kf_hmin(tn);
    ft->tf = kf_hmax(tf);
    kf_tile_update_term(c, ft);
}

/* ---- output ----------------------------------------------------------------- */

/* Closest-hit results of a whole block, a vector at a time. */
KD_TARGET static void kf_write_block(const kf_group *g, kdr_hits *out) {
    const VF prim = V(load)((const float *)g->prim);
    const VF nohit = V(ieq)(prim, V(seti)(KF_NO_PRIM));
    const int32_t p0 = g->pix[0], p1 = g->pix[KF_BW];
    float *prims = (float *)out->prim;
    V(store_halves)(out->t + p0, out->t + p1,
                    V(sel)(nohit, V(set1)(-1.0f), V(load)(g->t)));
    V(store_halves)(prims + p0, prims + p1, V(sel)(nohit, V(seti)(-1), prim));
    V(store_halves)(out->u + p0, out->u + p1, V(andnot)(nohit, V(load)(g->u)));
    V(store_halves)(out->v + p0, out->v + p1, V(andnot)(nohit, V(load)(g->v)));
}

KD_TARGET static void kf_write(const kf_ctx *c, kdr_hits *out) {
    for (int l = 0; l < c->nlanes; l++) {
        const kf_tile *ft = &c->ft[l];
        for (size_t k = 0; k < ft->ng; k++) {
            const kf_group *g = &c->groups[ft->g0 + k];
            if (c->q == KDR_CLOSEST && g->pix[KD_W - 1] >= 0) { /* whole block */
                kf_write_block(g, out);
                continue;
            }
            for (int j = 0; j < KD_W; j++) {
                const int32_t i = g->pix[j];
                const int hit = g->prim[j] != KF_NO_PRIM;
                if (i < 0)
                    continue;
                if (c->q == KDR_ANY) {
                    out->hit[i] = (uint8_t)hit;
                    continue;
                }
                out->t[i] = hit ? g->t[j] : -1.0f;
                out->prim[i] = hit ? g->prim[j] : -1;
                out->u[i] = hit ? g->u[j] : 0.0f;
                out->v[i] = hit ? g->v[j] : 0.0f;
            }
        }
    }
}
