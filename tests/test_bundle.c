/*
 * test_bundle.c — omni-directional bundles must answer exactly like single
 * rays: for every ray, t, u, v (bit patterns), prim and the any-hit flag of
 * kdr_trace_batch in every mode equal kdr_intersect1 / kdr_occluded1.
 *
 * Scenes: a random soup, an integer lattice of axis-aligned quads (triangles
 * in split planes, shared edges, equal-t ties), a closed tessellated sphere,
 * and, when scenes/fetch prepared them, the real-scene ladder. Ray sets:
 * camera and hemisphere rays from one shared origin (mixed direction signs
 * in every bundle), distinct random origins, +0/-0 direction components,
 * origins placed exactly on split planes read from the tree (some rays
 * lying in the plane), odd intervals (tmax < tmin, tmin == tmax, finite
 * tmax, negative tmin, NaN/inf inputs), rays aimed at vertices and edge
 * midpoints, each cut into calls of 1, 3, 5, 7, 9, 13 and 64 rays. The 4- and 8-wide drivers are also called directly with
 * the incoherence fallback off, so the SIMD path sees every adversarial ray.
 * So does the interleaved walk of incoherent rays (kd_stream.h): its scalar
 * and AVX-512 forms are called directly on every set, each also with its
 * leaves staged (the large-scene path), and through its dispatch with the
 * rays in reverse order (the id list the bundle fallback passes); as it
 * takes the single walk's steps, its work sums (rays, nodes entered,
 * triangle tests) must also equal the single walk's. That is what catches
 * a wrong NaN rule in its node step (slack-planes): the far child a NaN
 * crossing pushes lies exactly the slack beyond the ray, holds nothing the
 * ray hits, so dropping it changes no answer, only the work.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_stream.h"
#include "kd_traverse.h"
#include "kd_traverse_bundle.h"
#include "kdray.h"
#include "ladder.h"

#define NRAYS 1536
#define PI 3.14159265358979323846

static int g_failures;

/* ---- deterministic random numbers (xorshift64*) --------------------------- */

static uint64_t g_rng = 0x9E3779B97F4A7C15ull;

static uint32_t rnd_u32(void) {
    g_rng ^= g_rng >> 12;
    g_rng ^= g_rng << 25;
    g_rng ^= g_rng >> 27;
    return (uint32_t)((g_rng * 0x2545F4914F6CDD1Dull) >> 32);
}
static float rnd01(void) { return (float)(rnd_u32() >> 8) * 0x1p-24f; }
static float rnd_in(float a, float b) { return a + (b - a) * rnd01(); }
static void rnd_dir(float d[3]) {
    float len;
    do {
        for (int k = 0; k < 3; k++)
            d[k] = rnd_in(-1.0f, 1.0f);
        len = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    } while (len > 1.0f || len < 1e-4f);
}

/* ---- scenes ---------------------------------------------------------------- */

typedef struct scene_src {
    const char *name;
    float *tris;
    size_t ntris;
} scene_src;

static void put_tri(float *t, const float a[3], const float b[3],
                    const float c[3]) {
    memcpy(t, a, 12);
    memcpy(t + 3, b, 12);
    memcpy(t + 6, c, 12);
}

static scene_src make_soup(size_t n) {
    scene_src s = {"soup", malloc(n * 9 * sizeof(float)), n};
    for (size_t i = 0; i < n; i++) {
        float c[3], v[3][3];
        for (int k = 0; k < 3; k++)
            c[k] = rnd_in(-1.0f, 1.0f);
        float size = rnd_in(0.02f, 0.3f);
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 3; k++)
                v[j][k] = c[k] + size * rnd_in(-1.0f, 1.0f);
        put_tri(s.tris + 9 * i, v[0], v[1], v[2]);
    }
    return s;
}

/* Unit quads on an integer lattice, each as two triangles sharing a
 * diagonal: many triangles lie in the planes the SAH build splits on. */
