/*
 * test_core.c — the kd-tree build and single-ray traversal against a brute
 * force loop over every triangle with the same triangle test and tie rule:
 * answers must agree bit for bit (t, prim, u, v). Scenes are chosen to
 * stress the build's corner cases (triangles in and touching split planes,
 * shared faces, coincident triangles, huge offsets) and rays to stress the
 * walk's (zero and -0.0 direction components, origins on split planes, rays
 * lying in planes, odd intervals). Also checks tree invariants and the
 * error paths of kdr_scene_build.
 */
#include "test_core_util.h"

/* ---- scenes ------------------------------------------------------------------ */

typedef struct soup {
    float *t;
    size_t n, cap;
} soup;

static void soup_add(soup *s, const float v[9]) {
    if (s->n == s->cap) {
        s->cap = s->cap ? 2 * s->cap : 256;
        s->t = realloc(s->t, s->cap * 9 * sizeof(float));
        if (!s->t)
            abort();
    }
    memcpy(s->t + 9 * s->n++, v, 9 * sizeof(float));
}

static void soup_random(soup *s, size_t n, float size, float quantum) {
    for (size_t i = 0; i < n; i++) {
        float c[3] = {rng_f(0, 1), rng_f(0, 1), rng_f(0, 1)}, v[9];
        for (int j = 0; j < 9; j++) {
            v[j] = c[j % 3] + rng_f(-size, size);
            if (quantum > 0)
                v[j] = roundf(v[j] / quantum) * quantum;
        }
        soup_add(s, v);
    }
}

