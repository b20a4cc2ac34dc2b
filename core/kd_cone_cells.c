/*
 * kd_cone_cells.c — adaptive sub-cones for one (point, light): the samples
 * are split into cells of their own parameters, each cell's cone decides
 * its samples if it can, and only the cells that stay undecided trace
 * their samples (kd_cone.c, step 3 of its header, says when this runs).
 *
 * A cell is a box of sample parameters: strata [s0, s1) (so 1 - cos(theta)
 * lies in [s0, s1] / n times 1 - cos(alpha): stratum s holds exactly
 * sample s) and phase [p0, p1) turns (kd_shadow_frame_phase). Its samples
 * are exactly those whose parameters lie in it — a list kept by
 * partitioning the parent's list — and its cone holds all their directions:
 * the axis at the cell's middle (u = (s0 + s1) / 2n, phase (p0 + p1) / 2),
 * the half-angle the largest angle to the cell's four corners (on the
 * sphere, the farthest point of such a cell from a point inside it is a
 * corner: along a circle of latitude the distance grows with the azimuth
 * difference, along a meridian it is monotone on either side of its
 * minimum, and it has no maximum inside), widened by CELL_SLACK for the
 * rounding of the float directions (~1e-7 rad).
 *
 * Per cell, the candidates are the parent's, filtered (the root's: those
 * of the whole light's walk, which judges them as it goes). A
 * candidate whose proof (kd_cone_proof.c) says it misses every segment of
 * the cell is dropped; one that covers them all puts the cell in umbra;
 * none left: lit. Without a fixed origin (no normals: each ray starts
 * along itself) there are no proofs and the walk's own cull
 * (kd_cone_tri_may_block) filters the lists. A cell still undecided splits
 * into four (twice the longer of its radial and azimuthal sides on the
 * light's disc, so cells stay square-ish) while it holds more than
 * CELL_LEAF_SAMPLES samples; a leaf tests its samples against its list in
 * packets of 16 (AVX-512), 8 or 4. Only the whole light walks the tree:
 * when that walk is over budget, nothing is decided here (kd_cone.c traces
 * a busy cone otherwise).
 */
#include <stdlib.h>
#include <string.h>

#include "kd_cone.h"
#include "kd_internal.h"

/* Plain-comparison min/max: fmin/fmax are libm calls without -ffast-math
 * (their NaN rules), and no operand here is NaN. */
static inline double dmax(double a, double b) { return a > b ? a : b; }
static inline double dmin(double a, double b) { return a < b ? a : b; }

#define TWO_PI 6.283185307179586477
/* Angular slack of a cell's cone over its exact directions (radians). */
#define CELL_SLACK 1e-6
#define WALK_LIST ((const uint32_t *)0) /* the root: walk the tree */

typedef struct cell {
    uint32_t i0, i1;     /* its samples: c->idx[i0 .. i1) */
    uint32_t s0, s1;     /* strata */
    double p0, p1;       /* phase, turns */
    double cphi, sphi;   /* cos, sin of 2 pi (p0 + p1) / 2 */
    int wlevel;          /* p1 - p0 = 2^-wlevel */
} cell;

/* ---- workspace -------------------------------------------------------------- */

int kd_cells_reserve(kd_cells *c, uint32_t nsamples) {
    if (c->idx && c->cap_samples >= nsamples)
        return KDR_OK;
    free(c->idx);
    free(c->phase);
    c->idx = malloc(nsamples * sizeof *c->idx);
    c->phase = malloc(nsamples * sizeof *c->phase);
    c->cap_samples = nsamples;
    if (!c->hw_ready) {
        for (int k = 0; k < KD_CELL_MAX_LEVEL; k++) {
            c->hw_cos[k] = cos(TWO_PI * 0.5 * ldexp(1.0, -k));
            c->hw_sin[k] = sin(TWO_PI * 0.5 * ldexp(1.0, -k));
        }
        c->slack_cos = cos(CELL_SLACK);
        c->slack_sin = sin(CELL_SLACK);
        c->hw_ready = 1;
    }
    return c->idx && c->phase ? KDR_OK : KDR_ENOMEM;
}

void kd_cells_free(kd_cells *c) {
    free(c->idx);
    free(c->phase);
    free(c->views);
    free(c->lists);
    free(c->cl.v);
}