static scene_src make_lattice(int cells, float density) {
    size_t cap = (size_t)3 * cells * cells * (cells + 1) * 2;
    scene_src s = {"lattice", malloc(cap * 9 * sizeof(float)), 0};
    for (int axis = 0; axis < 3; axis++)
        for (int a = 0; a <= cells; a++)
            for (int b = 0; b < cells; b++)
                for (int c = 0; c < cells; c++) {
                    if (rnd01() >= density)
                        continue;
                    float p[4][3];
                    const int du[4] = {0, 1, 1, 0}, dv[4] = {0, 0, 1, 1};
                    for (int q = 0; q < 4; q++) {
                        p[q][axis] = (float)a;
                        p[q][(axis + 1) % 3] = (float)(b + du[q]);
                        p[q][(axis + 2) % 3] = (float)(c + dv[q]);
                    }
                    put_tri(s.tris + 9 * s.ntris++, p[0], p[1], p[2]);
                    put_tri(s.tris + 9 * s.ntris++, p[0], p[2], p[3]);
                }
    return s;
}

/* A closed UV sphere: each vertex computed once, so edges match exactly. */
static scene_src make_sphere(int rings, int segs) {
    float(*v)[3] = malloc(sizeof(float[3]) * (size_t)(rings + 1) * segs);
    for (int r = 0; r <= rings; r++)
        for (int g = 0; g < segs; g++) {
            double th = PI * r / rings, ph = 2.0 * PI * g / segs;
            float *p = v[r * segs + g];
            p[0] = (float)(sin(th) * cos(ph));
            p[1] = (float)cos(th);
            p[2] = (float)(sin(th) * sin(ph));
        }
    scene_src s = {"sphere", malloc(sizeof(float) * 9 * 2 * rings * segs), 0};
    for (int r = 0; r < rings; r++)
        for (int g = 0; g < segs; g++) {
            int g1 = (g + 1) % segs;
            float *a = v[r * segs + g], *b = v[r * segs + g1];
            float *c = v[(r + 1) * segs + g1], *d = v[(r + 1) * segs + g];
            put_tri(s.tris + 9 * s.ntris++, a, b, c);
            put_tri(s.tris + 9 * s.ntris++, a, c, d);
        }
    free(v);
    return s;
}

/* ---- ray sets -------------------------------------------------------------- */

typedef struct rayset {
    const char *name;
    size_t n;
    float *org, *dir, *tmin, *tmax;
    int shared_org;
} rayset;

static rayset rays_alloc(const char *name, int shared_org) {
    rayset r = {name, NRAYS, malloc(3 * NRAYS * sizeof(float)),
                malloc(3 * NRAYS * sizeof(float)), malloc(NRAYS * sizeof(float)),
                malloc(NRAYS * sizeof(float)), shared_org};
    for (size_t i = 0; i < NRAYS; i++) {
        r.tmin[i] = 0.0f;
        r.tmax[i] = INFINITY;
    }
    return r;
}

static void rays_free(rayset *r) {
    free(r->org);
    free(r->dir);
    free(r->tmin);
    free(r->tmax);
}

static void rnd_point(const kdr_bounds *b, float margin, float p[3]) {
    for (int k = 0; k < 3; k++) {
        float ext = b->max[k] - b->min[k];
        p[k] = rnd_in(b->min[k] - margin * ext, b->max[k] + margin * ext);
    }
}

/* A pinhole camera outside the scene looking at its centre. */
static rayset rays_camera(const kdr_bounds *b) {
    rayset r = rays_alloc("camera", 1);
    float c[3], eye[3];
    for (int k = 0; k < 3; k++)
        c[k] = 0.5f * (b->min[k] + b->max[k]);
    eye[0] = c[0] + 1.1f * (b->max[0] - b->min[0]);
    eye[1] = c[1] + 0.4f * (b->max[1] - b->min[1]);
    eye[2] = c[2] + 1.3f * (b->max[2] - b->min[2]);
    memcpy(r.org, eye, sizeof eye);
    const int w = 48; /* rows of 48 pixels, 32 rows */
    for (size_t i = 0; i < r.n; i++) {
        float sx = ((float)(i % w) + 0.5f) / w - 0.5f;
        float sy = ((float)(i / w) + 0.5f) / (r.n / w) - 0.5f;
        for (int k = 0; k < 3; k++)
            r.dir[3 * i + k] = c[k] - eye[k];
        r.dir[3 * i + 0] += sx * (b->max[0] - b->min[0]);
        r.dir[3 * i + 1] += sy * (b->max[1] - b->min[1]);
        r.dir[3 * i + 2] -= sx * (b->max[2] - b->min[2]);
    }
    return r;
}

