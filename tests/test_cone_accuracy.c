/*
 * test_cone_accuracy.c — cone-shadow visibility on a scene with far-flung
 * parts, against an independent reference (issue 12, item 4; API v1.1).
 *
 * The scene: small objects near the origin (a single-sided ground quad, a
 * single-sided wall, a closed box and a closed octahedron) and closed boxes
 * 1e5 away, so the bounding diagonal is about 3.5e5. Points lie exactly on
 * the surfaces, facing toward and away from two lights (one over the small
 * objects, one over a far box), with their normals AS GIVEN by the surface
 * they are on (outward for closed ones; both sides of the single-sided
 * ones).
 *
 * The reference is robust Embree at 4096 samples per (point, light) on rays
 * this file builds itself: the start is the point moved one float step off
 * its axis-aligned face along the given normal (exactly "just off the
 * surface"; for the octahedron's tilted faces 1e-6 of the point's size, in
 * double, rounded outward), directions stratified uniformly over the cone
 * of the light with this file's own generator, each ray ending on the
 * light's near side. kdray answers with kdr_shadow_trace at 256 samples,
 * the contract's default "auto" offset, both modes (which must agree bit for
 * bit). The gates: RMSE over all pairs <= 0.02; no pair off by more than 0.1
 * where the reference is exactly 0 or 1; and v1.1's meaning spelled out:
 * every point whose normal faces away from a light behind the single-sided
 * ground or wall gets exactly 0.
 *
 * The same gates applied to v1's starts (epsilon 1e-4 times the diagonal,
 * 35 units here, along normals turned toward each light) must fail: that
 * is checked too, so this test is known to catch the fault it was written
 * for.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdray.h"
#include "oracle.h"
#include "test_cone_util.h"

#define REF_SAMPLES 4096 /* 64 x 64 strata of (cos theta, phi) */
#define KD_SAMPLES 256
#define MAX_RMSE 0.02
#define MAX_OFF_EXACT 0.1
#define FAR 1e5f

/* ---- the scene ------------------------------------------------------------- */

static void add_tri(tri_buf *b, const float p[3], const float q[3], const float r[3]) {
    const float t[9] = {p[0], p[1], p[2], q[0], q[1], q[2], r[0], r[1], r[2]};
    tb_add(b, t);
}

/* Quad p0 p1 p2 p3 (counter-clockwise seen from its front). */
static void add_quad(tri_buf *b, const float p[4][3]) {
    add_tri(b, p[0], p[1], p[2]);
    add_tri(b, p[0], p[2], p[3]);
}

/* Closed box [lo, hi], faces wound outward: the face at hi[k] runs
 * counter-clockwise in the (k+1, k+2) plane (normal e_k+1 x e_k+2 = e_k),
 * the face at lo[k] the other way round. */
static void add_box(tri_buf *b, const float lo[3], const float hi[3]) {
    for (int k = 0; k < 3; k++) {
        const int i = (k + 1) % 3, j = (k + 2) % 3;
        const float u[4] = {lo[i], hi[i], hi[i], lo[i]};
        const float v[4] = {lo[j], lo[j], hi[j], hi[j]};
        for (int side = 0; side < 2; side++) {
            float p[4][3];
            for (int c = 0; c < 4; c++) {
                const int cc = side ? c : 3 - c;
                p[c][k] = side ? hi[k] : lo[k];
                p[c][i] = u[cc];
                p[c][j] = v[cc];
            }
            add_quad(b, (const float(*)[3])p);
        }
    }
}

/* Closed octahedron around c with radius r (8 faces, wound outward). */
static void add_octahedron(tri_buf *b, const float c[3], float r) {
    for (int sx = -1; sx <= 1; sx += 2)
        for (int sy = -1; sy <= 1; sy += 2)
            for (int sz = -1; sz <= 1; sz += 2) {
                const float a[3] = {c[0] + sx * r, c[1], c[2]};
                const float d[3] = {c[0], c[1] + sy * r, c[2]};
                const float e[3] = {c[0], c[1], c[2] + sz * r};
                if (sx * sy * sz > 0)
                    add_tri(b, a, d, e);
                else
                    add_tri(b, a, e, d);
            }
}

