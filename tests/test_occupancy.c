/*
 * test_occupancy.c — inside/outside by voting (kdr_occupancy1, _batch)
 * against the generalized winding number in double precision.
 *
 * Ground truth: the winding number W(p) = sum over triangles of the signed
 * solid angle (Van Oosterom and Strackee) / 4 pi, in double; for closed
 * meshes it is an integer away from the surface, and W mod 2 is the
 * parity occupancy answers (a point inside k closed meshes has W = +-1 per
 * mesh). A scene is judged only if W is within 1e-3 of an integer at every
 * sample point outside the band (it is closed); the stress scenes with
 * closed meshes must pass that check.
 *
 * Points: on random surface points moved 1.5e-4 .. 1e-1 of the diagonal in
 * random directions; vertices and edge midpoints moved back along one of
 * the vote's directions (so that ray passes exactly through a shared vertex
 * or edge: one ray alone is then often wrong); the closed regions' inside
 * points; uniform in 1.3x the box. A point farther than 1e-4 x diagonal from every
 * triangle (its distance from kdr_closest_point1) must get the right answer: 0 wrong
 * answers allowed. Points within the band are counted and reported, not
 * judged. The single-ray parity (the first direction alone) is reported
 * too, to show what voting buys.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_traverse.h"
#include "kdray.h"
#include "stress.h"
#include "check.h"
#ifdef KDRAY_HAVE_GLTF
#include "kdr_gltf.h"
#endif

#define SEED 20261201u
#define BAND 1e-4

/* Signed solid angle of triangle (a, b, c) seen from p. */
static double solid_angle(const float p[3], const float *t) {
    double a[3], b[3], c[3];
    for (int k = 0; k < 3; k++) {
        a[k] = (double)t[k] - p[k];
        b[k] = (double)t[3 + k] - p[k];
        c[k] = (double)t[6 + k] - p[k];
    }
    const double la = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    const double lb = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    const double lc = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    const double det = a[0] * (b[1] * c[2] - b[2] * c[1]) -
                       a[1] * (b[0] * c[2] - b[2] * c[0]) +
                       a[2] * (b[0] * c[1] - b[1] * c[0]);
    const double ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const double bc = b[0] * c[0] + b[1] * c[1] + b[2] * c[2];
    const double ca = c[0] * a[0] + c[1] * a[1] + c[2] * a[2];
    const double den = la * lb * lc + ab * lc + bc * la + ca * lb;
    return 2.0 * atan2(det, den);
}

static double winding(const float *tris, size_t ntris, const float p[3]) {
    double w = 0.0;
    for (size_t i = 0; i < ntris; i++)
        if (!kd_tri_degenerate(tris + 9 * i)) w += solid_angle(p, tris + 9 * i);
    return w / (4.0 * 3.14159265358979323846);
}

typedef struct occ_tally {
    unsigned long judged, wrong, single_wrong, band, band_agree, open_points;
} occ_tally;

/* must_be_closed: fail unless W is integral at every judged point. */
static void run(const char *label, const float *tris, size_t ntris, const float *extra,
                size_t nextra, size_t npts, int must_be_closed) {
    kdr_scene *sc = NULL;
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &sc) != KDR_OK) {
        failures++;
        return;
    }
    kdr_bounds bb;
    kdr_scene_bounds(sc, &bb);
    const double diag = kdr_scene_diagonal(sc);
    stress_rng r;
    stress_rng_seed(&r, SEED + ntris);
    const size_t n = npts + nextra;
    float *pts = malloc(3 * n * sizeof *pts);
    static const double offs[] = {1.5e-4, 1e-3, 1e-2, 1e-1};
    for (size_t i = 0; i < npts; i++) {
        float *p = pts + 3 * i;
        if (i % 3 == 2) {
            for (int k = 0; k < 3; k++) {
                const float c = 0.5f * (bb.min[k] + bb.max[k]),
                            h = 0.5f * (bb.max[k] - bb.min[k]);
                p[k] = c + 1.3f * h * (stress_rng_float(&r) * 2 - 1);
            }
            continue;
        }
        const float *t = tris + 9 * (stress_rng_next(&r) % ntris);
        float a = stress_rng_float(&r), b = stress_rng_float(&r), d[3];
        if (a + b > 1) a = 1 - a, b = 1 - b;
        stress_rng_dir(&r, d);
        if (i % 3 ==
            1) { /* one vote's ray aimed exactly at a vertex or an edge midpoint */
            const int v = (int)(stress_rng_next(&r) % 6);
            a = v == 1 ? 1.0f : v == 3 || v == 4 ? 0.5f : 0.0f;
            b = v == 2 ? 1.0f : v == 4 || v == 5 ? 0.5f : 0.0f;
            kdr_occupancy_direction((int)(stress_rng_next(&r) % KDR_OCCUPANCY_RAYS), d);
            for (int k = 0; k < 3; k++)
                d[k] = -d[k];
        }
        const double off = offs[i % 4] * diag;
        for (int k = 0; k < 3; k++)
            p[k] = (float)((1 - a - b) * t[k] + a * t[3 + k] + b * t[6 + k] + off * d[k]);
    }
    if (nextra) /* memcpy from NULL is undefined even for 0 bytes */
        memcpy(pts + 3 * npts, extra, 3 * nextra * sizeof *pts);
    uint8_t *batch = malloc(n);
    if (kdr_occupancy_batch(sc, pts, 0, n, batch, NULL) != KDR_OK) failures++;
    occ_tally t = {0};
    int printed = 0;
    for (size_t i = 0; i < n; i++) {
        const float *p = pts + 3 * i;
        kdr_closest c;
        kdr_closest_point1(sc, p, INFINITY, &c, NULL);
        const double w = winding(tris, ntris, p);
        const long wi = lround(w);
        const int truth = (int)(labs(wi) & 1);
        uint8_t in = 0, votes = 0;
        kdr_occupancy1(sc, p, &in, &votes, NULL);
        if (in != batch[i]) failures++;
        if (c.prim >= 0 && c.distance <= BAND * diag) {
            t.band++;
            t.band_agree += in == truth;
            continue;
        }
        if (fabs(w - (double)wi) > 1e-3) {
            t.open_points++;
            continue;
        }
        t.judged++;
        kdr_ray ray = {{p[0], p[1], p[2]}, {0, 0, 0}, 0.0f, INFINITY};
        kdr_occupancy_direction(0, ray.dir);
        uint32_t cnt = 0;
        kdr_count1(sc, &ray, &cnt, NULL);
        t.single_wrong += (int)(cnt & 1) != truth;
        if (in != truth) {
            t.wrong++;
            if (printed++ < 5)
                fprintf(
                    stderr,
                    "  %s: WRONG at %a %a %a: inside %d (votes %d of %d), winding %.6f, "
                    "distance %.3g diag\n",
                    label, p[0], p[1], p[2], in, votes, KDR_OCCUPANCY_RAYS, w,
                    c.distance / diag);
        }
    }
    const int closed = t.open_points == 0;
    printf("%-14s %s points %5zu judged %5lu wrong %lu (one ray alone: %lu) | in band "
           "%lu (agree %lu) | not integral W %lu\n",
           label, closed ? "closed" : "OPEN  ", n, t.judged, t.wrong, t.single_wrong,
           t.band, t.band_agree, t.open_points);
    if (t.wrong || (must_be_closed && !closed)) failures++;
    free(pts);
    free(batch);
    kdr_scene_free(sc);
}