/* All directions from one point inside the scene: every sign mix. */
static rayset rays_omni(const kdr_bounds *b) {
    rayset r = rays_alloc("omni", 1);
    rnd_point(b, -0.2f, r.org);
    for (size_t i = 0; i < r.n; i++)
        rnd_dir(r.dir + 3 * i);
    return r;
}

static rayset rays_distinct(const kdr_bounds *b) {
    rayset r = rays_alloc("distinct", 0);
    for (size_t i = 0; i < r.n; i++) {
        rnd_point(b, 0.1f, r.org + 3 * i);
        rnd_dir(r.dir + 3 * i);
    }
    return r;
}

/* Coherent rays from nearby, distinct origins: bundles stay together. */
static rayset rays_nearby(const kdr_bounds *b) {
    rayset r = rays_alloc("nearby", 0);
    float base[3] = {0, 0, 0}, d[3] = {1, 0, 0};
    for (size_t i = 0; i < r.n; i++) {
        if (i % 8 == 0) {
            rnd_point(b, 0.0f, base);
            rnd_dir(d);
        }
        for (int k = 0; k < 3; k++) {
            r.org[3 * i + k] = base[k] + 0.01f * rnd_in(-1, 1) * (b->max[k] - b->min[k]);
            r.dir[3 * i + k] = d[k] + 0.05f * rnd_in(-1, 1);
        }
    }
    return r;
}

/* Direction components replaced by +0.0 or -0.0; origins on the lattice's
 * integer planes when the scene is one. */
static rayset rays_zeros(const kdr_bounds *b, int integer_org) {
    rayset r = rays_alloc("zeros", 0);
    for (size_t i = 0; i < r.n; i++) {
        float *o = r.org + 3 * i, *d = r.dir + 3 * i;
        rnd_point(b, 0.05f, o);
        if (integer_org)
            for (int k = 0; k < 3; k++)
                if (rnd_u32() & 1)
                    o[k] = floorf(o[k]);
        rnd_dir(d);
        int nz = 1 + (int)(rnd_u32() % 2);
        for (int z = 0; z < nz; z++)
            d[rnd_u32() % 3] = (rnd_u32() & 1) ? -0.0f : 0.0f;
    }
    return r;
}

/* Origins exactly on split planes of random interior nodes; a third of the
 * rays lie in their plane (direction component +0 or -0). */
static rayset rays_on_splits(const kdr_scene *s, const kdr_bounds *b,
                             int shared) {
    rayset r = rays_alloc(shared ? "split-shared" : "split-planes", shared);
    size_t n_org = shared ? 1 : r.n;
    for (size_t i = 0; i < n_org; i++) {
        float *o = r.org + 3 * i;
        rnd_point(b, 0.0f, o);
        for (int tries = 0; tries < 64 && s->nnodes > 1; tries++) {
            const kd_node *n = &s->nodes[rnd_u32() % s->nnodes];
            if (!kd_is_leaf(n)) {
                o[kd_axis(n)] = n->u.split;
                break;
            }
        }
    }
    for (size_t i = 0; i < r.n; i++) {
        float *d = r.dir + 3 * i;
        rnd_dir(d);
        if (rnd_u32() % 3 == 0)
            d[rnd_u32() % 3] = (rnd_u32() & 1) ? -0.0f : 0.0f;
    }
    return r;
}

/* The walk's positional slack for an origin (kd_walk_setup's). */
static float walk_slack(const kdr_scene *s, const float o[3]) {
    float m = s->root_mag;
    for (int k = 0; k < 3; k++)
        m = fabsf(o[k]) > m ? fabsf(o[k]) : m;
    return m * KD_SLACK_REL;
}