static int push_view(kd_cells *c, const kd_cone_pair *pr, uint32_t prim, uint32_t *at) {
    if (c->nviews == c->cap_views) {
        const size_t cap = c->cap_views ? 2 * c->cap_views : 64;
        kd_tri_view *v = realloc(c->views, cap * sizeof *v);
        if (!v)
            return KDR_ENOMEM;
        c->views = v;
        c->cap_views = cap;
    }
    kd_tri_view_init(&c->views[c->nviews], pr->scene->tris + 9 * (size_t)prim, prim,
                     pr->f->apex);
    *at = (uint32_t)c->nviews++;
    return KDR_OK;
}

/* The list buffer of one depth (CONE_MAX_CANDS entries each). */
static uint32_t *list_at(kd_cells *c, int depth) {
    return c->lists + (size_t)depth * CONE_MAX_CANDS;
}

/* ---- geometry of a cell --------------------------------------------------------- */

static double cos_theta(const kd_shadow_frame *f, double u) { return 1.0 - u * f->one_minus_cos; }
static double sin_theta(const kd_shadow_frame *f, double u) {
    const double o = u * f->one_minus_cos;
    return sqrt(o * (2.0 - o));
}

/* The cell's cone: world axis, half-angle (slack included). */
static void cell_cone(const kd_cells *c, const kd_cone_pair *pr, const cell *ce,
                      kd_dir_cone *dc) {
    const kd_shadow_frame *f = pr->f;
    const double n = pr->n, u0 = ce->s0 / n, u1 = ce->s1 / n, um = 0.5 * (u0 + u1);
    const double cm = cos_theta(f, um), sm = sin_theta(f, um);
    const double ch = c->hw_cos[ce->wlevel]; /* cos of the half-width */
    double axis[3];
    for (int k = 0; k < 3; k++)
        axis[k] = cm * f->axis[k] + sm * (ce->cphi * f->b1[k] + ce->sphi * f->b2[k]);
    const double l = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    for (int k = 0; k < 3; k++)
        axis[k] /= l;
    /* cos of the angle to the corners at u0 and u1 (either side alike) */
    const double d0 = cm * cos_theta(f, u0) + sm * sin_theta(f, u0) * ch;
    const double d1 = cm * cos_theta(f, u1) + sm * sin_theta(f, u1) * ch;
    const double cg = dmin(dmin(d0, d1), 1.0), sg = sqrt(dmax(0.0, (1.0 - cg) * (1.0 + cg)));
    kd_dir_cone_set(dc, axis, cg * c->slack_cos - sg * c->slack_sin,
                    sg * c->slack_cos + cg * c->slack_sin, pr->tmax_lo);
}

/* The whole light's cone (the root cell). */
static void light_cone(const kd_cells *c, const kd_cone_pair *pr, kd_dir_cone *dc) {
    const double sa = pr->f->sin_a, ca = sqrt((1.0 - sa) * (1.0 + sa));
    kd_dir_cone_set(dc, pr->f->axis, ca * c->slack_cos - sa * c->slack_sin,
                    sa * c->slack_cos + ca * c->slack_sin, pr->tmax_lo);
}

/* Splits in two along the longer side on the light's disc (radius sqrt(u),
 * arc 2 pi dp sqrt(u1)), partitioning the samples; 0 if it cannot. */
static int split2(kd_cells *c, const kd_cone_pair *pr, const cell *in, cell out[2]) {
    const double n = pr->n;
    const double radial = sqrt(in->s1 / n) - sqrt(in->s0 / n);
    const double arc = TWO_PI * (in->p1 - in->p0) * sqrt(in->s1 / n);
    const int by_phase = in->s1 - in->s0 < 2 || arc > radial;
    if (by_phase && in->wlevel + 1 >= KD_CELL_MAX_LEVEL)
        return 0;
    uint32_t *idx = c->idx, lo = in->i0, hi = in->i1;
    const double pm = 0.5 * (in->p0 + in->p1);
    const uint32_t sm = in->s0 + (in->s1 - in->s0) / 2;
    while (lo < hi) { /* the first child's samples to the front */
        const uint32_t s = idx[lo];
        if (by_phase ? c->phase[s] < pm : s < sm)
            lo++;
        else {
            idx[lo] = idx[--hi];
            idx[hi] = s;
        }
    }
    out[0] = out[1] = *in;
    out[0].i1 = out[1].i0 = lo;
    if (by_phase) {
        const double hc = c->hw_cos[in->wlevel + 1], hs = c->hw_sin[in->wlevel + 1];
        out[0].p1 = out[1].p0 = pm;
        out[0].wlevel = out[1].wlevel = in->wlevel + 1;
        out[0].cphi = in->cphi * hc + in->sphi * hs; /* rotated by -+ the child's */
        out[0].sphi = in->sphi * hc - in->cphi * hs; /* half-width */
        out[1].cphi = in->cphi * hc - in->sphi * hs;
        out[1].sphi = in->sphi * hc + in->cphi * hs;
    } else {
        out[0].s1 = out[1].s0 = sm;
    }
    return 1;
}

