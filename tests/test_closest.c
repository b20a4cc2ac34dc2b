/*
 * test_closest.c — closest points (kdr_closest_point1, _batch) and the
 * point-triangle distance they rest on.
 *
 *  - kdr_point_triangle against an independent reference in double (the
 *    projection onto the plane when it falls inside, else the nearest of
 *    the three edge segments), on random, sliver and needle triangles:
 *    squared distances agree within 1e-12 of the squared scale, and the
 *    returned point lies on the triangle at that distance;
 *  - the kd search against brute force (every non-degenerate triangle,
 *    the same distance, smaller prim on ties): identical answers bit for
 *    bit, on the stress corpus and the default scene, for points on the
 *    surfaces, near them (offsets 1e-7 .. 1e-1 of the diagonal), inside
 *    the closed meshes and far outside; with max_distance too;
 *  - against Embree's rtcPointQuery with a closest-triangle callback:
 *    the same distance bit for bit, the same prim unless a tie;
 *  - a tessellated sphere queried at and near its centre, where every
 *    triangle is about equally far: the search visits most of the tree and
 *    holds far more pending cells than its nearest-first limit
 *    (CP_NEAREST_MAX in kd_closest.c), so its depth-first fallback runs;
 *    answers against brute force as above.
 * Exit 1 on any failure.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_traverse.h"
#include "kdray.h"
#include "oracle.h"
#include "stress.h"
#define CHECK_PRINT_MAX 10
#include "check.h"
#ifdef KDRAY_HAVE_GLTF
#include "kdr_gltf.h"
#endif

#define SEED 20261201u

/* Squared distance from p to segment [a, b]. */
static double seg_d2(const double p[3], const double a[3], const double b[3]) {
    double ab[3], ap[3], l2 = 0, t = 0;
    for (int k = 0; k < 3; k++) {
        ab[k] = b[k] - a[k];
        ap[k] = p[k] - a[k];
        l2 += ab[k] * ab[k];
        t += ap[k] * ab[k];
    }
    t = l2 > 0 ? fmin(1.0, fmax(0.0, t / l2)) : 0.0;
    double d2 = 0;
    for (int k = 0; k < 3; k++) {
        const double e = ap[k] - t * ab[k];
        d2 += e * e;
    }
    return d2;
}

/* The reference: plane projection if inside, else the nearest edge. */
static double ref_d2(const float pf[3], const float *tri) {
    double p[3], a[3], b[3], c[3], n[3], e1[3], e2[3];
    for (int k = 0; k < 3; k++) {
        p[k] = pf[k];
        a[k] = tri[k];
        b[k] = tri[3 + k];
        c[k] = tri[6 + k];
        e1[k] = b[k] - a[k];
        e2[k] = c[k] - a[k];
    }
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    const double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    double best = fmin(seg_d2(p, a, b), fmin(seg_d2(p, b, c), seg_d2(p, c, a)));
    if (nn > 0) {
        const double s =
            ((p[0] - a[0]) * n[0] + (p[1] - a[1]) * n[1] + (p[2] - a[2]) * n[2]) / nn;
        double q[3];
        for (int k = 0; k < 3; k++)
            q[k] = p[k] - s * n[k];
        /* inside: the three edge normals' signs agree */
        int pos = 0, neg = 0;
        const double *v[3] = {a, b, c};
        for (int i = 0; i < 3; i++) {
            const double *u0 = v[i], *u1 = v[(i + 1) % 3];
            double ed[3], qd[3];
            for (int k = 0; k < 3; k++) {
                ed[k] = u1[k] - u0[k];
                qd[k] = q[k] - u0[k];
            }
            const double cr = (ed[1] * qd[2] - ed[2] * qd[1]) * n[0] +
                              (ed[2] * qd[0] - ed[0] * qd[2]) * n[1] +
                              (ed[0] * qd[1] - ed[1] * qd[0]) * n[2];
            pos += cr >= 0;
            neg += cr <= 0;
        }
        if (pos == 3 || neg == 3) best = fmin(best, s * s * nn);
    }
    return best;
}

static double scale2(const float p[3], const float *tri) {
    double m = 0;
    for (int k = 0; k < 3; k++)
        m = fmax(m, fabs(p[k]));
    for (int k = 0; k < 9; k++)
        m = fmax(m, fabs(tri[k]));
    return m * m;
}