/* Rays lying in a plane parallel to a split plane at exactly the slack
 * from it (direction component +-0 on the split axis, origin where
 * split - org -/+ slack is exactly 0): the crossing 0 * inf is a NaN, so
 * this is where a walk's "NaN visits both children" rule shows. For the
 * slack to be a round number the origin sits outside the box on another
 * axis, at a power of two P above the scene's magnitude (slack P * 2^-16),
 * and aims back into the box. */
static rayset rays_slack_planes(const kdr_scene *s, const kdr_bounds *b) {
    rayset r = rays_alloc("slack-planes", 0);
    float p2 = 1.0f;
    while (p2 <= s->root_mag)
        p2 *= 2.0f;
    for (size_t i = 0; i < r.n; i++) {
        float *o = r.org + 3 * i, *d = r.dir + 3 * i;
        rnd_point(b, 0.0f, o);
        rnd_dir(d);
        const kd_node *n = NULL;
        for (int tries = 0; tries < 64 && s->nnodes > 1 && !n; tries++) {
            n = &s->nodes[rnd_u32() % s->nnodes];
            n = kd_is_leaf(n) ? NULL : n;
        }
        if (!n)
            continue;
        const int k = kd_axis(n), j = (k + 1 + (int)(rnd_u32() & 1)) % 3;
        const float sgn = (rnd_u32() & 1) ? 1.0f : -1.0f;
        o[j] = sgn * p2;
        d[j] = -sgn * fabsf(d[j]) - 0.1f * sgn;
        d[k] = (rnd_u32() & 1) ? -0.0f : 0.0f;
        const float sl = walk_slack(s, o);
        /* exact: sl is a power of two at least 2^7 ulps of the split */
        o[k] = (rnd_u32() & 1) ? n->u.split + sl : n->u.split - sl;
    }
    return r;
}

/* Rays aimed exactly at vertices and edge midpoints (edge functions of 0
 * and the double-precision fallback), from one shared point or from
 * distinct points. */
static rayset rays_aimed(const scene_src *src, const kdr_bounds *b, int shared) {
    rayset r = rays_alloc(shared ? "aimed-shared" : "aimed", shared);
    rnd_point(b, 0.0f, r.org);
    for (size_t i = 0; i < r.n; i++) {
        float *o = r.org + (shared ? 0 : 3 * i), *d = r.dir + 3 * i;
        if (!shared)
            rnd_point(b, 0.1f, o);
        const float *tri = src->tris + 9 * (rnd_u32() % src->ntris);
        int a = (int)(rnd_u32() % 3), c = (a + 1) % 3, mid = (int)(rnd_u32() & 1);
        for (int k = 0; k < 3; k++) {
            float p = mid ? 0.5f * (tri[3 * a + k] + tri[3 * c + k]) : tri[3 * a + k];
            d[k] = p - o[k];
        }
    }
    return r;
}

/* Odd intervals and inputs the bundles must hand to single rays. Shared:
 * one origin for all (the chunks stay with bundles, so kd_batch_live's
 * four-at-a-time test meets them), an inf direction component instead of
 * an inf origin, and some zero directions. */
static rayset rays_intervals(const kdr_bounds *b, int shared) {
    rayset r = rays_alloc(shared ? "intervals-shared" : "intervals", shared);
    float diag = 0.0f;
    for (int k = 0; k < 3; k++)
        diag += (b->max[k] - b->min[k]) * (b->max[k] - b->min[k]);
    diag = sqrtf(diag);
    for (size_t i = 0; i < r.n; i++) {
        rnd_point(b, 0.05f, r.org + 3 * (shared ? 0 : i));
        rnd_dir(r.dir + 3 * i);
        float a = rnd_in(0.0f, diag), c = rnd_in(0.0f, diag);
        switch (rnd_u32() % 8) {
        case 0: r.tmin[i] = c, r.tmax[i] = a < c ? a : c * 0.5f; break; /* empty */
        case 1: r.tmin[i] = r.tmax[i] = a; break;
        case 2: r.tmin[i] = -a; break;
        case 3: r.tmin[i] = a < c ? a : c, r.tmax[i] = a < c ? c : a; break;
        case 4: r.tmax[i] = a; break;
        case 5: r.dir[3 * i + rnd_u32() % 3] = NAN; break;
        case 6: (shared ? r.dir : r.org)[3 * i + rnd_u32() % 3] = INFINITY; break;
        default:
            if (shared && (rnd_u32() & 1))
                r.dir[3 * i] = r.dir[3 * i + 1] = r.dir[3 * i + 2] = 0.0f;
            break;
        }
    }
    return r;
}