/* ---- deciding a cell's samples -------------------------------------------------------- */

static uint32_t popcount8(int m) {
    uint32_t k = 0;
    for (; m; m &= m - 1)
        k++;
    return k;
}

/* Lit samples of the cell against a complete list of candidates. */
static uint32_t trace_list(kd_cells *c, kd_cone_pair *pr, const cell *ce,
                           const uint32_t *prims, size_t np) {
    uint32_t lit = 0;
    /* 16 lanes where AVX-512 runs and more than 8 samples are left, else
     * 8 (AVX2) or 4 */
    const uint32_t width = pr->wide16 && ce->i1 - ce->i0 > 8 ? 16u : pr->wide ? 8u : 4u;
    for (uint32_t g = ce->i0; g < ce->i1; g += width) {
        const int m = (int)(ce->i1 - g < width ? ce->i1 - g : width);
        const kdr_ray *lanes[16];
        kd_shadow_frame_rays(pr->f, c->idx + g, 0, (uint32_t)m, pr->n, c->rays);
        for (int j = 0; j < m; j++)
            lanes[j] = &c->rays[j];
        const int blocked =
            np ? kd_cone_packet_blocked(pr->scene, lanes, m, prims, np, &pr->last, (int)width)
               : 0;
        lit += (uint32_t)m - popcount8(blocked);
    }
    pr->st.rays_traced += ce->i1 - ce->i0;
    return lit;
}

static uint32_t process(kd_cells *c, kd_cone_pair *pr, const cell *ce,
                        const uint32_t *plist, size_t np, int depth);

/* The four children (two binary splits), or 0 if the cell cannot split. */
static int children(kd_cells *c, kd_cone_pair *pr, const cell *ce, cell kids[4], int *nk) {
    cell half[2];
    if (!split2(c, pr, ce, half))
        return 0;
    *nk = 0;
    for (int h = 0; h < 2; h++) {
        if (split2(c, pr, &half[h], kids + *nk))
            *nk += 2;
        else
            kids[(*nk)++] = half[h];
    }
    return 1;
}

/* 1 if prim was seen before in this walk (and marks it seen, while the
 * table is at most half full): a triangle straddling splits sits in
 * several leaves and is judged once. */
static int seen_before(kd_cells *c, uint32_t prim) {
    const uint32_t mask = (1u << KD_SEEN_BITS) - 1;
    for (uint32_t h = (prim * 2654435761u) >> (32 - KD_SEEN_BITS);; h = (h + 1) & mask) {
        if (c->seen_stamp[h] != c->stamp) {
            if (c->nseen < mask / 2) {
                c->seen_stamp[h] = c->stamp;
                c->seen_prim[h] = prim;
                c->nseen++;
            }
            return 0;
        }
        if (c->seen_prim[h] == prim)
            return 1;
    }
}

/* Judges triangle prim for the cell (the cheap edge test, else a view and
 * its verdict): listed
 * (as a view index) unless it misses; KD_CONE_OVER past CONE_MAX_CANDS. */
static int judge_view(kd_cells *c, kd_cone_pair *pr, const kd_dir_cone *dc, uint32_t prim,
                      uint32_t *out, size_t *nl, int *covered);

static int judge(kd_cells *c, kd_cone_pair *pr, const kd_dir_cone *dc, uint32_t prim,
                 uint32_t *out, size_t *nl, int *covered) {
    if (kd_tri_edges_miss(pr->scene->tris + 9 * (size_t)prim, pr->f->apex, dc))
        return KDR_OK; /* beside the cone: no view needed */
    return judge_view(c, pr, dc, prim, out, nl, covered);
}