static void test_distance(void) {
    stress_rng r;
    stress_rng_seed(&r, SEED);
    for (int i = 0; i < 200000; i++) {
        float tri[9], p[3];
        const int kind = i % 4;
        for (int k = 0; k < 9; k++)
            tri[k] = stress_rng_float(&r) * 2 - 1;
        if (kind == 1) /* sliver: c near the line ab */
            for (int k = 0; k < 3; k++)
                tri[6 + k] =
                    tri[k] + (tri[3 + k] - tri[k]) * 0.37f + 1e-4f * stress_rng_float(&r);
        if (kind == 2) /* needle: b near a */
            for (int k = 0; k < 3; k++)
                tri[3 + k] = tri[k] + 1e-5f * stress_rng_float(&r);
        for (int k = 0; k < 3; k++)
            p[k] = (stress_rng_float(&r) * 2 - 1) * (kind == 3 ? 100.0f : 1.5f);
        if (kd_tri_degenerate(tri)) continue;
        double q[3], u, v, d2;
        kdr_point_triangle(p, tri, q, &u, &v, &d2);
        const double want = ref_d2(p, tri), tol = 1e-12 * scale2(p, tri);
        if (!(fabs(d2 - want) <= tol))
            FAIL("point_triangle %d: d2 %.17g, reference %.17g\n", i, d2, want);
        /* the point: on the triangle (barycentrics in [0,1]), at that distance */
        double e2 = 0;
        for (int k = 0; k < 3; k++) {
            const double x = (1 - u - v) * tri[k] + u * tri[3 + k] + v * tri[6 + k];
            e2 += (x - q[k]) * (x - q[k]);
        }
        if (!(u >= -1e-12 && v >= -1e-12 && u + v <= 1 + 1e-12 && e2 <= tol))
            FAIL("point_triangle %d: u %g v %g, point off by %g\n", i, u, v, sqrt(e2));
    }
}

static void brute(const float *tris, size_t ntris, const float p[3], float maxd,
                  kdr_closest *out) {
    double best = (double)maxd * maxd;
    out->prim = -1;
    for (size_t t = 0; t < ntris; t++) {
        const float *tri = tris + 9 * t;
        if (kd_tri_degenerate(tri)) continue;
        double q[3], u, v, d2;
        kdr_point_triangle(p, tri, q, &u, &v, &d2);
        if (d2 < best || (d2 == best && out->prim >= 0 && (int32_t)t < out->prim) ||
            (d2 == best && out->prim < 0)) {
            best = d2;
            out->prim = (int32_t)t;
            out->u = (float)u;
            out->v = (float)v;
            out->distance = (float)sqrt(d2);
            for (int k = 0; k < 3; k++)
                out->point[k] = (float)q[k];
        }
    }
}

static int same(const kdr_closest *a, const kdr_closest *b) {
    if (a->prim < 0 || b->prim < 0) return a->prim == b->prim;
    return a->prim == b->prim && a->distance == b->distance && a->u == b->u &&
           a->v == b->v && !memcmp(a->point, b->point, sizeof a->point);
}

/* Query points: on triangles, just off them along random directions at
 * several scales, random points in and far around the box. */
static size_t make_points(const float *tris, size_t ntris, const kdr_bounds *bb, size_t n,
                          float *pts) {
    stress_rng r;
    stress_rng_seed(&r, SEED + ntris);
    float diag = 0;
    for (int k = 0; k < 3; k++)
        diag += (bb->max[k] - bb->min[k]) * (bb->max[k] - bb->min[k]);
    diag = sqrtf(diag);
    static const float offs[] = {0.0f, 1e-7f, 1e-5f, 1e-3f, 1e-1f};
    for (size_t i = 0; i < n; i++) {
        float *p = pts + 3 * i;
        if (i % 4 == 3) { /* box and 3x around it */
            const float f = i % 8 == 3 ? 1.0f : 3.0f;
            for (int k = 0; k < 3; k++) {
                const float c = 0.5f * (bb->min[k] + bb->max[k]),
                            h = 0.5f * (bb->max[k] - bb->min[k]);
                p[k] = c + f * h * (stress_rng_float(&r) * 2 - 1);
            }
            continue;
        }
        const float *tri = tris + 9 * (stress_rng_next(&r) % ntris);
        float a = stress_rng_float(&r), b = stress_rng_float(&r);
        if (a + b > 1) {
            a = 1 - a;
            b = 1 - b;
        }
        float d[3];
        stress_rng_dir(&r, d);
        const float off = offs[i % 5] * diag;
        for (int k = 0; k < 3; k++)
            p[k] = (1 - a - b) * tri[k] + a * tri[3 + k] + b * tri[6 + k] + off * d[k];
    }
    return n;
}

