/*
 * test_cone.c — cone-shadow queries (core/kd_cone*.c): the sample rays'
 * definition, analytic visibilities, KDR_SHADOW_CONE == KDR_SHADOW_RAYS ==
 * brute force sample by sample, Embree on the same rays, and adversarial
 * cones placed on the tree's actual split planes.
 *
 * The brute-force reference tests every triangle with core/kd_tri.h, so a
 * cone traversal that skips a leaf some sample enters shows up as a count
 * mismatch; the scenes are many small triangles so that most blocked
 * samples are blocked by one triangle only.
 *
 *   test_cone [--caps NAME]   NAME: bound the explained classes of the
 *                             Embree comparison (tests/support/caps.h)
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "caps.h"
#include "compare.h"
#include "kd_cone.h"
#include "kd_internal.h"
#include "kd_tri.h"
#include "kdray.h"
#include "oracle.h"

static int failures;
static const char *g_caps; /* --caps NAME, or NULL */

#define CHECK(cond, ...)                                                     \
    do {                                                                     \
        if (!(cond)) {                                                       \
            failures++;                                                      \
            fprintf(stderr, "%s:%d: FAILED %s: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                    \
            fputc('\n', stderr);                                             \
        }                                                                    \
    } while (0)

/* ---- scenes ---------------------------------------------------------------- */

typedef struct tri_buf {
    float *v;
    size_t n, cap;
} tri_buf;

static void tb_add(tri_buf *b, const float t[9]) {
    if (b->n == b->cap) {
        b->cap = b->cap ? 2 * b->cap : 64;
        b->v = realloc(b->v, b->cap * 9 * sizeof(float));
        if (!b->v)
            abort();
    }
    memcpy(b->v + 9 * b->n++, t, 9 * sizeof(float));
}

/* Axis-aligned rectangle in the plane x_axis = c over [a0,a1] x [b0,b1]. */
static void tb_rect(tri_buf *b, int axis, float c, float a0, float a1, float b0,
                    float b1) {
    const int i = (axis + 1) % 3, j = (axis + 2) % 3;
    float p[4][3];
    const float ua[4] = {a0, a1, a1, a0}, ub[4] = {b0, b0, b1, b1};
    for (int q = 0; q < 4; q++) {
        p[q][axis] = c;
        p[q][i] = ua[q];
        p[q][j] = ub[q];
    }
    const float t0[9] = {p[0][0], p[0][1], p[0][2], p[1][0], p[1][1],
                         p[1][2], p[2][0], p[2][1], p[2][2]};
    const float t1[9] = {p[0][0], p[0][1], p[0][2], p[2][0], p[2][1],
                         p[2][2], p[3][0], p[3][1], p[3][2]};
    tb_add(b, t0);
    tb_add(b, t1);
}

static uint64_t rng_state;
static double rnd(void) {
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(rng_state >> 11) * 0x1p-53;
}

/* n small random triangles (edge ~size) inside [0, extent]^3. */
static void tb_soup(tri_buf *b, size_t n, float extent, float size) {
    for (size_t t = 0; t < n; t++) {
        float c[3], tri[9];
        for (int k = 0; k < 3; k++)
            c[k] = (float)(rnd() * extent);
        for (int j = 0; j < 9; j++)
            tri[j] = c[j % 3] + (float)((rnd() - 0.5) * size);
        tb_add(b, tri);
    }
}

static kdr_scene *build(const tri_buf *b) {
    kdr_build_opts o;
    kdr_scene *s = NULL;
    kdr_build_opts_default(&o);
    if (kdr_scene_build(b->v, b->n, &o, NULL, NULL, &s) != KDR_OK || !s) {
        fprintf(stderr, "scene build failed\n");
        exit(1);
    }
    return s;
}

static kdr_shadow_query make_query(const float *pts, size_t n,
                                   const kdr_sphere_light *lights, size_t nl,
                                   uint32_t samples) {
    kdr_shadow_query q = {0};
    q.n = n;
    q.points = pts;
    q.lights = lights;
    q.nlights = nl;
    q.samples = samples;
    q.seed = 7;
    q.offset = KDR_OFFSET_AUTO; /* the contract's default (API v1.1) */
    return q;
}

/* ---- the checks ------------------------------------------------------------ */

/* Lit-sample counts of (point, light) pairs by brute force over all
 * triangles with the core's triangle test. */
static uint32_t brute_lit(const kdr_scene *s, const tri_buf *b,
                          const kdr_shadow_query *q, size_t i, size_t l) {
    uint32_t lit = 0;
    (void)s;
    for (uint32_t k = 0; k < q->samples; k++) {
        kdr_ray r;
        if (kdr_shadow_ray(s, q, i, l, k, &r) != KDR_OK)
            return UINT32_MAX;
        lit += ref_occluded1(b->v, b->n, &r) ? 0u : 1u;
    }
    return lit;
}

/* Both modes against brute force, pair by pair; returns cones decided. */
static uint64_t check_modes(const char *label, const kdr_scene *s,
                            const tri_buf *b, const kdr_shadow_query *q) {
    const size_t m = q->n * q->nlights;
    float *vc = malloc(m * sizeof *vc), *vr = malloc(m * sizeof *vr);
    kdr_shadow_stats sc = {0}, sr = {0};
    CHECK(kdr_shadow_trace(s, q, 0, q->n, KDR_SHADOW_CONE, vc, &sc) == KDR_OK,
          "%s cone", label);
    CHECK(kdr_shadow_trace(s, q, 0, q->n, KDR_SHADOW_RAYS, vr, &sr) == KDR_OK,
          "%s rays", label);
    /* the walk forced on and off: the same answers, bit for bit */
    const kd_walk_policy forced[2] = {KD_WALK_ALWAYS, KD_WALK_NEVER};
    for (int k = 0; k < 2; k++) {
        float *vf = malloc(m * sizeof *vf);
        kdr_shadow_stats sf = {0};
        CHECK(kd_shadow_trace_policy(s, q, 0, q->n, KDR_SHADOW_CONE, forced[k], vf,
                                     &sf) == KDR_OK,
              "%s policy %d", label, (int)forced[k]);
        CHECK(memcmp(vf, vr, m * sizeof *vf) == 0, "%s: walk %s differs from rays",
              label, k ? "off" : "on");
        if (k == 1)
            CHECK(sf.cones_decided == 0 && sf.rays_traced == (uint64_t)m * q->samples,
                  "%s walk off traces every sample", label);
        free(vf);
    }
    int bad = 0;
    for (size_t i = 0; i < q->n && bad < 5; i++) {
        for (size_t l = 0; l < q->nlights; l++) {
            const uint32_t lit = brute_lit(s, b, q, i, l);
            const float want = (float)lit / (float)q->samples;
            const float c = vc[i * q->nlights + l], r = vr[i * q->nlights + l];
            if (c != want || r != want) {
                bad++;
                CHECK(0, "%s point %zu light %zu: cone %.6f rays %.6f brute %.6f",
                      label, i, l, c, r, want);
            }
        }
    }
    CHECK(sr.cones_decided == 0 && sr.rays_traced == (uint64_t)m * q->samples,
          "%s rays-mode stats", label);
    printf("%-28s pairs %5zu decided %5llu rays cone %8llu rays %8llu\n", label,
           m, (unsigned long long)sc.cones_decided,
           (unsigned long long)sc.rays_traced, (unsigned long long)sr.rays_traced);
    free(vc);
    free(vr);
    return sc.cones_decided;
}

static void test_invalid(void) {
    tri_buf b = {0};
    tb_rect(&b, 2, 1.0f, -1, 1, -1, 1);
    kdr_scene *s = build(&b);
    const float pts[6] = {0, 0, 0, 0, 0, 5};
    kdr_sphere_light li = {{0, 0, 5}, 1.0f};
    kdr_shadow_query q = make_query(pts, 2, &li, 1, 4);
    float vis[2];
    kdr_ray r;
    CHECK(kdr_shadow_trace(s, &q, 0, 2, KDR_SHADOW_CONE, vis, NULL) == KDR_EINVAL,
          "point inside the light");
    CHECK(kdr_shadow_ray(s, &q, 1, 0, 0, &r) == KDR_EINVAL, "ray inside light");
    CHECK(kdr_shadow_ray(s, &q, 0, 0, 4, &r) == KDR_EINVAL, "sample >= samples");
    CHECK(kdr_shadow_trace(s, &q, 1, 2, KDR_SHADOW_CONE, vis, NULL) == KDR_EINVAL,
          "range past n");
    q.samples = 0;
    CHECK(kdr_shadow_trace(s, &q, 0, 1, KDR_SHADOW_CONE, vis, NULL) == KDR_EINVAL,
          "0 samples");
    q.samples = 4097;
    CHECK(kdr_shadow_trace(s, &q, 0, 1, KDR_SHADOW_RAYS, vis, NULL) == KDR_EINVAL,
          "4097 samples");
    q.samples = 4;
    li.radius = 0.0f;
    CHECK(kdr_shadow_trace(s, &q, 0, 1, KDR_SHADOW_CONE, vis, NULL) == KDR_EINVAL,
          "radius 0");
    li.radius = NAN;
    CHECK(kdr_shadow_trace(s, &q, 0, 1, KDR_SHADOW_CONE, vis, NULL) == KDR_EINVAL,
          "radius NaN");
    li.radius = 1.0f;
    q.offset = KDR_OFFSET_DIAGONAL;
    q.epsilon = -1.0f;
    CHECK(kdr_shadow_ray(s, &q, 0, 0, 0, &r) == KDR_EINVAL, "negative epsilon");
    q.epsilon = NAN;
    CHECK(kdr_shadow_ray(s, &q, 0, 0, 0, &r) == KDR_EINVAL, "NaN epsilon");
    q.epsilon = 3e38f; /* the diagonal is 2.8: epsilon * diagonal overflows */
    CHECK(kdr_shadow_ray(s, &q, 0, 0, 0, &r) == KDR_EINVAL, "overflowing offset");
    CHECK(kdr_shadow_trace(s, &q, 0, 1, KDR_SHADOW_CONE, vis, NULL) == KDR_EINVAL,
          "overflowing offset, trace");
    q.epsilon = 1e-4f;
    CHECK(kdr_shadow_ray(s, &q, 0, 0, 0, &r) == KDR_OK, "diagonal offset");
    q.offset = (kdr_shadow_offset)2;
    CHECK(kdr_shadow_ray(s, &q, 0, 0, 0, &r) == KDR_EINVAL, "unknown offset mode");
    q.offset = KDR_OFFSET_AUTO;
    q.epsilon = NAN; /* ignored by "auto" */
    CHECK(kdr_shadow_ray(s, &q, 0, 0, 0, &r) == KDR_OK, "auto ignores epsilon");
    kdr_scene_free(s);
    free(b.v);
}

/* Every sample ray: unit direction inside the cone, end point on the sphere,
 * the same ray for the same (seed, i, l, s) and a different one for another
 * seed; the samples' mean direction is the cone axis. */
static void test_ray_definition(void) {
    tri_buf b = {0};
    tb_rect(&b, 2, 100.0f, -1, 1, -1, 1);
    kdr_scene *s = build(&b);
    const float pts[3] = {0.5f, -0.25f, 0.0f};
    const kdr_sphere_light lights[3] = {
        {{3, 4, 12}, 1.0f}, {{0.5f, -0.25f, 2.0f}, 1.9f}, {{-7, 0, 0}, 1e-3f}};
    kdr_shadow_query q = make_query(pts, 1, lights, 3, 256);
    for (size_t l = 0; l < 3; l++) {
        const float *c = lights[l].center;
        double ax[3], D = 0, mean[3] = {0, 0, 0};
        for (int k = 0; k < 3; k++) {
            ax[k] = c[k] - pts[k];
            D += ax[k] * ax[k];
        }
        D = sqrt(D);
        const double cos_a = sqrt(1.0 - (lights[l].radius / D) * (lights[l].radius / D));
        for (uint32_t k = 0; k < q.samples; k++) {
            kdr_ray r, r2;
            CHECK(kdr_shadow_ray(s, &q, 0, l, k, &r) == KDR_OK, "ray");
            kdr_shadow_ray(s, &q, 0, l, k, &r2);
            CHECK(memcmp(&r, &r2, sizeof r) == 0, "reproducible");
            double len = 0, ct = 0, e2 = 0;
            for (int j = 0; j < 3; j++) {
                len += (double)r.dir[j] * r.dir[j];
                ct += r.dir[j] * ax[j] / D;
                mean[j] += r.dir[j];
            }
            CHECK(fabs(len - 1.0) < 1e-6, "unit dir %g", len);
            CHECK(ct >= cos_a - 1e-6, "inside cone: cos %.9f < %.9f", ct, cos_a);
            for (int j = 0; j < 3; j++) {
                const double e = r.org[j] + (double)r.tmax * r.dir[j] - c[j];
                e2 += e * e;
            }
            CHECK(fabs(sqrt(e2) - lights[l].radius) <= 1e-4 * D,
                  "end on sphere: %g vs %g", sqrt(e2), lights[l].radius);
            CHECK(r.tmin == 0.0f && r.tmax > 0.0f, "interval");
        }
        double mlen = sqrt(mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2]);
        double mc = (mean[0] * ax[0] + mean[1] * ax[1] + mean[2] * ax[2]) / (mlen * D);
        /* the sample mean lies within a small angle of the axis */
        CHECK(1.0 - mc < 0.02 * (1.0 - cos_a) + 1e-9, "mean direction %g", 1.0 - mc);
    }
    kdr_ray r1, r2;
    kdr_shadow_ray(s, &q, 0, 0, 3, &r1);
    q.seed = 8;
    kdr_shadow_ray(s, &q, 0, 0, 3, &r2);
    CHECK(memcmp(r1.dir, r2.dir, sizeof r1.dir) != 0, "seed changes the rays");
    kdr_scene_free(s);
    free(b.v);
}

/* Analytic cases: a big blocker (0), an unoccluded light (1 with no rays)
 * and a half-plane blocker whose blocked solid-angle fraction is integrated
 * numerically (uniform in cos theta: a sampler uniform in theta fails). */
static double half_plane_blocked(double h, double x0, double sin_a) {
    const double cos_a = sqrt(1 - sin_a * sin_a);
    const int steps = 200000;
    double acc = 0;
    for (int j = 0; j < steps; j++) {
        const double ct = cos_a + (1 - cos_a) * (j + 0.5) / steps;
        const double tt = sqrt(1 - ct * ct) / ct;
        const double x = tt > 0 ? x0 / (h * tt) : (x0 > 0 ? 2.0 : -2.0);
        acc += acos(fmax(-1.0, fmin(1.0, x))) / 3.14159265358979323846;
    }
    return acc / steps;
}

static void test_analytic(void) {
    tri_buf b = {0};
    tb_rect(&b, 2, 1.0f, -50, 50, -50, 50);      /* roof at z = 1 */
    tb_rect(&b, 2, -3.0f, -50, 50, -50, 50);     /* floor below the points */
    tb_rect(&b, 0, 20.0f, -50, 50, 5, 50);       /* wall far to the side */
    kdr_scene *s = build(&b);
    float pts[3 * 16];
    for (int i = 0; i < 16; i++) {
        pts[3 * i] = (float)(i % 4) - 1.5f;
        pts[3 * i + 1] = (float)(i / 4) - 1.5f;
        pts[3 * i + 2] = 0.0f;
    }
    /* light 0 above the roof, light 1 below the roof beside the points */
    const kdr_sphere_light lights[2] = {{{0, 0, 6}, 2.0f}, {{0, 0, -1}, 0.5f}};
    /* the open light is exactly 1 on every path; where the cone walks
     * (forced, or from CONE_WALK_FROM samples on) it decides the open
     * light's cones without rays; below CONE_WALK_FROM the cheap test sends
     * every sample to the any-hit bundles instead (both lights are wide:
     * from CONE_WALK_WIDE_FROM on, AUTO walks too) */
    const uint32_t spp[4] = {1, 4, 31, CONE_WALK_WIDE_FROM};
    kdr_shadow_query q = make_query(pts, 16, lights, 2, 64);
    for (int k = 0; k < 8; k++) {
        float vis[32];
        kdr_shadow_stats st = {0};
        const int walk = k >= 4 || spp[k % 4] >= CONE_WALK_WIDE_FROM;
        q.samples = spp[k % 4];
        CHECK(kd_shadow_trace_policy(s, &q, 0, 16, KDR_SHADOW_CONE,
                                     k >= 4 ? KD_WALK_ALWAYS : KD_WALK_AUTO, vis,
                                     &st) == KDR_OK,
              "ok");
        for (int i = 0; i < 16; i++) {
            CHECK(vis[2 * i] == 0.0f, "under the roof: %g", vis[2 * i]);
            CHECK(vis[2 * i + 1] == 1.0f, "open light: %g", vis[2 * i + 1]);
        }
        if (walk) {
            CHECK(st.cones_decided == 16, "open cones decided at %u spp: %llu",
                  spp[k % 4], (unsigned long long)st.cones_decided);
            CHECK(st.rays_traced <= 16u * spp[k % 4],
                  "rays only toward the roofed light: %llu",
                  (unsigned long long)st.rays_traced);
        } else {
            CHECK(st.cones_decided == 0 && st.rays_traced == 32u * spp[k % 4],
                  "no walk at %u spp: decided %llu, rays %llu", spp[k % 4],
                  (unsigned long long)st.cones_decided,
                  (unsigned long long)st.rays_traced);
        }
    }
    q.samples = 64;
    check_modes("analytic roof", s, &b, &q);
    kdr_scene_free(s);
    free(b.v);

    /* half-plane x >= x0 at z = h between the point and a close light */
    const float h = 0.25f, D = 2.0f, r = 1.6f; /* sphere starts at z = 0.4 */
    const double sin_a = r / D, tan_a = sin_a / sqrt(1 - sin_a * sin_a);
    const float x0s[3] = {0.0f, (float)(0.4 * h * tan_a), (float)(-0.7 * h * tan_a)};
    for (int c = 0; c < 3; c++) {
        tri_buf hb = {0};
        tb_rect(&hb, 2, h, x0s[c], 30, -30, 30);
        kdr_scene *hs = build(&hb);
        const float p[3] = {0, 0, 0};
        const kdr_sphere_light hl = {{0, 0, D}, r};
        kdr_shadow_query hq = make_query(p, 1, &hl, 1, 4096);
        const double want = 1.0 - half_plane_blocked(h, x0s[c], sin_a);
        for (int seed = 0; seed < 3; seed++) {
            float v;
            hq.seed = (uint64_t)seed;
            kdr_shadow_trace(hs, &hq, 0, 1, KDR_SHADOW_CONE, &v, NULL);
            CHECK(fabs(v - want) < 0.02, "half-plane x0=%g: %g want %g", x0s[c], v, want);
        }
        kdr_scene_free(hs);
        free(hb.v);
    }
}

/* Normals (API v1.1): the start moves along the normal AS GIVEN. On a
 * single-sided floor lit from above, points whose normal faces the light
 * are lit and points whose normal faces away are shadowed by the floor
 * itself (the caller says the point is on the floor's underside). v1 turned
 * every normal toward the light and found both lit; this test asserted
 * that and now asserts the contract's answer. Without normals the start
 * moves along each ray, and the floor does not shadow its own points. */
static void test_normals(void) {
    tri_buf b = {0};
    tb_rect(&b, 1, 0.0f, -10, 10, -10, 10); /* floor y = 0 */
    kdr_scene *s = build(&b);
    const float pts[6] = {0, 0, 0, 2.5f, 0, 1.0f};
    const float down[6] = {0, -1, 0, 0, -3, 0};
    const float up[6] = {0, 1, 0, 0, 1, 0};
    const kdr_sphere_light li = {{1, 5, 1}, 1.0f};
    kdr_shadow_query q = make_query(pts, 2, &li, 1, 32);
    const float *nrm[3] = {down, up, NULL};
    const float want[3] = {0.0f, 1.0f, 1.0f};
    for (int off = 0; off < 2; off++) {
        q.offset = off ? KDR_OFFSET_DIAGONAL : KDR_OFFSET_AUTO;
        q.epsilon = 1e-4f;
        for (int c = 0; c < 3; c++) {
            float vis[2];
            q.normals = nrm[c];
            for (int m = 0; m < 2; m++) {
                kdr_shadow_trace(s, &q, 0, 2, (kdr_shadow_mode)m, vis, NULL);
                CHECK(vis[0] == want[c] && vis[1] == want[c],
                      "floor, normals %s, offset %s, mode %d: %g %g (want %g)",
                      c == 0 ? "down" : c == 1 ? "up" : "none", off ? "diagonal" : "auto",
                      m, vis[0], vis[1], want[c]);
            }
            check_modes("normals on floor", s, &b, &q);
        }
    }
    kdr_scene_free(s);
    free(b.v);
}

/* The offset itself: "auto" moves KDR_OFFSET_AUTO_ULPS ulps of the point's
 * largest coordinate along the normal as given, at the origin as 1e5 away;
 * a numeric epsilon moves epsilon * diagonal; rounding never shortens it. */
static void test_offsets(void) {
    tri_buf b = {0};
    tb_rect(&b, 1, 0.0f, -1e5f, 1e5f, -1e5f, 1e5f);
    kdr_scene *s = build(&b);
    const float pts[9] = {1e5f, 0.5f, 3.0f, 0.25f, 0.0f, -0.75f, 0.0f, 0.0f, 0.0f};
    const float nrm[9] = {0, 1, 0, 0, -2, 0, 1, 1, 0};
    const kdr_sphere_light li = {{0, 1e4f, 0}, 10.0f};
    kdr_shadow_query q = make_query(pts, 3, &li, 1, 4);
    q.normals = nrm;
    kdr_ray r;
    /* 1e5 is in [2^16, 2^17): ulp 2^-7, so 16 ulps are 0.125 */
    CHECK(kdr_shadow_ray(s, &q, 0, 0, 1, &r) == KDR_OK && r.org[0] == 1e5f &&
              r.org[1] == 0.625f && r.org[2] == 3.0f,
          "auto at 1e5: %.9g %.9g %.9g", r.org[0], r.org[1], r.org[2]);
    /* 0.75 is in [2^-1, 2^0): ulp 2^-24, 16 ulps 2^-20; down, as given */
    CHECK(kdr_shadow_ray(s, &q, 1, 0, 1, &r) == KDR_OK && r.org[0] == 0.25f &&
              r.org[1] == -0x1p-20f && r.org[2] == -0.75f,
          "auto near 0, normal down: %.9g %.9g %.9g", r.org[0], r.org[1], r.org[2]);
    /* at the origin: 16 ulps of FLT_MIN along (1,1,0)/sqrt(2), each
     * coordinate rounded away from the point (never to 0) */
    CHECK(kdr_shadow_ray(s, &q, 2, 0, 1, &r) == KDR_OK && r.org[0] > 0.0f &&
              r.org[1] > 0.0f && r.org[2] == 0.0f &&
              (double)r.org[0] + r.org[1] >= 16 * 0x1p-149 * sqrt(2.0),
          "auto at 0: %g %g %g", r.org[0], r.org[1], r.org[2]);
    q.offset = KDR_OFFSET_DIAGONAL;
    q.epsilon = 1e-6f;
    const double want = 1e-6f * kdr_scene_diagonal(s);
    CHECK(kdr_shadow_ray(s, &q, 1, 0, 1, &r) == KDR_OK && -(double)r.org[1] >= want &&
              -(double)r.org[1] < want * (1 + 1e-6),
          "diagonal: %.9g want %.9g", -r.org[1], want);
    q.normals = NULL; /* along each ray: the origin moves, the apex does not */
    q.offset = KDR_OFFSET_AUTO;
    CHECK(kdr_shadow_ray(s, &q, 1, 0, 1, &r) == KDR_OK &&
              fabs(r.org[1] - 0x1p-20 * r.dir[1]) <= 0x1p-44,
          "auto along the ray: %.9g", r.org[1]);
    kdr_scene_free(s);
    free(b.v);
}

/* Random soup: modes vs brute force, and Embree on the same sample rays. */
static void test_soup_vs_embree(void) {
    rng_state = 12345;
    tri_buf b = {0};
    tb_soup(&b, 3000, 10.0f, 0.6f);
    kdr_scene *s = build(&b);
    enum { NP = 48, NL = 3 };
    float pts[3 * NP], nrm[3 * NP];
    kdr_sphere_light lights[NL] = {
        {{5, 5, 14}, 2.0f}, {{5, 5, 5}, 0.8f}, {{-2, 11, 3}, 0.3f}};
    for (int i = 0; i < 3 * NP; i++) {
        pts[i] = (float)(rnd() * 10.0);
        nrm[i] = (float)(rnd() - 0.5);
    }
    for (int i = 0; i < NP; i++) { /* keep points out of the lights */
        for (int l = 0; l < NL; l++) {
            double d2 = 0;
            for (int k = 0; k < 3; k++)
                d2 += (pts[3 * i + k] - lights[l].center[k]) *
                      (pts[3 * i + k] - lights[l].center[k]);
            if (d2 <= 1.1 * lights[l].radius * lights[l].radius)
                pts[3 * i + 2] = -1.0f;
        }
    }
    kdr_shadow_query q = make_query(pts, NP, lights, NL, 32);
    check_modes("soup", s, &b, &q);
    q.normals = nrm;
    q.samples = 5;
    check_modes("soup with normals", s, &b, &q);
    /* wide cones over the busy soup: the grouped-sample path */
    kdr_sphere_light wide[2] = {{{5, 5, 16}, 4.5f}, {{5, 17, 5}, 4.0f}};
    kdr_shadow_query qw = make_query(pts, NP, wide, 2, 96);
    check_modes("soup, wide cones, grouped", s, &b, &qw);

    oracle_opts oo;
    oracle_opts_judge(&oo);
    oracle *o = oracle_create(b.v, b.n, &oo);
    CHECK(o != NULL, "embree oracle");
    cmp_tally tally;
    cmp_tally_init(&tally);
    for (size_t i = 0; o && i < NP; i++) {
        for (size_t l = 0; l < NL; l++) {
            for (uint32_t k = 0; k < q.samples; k++) {
                kdr_ray r;
                kdr_hit kh, eh;
                kdr_shadow_ray(s, &q, i, l, k, &r);
                const int kd = kdr_occluded1(s, &r, NULL);
                const int em = oracle_occluded1(o, &r);
                kdr_intersect1(s, &r, &kh, NULL);
                oracle_intersect1(o, &r, &eh);
                cmp_tally_add(&tally, &r,
                              cmp_occluded(b.v, b.n, &r, kd, em, &kh, &eh), 0.0, em);
            }
        }
    }
    cmp_tally_print(stdout, "cone samples vs embree", &tally);
    cmp_tally_print_bad(stderr, "cone samples vs embree", &tally);
    CHECK(cmp_tally_unexplained(&tally) == 0, "embree disagreements");
    CHECK(caps_check(stdout, g_caps, "cone samples vs embree", &tally) == 0,
          "explained classes within their caps");
    CHECK(tally.hits > 0 && tally.hits < tally.rays, "mixed shadow");
    if (o)
        oracle_free(o);
    kdr_scene_free(s);
    free(b.v);
}

/* Split planes (axis, position) of interior nodes spread over the node
 * array: the root's big planes and deep ones between small cells. */
static size_t tree_splits(const kdr_scene *s, int *axis, float *pos, size_t max) {
    size_t n = 0;
    const size_t step = s->nnodes / (2 * max) + 1;
    for (size_t j = 0; j < s->nnodes && n < max; j += step) {
        while (j < s->nnodes && kd_is_leaf(&s->nodes[j]))
            j++;
        if (j < s->nnodes) {
            axis[n] = kd_axis(&s->nodes[j]);
            pos[n++] = s->nodes[j].u.split;
        }
    }
    return n;
}

/* Cones placed on the tree's own split planes: apex on a plane, axis
 * parallel to it or along a coordinate axis, tiny and near-90-degree
 * half-angles, light straddling the plane. */
static void test_adversarial(void) {
    rng_state = 999;
    tri_buf b = {0};
    tb_soup(&b, 2500, 8.0f, 0.35f);
    for (int k = 1; k < 8; k += 3) /* triangles lying in likely split planes */
        tb_rect(&b, k % 3, (float)k, 2.0f, 2.5f, 3.0f, 3.75f);
    kdr_scene *s = build(&b);
    int axis[10];
    float pos[10];
    const size_t ns = tree_splits(s, axis, pos, 10);
    CHECK(ns > 4, "tree has splits");
    enum { NP = 16 };
    for (size_t c = 0; c < ns; c++) {
        const int k = axis[c], i1 = (k + 1) % 3, i2 = (k + 2) % 3;
        float pts[3 * NP];
        kdr_sphere_light lights[5];
        for (int i = 0; i < NP; i++) {
            pts[3 * i + k] = pos[c];
            pts[3 * i + i1] = (float)(rnd() * 8.0);
            pts[3 * i + i2] = (float)(rnd() * 8.0);
        }
        /* 0: in the plane (axis parallel to it), tiny cone; 1: in the plane,
         * close and wide; 2: straddling, axis along k; 3: near 90 degrees;
         * 4: tiny and far along axis i1 */
        float cen[5][3];
        const float rad[5] = {1e-4f, 2.0f, 1.5f, 0.0f, 2e-3f};
        for (int j = 0; j < 5; j++) {
            cen[j][k] = pos[c];
            cen[j][i1] = 4.0f;
            cen[j][i2] = 4.0f;
        }
        cen[1][i1] = 9.0f;
        cen[2][k] = pos[c] + 6.0f;
        cen[4][i1] = 40.0f;
        cen[4][k] = pos[c] + 0.01f;
        for (int j = 0; j < 5; j++) {
            for (int m = 0; m < 3; m++)
                lights[j].center[m] = cen[j][m];
            lights[j].radius = rad[j];
        }
        /* light 3 sits just beyond point 0 */
        lights[3].radius = 1.0f;
        for (int m = 0; m < 3; m++)
            lights[3].center[m] = pts[m] + (m == i1 ? 1.002f : 0.0f);
        for (int i = 0; i < NP; i++) { /* keep points out of the lights */
            for (int l = 0; l < 5; l++) {
                double d2 = 0;
                for (int m = 0; m < 3; m++)
                    d2 += (pts[3 * i + m] - lights[l].center[m]) *
                          (pts[3 * i + m] - lights[l].center[m]);
                if (d2 <= 1.01 * lights[l].radius * lights[l].radius)
                    pts[3 * i + i1] = -3.0f - (float)i;
            }
        }
        char label[64];
        /* 32 spp walks; 4 and 16 take the cheap test's any-hit bundles */
        const uint32_t spp[3] = {32, 4, 16};
        for (int j = 0; j < 3; j++) {
            kdr_shadow_query q = make_query(pts, NP, lights, 5, spp[j]);
            snprintf(label, sizeof label, "split %zu axis %d at %g, %u spp", c, k,
                     pos[c], spp[j]);
            check_modes(label, s, &b, &q);
        }
    }
    kdr_scene_free(s);
    free(b.v);
}

/* The SIMD packet tests (4- and 8-wide, whatever the CPU the suite runs
 * on would pick) against the scalar triangle test, lane by lane. */
static void test_packets(void) {
    rng_state = 4242;
    tri_buf b = {0};
    tb_soup(&b, 600, 4.0f, 0.8f);
    kdr_scene *s = build(&b);
    const float pts[3] = {2.0f, 2.0f, -1.0f};
    const kdr_sphere_light li = {{2.0f, 2.0f, 7.0f}, 1.5f};
    kdr_shadow_query q = make_query(pts, 1, &li, 1, 8);
    kd_shadow_frame f;
    CHECK(kd_shadow_frame_init(s, &q, 0, 0, &f) == KDR_OK, "frame");
    uint32_t cands[600];
    for (uint32_t j = 0; j < 600; j++)
        cands[j] = j;
    const int widths = kdr_cpu_has_avx2() ? 2 : 1;
    int lanes_total = 0, lanes_blocked = 0;
    for (uint32_t round = 0; round < 64; round++) {
        kdr_ray rays[8];
        const kdr_ray *lanes[8];
        int want = 0;
        const int n = 1 + (int)(round % 8);
        for (int j = 0; j < n; j++) {
            kd_shadow_frame_ray(&f, (round * 8 + (uint32_t)j) % 512, 512, &rays[j]);
            lanes[j] = &rays[j];
            kd_ray_pre pre;
            kd_ray_precompute(rays[j].org, rays[j].dir, &pre);
            for (uint32_t c = 0; c < 600; c++) {
                float t, u, v;
                if (kd_tri_intersect(&pre, b.v + 9 * c, rays[j].tmin, rays[j].tmax,
                                     &t, &u, &v)) {
                    want |= 1 << j;
                    break;
                }
            }
        }
        lanes_total += n;
        for (int j = 0; j < n; j++)
            lanes_blocked += (want >> j) & 1;
        for (int w = 0; w < widths; w++) {
            uint32_t blocker = UINT32_MAX;
            CHECK(kd_cone_packet_blocked(s, lanes, n, cands, 600, &blocker, w) == want,
                  "packet list width %d round %u", w ? 8 : 4, round);
            if (n > (w ? 8 : 4)) /* a 4-wide walk takes at most 4 lanes */
                continue;
            kd_cone c;
            int open = 0;
            uint64_t visited = 0;
            kd_cone_init(&c, s, &f, NULL, 0.0);
            const int got = kd_cone_packet_walk(s, &c, lanes, n, UINT64_MAX, &blocker,
                                                &visited, &open, w);
            CHECK(got == want && open == 0, "packet walk width %d round %u: %x vs %x",
                  w ? 8 : 4, round, got, want);
        }
    }
    CHECK(lanes_blocked > lanes_total / 8 && lanes_blocked < lanes_total - lanes_total / 8,
          "packet test needs both outcomes: %d of %d blocked", lanes_blocked, lanes_total);
    kdr_scene_free(s);
    free(b.v);
}

/* ---- proofs about one triangle (kd_cone_proof.c) ------------------------- */

static double rnd_log(double lo, double hi) { return lo * pow(hi / lo, rnd()); }

static void unit_basis(const double a[3], double b1[3], double b2[3]) {
    const double t[3] = {fabs(a[0]) < 0.6 ? 1.0 : 0.0, fabs(a[0]) < 0.6 ? 0.0 : 1.0, 0.0};
    b1[0] = a[1] * t[2] - a[2] * t[1];
    b1[1] = a[2] * t[0] - a[0] * t[2];
    b1[2] = a[0] * t[1] - a[1] * t[0];
    const double l = sqrt(b1[0] * b1[0] + b1[1] * b1[1] + b1[2] * b1[2]);
    for (int k = 0; k < 3; k++)
        b1[k] /= l;
    b2[0] = a[1] * b1[2] - a[2] * b1[1];
    b2[1] = a[2] * b1[0] - a[0] * b1[2];
    b2[2] = a[0] * b1[1] - a[1] * b1[0];
}

static void rnd_unit(double d[3]) {
    double l;
    do {
        for (int k = 0; k < 3; k++)
            d[k] = 2.0 * rnd() - 1.0;
        l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    } while (l < 0.1 || l > 1.0);
    for (int k = 0; k < 3; k++)
        d[k] /= l;
}

/* A float direction within angle b of axis (on the rim half the time). */
static void rnd_in_cone(const double a[3], double b, float d[3]) {
    double b1[3], b2[3], v[3];
    unit_basis(a, b1, b2);
    const double th = rnd() < 0.5 ? b : b * sqrt(rnd()), ph = 6.283185307179586 * rnd();
    for (int k = 0; k < 3; k++)
        v[k] = cos(th) * a[k] + sin(th) * (cos(ph) * b1[k] + sin(ph) * b2[k]);
    const double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; k++)
        d[k] = (float)(v[k] / l);
}

/* Random triangles and cones aimed at the proofs' edges: a point's own
 * surface with the apex 1 to 1e4 ulps of the triangle's size above it
 * (acne territory) and cones leaving it at any angle, and triangles across
 * the cone near its rim, near tmax and at grazing angles; every verdict
 * other than UNKNOWN is checked with float rays through the cone (half of
 * them on its rim) against kd_tri_intersect. */
static void test_proofs(void) {
    rng_state = 2024;
    long verdicts[3] = {0, 0, 0}, rays = 0, wrong = 0;
    for (int trial = 0; trial < 40000 && wrong < 5; trial++) {
        const double L = rnd_log(1e-2, 1e5);
        float apex[3], tri[9];
        double axis[3], nrm[3], b1[3], b2[3];
        for (int k = 0; k < 3; k++)
            apex[k] = (float)((2.0 * rnd() - 1.0) * L);
        const int own = trial % 2 == 0;
        if (rnd() < 0.3) { /* an axis-aligned plane */
            nrm[0] = nrm[1] = nrm[2] = 0.0;
            nrm[trial % 3] = rnd() < 0.5 ? 1.0 : -1.0;
        } else {
            rnd_unit(nrm);
        }
        unit_basis(nrm, b1, b2);
        const double M = own ? L * rnd_log(1e-3, 10.0) : L * rnd_log(1e-3, 1.0);
        double tmax_lo;
        if (own) { /* a plane just below the apex, the apex over the triangle */
            const double h = M * 0x1p-24 * rnd_log(1.0, 1e4);
            const double ph = 6.283185307179586 * rnd();
            for (int i = 0; i < 3; i++) {
                const double an = ph + 2.0944 * i + 0.5 * (rnd() - 0.5);
                const double r = M * (0.3 + rnd());
                for (int k = 0; k < 3; k++)
                    tri[3 * i + k] = (float)(apex[k] - h * nrm[k] +
                                             r * (cos(an) * b1[k] + sin(an) * b2[k]));
            }
            for (int k = 0; k < 3; k++) /* mostly leaving the plane */
                axis[k] = nrm[k] * (rnd() * 1.3 - 0.3) + (rnd() - 0.5);
            tmax_lo = L * rnd_log(1e-3, 10.0);
        } else { /* a triangle ahead, the cone through it, near it or grazing */
            double c[3], dir[3];
            rnd_unit(dir);
            const double dist = M * rnd_log(0.5, 100.0);
            for (int k = 0; k < 3; k++)
                c[k] = apex[k] + dist * dir[k];
            for (int i = 0; i < 3; i++) {
                const double an = 2.0944 * i + 0.7 * (rnd() - 0.5);
                const double r = M * (0.3 + rnd());
                for (int k = 0; k < 3; k++)
                    tri[3 * i + k] =
                        (float)(c[k] + r * (cos(an) * b1[k] + sin(an) * b2[k]));
            }
            const double off = M / dist * (rnd() * 1.5);
            double e1[3], e2[3];
            unit_basis(dir, e1, e2);
            for (int k = 0; k < 3; k++)
                axis[k] = dir[k] + off * (rnd() < 0.5 ? e1[k] : e2[k]);
            tmax_lo = dist * rnd_log(0.7, 3.0);
        }
        const double al = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
        if (!(al > 1e-6))
            continue;
        for (int k = 0; k < 3; k++)
            axis[k] /= al;
        double bgeo = rnd_log(1e-6, 0.8);
        kd_tri_view v;
        kd_dir_cone dc;
        kd_tri_view_init(&v, tri, 0, apex);
        /* a quarter of the triangles ahead: a cone touching one edge's plane
         * from either side, its tangent ray among the rays fired */
        double touch[3] = {0, 0, 0};
        if (!own && trial % 4 == 1) {
            const int e = (int)(rnd() * 3) % 3, j = (e + 1) % 3;
            double m[3], ml = 0.0, side = rnd() < 0.5 ? 1.0 : -1.0;
            for (int k = 0; k < 3; k++) { /* a point of the edge, seen from the apex */
                const double f = 0.1 + 0.8 * rnd();
                m[k] = (1 - f) * tri[3 * j + k] + f * tri[3 * ((j + 1) % 3) + k] - apex[k];
                ml += m[k] * m[k];
            }
            ml = sqrt(ml);
            bgeo = rnd_log(1e-6, 0.3);
            for (int k = 0; k < 3; k++) {
                touch[k] = m[k] / ml;
                axis[k] = cos(bgeo) * touch[k] + side * sin(bgeo) * v.edge[e][k];
            }
        }
        const double b = bgeo + 2e-7; /* the test's float directions: 1e-7 */
        kd_dir_cone_set(&dc, axis, cos(b), sin(b), tmax_lo);
        const kd_verdict vd = kd_tri_view_classify(&v, &dc);
        verdicts[vd]++;
        if (vd == KD_TRI_UNKNOWN)
            continue;
        float tmax = (float)tmax_lo;
        if ((double)tmax > tmax_lo)
            tmax = nextafterf(tmax, 0.0f);
        for (int r = 0; r < 100; r++) {
            float d[3], t = -1.0f, u, w;
            kd_ray_pre pre;
            rnd_in_cone(axis, bgeo, d);
            if (touch[0] != 0 || touch[1] != 0 || touch[2] != 0) {
                if (r < 8) /* the tangent direction and float neighbours */
                    for (int k = 0; k < 3; k++)
                        d[k] = (float)touch[k];
                if (r > 0 && r < 8)
                    d[r % 3] = nextafterf(d[r % 3], r < 4 ? INFINITY : -INFINITY);
            }
            kd_ray_precompute(apex, d, &pre);
            const int hit = kd_tri_intersect(&pre, tri, 0.0f,
                                             vd == KD_TRI_COVERS ? tmax : INFINITY, &t, &u, &w);
            rays++;
            if (hit != (vd == KD_TRI_COVERS)) {
                wrong++;
                CHECK(0, "trial %d: verdict %d but ray (%.9g %.9g %.9g) %s (t %g, tmax_lo %g)",
                      trial, (int)vd, d[0], d[1], d[2], hit ? "hits" : "misses", t,
                      tmax_lo);
                break;
            }
        }
    }
    printf("proofs: %ld unknown, %ld misses, %ld covers; %ld rays checked\n", verdicts[0],
           verdicts[1], verdicts[2], rays);
    CHECK(verdicts[1] > 5000 && verdicts[2] > 1000 && verdicts[0] > 1000,
          "the trials must reach every verdict");
}

/* Any split of the point range gives the same visibilities (the per-light
 * state carried between points only changes the path, never the answer). */
static void test_ranges(void) {
    rng_state = 77;
    tri_buf b = {0};
    tb_soup(&b, 1500, 10.0f, 0.8f);
    kdr_scene *s = build(&b);
    enum { NP = 40 };
    float pts[3 * NP];
    for (int i = 0; i < NP; i++) {
        pts[3 * i] = (float)(rnd() * 10.0);
        pts[3 * i + 1] = (float)(rnd() * 10.0);
        pts[3 * i + 2] = -0.5f;
    }
    const kdr_sphere_light lights[3] = {
        {{5, 5, 14}, 0.4f}, {{5, 5, 13}, 3.0f}, {{-4, 5, 5}, 1.0f}};
    kdr_shadow_query q = make_query(pts, NP, lights, 3, 40);
    float whole[3 * NP], parts[3 * NP];
    kdr_shadow_trace(s, &q, 0, NP, KDR_SHADOW_CONE, whole, NULL);
    for (size_t first = 0; first < NP; first += 7)
        kdr_shadow_trace(s, &q, first, first + 7 <= NP ? 7 : NP - first,
                         KDR_SHADOW_CONE, parts, NULL);
    CHECK(memcmp(whole, parts, sizeof whole) == 0, "ranges differ");
    check_modes("soup, three lights", s, &b, &q);
    kdr_scene_free(s);
    free(b.v);
}

int main(int argc, char **argv) {
    g_caps = caps_arg(&argc, argv);
    if (argc > 1) {
        fprintf(stderr, "usage: %s [--caps NAME]\n", argv[0]);
        return 2;
    }
    test_invalid();
    test_ray_definition();
    test_analytic();
    test_normals();
    test_offsets();
    test_soup_vs_embree();
    test_adversarial();
    test_packets();
    test_proofs();
    test_ranges();
    if (failures) {
        fprintf(stderr, "test_cone: %d failures\n", failures);
        return 1;
    }
    printf("test_cone: all passed\n");
    return 0;
}