/* ---- comparison ------------------------------------------------------------ */

typedef struct results {
    float *t, *u, *v;
    int32_t *prim;
    uint8_t *hit;
    kdr_trav_stats st[2]; /* per query (closest, any): the walk's work */
} results;

static results res_alloc(size_t n) {
    results r = {malloc(n * 4), malloc(n * 4), malloc(n * 4), malloc(n * 4),
                 malloc(n), {{0}}};
    memset(r.t, 0xA5, n * 4); /* sentinels: unwritten entries fail the test */
    memset(r.u, 0xA5, n * 4);
    memset(r.v, 0xA5, n * 4);
    memset(r.prim, 0xA5, n * 4);
    memset(r.hit, 0xA5, n);
    return r;
}

static void res_free(results *r) {
    free(r->t), free(r->u), free(r->v), free(r->prim), free(r->hit);
}

static kdr_ray batch_ray_at(const kdr_ray_batch *b, size_t i) {
    kdr_ray r;
    memcpy(r.org, b->org + b->org_stride * i, sizeof r.org);
    memcpy(r.dir, b->dir + 3 * i, sizeof r.dir);
    r.tmin = b->tmin[b->tmin_stride * i];
    r.tmax = b->tmax[b->tmax_stride * i];
    return r;
}

static results reference(const kdr_scene *s, const kdr_ray_batch *b) {
    results ref = res_alloc(b->n);
    for (size_t i = 0; i < b->n; i++) {
        kdr_ray r = batch_ray_at(b, i);
        kdr_hit h;
        kdr_intersect1(s, &r, &h, &ref.st[KDR_CLOSEST]);
        ref.t[i] = h.t, ref.u[i] = h.u, ref.v[i] = h.v, ref.prim[i] = h.prim;
        ref.hit[i] = (uint8_t)kdr_occluded1(s, &r, &ref.st[KDR_ANY]);
    }
    return ref;
}

static int differ(const results *a, const results *b, size_t i, kdr_query q) {
    if (q == KDR_ANY)
        return a->hit[i] != b->hit[i];
    return memcmp(&a->t[i], &b->t[i], 4) || memcmp(&a->u[i], &b->u[i], 4) ||
           memcmp(&a->v[i], &b->v[i], 4) || a->prim[i] != b->prim[i];
}

/* The traversal under test: 0..3 = the public modes, 4/5 = the 4/8-wide
 * drivers without the incoherence fallback, 6..9 = the interleaved walk's
 * scalar and AVX-512 forms, plain and with staged leaves, 10 = its
 * dispatch with an id list (the rays in reverse order), 11/12 = its AVX2
 * 8-lane form, plain and staged. */
#define NWAYS 13
static const char *const way_names[NWAYS] = {
    "auto",   "single",        "bundle4",  "bundle8",          "raw4",      "raw8",
    "stream", "stream-staged", "stream16", "stream16-staged", "stream-ids",
    "stream8", "stream8-staged"};

/* 0 when the CPU cannot run that way (8 lanes without AVX2, 16 without
 * AVX-512). */
static int way_runs(int way) {
    if (way == 3 || way == 5 || way == 11 || way == 12)
        return kdr_cpu_has_avx2(); /* bundle8 would run 4-wide: raw8 must not run */
    if (way == 8 || way == 9)
        return kd_cpu_has_avx512();
    return 1;
}