static void run(const char *label, const float *tris, size_t ntris, size_t npts,
                const float *extra, size_t nextra) {
    kdr_scene *sc = NULL;
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &sc) != KDR_OK) {
        FAIL("%s: build failed\n", label);
        return;
    }
    oracle *o = oracle_create(tris, ntris, NULL);
    kdr_bounds bb;
    kdr_scene_bounds(sc, &bb);
    float *pts = malloc(3 * (npts + nextra) * sizeof *pts);
    make_points(tris, ntris, &bb, npts, pts);
    if (nextra) /* memcpy from NULL is undefined even for 0 bytes */
        memcpy(pts + 3 * npts, extra, 3 * nextra * sizeof *pts);
    const size_t n = npts + nextra;
    kdr_closest *batch = malloc(n * sizeof *batch);
    unsigned long bad = 0, ties = 0, limited = 0;
    kdr_trav_stats st = {0};
    if (kdr_closest_point_batch(sc, pts, 0, n, INFINITY, batch, &st) != KDR_OK)
        FAIL("%s: batch failed\n", label);
    for (size_t i = 0; i < n; i++) {
        const float *p = pts + 3 * i;
        kdr_closest kd, bf, em;
        kdr_closest_point1(sc, p, INFINITY, &kd, NULL);
        brute(tris, ntris, p, INFINITY, &bf);
        if (!same(&kd, &bf) || !same(&kd, &batch[i])) {
            bad++;
            FAIL("%s: point %zu (%a %a %a): kd prim %d d %a, brute prim %d d %a\n", label,
                 i, p[0], p[1], p[2], kd.prim, kd.distance, bf.prim, bf.distance);
        }
        oracle_closest_point(o, tris, p, INFINITY, &em);
        if (em.distance != kd.distance) {
            bad++;
            FAIL("%s: point %zu: Embree distance %a, kd %a\n", label, i, em.distance,
                 kd.distance);
        } else if (em.prim != kd.prim) {
            ties++;
        }
        /* a limit just below / at the distance */
        if (kd.prim >= 0 && kd.distance > 0) {
            kdr_closest lim;
            const float below = nextafterf(kd.distance, 0.0f) * 0.999f;
            kdr_closest_point1(sc, p, below, &lim, NULL);
            brute(tris, ntris, p, below, &bf);
            if (!same(&lim, &bf)) {
                bad++;
                FAIL("%s: point %zu: max_distance %a: kd prim %d, brute prim %d\n", label,
                     i, below, lim.prim, bf.prim);
            }
            limited += lim.prim < 0;
        }
    }
    printf("%-14s points %6zu  kd == brute force bit for bit: %s, Embree ties %lu, "
           "nodes/point %.1f, tests/point %.1f, none within a limit %lu\n",
           label, n, bad ? "NO" : "yes", ties, (double)st.nodes_visited / (double)n,
           (double)st.tri_tests / (double)n, limited);
    free(pts);
    free(batch);
    oracle_free(o);
    kdr_scene_free(sc);
}

/* A UV sphere of radius 1 around c with nlat x nlon quads (two triangles
 * each), queried at c and at points a little off it. */