/* judge after the edge test: the view and its verdict. */
static int judge_view(kd_cells *c, kd_cone_pair *pr, const kd_dir_cone *dc, uint32_t prim,
                      uint32_t *out, size_t *nl, int *covered) {
    uint32_t at;
    if (push_view(c, pr, prim, &at) != KDR_OK)
        return KDR_ENOMEM;
    const kd_verdict v = kd_tri_view_classify(&c->views[at], dc);
    if (v == KD_TRI_COVERS) {
        *covered = 1;
        pr->last = prim;
    } else if (v == KD_TRI_MISSES) {
        c->nviews--; /* the view was the last one made */
    } else if (*nl == pr->max_cands) {
        return KD_CONE_OVER;
    } else {
        out[(*nl)++] = at;
    }
    return KDR_OK;
}

/* The cell's own walk with proofs: every triangle the walk's cull keeps
 * gets a view; those that miss every segment of dc are dropped, the others
 * are listed (as view indices) until more than CONE_MAX_CANDS remain
 * (KD_CONE_OVER) or one covers the cell (*covered). */
static int walk_with_proofs(kd_cells *c, kd_cone_pair *pr, const kd_dir_cone *dc,
                            const kd_cone *kc, uint32_t *out, size_t *nl, int *covered) {
    const uint64_t max_nodes = CONE_NODES_BASE + CONE_NODES_PER_SAMPLE * (uint64_t)pr->n;
    kd_cone_walk w;
    const kd_node *leaf;
    int rc = KDR_OK;
    if (++c->stamp == 0) { /* the stamps wrapped: forget every mark */
        memset(c->seen_stamp, 0, sizeof c->seen_stamp);
        c->stamp = 1;
    }
    c->nseen = 0;
    /* with AVX2 the cull's sphere tests go four at a time (the same
     * answers, kd_cone_cull4.c); judged in the leaf's order either way
     * (marks made past a covering triangle do not matter: the walk ends) */
    const int wide4 = pr->wide && kc->cos_p != 0.0;
    kd_cone_walk_init(&w, pr->scene, kc);
    while (rc == KDR_OK && (leaf = kd_cone_walk_next(&w)) != NULL) {
        const uint32_t *refs = pr->scene->refs + leaf->u.first;
        const uint32_t count = kd_count(leaf);
        const float *tris[4];
        uint32_t prims[4];
        int nb = 0;
        for (uint32_t j = 0; wide4 && j <= count && rc == KDR_OK && !*covered; j++) {
            if (j < count && !seen_before(c, refs[j])) {
                prims[nb] = refs[j];
                tris[nb++] = pr->scene->tris + 9 * (size_t)refs[j];
            }
            if (nb == 4 || (j == count && nb > 0)) {
                const int near = kd_cone_tri_sphere4(kc, tris, nb);
                int nk = 0; /* the cull's survivors, then their edge tests at once */
                for (int i = 0; i < nb; i++)
                    if ((near >> i) & 1 && kd_cone_tri_rest_may(kc, tris[i])) {
                        tris[nk] = tris[i];
                        prims[nk++] = prims[i];
                    }
                const int miss = nk ? kd_tri_edges_miss4(tris, nk, pr->f->apex, dc) : 0;
                for (int i = 0; i < nk && rc == KDR_OK && !*covered; i++)
                    if (!((miss >> i) & 1))
                        rc = judge_view(c, pr, dc, prims[i], out, nl, covered);
                nb = 0;
            }
        }
        for (uint32_t j = 0; !wide4 && j < count && rc == KDR_OK; j++) {
            const uint32_t prim = refs[j];
            if (seen_before(c, prim) ||
                !kd_cone_tri_may_block(kc, pr->scene->tris + 9 * (size_t)prim))
                continue;
            rc = judge(c, pr, dc, prim, out, nl, covered);
            if (*covered)
                break;
        }
        if (*covered)
            break;
        if (w.visited > max_nodes)
            rc = KD_CONE_OVER;
    }
    pr->st.nodes_visited += w.visited;
    return rc;
}

/* walk_with_proofs over the group's list instead of the tree: the pair's
 * cull, then the proofs (the list has no duplicates). */