typedef struct point_set {
    float p[3 * 512], n[3 * 512];
    int tilted[512]; /* on a tilted face: the reference offsets in double */
    int backside[512]; /* single-sided surface, normal away from both lights */
    size_t count;
} point_set;

static void add_point(point_set *ps, float x, float y, float z, float nx, float ny,
                      float nz, int tilted, int backside) {
    const size_t i = ps->count++;
    ps->p[3 * i] = x, ps->p[3 * i + 1] = y, ps->p[3 * i + 2] = z;
    ps->n[3 * i] = nx, ps->n[3 * i + 1] = ny, ps->n[3 * i + 2] = nz;
    ps->tilted[i] = tilted;
    ps->backside[i] = backside;
}

static const float box_lo[3] = {-0.5f, 1.0f, -0.5f}, box_hi[3] = {0.5f, 2.0f, 0.5f};
static const float octa_c[3] = {-1.5f, 0.75f, 1.25f};
static const float octa_r = 0.5f;
static const float far_lo[3] = {FAR - 10, FAR - 10, FAR - 10};
static const float far_hi[3] = {FAR + 10, FAR + 10, FAR + 10};

static void build_scene(tri_buf *b, point_set *ps) {
    /* ground y = 0 over [-3, 3]^2, single-sided (front +y) */
    const float g[4][3] = {{-3, 0, -3}, {-3, 0, 3}, {3, 0, 3}, {3, 0, -3}};
    add_quad(b, g);
    /* wall x = 2, y in [0, 2], z in [-1, 1], single-sided (front -x) */
    const float w[4][3] = {{2, 0, -1}, {2, 0, 1}, {2, 2, 1}, {2, 2, -1}};
    add_quad(b, w);
    add_box(b, box_lo, box_hi);
    add_octahedron(b, octa_c, octa_r);
    add_box(b, far_lo, far_hi);
    const float f2lo[3] = {-1.35e5f, -10, -1.35e5f}, f2hi[3] = {-1.35e5f + 20, 10,
                                                                -1.35e5f + 20};
    add_box(b, f2lo, f2hi);

    /* the ground's top (toward both lights) and its underside (away) */
    for (int i = 0; i <= 12; i++)
        for (int j = 0; j <= 12; j++)
            add_point(ps, -2.5f + 0.4375f * i, 0.0f, -2.5f + 0.4375f * j, 0, 1, 0, 0, 0);
    for (int i = 0; i < 5; i++)
        for (int j = 0; j < 4; j++)
            add_point(ps, -2.0f + i, 0.0f, -1.5f + j, 0, -1, 0, 0, 1);
    /* the wall: its lit front (-x) and its back (+x, away from the light
     * over the origin, which lies at x < 2) */
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 3; j++) {
            add_point(ps, 2.0f, 0.25f + 0.5f * i, -0.75f + 0.75f * j, -1, 0, 0, 0, 0);
            add_point(ps, 2.0f, 0.25f + 0.5f * i, -0.75f + 0.75f * j, 1, 0, 0, 0, 1);
        }
    /* the box's six faces, outward normals (its bottom faces away) */
    for (int k = 0; k < 3; k++)
        for (int side = 0; side < 2; side++)
            for (int a = 0; a < 3; a++)
                for (int c = 0; c < 3; c++) {
                    float p[3], n[3] = {0, 0, 0};
                    const int i = (k + 1) % 3, j = (k + 2) % 3;
                    p[k] = side ? box_hi[k] : box_lo[k];
                    p[i] = box_lo[i] + (box_hi[i] - box_lo[i]) * (0.2f + 0.3f * a);
                    p[j] = box_lo[j] + (box_hi[j] - box_lo[j]) * (0.2f + 0.3f * c);
                    n[k] = side ? 1.0f : -1.0f;
                    add_point(ps, p[0], p[1], p[2], n[0], n[1], n[2], 0, 0);
                }
    /* the octahedron: each face's centroid, outward normal */
    for (size_t t = 0; t < 8; t++) {
        const float *v = b->v + 9 * (4 + 12 + t);
        float p[3], e1[3], e2[3];
        for (int k = 0; k < 3; k++) {
            p[k] = (v[k] + v[3 + k] + v[6 + k]) / 3.0f;
            e1[k] = v[3 + k] - v[k];
            e2[k] = v[6 + k] - v[k];
        }
        add_point(ps, p[0], p[1], p[2], e1[1] * e2[2] - e1[2] * e2[1],
                  e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0], 1, 0);
    }
    /* the far box: a few points per face, outward normals */
    for (int k = 0; k < 3; k++)
        for (int side = 0; side < 2; side++)
            for (int a = 0; a < 2; a++) {
                float p[3], n[3] = {0, 0, 0};
                const int i = (k + 1) % 3, j = (k + 2) % 3;
                p[k] = side ? far_hi[k] : far_lo[k];
                p[i] = FAR - 6 + 12 * a;
                p[j] = FAR + 4;
                n[k] = side ? 1.0f : -1.0f;
                add_point(ps, p[0], p[1], p[2], n[0], n[1], n[2], 0, 0);
            }
}