static void sphere_centre(void) {
    const int nlat = 60, nlon = 120;
    const double pi = 3.14159265358979323846;
    const float c[3] = {0.25f, -0.5f, 2.0f};
    const size_t ntris = (size_t)2 * nlat * nlon;
    float *tris = malloc(9 * ntris * sizeof *tris);
    size_t t = 0;
    for (int i = 0; i < nlat; i++)
        for (int j = 0; j < nlon; j++) {
            float v[4][3];
            for (int k = 0; k < 4; k++) {
                const double th = pi * (i + (k >> 1)) / nlat,
                             ph = 2 * pi * (j + (k & 1)) / nlon;
                v[k][0] = c[0] + (float)(sin(th) * cos(ph));
                v[k][1] = c[1] + (float)(sin(th) * sin(ph));
                v[k][2] = c[2] + (float)cos(th);
            }
            static const int q[2][3] = {{0, 2, 1}, {1, 2, 3}};
            for (int h = 0; h < 2; h++, t++)
                for (int k = 0; k < 3; k++)
                    memcpy(tris + 9 * t + 3 * k, v[q[h][k]], sizeof v[0]);
        }
    kdr_scene *sc = NULL;
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &sc) != KDR_OK) {
        FAIL("sphere: build failed\n");
        free(tris);
        return;
    }
    static const float off[][3] = {{0, 0, 0}, {1e-3f, 0, 0}, {0, -2e-2f, 1e-2f},
                                   {0.1f, 0.1f, -0.1f}};
    kdr_trav_stats st = {0};
    for (size_t i = 0; i < sizeof off / sizeof *off; i++) {
        const float p[3] = {c[0] + off[i][0], c[1] + off[i][1], c[2] + off[i][2]};
        kdr_closest kd, bf;
        kdr_closest_point1(sc, p, INFINITY, &kd, i == 0 ? &st : NULL);
        brute(tris, ntris, p, INFINITY, &bf);
        if (!same(&kd, &bf))
            FAIL("sphere: point %zu: kd prim %d d %a, brute prim %d d %a\n", i, kd.prim,
                 kd.distance, bf.prim, bf.distance);
    }
    /* at the centre the search must visit well over the nearest-first
     * limit of pending cells (64), or this case tests nothing */
    if (st.nodes_visited < 1000)
        FAIL("sphere: only %llu nodes visited from the centre\n",
             (unsigned long long)st.nodes_visited);
    printf("sphere centre  %zu triangles, nodes visited from the centre %llu\n", ntris,
           (unsigned long long)st.nodes_visited);
    kdr_scene_free(sc);
    free(tris);
}

static void api(void) {
    const float tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    kdr_scene *sc = NULL;
    kdr_scene_build(tri, 1, NULL, NULL, NULL, &sc);
    kdr_closest c;
    const float p[3] = {0.25f, 0.25f, 2.0f}, nanp[3] = {NAN, 0, 0};
    if (kdr_closest_point1(sc, p, INFINITY, &c, NULL) != KDR_OK || c.prim != 0 ||
        c.distance != 2.0f || c.u != 0.25f || c.v != 0.25f || c.point[2] != 0.0f)
        FAIL("api: plain case\n");
    if (kdr_closest_point1(sc, p, 2.0f, &c, NULL) != KDR_OK || c.prim != 0)
        FAIL("api: a triangle at exactly max_distance counts\n");
    if (kdr_closest_point1(sc, p, 1.5f, &c, NULL) != KDR_OK || c.prim != -1 ||
        c.distance != -1.0f)
        FAIL("api: nothing within max_distance\n");
    if (kdr_closest_point1(sc, nanp, INFINITY, &c, NULL) != KDR_EINVAL ||
        kdr_closest_point1(sc, p, -1.0f, &c, NULL) != KDR_EINVAL ||
        kdr_closest_point1(NULL, p, 1.0f, &c, NULL) != KDR_EINVAL)
        FAIL("api: invalid arguments\n");
    kdr_scene_free(sc);
}

int main(int argc, char **argv) {
    const size_t npts = argc > 1 ? (size_t)atol(argv[1]) : 2000;
    api();
    test_distance();
    sphere_centre();
    for (int k = 0; k < STRESS_NSCENES; k++) {
        stress_scene s;
        if (stress_scene_make((stress_scene_kind)k, SEED, &s) != 0) return 1;
        float *inside = malloc(3 * (s.nclosed + 1) * sizeof *inside);
        for (size_t c = 0; c < s.nclosed; c++)
            memcpy(inside + 3 * c, s.closed[c].inside, 3 * sizeof(float));
        run(stress_scene_name((stress_scene_kind)k), s.tris, s.ntris, npts, inside,
            s.nclosed);
        free(inside);
        stress_scene_free(&s);
    }
#ifdef KDRAY_HAVE_GLTF
    if (argc > 2) {
        kdr_gltf_scene g;
        char err[256];
        if (kdr_gltf_load(argv[2], &g, err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            return 1;
        }
        run("gltf", g.tris, g.ntris, npts, NULL, 0);
        kdr_gltf_free(&g);
    }
#endif
    if (failures) {
        printf("FAIL: %d failures\n", failures);
        return 1;
    }
    printf("ok\n");
    return 0;
}