static void run_way(const kdr_scene *s, const kdr_ray_batch *b, size_t first,
                    size_t count, kdr_query q, int way, results *out) {
    kdr_hits h = {out->t, out->prim, out->u, out->v, out->hit};
    kdr_trav_stats *st = &out->st[q];
    if (way == 4) {
        kd_bundle4_trace(s, b, first, count, q, 0, &h, NULL);
    } else if (way == 5) {
        kd_bundle8_trace(s, b, first, count, q, 0, &h, NULL);
    } else if (way == 6 || way == 7) {
        if (s->nodes)
            kd_stream_scalar_trace(s, b, NULL, first, count, q,
                                   way == 7 ? KD_STREAM_STAGE : 0, &h, st);
    } else if (way == 8 || way == 9) {
        if (s->nodes)
            kd_stream_trace16(s, b, NULL, first, count, q,
                              way == 9 ? KD_STREAM_STAGE : 0, &h, st);
    } else if (way == 11 || way == 12) {
        if (s->nodes)
            kd_stream_trace8(s, b, NULL, first, count, q,
                             way == 12 ? KD_STREAM_STAGE : 0, &h, st);
    } else if (way == 10) {
        size_t *ids = malloc(count * sizeof *ids);
        for (size_t i = 0; i < count; i++)
            ids[i] = first + count - 1 - i;
        if (s->nodes)
            kd_stream_trace(s, b, ids, 0, count, q, &h, st);
        free(ids);
    } else if (kdr_trace_batch(s, b, first, count, q, (kdr_trav_mode)way, &h, NULL)) {
        g_failures++;
    }
}

static void check_cut(const char *scene, const rayset *rs, const kdr_scene *s,
                      const kdr_ray_batch *b, const results *ref, kdr_query q,
                      int way, const size_t *sizes);

/* Traces the whole set in calls of 1, 3, 5, 7, 9, 13, 64 rays (cycling),
 * then in one call, and compares each ray with the single-ray reference. */
static void check_way(const char *scene, const rayset *rs, const kdr_scene *s,
                      const kdr_ray_batch *b, const results *ref, kdr_query q,
                      int way) {
    static const size_t sizes[] = {1, 3, 5, 7, 9, 13, 64};
    for (int whole = 0; whole < 2; whole++)
        check_cut(scene, rs, s, b, ref, q, way, whole ? NULL : sizes);
}

/* One pass: calls of sizes[] rays (cycling), or one call for all rays
 * (several chunks: regrouping and the fallback carry across them). */