/* Over the small objects (a penumbra the size of the box's shadow), and
 * over the far box. */
static const kdr_sphere_light lights[2] = {{{1.0f, 6.0f, 0.5f}, 0.6f},
                                           {{FAR + 35, FAR + 70, FAR + 15}, 6.0f}};

/* ---- the reference ---------------------------------------------------------- */

/* The reference start: one float step off the face along the normal (the
 * faces are axis-aligned and the points lie exactly on them), or for a
 * tilted face 1e-6 of the point's size along the normal in double, each
 * coordinate rounded outward. */
static void reference_start(const point_set *ps, size_t i, float o[3]) {
    const float *p = ps->p + 3 * i, *n = ps->n + 3 * i;
    const double len = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
    double size = 1.0;
    for (int k = 0; k < 3; k++)
        size = fmax(size, fabs(p[k]));
    for (int k = 0; k < 3; k++) {
        o[k] = p[k];
        if (n[k] == 0.0f)
            continue;
        if (!ps->tilted[i]) {
            o[k] = nextafterf(p[k], n[k] > 0 ? INFINITY : -INFINITY);
        } else {
            const double want = p[k] + 1e-6 * size * n[k] / len;
            o[k] = (float)want;
            if ((n[k] > 0 && o[k] < want) || (n[k] < 0 && o[k] > want))
                o[k] = nextafterf(o[k], n[k] > 0 ? INFINITY : -INFINITY);
        }
    }
}

/* Fraction of REF_SAMPLES stratified directions toward the light whose
 * segment from o to the sphere's near side robust Embree finds unblocked. */
static double reference_visibility(const oracle *em, const float o[3],
                                   const kdr_sphere_light *li) {
    double axis[3], D = 0.0;
    for (int k = 0; k < 3; k++) {
        axis[k] = (double)li->center[k] - o[k];
        D += axis[k] * axis[k];
    }
    D = sqrt(D);
    for (int k = 0; k < 3; k++)
        axis[k] /= D;
    const double r = li->radius, sin_a = r / D;
    const double one_minus_cos = sin_a * sin_a / (1.0 + sqrt(1.0 - sin_a * sin_a));
    double b1[3], b2[3]; /* any orthonormal basis around the axis */
    unit_basis(axis, b1, b2);
    int lit = 0;
    for (int a = 0; a < 64; a++)
        for (int c = 0; c < 64; c++) {
            const double omc = (a + rnd()) / 64.0 * one_minus_cos;
            const double st = sqrt(omc * (2.0 - omc)), phi = 6.283185307179586 * (c + rnd()) / 64.0;
            double d[3], oc = 0.0;
            for (int k = 0; k < 3; k++) {
                d[k] = (1.0 - omc) * axis[k] + st * (cos(phi) * b1[k] + sin(phi) * b2[k]);
                oc += d[k] * axis[k] * D;
            }
            /* near side of the sphere along d (|d| = 1): oc - sqrt(r^2 - (D^2 - oc^2)) */
            const double disc = fmax(0.0, r * r - (D - oc) * (D + oc));
            const double tn = (D - r) * (D + r) / (oc + sqrt(disc));
            kdr_ray ray;
            for (int k = 0; k < 3; k++) {
                ray.org[k] = o[k];
                ray.dir[k] = (float)d[k];
            }
            ray.tmin = 0.0f;
            ray.tmax = (float)(tn * (1.0 - 1e-6));
            lit += !oracle_occluded1(em, &ray);
        }
    return lit / (double)REF_SAMPLES;
}