int main(int argc, char **argv) {
    const size_t npts = argc > 1 ? (size_t)atol(argv[1]) : 1500;
    /* a unit cube, the documented rule at its simplest */
    {
        static const float v[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                      {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
        static const int f[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7},
                                     {0, 1, 5}, {0, 5, 4}, {2, 3, 7}, {2, 7, 6},
                                     {1, 2, 6}, {1, 6, 5}, {0, 4, 7}, {0, 7, 3}};
        float tris[12 * 9];
        for (int i = 0; i < 12; i++)
            for (int j = 0; j < 3; j++)
                memcpy(tris + 9 * i + 3 * j, v[f[i][j]], sizeof v[0]);
        kdr_scene *sc = NULL;
        kdr_scene_build(tris, 12, NULL, NULL, NULL, &sc);
        const float in[3] = {0.5f, 0.5f, 0.5f}, out[3] = {1.5f, 0.5f, 0.5f},
                    nanp[3] = {NAN, 0, 0};
        uint8_t a = 9, b = 9, votes = 0;
        if (kdr_occupancy1(sc, in, &a, &votes, NULL) != KDR_OK || a != 1 ||
            votes != KDR_OCCUPANCY_RAYS ||
            kdr_occupancy1(sc, out, &b, NULL, NULL) != KDR_OK || b != 0 ||
            kdr_occupancy1(sc, nanp, &a, NULL, NULL) != KDR_EINVAL) {
            fprintf(stderr, "cube: inside %d (votes %d), outside %d\n", a, votes, b);
            failures++;
        }
        kdr_scene_free(sc);
    }
    /* the split lattice is left out: its walls are single quads between
     * cells, not closed meshes (W is not an integer there, and a ray's
     * parity depends on its direction) */
    static const stress_scene_kind closed_kinds[] = {
        STRESS_SHARED_BOXES, STRESS_CLOSED_MESHES, STRESS_FAR_OFFSET};
    for (size_t k = 0; k < sizeof closed_kinds / sizeof closed_kinds[0]; k++) {
        stress_scene s;
        if (stress_scene_make(closed_kinds[k], SEED, &s) != 0) return 1;
        float *inside = malloc(3 * (s.nclosed + 1) * sizeof *inside);
        for (size_t c = 0; c < s.nclosed; c++)
            memcpy(inside + 3 * c, s.closed[c].inside, 3 * sizeof(float));
        run(stress_scene_name(closed_kinds[k]), s.tris, s.ntris, inside, s.nclosed, npts,
            1);
        free(inside);
        stress_scene_free(&s);
    }
#ifdef KDRAY_HAVE_GLTF
    for (int a = 2; a < argc; a++) { /* real models: judged where closed */
        kdr_gltf_scene g;
        char err[256];
        /* "closed:PATH": the model must be found closed (else a failure) */
        const int must = !strncmp(argv[a], "closed:", 7);
        const char *path = must ? argv[a] + 7 : argv[a];
        if (kdr_gltf_load(path, &g, err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            return 1;
        }
        const char *name = strrchr(path, '/');
        run(name ? name + 1 : path, g.tris, g.ntris, NULL, 0, npts, must);
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