static void check_cut(const char *scene, const rayset *rs, const kdr_scene *s,
                      const kdr_ray_batch *b, const results *ref, kdr_query q,
                      int way, const size_t *sizes) {
    results got = res_alloc(b->n);
    size_t first = 0;
    for (int c = 0; first < b->n; c = (c + 1) % 7) {
        size_t cnt = !sizes ? b->n : sizes[c] < b->n - first ? sizes[c] : b->n - first;
        run_way(s, b, first, cnt, q, way, &got);
        first += cnt;
    }
    int bad = 0;
    for (size_t i = 0; i < b->n; i++) {
        if (!differ(&got, ref, i, q))
            continue;
        if (bad++ < 3) {
            kdr_ray r = batch_ray_at(b, i);
            fprintf(stderr,
                    "FAIL %s/%s %s %s ray %zu o=(%a %a %a) d=(%a %a %a) "
                    "[%a %a]: got t=%a p=%d u=%a v=%a hit=%d, single t=%a "
                    "p=%d u=%a v=%a hit=%d\n",
                    scene, rs->name, way_names[way],
                    q == KDR_ANY ? "any" : "closest", i, r.org[0], r.org[1],
                    r.org[2], r.dir[0], r.dir[1], r.dir[2], r.tmin, r.tmax,
                    got.t[i], got.prim[i], got.u[i], got.v[i], got.hit[i],
                    ref->t[i], ref->prim[i], ref->u[i], ref->v[i], ref->hit[i]);
        }
    }
    if (bad)
        fprintf(stderr, "FAIL %s/%s %s%s: %d of %zu rays differ\n", scene,
                rs->name, way_names[way], sizes ? "" : " (one call)", bad, b->n);
    g_failures += bad;
    /* The interleaved walk takes the single walk's steps ray by ray, so it
     * enters the same nodes and tests the same triangles: equal work sums
     * catch a step that differs without changing an answer (a far child
     * dropped or entered that holds nothing the ray hits, e.g. a NaN
     * crossing's far entry, see rays_slack_planes). */
    const kdr_trav_stats *gs = &got.st[q], *rs_ = &ref->st[q];
    if (way >= 6 && way <= 12 && s->nodes &&
        (gs->rays != rs_->rays || gs->nodes_visited != rs_->nodes_visited ||
         gs->tri_tests != rs_->tri_tests)) {
        fprintf(stderr,
                "FAIL %s/%s %s %s%s: work differs from the single walk: rays %llu "
                "/ %llu, nodes %llu / %llu, triangle tests %llu / %llu\n",
                scene, rs->name, way_names[way], q == KDR_ANY ? "any" : "closest",
                sizes ? "" : " (one call)", (unsigned long long)gs->rays,
                (unsigned long long)rs_->rays, (unsigned long long)gs->nodes_visited,
                (unsigned long long)rs_->nodes_visited,
                (unsigned long long)gs->tri_tests, (unsigned long long)rs_->tri_tests);
        g_failures++;
    }
    res_free(&got);
}

static void check_set(const char *scene, const kdr_scene *s, rayset *rs) {
    kdr_ray_batch b = {rs->n, rs->org, rs->shared_org ? 0 : 3, rs->dir,
                       rs->tmin, 1, rs->tmax, 1};
    results ref = reference(s, &b);
    size_t hits = 0;
    for (size_t i = 0; i < b.n; i++)
        hits += ref.prim[i] >= 0;
    printf("%-8s %-13s %zu rays, %zu hits\n", scene, rs->name, b.n, hits);
    for (int q = KDR_CLOSEST; q <= KDR_ANY; q++)
        for (int way = 0; way < NWAYS; way++)
            if (way_runs(way))
                check_way(scene, rs, s, &b, &ref, (kdr_query)q, way);
    res_free(&ref);
}

static void check_scene(const scene_src *src, int integer) {
    kdr_scene *s = NULL;
    if (kdr_scene_build(src->tris, src->ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "FAIL: building %s\n", src->name);
        g_failures++;
        return;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s, &bb);
    rayset sets[] = {rays_camera(&bb),         rays_omni(&bb),
                     rays_distinct(&bb),       rays_nearby(&bb),
                     rays_zeros(&bb, integer), rays_on_splits(s, &bb, 0),
                     rays_on_splits(s, &bb, 1), rays_intervals(&bb, 0),
                     rays_intervals(&bb, 1),
                     rays_aimed(src, &bb, 0),  rays_aimed(src, &bb, 1),
                     rays_slack_planes(s, &bb)};
    for (size_t k = 0; k < sizeof sets / sizeof sets[0]; k++) {
        check_set(src->name, s, &sets[k]);
        rays_free(&sets[k]);
    }
    kdr_scene_free(s);
}