/* ---- the gates ----------------------------------------------------------------- */

typedef struct verdict {
    double rmse;
    size_t off_exact, pairs, exact; /* pairs off by > 0.1 where ref is 0 or 1 */
    size_t backside_lit;           /* single-sided back faces not exactly 0 */
    double worst;
    size_t worst_pair;
} verdict;

static verdict judge(const point_set *ps, const double *ref, const float *vis) {
    verdict v = {0};
    double se = 0.0;
    for (size_t i = 0; i < ps->count; i++)
        for (size_t l = 0; l < 2; l++) {
            const size_t j = 2 * i + l;
            const double e = vis[j] - ref[j];
            se += e * e;
            v.pairs++;
            if (ref[j] == 0.0 || ref[j] == 1.0) {
                v.exact++;
                v.off_exact += fabs(e) > MAX_OFF_EXACT;
            }
            if (ps->backside[i] && l == 0)
                v.backside_lit += vis[j] != 0.0f;
            if (fabs(e) > v.worst)
                v.worst = fabs(e), v.worst_pair = j;
        }
    v.rmse = sqrt(se / (double)v.pairs);
    return v;
}

static void print_verdict(const char *what, const verdict *v, const point_set *ps,
                          const double *ref, const float *vis) {
    const size_t i = v->worst_pair / 2;
    printf("%-44s RMSE %.4f (gate %.2f), off by > %.1f where exact: %zu of %zu, "
           "single-sided back faces not 0: %zu; worst point %zu (%g %g %g, normal %g %g "
           "%g) light %zu: %.4f vs %.4f\n",
           what, v->rmse, MAX_RMSE, MAX_OFF_EXACT, v->off_exact, v->exact, v->backside_lit,
           i, ps->p[3 * i], ps->p[3 * i + 1], ps->p[3 * i + 2], ps->n[3 * i],
           ps->n[3 * i + 1], ps->n[3 * i + 2], v->worst_pair % 2, vis[v->worst_pair],
           ref[v->worst_pair]);
}

static int passes(const verdict *v) {
    return v->rmse <= MAX_RMSE && v->off_exact == 0 && v->backside_lit == 0;
}

/* v1's starts: epsilon 1e-4 * diagonal along the normal turned toward each
 * light (one query per light, with the normals flipped as v1's core did). */
static void trace_v1(const kdr_scene *s, const point_set *ps, float *vis) {
    float *flip = malloc(sizeof ps->n);
    float *one = malloc(ps->count * sizeof *one);
    for (size_t l = 0; l < 2; l++) {
        for (size_t i = 0; i < ps->count; i++) {
            double facing = 0.0;
            for (int k = 0; k < 3; k++)
                facing += ps->n[3 * i + k] * ((double)lights[l].center[k] - ps->p[3 * i + k]);
            for (int k = 0; k < 3; k++)
                flip[3 * i + k] = facing < 0.0 ? -ps->n[3 * i + k] : ps->n[3 * i + k];
        }
        kdr_shadow_query q = {.n = ps->count, .points = ps->p, .normals = flip,
                              .lights = &lights[l], .nlights = 1, .samples = KD_SAMPLES,
                              .seed = 1, .offset = KDR_OFFSET_DIAGONAL, .epsilon = 1e-4f};
        CHECK(kdr_shadow_trace(s, &q, 0, ps->count, KDR_SHADOW_CONE, one, NULL) == KDR_OK,
              "v1 trace");
        for (size_t i = 0; i < ps->count; i++)
            vis[2 * i + l] = one[i];
    }
    free(flip);
    free(one);
}