static int judge_group(kd_cells *c, kd_cone_pair *pr, const kd_dir_cone *dc,
                       const kd_cone *kc, uint32_t *out, size_t *nl, int *covered) {
    if (pr->gsoa && kc->cos_p != 0.0) {
        /* the same cull four at a time, then the survivors' edge tests at
         * once (kd_cone_cull4.c: the same answer for each), the rest
         * judged in the list's order */
        for (size_t j = 0; j < pr->ngroup; j += 4) {
            const float *tris[4];
            uint32_t prims[4];
            int nb = 0;
            for (int keep = kd_cone_pre_may_block4(kc, pr->gsoa, j); keep; keep &= keep - 1) {
                const int i = keep & 1 ? 0 : keep & 2 ? 1 : keep & 4 ? 2 : 3;
                prims[nb] = pr->gsoa->prim[j + (size_t)i];
                tris[nb] = pr->scene->tris + 9 * (size_t)prims[nb];
                nb++;
            }
            const int miss = nb ? kd_tri_edges_miss4(tris, nb, pr->f->apex, dc) : 0;
            for (int i = 0; i < nb; i++) {
                if ((miss >> i) & 1)
                    continue; /* beside the cone: no view needed */
                const int rc = judge_view(c, pr, dc, prims[i], out, nl, covered);
                if (rc != KDR_OK || *covered)
                    return rc;
            }
        }
        return KDR_OK;
    }
    for (size_t j = 0; j < pr->ngroup; j++) {
        if (!kd_cone_pre_may_block(kc, &pr->group[j]))
            continue;
        const int rc = judge(c, pr, dc, pr->group[j].prim, out, nl, covered);
        if (rc != KDR_OK || *covered)
            return rc;
    }
    return KDR_OK;
}

/* The candidates of the cell: the parent's filtered by the cell's cone, or
 * its own walk's. Returns the list (in depth's buffer) and its length in
 * *nl, or NULL when the walk went over budget (incomplete); *covered is set
 * when a candidate covers the cell. */
static const uint32_t *cell_list(kd_cells *c, kd_cone_pair *pr, const kd_dir_cone *dc,
                                 const kd_cone *kc, const uint32_t *plist, size_t np,
                                 int depth, size_t *nl, int *covered) {
    uint32_t *out = list_at(c, depth);
    *nl = 0;
    *covered = 0;
    if (plist == WALK_LIST && pr->proofs && pr->last != UINT32_MAX &&
        !kd_tri_edges_miss(pr->scene->tris + 9 * (size_t)pr->last, pr->f->apex, dc)) {
        /* in umbra the light's last blocker often covers the next cone too
         * (points arrive in image order): a view of it before any walk */
        kd_tri_view v;
        kd_tri_view_init(&v, pr->scene->tris + 9 * (size_t)pr->last, pr->last,
                         pr->f->apex);
        if (kd_tri_view_classify(&v, dc) == KD_TRI_COVERS) {
            *covered = 1;
            return out;
        }
    }
    if (plist == WALK_LIST && pr->proofs && pr->group) {
        const int rc = judge_group(c, pr, dc, kc, out, nl, covered);
        if (rc == KDR_ENOMEM)
            pr->rc = KDR_ENOMEM;
        return rc == KDR_OK ? out : NULL;
    }
    if (plist == WALK_LIST && pr->proofs) {
        const int rc = walk_with_proofs(c, pr, dc, kc, out, nl, covered);
        if (rc == KDR_ENOMEM)
            pr->rc = KDR_ENOMEM;
        return rc == KDR_OK ? out : NULL;
    }
    if (plist == WALK_LIST) {
        const int rc = kd_cone_collect(pr->scene, kc, &c->cl, CONE_MAX_CANDS,
                                       CONE_NODES_BASE +
                                           CONE_NODES_PER_SAMPLE * (uint64_t)pr->n,
                                       1, &pr->st.nodes_visited);
        if (rc != KDR_OK) {
            if (rc == KDR_ENOMEM)
                pr->rc = KDR_ENOMEM;
            return NULL;
        }
        for (size_t j = 0; j < c->cl.n; j++)
            out[(*nl)++] = c->cl.v[j]; /* prims, already culled */
        return out;
    }
    for (size_t j = 0; j < np; j++) {
        const uint32_t e = plist[j];
        if (pr->proofs) {
            const kd_verdict v = kd_tri_view_classify(&c->views[e], dc);
            if (v == KD_TRI_COVERS) {
                *covered = 1;
                pr->last = c->views[e].prim;
                return out;
            }
            if (v == KD_TRI_UNKNOWN)
                out[(*nl)++] = e;
        } else if (kd_cone_tri_may_block(kc, pr->scene->tris + 9 * (size_t)e)) {
            out[(*nl)++] = e;
        }
    }
    return out;
}