/* Stride-0 tmin/tmax: one interval shared by every ray. */
static void check_shared_interval(const scene_src *src) {
    kdr_scene *s = NULL;
    if (kdr_scene_build(src->tris, src->ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        g_failures++;
        return;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s, &bb);
    rayset rs = rays_omni(&bb);
    rs.name = "omni-shared-interval";
    rs.tmin[0] = 0.05f;
    rs.tmax[0] = 0.5f * (bb.max[0] - bb.min[0]);
    kdr_ray_batch b = {rs.n, rs.org, 0, rs.dir, rs.tmin, 0, rs.tmax, 0};
    results ref = reference(s, &b);
    for (int q = KDR_CLOSEST; q <= KDR_ANY; q++)
        for (int way = 0; way < NWAYS; way++)
            if (way_runs(way))
                check_way(src->name, &rs, s, &b, &ref, (kdr_query)q, way);
    res_free(&ref);
    rays_free(&rs);
    kdr_scene_free(s);
}

/* Argument checks and the empty scene. */
static void check_api(void) {
    kdr_scene *s = NULL;
    if (kdr_scene_build(NULL, 0, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "FAIL: empty scene build\n");
        g_failures++;
        return;
    }
    float org[3] = {0, 0, 0}, dir[6] = {1, 0, 0, 0, -1, 0}, tmin = 0, tmax = 1;
    float t[2], u[2], v[2];
    int32_t prim[2];
    uint8_t hit[2];
    kdr_hits h = {t, prim, u, v, hit};
    kdr_ray_batch b = {2, org, 0, dir, &tmin, 0, &tmax, 0};
    int bad = 0;
    bad += kdr_trace_batch(s, &b, 0, 2, KDR_CLOSEST, KDR_TRAV_AUTO, &h, NULL) != KDR_OK;
    bad += prim[0] != -1 || prim[1] != -1 || t[0] != -1.0f || u[1] != 0.0f;
    bad += kdr_trace_batch(s, &b, 1, 2, KDR_CLOSEST, KDR_TRAV_AUTO, &h, NULL) != KDR_EINVAL;
    b.org_stride = 2;
    bad += kdr_trace_batch(s, &b, 0, 2, KDR_ANY, KDR_TRAV_AUTO, &h, NULL) != KDR_EINVAL;
    b.org_stride = 0;
    bad += kdr_trace_batch(s, &b, 0, 2, KDR_ANY, (kdr_trav_mode)7, &h, NULL) != KDR_EINVAL;
    bad += kdr_trace_batch(NULL, &b, 0, 2, KDR_ANY, KDR_TRAV_AUTO, &h, NULL) != KDR_EINVAL;
    if (bad)
        fprintf(stderr, "FAIL: %d API checks\n", bad);
    g_failures += bad;
    kdr_scene_free(s);
}

/* The real-scene ladder of scenes/fetch: every ray set on every scene. */
static int check_ladder(const char *dir) {
    ladder_entry *e = NULL;
    char err[256];
    int n = ladder_read(dir, &e, err, sizeof err);
    if (n < 0) {
        printf("no ladder: %s\n", err);
        return 77;
    }
    for (int i = 0; i < n; i++) {
        scene_src src = {e[i].name, NULL, 0};
        if (ladder_load(&e[i], &src.tris, &src.ntris, err, sizeof err) != 0) {
            fprintf(stderr, "FAIL: %s\n", err);
            g_failures++;
            continue;
        }
        if (src.ntris > 0)
            check_scene(&src, 0);
        free(src.tris);
    }
    free(e);
    printf("%s: %d mismatches\n", g_failures ? "FAILED" : "passed", g_failures);
    return g_failures ? 1 : 0;
}

/* No argument: generated scenes. One argument: the ladder directory. */
int main(int argc, char **argv) {
    printf("AVX2: %s\n", kdr_cpu_has_avx2() ? "yes (4- and 8-wide tested)"
                                            : "no (8-wide skipped)");
    printf("AVX-512: %s\n", kd_cpu_has_avx512() ? "yes (16-lane interleaved walk tested)"
                                               : "no (16-lane interleaved walk skipped)");
    if (argc > 1)
        return check_ladder(argv[1]);
    check_api();
    scene_src scenes[] = {make_soup(3000), make_lattice(6, 0.3f),
                          make_sphere(24, 48)};
    for (size_t k = 0; k < sizeof scenes / sizeof scenes[0]; k++) {
        check_scene(&scenes[k], k == 1);
        if (k == 0)
            check_shared_interval(&scenes[k]);
    }
    for (size_t k = 0; k < sizeof scenes / sizeof scenes[0]; k++)
        free(scenes[k].tris);
    printf("%s: %d mismatches\n", g_failures ? "FAILED" : "passed", g_failures);
    return g_failures ? 1 : 0;
}