int main(int argc, char **argv) {
    (void)argv;
    if (argc > 1) {
        fprintf(stderr, "usage: test_cone_accuracy\n");
        return 2;
    }
    rng_state = 0x1234567; /* the reference's strata jitter */
    tri_buf b = {0};
    static point_set ps;
    build_scene(&b, &ps);
    kdr_scene *s = NULL;
    if (kdr_scene_build(b.v, b.n, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "scene build failed\n");
        return 1;
    }
    oracle *em = oracle_create(b.v, b.n, NULL); /* robust, as the judge */
    if (!em)
        return 1;
    printf("scene: %zu triangles, diagonal %.4g; %zu points x 2 lights; reference %d "
           "samples (robust Embree), kdray %d\n",
           b.n, kdr_scene_diagonal(s), ps.count, REF_SAMPLES, KD_SAMPLES);
    CHECK(kdr_scene_diagonal(s) > 3e5f && kdr_scene_diagonal(s) < 4e5f, "diagonal %g",
          kdr_scene_diagonal(s));

    const size_t m = 2 * ps.count;
    double *ref = malloc(m * sizeof *ref);
    float *cone = malloc(m * sizeof *cone), *rays = malloc(m * sizeof *rays);
    float *v1 = malloc(m * sizeof *v1);
    size_t lit = 0, dark = 0;
    for (size_t i = 0; i < ps.count; i++) {
        float o[3];
        reference_start(&ps, i, o);
        for (size_t l = 0; l < 2; l++) {
            ref[2 * i + l] = reference_visibility(em, o, &lights[l]);
            lit += ref[2 * i + l] == 1.0, dark += ref[2 * i + l] == 0.0;
        }
    }
    printf("reference: lit %zu, umbra %zu, penumbra %zu pairs\n", lit, dark, m - lit - dark);
    CHECK(lit > m / 8 && dark > m / 8 && m - lit - dark > m / 16,
          "the scene needs lit, umbra and penumbra pairs");

    kdr_shadow_query q = {.n = ps.count, .points = ps.p, .normals = ps.n, .lights = lights,
                          .nlights = 2, .samples = KD_SAMPLES, .seed = 1};
    CHECK(q.offset == KDR_OFFSET_AUTO, "a zeroed query means \"auto\"");
    CHECK(kdr_shadow_trace(s, &q, 0, ps.count, KDR_SHADOW_CONE, cone, NULL) == KDR_OK,
          "cone trace");
    CHECK(kdr_shadow_trace(s, &q, 0, ps.count, KDR_SHADOW_RAYS, rays, NULL) == KDR_OK,
          "rays trace");
    CHECK(memcmp(cone, rays, m * sizeof *cone) == 0, "cone and rays modes differ");

    const verdict vk = judge(&ps, ref, cone);
    print_verdict("kdray, v1.1 (auto offset, normals as given)", &vk, &ps, ref, cone);
    CHECK(vk.rmse <= MAX_RMSE, "RMSE %.4f", vk.rmse);
    CHECK(vk.off_exact == 0, "%zu pairs off by more than %.1f where the reference is 0 or 1",
          vk.off_exact, MAX_OFF_EXACT);
    CHECK(vk.backside_lit == 0,
          "%zu points behind a single-sided surface, normal away from the light, not 0",
          vk.backside_lit);

    trace_v1(s, &ps, v1);
    const verdict vo = judge(&ps, ref, v1);
    print_verdict("v1's starts (epsilon 1e-4 x diagonal, flipped)", &vo, &ps, ref, v1);
    CHECK(!passes(&vo), "v1's starts pass the gates: the test cannot see the fault");

    free(ref), free(cone), free(rays), free(v1);
    oracle_free(em);
    kdr_scene_free(s);
    free(b.v);
    if (failures) {
        fprintf(stderr, "test_cone_accuracy: %d failures\n", failures);
        return 1;
    }
    printf("test_cone_accuracy: all passed\n");
    return 0;
}