/* A unit cube at (x, y, z) as 12 triangles; neighbours share faces. */
static void soup_cube(soup *s, float x, float y, float z) {
    static const int quads[6][4][3] = {
        {{0, 0, 0}, {0, 1, 0}, {0, 1, 1}, {0, 0, 1}}, {{1, 0, 0}, {1, 1, 0}, {1, 1, 1}, {1, 0, 1}},
        {{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}}, {{0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {0, 1, 1}},
        {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, {{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}}};
    const float o[3] = {x, y, z};
    for (int f = 0; f < 6; f++) {
        float p[4][3];
        for (int i = 0; i < 4; i++)
            for (int k = 0; k < 3; k++)
                p[i][k] = o[k] + (float)quads[f][i][k];
        float a[9] = {p[0][0], p[0][1], p[0][2], p[1][0], p[1][1], p[1][2], p[2][0], p[2][1], p[2][2]};
        float b[9] = {p[0][0], p[0][1], p[0][2], p[2][0], p[2][1], p[2][2], p[3][0], p[3][1], p[3][2]};
        soup_add(s, a);
        soup_add(s, b);
    }
}

/* ---- tree invariants ------------------------------------------------------------ */

static size_t check_node(const kdr_scene *s, uint32_t idx, kdr_bounds box,
                         int depth, uint8_t *seen) {
    EXPECT(idx < s->nnodes);
    EXPECT(depth <= KD_MAX_DEPTH);
    if (idx >= s->nnodes || depth > KD_MAX_DEPTH)
        return 0;
    const kd_node *n = &s->nodes[idx];
    if (kd_is_leaf(n)) {
        EXPECT((size_t)n->u.first + kd_count(n) <= s->nrefs);
        for (uint32_t i = 0; i < kd_count(n) && n->u.first + i < s->nrefs; i++) {
            uint32_t p = s->refs[n->u.first + i];
            EXPECT(p < s->ntris);
            if (p < s->ntris) {
                EXPECT(!kd_tri_degenerate(s->tris + 9 * p));
                seen[p] = 1;
            }
        }
        /* kd_layout's flat flag, which kd_leaf_behind trusts: 1 + the
         * first axis on which every vertex of the leaf has one value */
        int flat = 0;
        for (int k = 0; k < 3 && !flat && kd_count(n) > 0; k++) {
            const float c = s->tris[9 * (size_t)s->refs[n->u.first] + k];
            int all = 1;
            for (uint32_t i = 0; i < kd_count(n); i++)
                for (int v = 0; v < 3; v++)
                    all &= s->tris[9 * (size_t)s->refs[n->u.first + i] + 3 * v + k] == c;
            flat = all ? k + 1 : 0;
        }
        EXPECT(kd_leaf_flat(n) == flat);
        return 1;
    }
    const int k = kd_axis(n);
    EXPECT(n->u.split > box.min[k] && n->u.split < box.max[k]);
    EXPECT(kd_above(n) > idx + 1);
    /* kd_layout's empty-child flags, which walks trust without looking */
    if (kd_above(n) < s->nnodes) {
        const kd_node *b = n + 1, *a = &s->nodes[kd_above(n)];
        EXPECT(kd_below_empty(n) == (kd_is_leaf(b) && kd_count(b) == 0));
        EXPECT(kd_above_empty(n) == (kd_is_leaf(a) && kd_count(a) == 0));
    }
    kdr_bounds lb = box, rb = box;
    lb.max[k] = rb.min[k] = n->u.split;
    return 1 + check_node(s, idx + 1, lb, depth + 1, seen) +
           check_node(s, kd_above(n), rb, depth + 1, seen);
}

static void check_tree(const kdr_scene *s) {
    kdr_tree_stats st;
    kdr_scene_tree_stats(s, &st);
    EXPECT(st.nodes == s->nnodes);
    EXPECT(st.refs == s->nrefs);
    if (!s->nodes)
        return;
    uint8_t *seen = calloc(s->ntris + 1, 1);
    EXPECT(check_node(s, 0, s->bounds, 0, seen) == s->nnodes);
    for (size_t i = 0; i < s->ntris; i++)
        EXPECT(seen[i] || kd_tri_degenerate(s->tris + 9 * i));
    free(seen);
    EXPECT(st.leaves >= st.empty_leaves);
    EXPECT(st.max_depth <= KD_MAX_DEPTH);
}

/* ---- rays ------------------------------------------------------------------------ */

/* A random component, sometimes exactly 0 or -0.0. */
static float ray_dir_comp(void) {
    switch (rng_u32() % 8) {
    case 0:
        return 0.0f;
    case 1:
        return -0.0f;
    default:
        return rng_f(-1, 1);
    }
}

/* Random rays, a quarter with grid-aligned origins (on split planes when
 * the scene is quantised to `quantum`), many with zero components. */
static void random_ray(kdr_ray *r, float lo, float hi, float quantum) {
    for (int k = 0; k < 3; k++) {
        r->org[k] = rng_f(lo, hi);
        if (quantum > 0 && rng_u32() % 4 == 0)
            r->org[k] = roundf(r->org[k] / quantum) * quantum;
        r->dir[k] = ray_dir_comp();
    }
    if (r->dir[0] == 0 && r->dir[1] == 0 && r->dir[2] == 0)
        r->dir[rng_u32() % 3] = 1.0f;
    r->tmin = 0.0f;
    r->tmax = INFINITY;
    switch (rng_u32() % 8) {
    case 0:
        r->tmin = rng_f(0, 1);
        break;
    case 1:
        r->tmax = rng_f(0, 2);
        break;
    case 2:
        r->tmin = -INFINITY;
        break;
    }
}

/* A ray aimed at a vertex or edge point of a random triangle. */
static void aimed_ray(kdr_ray *r, const soup *s, float lo, float hi) {
    const float *t = s->t + 9 * (rng_u32() % s->n);
    int a = rng_u32() % 3, b = rng_u32() % 3;
    float w = (rng_u32() % 2) ? 0.5f : 0.0f;
    for (int k = 0; k < 3; k++) {
        r->org[k] = rng_f(lo, hi);
        float target = t[3 * a + k] + w * (t[3 * b + k] - t[3 * a + k]);
        r->dir[k] = target - r->org[k];
    }
    r->tmin = 0.0f;
    r->tmax = INFINITY;
}

#ifndef RAY_MULT
#define RAY_MULT 1
#endif

static size_t compare_many(const soup *sp, const kdr_scene *s, size_t nrays,
                           float lo, float hi, float quantum) {
    size_t bad = 0;
    for (size_t i = 0; i < nrays * RAY_MULT; i++) {
        kdr_ray r;
        if (i % 4 == 3)
            aimed_ray(&r, sp, lo, hi);
        else
            random_ray(&r, lo, hi, quantum);
        bad += !compare_ray(s, &r);
    }
    return bad;
}

/* Leaf size for the scenes below: 1 gives the deepest trees and the most
 * straddler clipping; 0 means the defaults. g_exact_max < 0 keeps the
 * default (the exact sweep everywhere on scenes this small); 0 bins every
 * node, a few dozen mixes binned tops with exact subtrees. g_threads goes
 * to kdr_build_opts.threads. */
static int g_leaf_size, g_exact_max = -1, g_threads;

static kdr_scene *build_or_die(const soup *sp) {
    kdr_scene *s = NULL;
    kdr_build_opts o;
    kdr_build_opts_default(&o);
    if (g_leaf_size > 0)
        o.leaf_size = g_leaf_size;
    if (g_exact_max >= 0)
        o.exact_max = g_exact_max;
    o.threads = g_threads;
    int err = kdr_scene_build(sp->t, sp->n, &o, NULL, NULL, &s);
    EXPECT(err == KDR_OK);
    if (err != KDR_OK) {
        fprintf(stderr, "build failed: %s\n", kdr_strerror(err));
        exit(1);
    }
    check_tree(s);
    return s;
}

/* ---- test cases -------------------------------------------------------------------- */

static void test_random_soups(void) {
    static const struct { size_t n; float size, quantum; } cases[] = {
        {1, 0.3f, 0}, {2000, 0.05f, 0}, {3000, 0.2f, 0}, {2000, 0.1f, 0.125f},
        {1500, 0.25f, 0.25f}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        soup sp = {0};
        soup_random(&sp, cases[c].n, cases[c].size, cases[c].quantum);
        kdr_scene *s = build_or_die(&sp);
        size_t bad = compare_many(&sp, s, 4000, -0.5f, 1.5f, cases[c].quantum);
        if (bad)
            fprintf(stderr, "random soup %zu: %zu mismatches\n", c, bad);
        EXPECT(bad == 0);
        kdr_scene_free(s);
        free(sp.t);
    }
}

/* Cubes on an integer grid: every face lies in a candidate split plane and
 * neighbouring cubes give coincident triangles (ties broken by prim). */
static void test_box_grid(void) {
    soup sp = {0};
    for (int x = 0; x < 6; x++)
        for (int y = 0; y < 5; y++)
            for (int z = 0; z < 4; z++)
                if (rng_u32() % 3)
                    soup_cube(&sp, (float)x, (float)y, (float)z);
    kdr_scene *s = build_or_die(&sp);
    size_t bad = compare_many(&sp, s, 12000, -1.0f, 7.0f, 1.0f);
    /* rays inside the planes: integer origin coordinate, zero component */
    for (int i = 0; i < 3000; i++) {
        kdr_ray r;
        random_ray(&r, -1.0f, 7.0f, 0.0f);
        int k = rng_u32() % 3;
        r.org[k] = (float)(rng_u32() % 7);
        r.dir[k] = (rng_u32() % 2) ? 0.0f : -0.0f;
        if (r.dir[(k + 1) % 3] == 0 && r.dir[(k + 2) % 3] == 0)
            r.dir[(k + 1) % 3] = 0.5f;
        bad += !compare_ray(s, &r);
    }
    /* rays whose end o + tmax d lies on a plane of the grid (exact in
     * float: half-integer origin, direction components 0.5 or 0.25 in
     * magnitude), where the far end first walk starts on a split plane,
     * and their start at tmin > 0; from an RNG of their own, so the
     * other cases keep their rays */
    const uint64_t saved_rng = g_rng;
    g_rng = 0x2545f4914f6cdd1dull;
    for (int i = 0; i < 3000; i++) {
        kdr_ray r;
        const int k = rng_u32() % 3;
        for (int j = 0; j < 3; j++) {
            r.org[j] = (float)(rng_u32() % 9) - 1.5f;
            r.dir[j] = (rng_u32() % 2 ? 0.5f : -0.25f) * (rng_u32() % 3 ? 1.0f : 0.0f);
        }
        r.dir[k] = rng_u32() % 2 ? 0.5f : -0.5f;
        const float plane = (float)(rng_u32() % 8) - 1.0f;
        r.tmax = (plane - r.org[k]) / r.dir[k];
        if (r.tmax < 0.0f)
            r.dir[k] = -r.dir[k], r.tmax = -r.tmax;
        r.tmin = rng_u32() % 2 ? 0.0f : rng_f(0.0f, r.tmax);
        bad += !compare_ray(s, &r);
    }
    g_rng = saved_rng;
    if (bad)
        fprintf(stderr, "box grid: %zu mismatches\n", bad);
    EXPECT(bad == 0);
    kdr_scene_free(s);
    free(sp.t);
}

/* Small triangles far from the origin: relative precision matters. */
static void test_huge_offsets(void) {
    soup sp = {0};
    soup_random(&sp, 2000, 0.02f, 0);
    for (size_t i = 0; i < 9 * sp.n; i++)
        sp.t[i] = sp.t[i] * 10.0f + 1e5f;
    kdr_scene *s = build_or_die(&sp);
    size_t bad = 0;
    for (int i = 0; i < 4000; i++) {
        kdr_ray r;
        if (i % 2)
            aimed_ray(&r, &sp, 1e5f - 5.0f, 1e5f + 15.0f);
        else
            random_ray(&r, 1e5f - 5.0f, 1e5f + 15.0f, 0.0f);
        bad += !compare_ray(s, &r);
    }
    EXPECT(bad == 0);
    kdr_scene_free(s);
    free(sp.t);
}

/* Extreme magnitudes: far, tiny and subnormal origins, huge and tiny
 * direction lengths, zero components. Nothing may crash, and answers still
 * equal brute force. Directions keep their components within ~2^40 of each
 * other: past that (or with subnormal components) the shear and edge
 * products of kd_tri_intersect underflow and it reports hits at t = +-0 that
 * lie at t < 0 or far from the ray, which no traversal can reproduce short
 * of testing every triangle. (Equal components are no shelter from a
 * different underflow, of t's numerator: test_underflow_t.) */
static float extreme_org(void) {
    static const float v[] = {0.0f, -0.0f, 1e-40f, -1e-40f, 1e-30f, -1e-30f,
                              1e30f, -1e30f, 1e5f, -1e5f, 3.0f, 0.5f};
    return rng_u32() % 2 ? v[rng_u32() % (sizeof v / sizeof v[0])] : rng_f(-2, 2);
}

static void extreme_dir(float d[3]) {
    static const float scale[] = {1e-30f, 1e-6f, 1.0f, 1e5f, 1e30f};
    const float s = scale[rng_u32() % (sizeof scale / sizeof scale[0])];
    for (int k = 0; k < 3; k++) {
        static const float v[] = {0.0f, -0.0f, 1e-6f, -1e-6f, 1e5f, 3.0f, -3.0f};
        float x = rng_u32() % 2 ? v[rng_u32() % (sizeof v / sizeof v[0])] : rng_f(-2, 2);
        d[k] = x * s;
    }
}

static void test_extreme_rays(void) {
    soup sp = {0};
    soup_random(&sp, 800, 0.2f, 0.25f);
    kdr_scene *s = build_or_die(&sp);
    size_t bad = 0;
    for (int i = 0; i < 6000; i++) {
        kdr_ray r;
        for (int k = 0; k < 3; k++) {
            r.org[k] = extreme_org();
        }
        extreme_dir(r.dir);
        if (i % 2) /* aim from a far origin at the scene */
            for (int k = 0; k < 3; k++)
                r.dir[k] = rng_f(0, 1) - r.org[k];
        r.tmin = i % 3 ? 0.0f : -INFINITY;
        r.tmax = i % 5 ? INFINITY : 1e30f;
        bad += !compare_ray(s, &r);
    }
    if (bad)
        fprintf(stderr, "extreme rays: %zu mismatches\n", bad);
    EXPECT(bad == 0);
    kdr_scene_free(s);
    free(sp.t);
}

/*
 * Underflow of t (docs/ACCURACY.md). With a long direction (|dir| 2^8 and
 * up) and an origin whose coordinates are tiny (1e-30, 1e-40), a triangle
 * the ray passes nearly parallel gets tiny edge functions U, V, W, and the
 * products U * az of kd_tri_intersect's T (az = z / dir) underflow: T came
 * out 0, so brute force reported t = 0 for a triangle that lies at
 * t ~ 2^-119 along the ray, beyond the walk's termination bound, and the
 * walk answered another triangle. The pinned ray is the one first met by
 * a shifted random stream (soup: the draws 2075100 on of the seed); the
 * class draws origins like extreme_org() and directions of nearly equal
 * components (the soup's planes x = z etc. make them near parallel) at
 * scales 2^0 .. 2^120. Before kd_tri_t_exact, 55 to 62 of its 20000 rays
 * (per build of main()) differed from brute force and the pinned ray
 * answered prim 58 against brute force's prim 652 at t = 0; with the fix in
 * kd_tri.h only (SIMD leaves not), 85 to 164, and 3 to 5 of the batches'. Its own draws are put back afterwards
 * so that the other cases keep their rays.
 */
/* The same class through kdr_trace_batch (bundles of 4/8/16 lanes for the
 * shared origin, the interleaved walks for distinct ones), closest and any
 * hit, ray by ray equal to kdr_intersect1 / kdr_occluded1. The pinned ray
 * (r) is ray 0 of each batch. */
static void check_underflow_batches(const kdr_scene *s, const kdr_ray *r) {
    enum { N = 2048 };
    static float org[3 * N], dir[3 * N], t[N], u[N], v[N];
    static int32_t prim[N];
    static uint8_t hit[N];
    for (int shared = 0; shared < 2; shared++) {
        for (int i = 0; i < N; i++) {
            const float base = rng_f(0.5f, 2.0f);
            const int e = (int)(rng_u32() % 121);
            for (int k = 0; k < 3; k++) {
                org[3 * i + k] = i == 0 ? r->org[k] : extreme_org();
                dir[3 * i + k] =
                    i == 0 ? r->dir[k]
                           : ldexpf(base * (rng_u32() % 4 ? 1.0f : rng_f(-2, 2)), e);
            }
        }
        const float tmin = 0.0f, tmax = INFINITY;
        kdr_ray_batch b = {N, org, shared ? 0 : 3, dir, &tmin, 0, &tmax, 0};
        kdr_hits h = {t, prim, u, v, hit};
        static const kdr_trav_mode modes[] = {KDR_TRAV_AUTO, KDR_TRAV_BUNDLE4,
                                              KDR_TRAV_BUNDLE8};
        for (size_t m = 0; m < sizeof modes / sizeof *modes; m++) {
            size_t bad = 0;
            memset(hit, 2, sizeof hit);
            EXPECT(kdr_trace_batch(s, &b, 0, N, KDR_ANY, modes[m], &h, NULL) == KDR_OK);
            EXPECT(kdr_trace_batch(s, &b, 0, N, KDR_CLOSEST, modes[m], &h, NULL) ==
                   KDR_OK);
            for (int i = 0; i < N; i++) {
                kdr_ray q = {{org[shared ? 0 : 3 * i], org[shared ? 1 : 3 * i + 1],
                              org[shared ? 2 : 3 * i + 2]},
                             {dir[3 * i], dir[3 * i + 1], dir[3 * i + 2]}, tmin, tmax};
                kdr_hit k, bh = {t[i], u[i], v[i], prim[i]};
                kdr_intersect1(s, &q, &k, NULL);
                bad += !same_hit(&k, &bh) || hit[i] != kdr_occluded1(s, &q, NULL);
            }
            if (bad)
                fprintf(stderr, "underflow of t, batch (%s origin, mode %d): %zu differ\n",
                        shared ? "shared" : "own", (int)modes[m], bad);
            EXPECT(bad == 0);
        }
    }
}

static void test_underflow_t(void) {
    const uint64_t saved = g_rng;
    g_rng = 0x9e3779b97f4a7c15ull;
    for (int i = 0; i < 2075100; i++)
        (void)rng_u32();
    soup sp = {0};
    soup_random(&sp, 800, 0.2f, 0.25f);
    kdr_scene *s = build_or_die(&sp);
    const float d = 0x1.342618p+116f;
    kdr_ray r = {{0x1.4484cp-100f, 0x1.4d2ae8p-1f, -0x1.16c2p-133f}, {d, d, d}, 0.0f,
                 0x1.93e594p+99f};
    EXPECT(compare_ray(s, &r));
    /* triangle 652 itself: the float T underflows to 0; its t is now where
     * it lies along the ray (2^-120 .. 2^-118), not 0 */
    kd_ray_pre pre;
    kd_ray_precompute(r.org, r.dir, &pre);
    float t = -1.0f, u, v;
    EXPECT(kd_tri_intersect(&pre, sp.t + 9 * 652, 0.0f, INFINITY, &t, &u, &v) == 1);
    EXPECT(t > 0x1p-120f && t < 0x1p-118f);
    kdr_hit h;
    EXPECT(kdr_intersect1(s, &r, &h, NULL) == 1 && h.prim == 58);
    size_t bad = 0;
    for (int i = 0; i < 20000; i++) {
        for (int k = 0; k < 3; k++)
            r.org[k] = extreme_org();
        const float base = rng_f(0.5f, 2.0f);
        const int e = (int)(rng_u32() % 121);
        for (int k = 0; k < 3; k++)
            r.dir[k] = ldexpf(base * (rng_u32() % 4 ? 1.0f : rng_f(-2, 2)), e);
        r.tmin = i % 3 ? 0.0f : -INFINITY;
        r.tmax = INFINITY;
        bad += !compare_ray(s, &r);
    }
    if (bad)
        fprintf(stderr, "underflow of t: %zu mismatches\n", bad);
    EXPECT(bad == 0);
    check_underflow_batches(s, &r);
    kdr_scene_free(s);
    free(sp.t);
    g_rng = saved;
}

/* A flat scene (every triangle in z = 0): the root box has no thickness,
 * every triangle is planar in z; rays come from above, below and inside
 * the plane. */
static void test_flat_scene(void) {
    soup sp = {0};
    soup_random(&sp, 1500, 0.1f, 0.125f);
    for (size_t i = 0; i < sp.n; i++)
        for (int v = 0; v < 3; v++)
            sp.t[9 * i + 3 * v + 2] = 0.0f;
    kdr_scene *s = build_or_die(&sp);
    size_t bad = 0;
    for (int i = 0; i < 4000; i++) {
        kdr_ray r;
        random_ray(&r, -0.5f, 1.5f, 0.125f);
        if (i % 3 == 0) { /* in the plane */
            r.org[2] = i % 2 ? 0.0f : -0.0f;
            r.dir[2] = i % 4 ? 0.0f : -0.0f;
            if (r.dir[0] == 0 && r.dir[1] == 0)
                r.dir[0] = 1.0f;
        }
        bad += !compare_ray(s, &r);
    }
    EXPECT(bad == 0);
    kdr_scene_free(s);
    free(sp.t);
}

/* Rays that start on, just above and just below an axis-aligned floor
 * (y = 0) and wall (x = 0) built of grid triangles, with a few boxes on
 * the floor, in every direction (steep, grazing, along the planes) and
 * with tmin 0, -0.0, > 0 and < 0: walks skip a flat leaf whose plane lies
 * behind the origin along the ray's dominant axis (kd_leaf_behind), which
 * must never change an answer. Rays straight up from just above the floor
 * must find the floor's leaves skipped (no triangle test), and the same
 * rays with tmin < 0 must still hit the floor behind them. */
static void test_floor_starts(void) {
    soup sp = {0};
    for (int i = 0; i < 8; i++)
        for (int k = 0; k < 8; k++) {
            const float x0 = (float)i * 0.25f, z0 = (float)k * 0.25f, e = 0.25f;
            const float f1[9] = {x0, 0, z0, x0 + e, 0, z0, x0, 0, z0 + e};
            const float f2[9] = {x0 + e, 0, z0, x0 + e, 0, z0 + e, x0, 0, z0 + e};
            soup_add(&sp, f1);
            soup_add(&sp, f2);
            const float w1[9] = {0, x0, z0, 0, x0 + e, z0, 0, x0, z0 + e};
            const float w2[9] = {0, x0 + e, z0, 0, x0 + e, z0 + e, 0, x0, z0 + e};
            soup_add(&sp, w1);
            soup_add(&sp, w2);
        }
    soup_cube(&sp, 0.6f, 0.0f, 0.6f);
    soup_cube(&sp, 1.2f, 0.3f, 0.9f);
    kdr_scene *s = build_or_die(&sp);
    size_t flat_leaves = 0;
    for (size_t i = 0; i < s->nnodes; i++)
        flat_leaves += kd_is_leaf(&s->nodes[i]) && kd_leaf_flat(&s->nodes[i]) != 0;
    EXPECT(flat_leaves > 0);
    static const float lift[] = {0.0f, 0x1p-24f, 0x1p-20f, 1e-6f, 1e-3f, -0x1p-24f, -1e-6f};
    static const float tmins[] = {0.0f, -0.0f, 1e-7f, -1.0f};
    size_t bad = 0;
    for (int i = 0; i < 6000; i++) {
        kdr_ray r;
        const int wall = i % 3 == 2; /* start on the wall (x = 0) */
        const float a = rng_f(0.01f, 1.99f), b = rng_f(0.01f, 1.99f);
        const float h = lift[rng_u32() % (sizeof lift / sizeof *lift)];
        r.org[0] = wall ? h : a;
        r.org[1] = wall ? a : h;
        r.org[2] = b;
        for (int k = 0; k < 3; k++)
            r.dir[k] = ray_dir_comp();
        switch (rng_u32() % 4) {
        case 0: /* steep: the plane's axis dominates */
            r.dir[wall ? 0 : 1] = rng_f(1.0f, 2.0f) * (rng_u32() % 4 ? 1.0f : -1.0f);
            break;
        case 1: /* grazing */
            r.dir[wall ? 0 : 1] = rng_f(-1e-3f, 1e-3f);
            break;
        }
        if (r.dir[0] == 0 && r.dir[1] == 0 && r.dir[2] == 0)
            r.dir[1] = 1.0f;
        r.tmin = tmins[rng_u32() % (sizeof tmins / sizeof *tmins)];
        r.tmax = rng_u32() % 2 ? INFINITY : rng_f(0.0f, 3.0f);
        bad += !compare_ray(s, &r);
    }
    if (bad)
        fprintf(stderr, "floor starts: %zu mismatches\n", bad);
    EXPECT(bad == 0);
    /* straight up from 2^-20 above the floor, away from the wall and the
     * boxes: the only leaves on the way hold the floor, which is behind */
    kdr_ray up = {{1.8f, 0x1p-20f, 0.1f}, {0.0f, 1.0f, 0.0f}, 0.0f, INFINITY};
    kdr_trav_stats st = {0};
    EXPECT(kdr_occluded1(s, &up, &st) == 0);
    kdr_hit h;
    EXPECT(kdr_intersect1(s, &up, &h, &st) == 0);
    EXPECT(st.tri_tests == 0);
    up.tmin = -1.0f; /* the floor 2^-20 behind the origin now counts */
    EXPECT(kdr_occluded1(s, &up, NULL) == 1);
    EXPECT(kdr_intersect1(s, &up, &h, NULL) == 1 && h.t < 0.0f);
    kdr_scene_free(s);
    free(sp.t);
}

static void expect_miss(const kdr_scene *s, const kdr_ray *r) {
    kdr_hit h;
    EXPECT(kdr_intersect1(s, r, &h, NULL) == 0);
    EXPECT(h.prim == -1 && h.t == -1.0f && h.u == 0.0f && h.v == 0.0f);
    EXPECT(kdr_occluded1(s, r, NULL) == 0);
}

static void test_small_scenes(void) {
    kdr_scene *s = NULL;
    kdr_ray r = {{0.2f, 0.2f, -1}, {0, 0, 1}, 0, INFINITY};
    EXPECT(kdr_scene_build(NULL, 0, NULL, NULL, NULL, &s) == KDR_OK);
    EXPECT(s && kdr_scene_triangle_count(s) == 0 && kdr_scene_diagonal(s) == 0);
    expect_miss(s, &r);
    kdr_scene_free(s);

    const float one[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    EXPECT(kdr_scene_build(one, 1, NULL, NULL, NULL, &s) == KDR_OK);
    kdr_hit h;
    EXPECT(kdr_intersect1(s, &r, &h, NULL) == 1);
    EXPECT(h.prim == 0 && h.t == 1.0f && fabsf(h.u - 0.2f) < 1e-6f &&
          fabsf(h.v - 0.2f) < 1e-6f);
    EXPECT(kdr_occluded1(s, &r, NULL) == 1);
    EXPECT(kdr_scene_triangle(s, 0) && kdr_scene_triangle(s, 0)[3] == 1.0f);
    EXPECT(kdr_scene_triangle(s, 1) == NULL);
    kdr_ray bad = r;
    bad.tmax = -1; /* tmax < tmin */
    expect_miss(s, &bad);
    bad = r;
    bad.dir[2] = 0; /* zero direction */
    expect_miss(s, &bad);
    bad = r;
    bad.org[0] = NAN;
    expect_miss(s, &bad);
    bad = r;
    bad.tmin = NAN;
    expect_miss(s, &bad);
    bad = r;
    bad.tmax = 0.5f; /* interval ends before the hit */
    expect_miss(s, &bad);
    bad = r;
    bad.tmin = bad.tmax = 1.0f; /* closed interval: t == 1 hits */
    EXPECT(kdr_occluded1(s, &bad, NULL) == 1);
    kdr_scene_free(s);

    /* degenerate only: repeated vertex, collinear, all equal */
    const float degen[27] = {0, 0, 0, 0, 0, 0, 1, 1, 1, 0, 0, 0, 1, 1, 1, 2, 2, 2,
                             3, 3, 3, 3, 3, 3, 3, 3, 3};
    EXPECT(kdr_scene_build(degen, 3, NULL, NULL, NULL, &s) == KDR_OK);
    EXPECT(kdr_scene_triangle_count(s) == 3);
    kdr_ray d = {{0.5f, 0.5f, 0.5f}, {1, -1, 0.3f}, -INFINITY, INFINITY};
    expect_miss(s, &d);
    kdr_scene_free(s);
}

static void test_build_errors(void) {
    kdr_scene *s = (kdr_scene *)1;
    float t[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    EXPECT(kdr_scene_build(t, 1, NULL, NULL, NULL, NULL) == KDR_EINVAL);
    EXPECT(kdr_scene_build(NULL, 1, NULL, NULL, NULL, &s) == KDR_EINVAL && !s);
    t[4] = NAN;
    EXPECT(kdr_scene_build(t, 1, NULL, NULL, NULL, &s) == KDR_EINVAL && !s);
    t[4] = INFINITY;
    EXPECT(kdr_scene_build(t, 1, NULL, NULL, NULL, &s) == KDR_EINVAL && !s);
    EXPECT(kdr_scene_build(t, ((size_t)1 << 30) + 1, NULL, NULL, NULL, &s) ==
          KDR_ERANGE);
    t[4] = 1;
    kdr_build_opts o;
    kdr_build_opts_default(&o);
    o.empty_bonus = 1.0f;
    EXPECT(kdr_scene_build(t, 1, &o, NULL, NULL, &s) == KDR_EINVAL);
    kdr_build_opts_default(&o);
    o.threads = -1;
    EXPECT(kdr_scene_build(t, 1, &o, NULL, NULL, &s) == KDR_EINVAL);
    kdr_build_opts_default(&o);
    o.exact_max = -1;
    EXPECT(kdr_scene_build(t, 1, &o, NULL, NULL, &s) == KDR_EINVAL);
    EXPECT(strcmp(kdr_strerror(KDR_ENOMEM), kdr_strerror(KDR_OK)) != 0);
}

static void count_log(void *user, const char *msg) {
    EXPECT(msg && strncmp(msg, "kd build:", 9) == 0);
    ++*(int *)user;
}

/* The log callback hears the start and the end; stats are consistent. */
static void test_log_and_stats(void) {
    soup sp = {0};
    soup_random(&sp, 500, 0.1f, 0);
    int lines = 0;
    kdr_scene *s = NULL;
    EXPECT(kdr_scene_build(sp.t, sp.n, NULL, count_log, &lines, &s) == KDR_OK);
    EXPECT(lines >= 2);
    kdr_tree_stats st;
    kdr_scene_tree_stats(s, &st);
    EXPECT(st.nodes == 2 * st.leaves - 1);
    EXPECT(st.refs >= 500 && st.sah_cost > 0 && st.build_ms >= 0);
    EXPECT(st.bytes >= st.nodes * 8 + st.refs * 4);
    EXPECT(fabs(st.refs_per_leaf * (double)(st.leaves - st.empty_leaves) -
               (double)st.refs) < 1e-6 * (double)st.refs);
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    EXPECT(b.min[0] <= b.max[0] && kdr_scene_diagonal(s) > 0);
    kdr_scene_free(s);
    free(sp.t);
}

/* Options change the tree but never an answer. */
static void test_build_options(void) {
    soup sp = {0};
    soup_random(&sp, 1500, 0.1f, 0.125f);
    kdr_build_opts o;
    kdr_build_opts_default(&o);
    o.max_depth = 3;
    o.leaf_size = 4;
    o.isect_cost = 5.0f;
    kdr_scene *s = NULL;
    EXPECT(kdr_scene_build(sp.t, sp.n, &o, NULL, NULL, &s) == KDR_OK);
    check_tree(s);
    kdr_tree_stats st;
    kdr_scene_tree_stats(s, &st);
    EXPECT(st.max_depth <= 3);
    EXPECT(compare_many(&sp, s, 2000, -0.5f, 1.5f, 0.125f) == 0);
    kdr_scene_free(s);
    free(sp.t);
}

int main(void) {
    test_build_errors();
    test_small_scenes();
    test_build_options();
    test_log_and_stats();
    /* the exact sweep (default and 1-triangle leaves), then binned trees
     * (every node binned, and binned tops over exact subtrees) built on
     * several threads: every answer must still equal brute force */
    static const struct { int exact_max, threads, leaf_size; } builds[] = {
        {-1, 0, 0}, {-1, 0, 1}, {0, 3, 1}, {40, 2, 0}};
    for (size_t i = 0; i < sizeof builds / sizeof *builds; i++) {
        g_exact_max = builds[i].exact_max;
        g_threads = builds[i].threads;
        g_leaf_size = builds[i].leaf_size;
        test_random_soups();
        test_box_grid();
        test_huge_offsets();
        test_extreme_rays();
        test_underflow_t();
        test_flat_scene();
        test_floor_starts();
    }
    if (failures)
        fprintf(stderr, "test_core: %d failures\n", failures);
    else
        printf("test_core: ok\n");
    return failures != 0;
}