/* The root's list of samples 0..n), made only when the whole light splits
 * or traces (most pairs are decided before: filling it for every pair was
 * 4% of a picture's instructions). */
static void root_samples(kd_cells *c, const kd_cone_pair *pr, int depth) {
    if (depth == 0)
        for (uint32_t s = 0; s < pr->n; s++)
            c->idx[s] = s;
}

/* The phase of every sample, made when the whole light first splits (most
 * pairs are decided before: no sample is ever looked at). Returns 1. */
static int phases(kd_cells *c, const kd_cone_pair *pr, int depth) {
    root_samples(c, pr, depth);
    if (depth == 0)
        for (uint32_t s = 0; s < pr->n; s++)
            c->phase[s] = kd_shadow_frame_phase(pr->f, s);
    return 1;
}

static uint32_t process(kd_cells *c, kd_cone_pair *pr, const cell *ce,
                        const uint32_t *plist, size_t np, int depth) {
    const uint32_t count = ce->i1 - ce->i0;
    if (count == 0 || pr->rc != KDR_OK)
        return 0;
    kd_dir_cone dc;
    kd_cone kc; /* for the walk and the walk's cull */
    if (depth == 0) {
        light_cone(c, pr, &dc);
        kd_cone_init(&kc, pr->scene, pr->f, NULL, 0.0);
    } else {
        cell_cone(c, pr, ce, &dc);
        if (!pr->proofs)
            kd_cone_init(&kc, pr->scene, pr->f, dc.axis, dc.sin_b);
    }
    size_t nl = 0, nviews = c->nviews;
    int covered = 0;
    const uint32_t *list = cell_list(c, pr, &dc, &kc, plist, np, depth, &nl, &covered);
    uint32_t lit = 0;
    cell kids[4];
    int nk = 0;
    const int leaf = count <= CELL_LEAF_SAMPLES || depth + 1 >= KD_CELL_MAX_DEPTH;
    if (pr->rc != KDR_OK) {
        lit = 0;
    } else if (!list) {
        pr->rc = KD_CONE_OVER; /* the whole light's walk: a busy cone */
    } else if (covered) {
        lit = 0; /* umbra: every sample blocked */
    } else if (nl == 0) {
        lit = count; /* lit: no candidate left */
    } else if (!leaf && phases(c, pr, depth) && children(c, pr, ce, kids, &nk)) {
        for (int k = 0; k < nk; k++)
            lit += process(c, pr, &kids[k], list, nl, depth + 1);
    } else {
        uint32_t prims[CONE_MAX_CANDS];
        if (leaf) /* (else phases() made the list) */
            root_samples(c, pr, depth);
        for (size_t j = 0; j < nl; j++)
            prims[j] = pr->proofs ? c->views[list[j]].prim : list[j];
        lit = trace_list(c, pr, ce, prims, nl);
    }
    c->nviews = nviews; /* views made here are not needed any more */
    return lit;
}

int kd_cells_lit(kd_cells *c, kd_cone_pair *pr, uint32_t *lit) {
    if (kd_cells_reserve(c, pr->n) != KDR_OK)
        return KDR_ENOMEM;
    if (!c->lists) {
        c->lists = malloc((size_t)KD_CELL_MAX_DEPTH * CONE_MAX_CANDS * sizeof *c->lists);
        if (!c->lists)
            return KDR_ENOMEM;
    }
    /* c->idx and the phases: when the root splits or traces */
    const cell root = {0, pr->n, 0, pr->n, 0.0, 1.0, -1.0, 0.0, 0};
    c->nviews = 0;
    pr->rc = KDR_OK;
    *lit = process(c, pr, &root, WALK_LIST, 0, 0);
    return pr->rc;
}
