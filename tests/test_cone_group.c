/*
 * test_cone_group.c — shared walks of the cone-shadow query
 * (core/kd_cone_group.c, kd_cone_query.c's trace_grouped): runs of consecutive
 * points walk one cone toward a light and judge its list.
 *
 *  - containment: the group's cone holds every sample segment of every
 *    point of the group (points along each sampled segment, checked
 *    against the cone's own apex, axis, half-angle and [t_near, t_far]);
 *  - answers: the automatic policy (groups), groups forced wherever the
 *    geometry allows one, walks forced on (no groups) and off, and
 *    KDR_SHADOW_RAYS agree bit for bit on every pair, and equal a
 *    brute-force count over every triangle on one pair in 31, on coherent
 *    runs of points (a grid in scan order on a tessellated floor and on a
 *    sphere, under occluders, toward small, large and straddling lights,
 *    one and two lights a query);
 *  - split runs: a run straddling two heights is cut in two and each half
 *    shares a walk (test_split_runs);
 *  - order: kdr_shadow_trace_order (render passes 4x4 squares of pixels)
 *    gives each point of its list, in any order, exactly its own answer
 *    under every policy (squares of a grid, a shuffle, with points left
 *    out: their slots are not written), and refuses an index out of range;
 *  - group clearing (kd_group_clear): a group triangle marked clear is hit
 *    by no float sample ray of any point of the group, and every point's
 *    own cull drops it too; points on a bumpy floor under lights near and
 *    far, among tilted triangles through and beside the points;
 *  - the cheap edge test (kd_tri_edges_miss) says MISSES only where the
 *    full proof does and no float ray of the cone hits the triangle;
 *  - sharing: points in free space under an empty sky are decided by one
 *    walk per group (fewer nodes than their own walks), and all lit;
 *  - unwalked routes: at 1, 2, 3 and 8 samples on a small and a large
 *    scene (16- and 8-lane bundles, and the interleaved walk far end
 *    first), every policy equals the reference mode and brute force
 *    (test_unwalked_routes).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "test_cone_util.h"

#define KPI 3.14159265358979323846

/* ---- scenes ---------------------------------------------------------------- */

/* This file's own generator (xorshift; its cases were drawn with it), not
 * test_cone_util.h's rnd. */
static uint64_t xs_state = 0x2545F4914F6CDD1Dull;
static double xrnd(void) {
    xs_state ^= xs_state << 13;
    xs_state ^= xs_state >> 7;
    xs_state ^= xs_state << 17;
    return (double)(xs_state >> 11) * 0x1p-53;
}

/* A floor y = 0 over [-1, 1]^2 in cells x cells quads, slightly bumpy (each
 * vertex lifted by up to bump) so neighbouring triangles are not coplanar. */
static void floor_grid(tri_buf *b, int cells, float bump) {
    const float h = 2.0f / (float)cells;
    for (int i = 0; i < cells; i++)
        for (int j = 0; j < cells; j++) {
            float y[4];
            for (int k = 0; k < 4; k++) {
                const int a = i + (k & 1), c = j + (k >> 1);
                y[k] = bump * (float)sin(1.7 * a + 2.3 * c * c);
            }
            const float x0 = -1.0f + h * (float)i, z0 = -1.0f + h * (float)j;
            const float t1[9] = {x0, y[0], z0, x0 + h, y[1], z0, x0, y[2], z0 + h};
            const float t2[9] = {x0 + h, y[1], z0,   x0 + h, y[3],
                                 z0 + h, x0,   y[2], z0 + h};
            tb_add(b, t1);
            tb_add(b, t2);
        }
}

/* n small random triangles in the box [lo, hi]. */
static void soup(tri_buf *b, size_t n, const float lo[3], const float hi[3], float size) {
    for (size_t i = 0; i < n; i++) {
        float c[3], t[9];
        for (int k = 0; k < 3; k++)
            c[k] = lo[k] + (hi[k] - lo[k]) * (float)xrnd();
        for (int v = 0; v < 9; v++)
            t[v] = c[v % 3] + size * (float)(xrnd() - 0.5);
        tb_add(b, t);
    }
}

/* A UV sphere (outward winding not needed: the test is two-sided). */
static void sphere(tri_buf *b, const float c[3], float r, int rings, int segs) {
    for (int i = 0; i < rings; i++)
        for (int j = 0; j < segs; j++) {
            float p[4][3];
            for (int k = 0; k < 4; k++) {
                const double th = KPI * (i + (k & 1)) / rings;
                const double ph = 2.0 * KPI * (j + (k >> 1)) / segs;
                p[k][0] = c[0] + r * (float)(sin(th) * cos(ph));
                p[k][1] = c[1] + r * (float)cos(th);
                p[k][2] = c[2] + r * (float)(sin(th) * sin(ph));
            }
            const float t1[9] = {p[0][0], p[0][1], p[0][2], p[1][0], p[1][1],
                                 p[1][2], p[2][0], p[2][1], p[2][2]};
            const float t2[9] = {p[1][0], p[1][1], p[1][2], p[3][0], p[3][1],
                                 p[3][2], p[2][0], p[2][1], p[2][2]};
            tb_add(b, t1);
            tb_add(b, t2);
        }
}

/* Points on the floor: a res x res grid in scan order (consecutive points
 * are neighbours, as a render's rows are), on the bumpy surface's plane
 * y = 0 lifted to the first triangle hit from above; normals up. */
typedef struct points {
    float *p, *n;
    size_t count;
} points;

static void floor_points(const kdr_scene *s, int res, float span, points *pts) {
    pts->p = malloc((size_t)res * res * 3 * sizeof(float));
    pts->n = malloc((size_t)res * res * 3 * sizeof(float));
    pts->count = 0;
    for (int y = 0; y < res; y++)
        for (int x = 0; x < res; x++) {
            kdr_ray r = {.org = {span * (2.0f * (x + 0.5f) / res - 1.0f), 5.0f,
                                 span * (2.0f * (y + 0.5f) / res - 1.0f)},
                         .dir = {0, -1, 0},
                         .tmin = 0,
                         .tmax = INFINITY};
            kdr_hit h;
            if (!kdr_intersect1(s, &r, &h, NULL)) continue;
            float *p = pts->p + 3 * pts->count, *n = pts->n + 3 * pts->count;
            p[0] = r.org[0];
            p[1] = r.org[1] - h.t;
            p[2] = r.org[2];
            n[0] = 0.0f, n[1] = 1.0f, n[2] = 0.0f;
            pts->count++;
        }
}

/* Points on a sphere's upper half, a latitude/longitude grid in scan order,
 * normals outward. */
static void sphere_points(const float c[3], float r, int res, points *pts) {
    pts->p = malloc((size_t)res * res * 3 * sizeof(float));
    pts->n = malloc((size_t)res * res * 3 * sizeof(float));
    pts->count = 0;
    for (int i = 0; i < res; i++)
        for (int j = 0; j < res; j++) {
            const double th = 0.5 * KPI * (i + 0.5) / res,
                         ph = 2.0 * KPI * (j + 0.5) / res;
            const double d[3] = {sin(th) * cos(ph), cos(th), sin(th) * sin(ph)};
            float *p = pts->p + 3 * pts->count, *n = pts->n + 3 * pts->count;
            for (int k = 0; k < 3; k++) {
                p[k] = c[k] + r * (float)d[k];
                n[k] = (float)d[k];
            }
            pts->count++;
        }
}

/* ---- containment ------------------------------------------------------------ */

/* Every sample segment of every point lies in the group's cone. */
static void test_containment(void) {
    tri_buf b = {0};
    floor_grid(&b, 8, 0.01f);
    kdr_scene *s = build(&b);
    int groups = 0;
    for (int trial = 0; trial < 300; trial++) {
        enum { N = 16 };
        float pts[3 * N], nrm[3 * N];
        const float spread = (float)pow(10.0, -3.0 + 3.0 * xrnd());
        float base[3] = {(float)(xrnd() - 0.5), (float)(0.5 * xrnd()),
                         (float)(xrnd() - 0.5)};
        for (int i = 0; i < N; i++)
            for (int k = 0; k < 3; k++) {
                pts[3 * i + k] = base[k] + spread * (float)(xrnd() - 0.5);
                nrm[3 * i + k] = (float)(xrnd() - 0.5);
            }
        const double dist = 0.5 + 4.0 * xrnd();
        kdr_sphere_light light = {{(float)(dist * (xrnd() - 0.5)), (float)(0.6 + dist),
                                   (float)(dist * (xrnd() - 0.5))},
                                  (float)(pow(10.0, -2.0 + 2.0 * xrnd()) * dist)};
        kdr_shadow_query q = {.n = N,
                              .points = pts,
                              .normals = nrm,
                              .lights = &light,
                              .nlights = 1,
                              .samples = 64,
                              .seed = (uint64_t)trial,
                              .offset = KDR_OFFSET_AUTO};
        kd_shadow_frame fr[N];
        const kd_shadow_frame *fs[N];
        int ok = 1;
        for (int i = 0; i < N; i++) {
            ok &= kd_shadow_frame_init(s, &q, (size_t)i, 0, &fr[i]) == KDR_OK;
            fs[i] = &fr[i];
        }
        kd_cone c;
        if (!ok || !kd_group_cone(s, fs, N, 1.0, &c)) continue;
        groups++;
        const double cos_h = c.cos_p; /* the cull's half-angle: widest */
        for (int i = 0; i < N; i++)
            for (uint32_t k = 0; k < q.samples; k++) {
                kdr_ray r;
                kd_shadow_frame_ray(&fr[i], k, q.samples, &r);
                for (int m = 0; m <= 8; m++) {
                    const double t = r.tmax * m / 8.0;
                    double w[3], len = 0.0, ax = 0.0;
                    for (int d = 0; d < 3; d++) {
                        w[d] = (double)r.org[d] + t * r.dir[d] - c.dapex[d];
                        len += w[d] * w[d];
                        ax += w[d] * c.axis[d];
                    }
                    len = sqrt(len);
                    if (!(ax >= cos_h * len && ax >= c.t_near && ax <= c.t_far)) {
                        CHECK(0,
                              "trial %d point %d sample %u t %g: axial %g of %g "
                              "(cos %g, want >= %g), range [%g, %g]",
                              trial, i, k, t, ax, len, ax / len, cos_h, c.t_near,
                              c.t_far);
                        i = N, k = q.samples, m = 9; /* one report a trial */
                    }
                }
            }
    }
    printf("containment: %d groups of 300 had a cone\n", groups);
    CHECK(groups > 100, "too few groups formed (%d)", groups);
    kdr_scene_free(s);
    free(b.v);
}

/* ---- group clearing ---------------------------------------------------------------- */

/* kd_group_clear marks only triangles that no sample segment of the group
 * touches (every float sample ray of every point tested with
 * kd_tri_intersect) and that every point's own cull would drop. */
static void test_clear(void) {
    tri_buf b = {0};
    floor_grid(&b, 8, 0.01f);
    kdr_scene *s = build(&b);
    long cleared = 0, judged = 0, rays = 0;
    for (int trial = 0; trial < 200; trial++) {
        enum { N = 16, T = 48 };
        float pts[3 * N], nrm[3 * N];
        /* points on the floor (a 4x4 patch found by rays from above) */
        const float span = (float)pow(10.0, -3.0 + 2.0 * xrnd());
        const float bx = (float)(1.6 * (xrnd() - 0.5)), bz = (float)(1.6 * (xrnd() - 0.5));
        int ok = 1;
        for (int i = 0; i < N; i++) {
            kdr_ray r = {.org = {bx + span * (float)(i % 4), 5.0f, bz + span * (float)(i / 4)},
                         .dir = {0, -1, 0},
                         .tmin = 0,
                         .tmax = INFINITY};
            kdr_hit h;
            ok &= kdr_intersect1(s, &r, &h, NULL);
            pts[3 * i] = r.org[0], pts[3 * i + 1] = r.org[1] - h.t, pts[3 * i + 2] = r.org[2];
            nrm[3 * i] = 0.0f, nrm[3 * i + 1] = 1.0f, nrm[3 * i + 2] = 0.0f;
        }
        const double dist = 0.3 + 4.0 * xrnd();
        kdr_sphere_light light = {{(float)(dist * (xrnd() - 0.5)), (float)(0.2 + dist),
                                   (float)(dist * (xrnd() - 0.5))},
                                  (float)(pow(10.0, -2.0 + 1.5 * xrnd()) * dist)};
        kdr_shadow_query q = {.n = N, .points = pts, .normals = nrm, .lights = &light,
                              .nlights = 1, .samples = 64, .seed = (uint64_t)trial,
                              .offset = trial % 2 ? KDR_OFFSET_AUTO : KDR_OFFSET_DIAGONAL,
                              .epsilon = 1e-4f};
        kd_shadow_frame fr[N];
        const kd_shadow_frame *fs[N];
        for (int i = 0; ok && i < N; i++) {
            ok &= kd_shadow_frame_init(s, &q, (size_t)i, 0, &fr[i]) == KDR_OK;
            fs[i] = &fr[i];
        }
        kd_cone gc;
        if (!ok || !kd_group_cone(s, fs, N, 1.0, &gc)) continue;
        /* the floor's triangles, and tilted ones through, under and beside
         * the patch */
        float tris[9 * T];
        kd_tri_pre pre[T];
        size_t nt = 0;
        for (size_t t = 0; t < b.n && nt < T / 2; t++) {
            const float *v = b.v + 9 * t;
            if (fabsf(v[0] - bx) < 0.5f && fabsf(v[2] - bz) < 0.5f)
                memcpy(tris + 9 * nt++, v, 9 * sizeof(float));
        }
        while (nt < T) {
            const float size = span * (float)pow(10.0, 2.0 * xrnd());
            const float lift = (float)((xrnd() - 0.6) * 4.0 * span);
            for (int v = 0; v < 3; v++) {
                tris[9 * nt + 3 * v] = bx + 1.5f * span + size * (float)(xrnd() - 0.5);
                tris[9 * nt + 3 * v + 1] = pts[1] + lift + 0.3f * size * (float)(xrnd() - 0.5);
                tris[9 * nt + 3 * v + 2] = bz + 1.5f * span + size * (float)(xrnd() - 0.5);
            }
            nt++;
        }
        for (size_t t = 0; t < nt; t++)
            kd_tri_pre_init(&pre[t], tris + 9 * t, (uint32_t)t);
        kd_group_clear(fs, N, gc.band, pre, nt);
        for (size_t t = 0; t < nt; t++) {
            judged++;
            if (!pre[t].clear) continue;
            cleared++;
            for (int i = 0; i < N; i++) {
                kd_cone pc;
                kd_cone_init(&pc, s, &fr[i], NULL, 0.0);
                CHECK(!kd_cone_pre_may_block(&pc, &pre[t]),
                      "trial %d: triangle %zu cleared but point %d's cull keeps it", trial, t, i);
                for (uint32_t k = 0; k < q.samples; k++) {
                    kdr_ray r;
                    kd_shadow_frame_ray(&fr[i], k, q.samples, &r);
                    kd_ray_pre rp;
                    float th, u, v;
                    kd_ray_precompute(r.org, r.dir, &rp);
                    rays++;
                    if (kd_tri_intersect(&rp, tris + 9 * t, r.tmin, r.tmax, &th, &u, &v)) {
                        CHECK(0, "trial %d: triangle %zu cleared but point %d sample %u hits it",
                              trial, t, i, k);
                        k = q.samples, i = N;
                    }
                }
            }
        }
    }
    printf("clear: %ld of %ld group triangles cleared, %ld rays tested\n", cleared, judged,
           rays);
    CHECK(cleared > judged / 10, "too few triangles cleared (%ld of %ld)", cleared, judged);
    kdr_scene_free(s);
    free(b.v);
}

/* ---- the cheap edge test --------------------------------------------------------- */

/* kd_tri_edges_miss decides only what the full view decides as MISSES, and
 * no float ray of the cone (rim included, and the ray through an edge point
 * the cone touches) hits the triangle. Cones are aimed beside a triangle,
 * across one of its edges at a small distance, at every scale. */
static void test_edges_miss(void) {
    long said = 0, rays = 0;
    int wrong = 0;
    for (int trial = 0; trial < 30000 && wrong < 5; trial++) {
        const double L = pow(10.0, -2.0 + 7.0 * xrnd());
        float apex[3], tri[9];
        double c[3], dir[3], b1[3], b2[3], axis[3];
        for (int k = 0; k < 3; k++) {
            apex[k] = (float)((2.0 * xrnd() - 1.0) * L);
            dir[k] = xrnd() - 0.5;
        }
        const double dl = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
        const double M = L * pow(10.0, -3.0 + 3.0 * xrnd()),
                     dist = M * pow(10.0, 2.0 * xrnd());
        double nrm[3] = {xrnd() - 0.5, xrnd() - 0.5, xrnd() - 0.5};
        unit_basis(nrm[0] || nrm[1] || nrm[2] ? nrm : dir, b1, b2);
        for (int k = 0; k < 3; k++)
            c[k] = apex[k] + dist * dir[k] / dl;
        for (int i = 0; i < 3; i++) {
            const double an = 2.0944 * i + 0.7 * (xrnd() - 0.5), r = M * (0.3 + xrnd());
            for (int k = 0; k < 3; k++)
                tri[3 * i + k] = (float)(c[k] + r * (cos(an) * b1[k] + sin(an) * b2[k]));
        }
        /* the cone's axis through a point just outside edge e */
        const int e = trial % 3, j = (e + 1) % 3, o = (e + 2) % 3;
        const double f = 0.1 + 0.8 * xrnd(), out = pow(10.0, -6.0 + 6.0 * xrnd());
        double m[3], ml = 0.0;
        for (int k = 0; k < 3; k++) {
            const double pe = (1 - f) * tri[3 * e + k] + f * tri[3 * j + k];
            m[k] = pe + out * (pe - tri[3 * o + k]) - apex[k];
            ml += m[k] * m[k];
        }
        ml = sqrt(ml);
        for (int k = 0; k < 3; k++)
            axis[k] = m[k] / ml;
        const double bgeo = pow(10.0, -6.0 + 5.5 * xrnd()), b = bgeo + 2e-7;
        kd_dir_cone dc;
        kd_dir_cone_set(&dc, axis, cos(b), sin(b), 1e30);
        if (!kd_tri_edges_miss(tri, apex, &dc)) continue;
        said++;
        kd_tri_view v;
        kd_tri_view_init(&v, tri, 0, apex);
        if (kd_tri_view_classify(&v, &dc) != KD_TRI_MISSES) {
            wrong++;
            CHECK(0, "trial %d: edges_miss but the view says %d", trial,
                  (int)kd_tri_view_classify(&v, &dc));
        }
        double a1[3], a2[3];
        unit_basis(axis, a1, a2);
        for (int r = 0; r < 64; r++) {
            const double th = r < 32 ? bgeo : bgeo * sqrt(xrnd()),
                         ph = 6.283185307 * xrnd();
            float d[3], t, u, w;
            for (int k = 0; k < 3; k++)
                d[k] = (float)(cos(th) * axis[k] +
                               sin(th) * (cos(ph) * a1[k] + sin(ph) * a2[k]));
            kd_ray_pre pre;
            kd_ray_precompute(apex, d, &pre);
            rays++;
            if (kd_tri_intersect(&pre, tri, 0.0f, INFINITY, &t, &u, &w)) {
                wrong++;
                CHECK(0, "trial %d: edges_miss but ray %d hits at t %g", trial, r, t);
                break;
            }
        }
    }
    printf("edges_miss: %ld of 30000 cones decided, %ld rays checked\n", said, rays);
    CHECK(said > 3000, "too few cones decided by the edge test (%ld)", said);
}

/* ---- answers ------------------------------------------------------------------ */

/* A permutation of a subset of 0..n): the points in 4x4 squares of a
 * side x side grid (n = side^2, scan order inside a square), else a
 * shuffle; every point with i % 7 == 3 left out. Its own generator, so the
 * cases drawn with xrnd stay the same. Returns the length. */
static size_t make_order(size_t n, size_t *order) {
    size_t side = (size_t)sqrt((double)n), m = 0;
    if (side * side == n) {
        for (size_t ty = 0; ty < side; ty += 4)
            for (size_t tx = 0; tx < side; tx += 4)
                for (size_t y = ty; y < ty + 4 && y < side; y++)
                    for (size_t x = tx; x < tx + 4 && x < side; x++)
                        if ((y * side + x) % 7 != 3) order[m++] = y * side + x;
        return m;
    }
    for (size_t i = 0; i < n; i++)
        if (i % 7 != 3) order[m++] = i;
    uint64_t z = 0x9E3779B97F4A7C15ull;
    for (size_t i = m; i > 1; i--) {
        z = z * 6364136223846793005ull + 1442695040888963407ull;
        const size_t j = (size_t)((z >> 33) % i), t = order[i - 1];
        order[i - 1] = order[j];
        order[j] = t;
    }
    return m;
}

/* kdr_shadow_trace_order under every policy (and the reference mode): each
 * listed point's slots equal the plain query's vr, the others untouched. */
static void check_order(const char *label, const kdr_scene *s, const kdr_shadow_query *q,
                        const float *vr) {
    const size_t m = q->n * q->nlights;
    size_t *order = malloc(q->n * sizeof *order);
    float *v = malloc(m * sizeof *v);
    const size_t count = make_order(q->n, order);
    const kd_walk_policy pol[4] = {KD_WALK_AUTO, KD_WALK_GROUPS, KD_WALK_ALWAYS,
                                   KD_WALK_NEVER};
    const char *names[5] = {"auto", "groups", "always", "never", "rays"};
    for (int k = 0; k < 5; k++) {
        for (size_t j = 0; j < m; j++)
            v[j] = -1.0f;
        const int rc = k < 4 ? kd_shadow_trace_order_policy(s, q, order, count,
                                                            KDR_SHADOW_CONE, pol[k], v, NULL)
                             : kdr_shadow_trace_order(s, q, order, count, KDR_SHADOW_RAYS,
                                                      v, NULL);
        CHECK(rc == KDR_OK, "%s ordered %s", label, names[k]);
        size_t bad = 0, first = 0;
        for (size_t j = 0; j < m; j++) {
            const float want = (j / q->nlights) % 7 == 3 ? -1.0f : vr[j];
            if (memcmp(&v[j], &want, sizeof want) != 0 && bad++ == 0) first = j;
        }
        CHECK(bad == 0, "%s: ordered %s differs on %zu slots (first %zu: %.6f vs %.6f)",
              label, names[k], bad, first, v[first], vr[first]);
    }
    /* an index out of range, or no list, is refused before anything is written */
    order[count / 2] = q->n;
    v[0] = -2.0f;
    CHECK(kdr_shadow_trace_order(s, q, order, count, KDR_SHADOW_CONE, v, NULL) ==
                  KDR_EINVAL &&
              kdr_shadow_trace_order(s, q, NULL, 1, KDR_SHADOW_CONE, v, NULL) == KDR_EINVAL &&
              v[0] == -2.0f,
          "%s: a bad order is refused", label);
    free(order);
    free(v);
}

/* Every policy and the reference mode agree bit for bit, and equal a brute
 * force count; the same answers in another order; returns the automatic
 * policy's stats. */
static kdr_shadow_stats check_policies(const char *label, const kdr_scene *s,
                                       const tri_buf *b, const kdr_shadow_query *q) {
    const size_t m = q->n * q->nlights;
    float *vr = malloc(m * sizeof *vr), *v = malloc(m * sizeof *v);
    kdr_shadow_stats sr = {0}, sa = {0};
    CHECK(kdr_shadow_trace(s, q, 0, q->n, KDR_SHADOW_RAYS, vr, &sr) == KDR_OK, "%s rays",
          label);
    const kd_walk_policy pol[4] = {KD_WALK_AUTO, KD_WALK_GROUPS, KD_WALK_ALWAYS,
                                   KD_WALK_NEVER};
    const char *names[4] = {"auto", "groups", "always", "never"};
    for (int k = 0; k < 4; k++) {
        kdr_shadow_stats st = {0};
        CHECK(kd_shadow_trace_policy(s, q, 0, q->n, KDR_SHADOW_CONE, pol[k], v, &st) ==
                  KDR_OK,
              "%s %s", label, names[k]);
        size_t bad = 0, first = 0;
        for (size_t j = 0; j < m; j++)
            if (memcmp(&v[j], &vr[j], sizeof *v) != 0 && bad++ == 0) first = j;
        CHECK(bad == 0,
              "%s: policy %s differs from rays on %zu pairs (first %zu: %.6f vs %.6f)",
              label, names[k], bad, first, v[first], vr[first]);
        if (k == 0) sa = st;
    }
    check_order(label, s, q, vr);
    /* brute force on a spread subset of the pairs */
    size_t bad = 0;
    for (size_t j = 0; j < m; j += 31) {
        const size_t i = j / q->nlights, l = j % q->nlights;
        uint32_t lit = 0;
        for (uint32_t k = 0; k < q->samples; k++) {
            kdr_ray r;
            CHECK(kdr_shadow_ray(s, q, i, l, k, &r) == KDR_OK, "%s ray", label);
            lit += ref_occluded1(b->v, b->n, &r) ? 0u : 1u;
        }
        if (vr[j] != (float)lit / (float)q->samples && bad++ < 3)
            CHECK(0, "%s pair %zu: %.6f, brute force %.6f", label, j, vr[j],
                  (float)lit / (float)q->samples);
    }
    printf("%-34s pairs %5zu decided %5llu rays %8llu nodes %9llu\n", label, m,
           (unsigned long long)sa.cones_decided, (unsigned long long)sa.rays_traced,
           (unsigned long long)sa.nodes_visited);
    free(vr);
    free(v);
    return sa;
}

static void test_answers(void) {
    tri_buf b = {0};
    floor_grid(&b, 24, 0.004f);
    const float lo[3] = {-0.8f, 0.05f, -0.8f}, hi[3] = {0.8f, 0.6f, 0.8f};
    soup(&b, 300, lo, hi, 0.12f);
    const float sc[3] = {0.4f, 0.3f, -0.3f};
    sphere(&b, sc, 0.25f, 12, 24);
    kdr_scene *s = build(&b);
    points fp, sp;
    floor_points(s, 40, 0.95f, &fp);
    sphere_points(sc, 0.25f, 24, &sp);
    const kdr_sphere_light small = {{0.3f, 3.0f, 0.2f}, 0.1f};
    const kdr_sphere_light large = {{-0.2f, 1.2f, 0.1f}, 0.5f};
    const kdr_sphere_light straddle = {{0.0f, 0.35f, 0.0f}, 0.04f}; /* among the soup */
    const kdr_sphere_light two[2] = {{{0.3f, 3.0f, 0.2f}, 0.1f},
                                     {{-2.0f, 2.0f, 1.0f}, 0.3f}};
    /* a narrow light whose points walk beside a wide one whose points (at 32
     * to CONE_WALK_WIDE_FROM spp) do not walk: their answers land in the
     * right (point, light) slots among walked ones */
    const kdr_sphere_light mixed[2] = {small, large};
    const struct {
        const char *label;
        const points *p;
        const kdr_sphere_light *l;
        size_t nl;
        uint32_t spp;
    } cases[] = {
        {"floor, small light, 64 spp", &fp, &small, 1, 64},
        {"floor, small light, 256 spp", &fp, &small, 1, 256},
        {"floor, large light, 128 spp", &fp, &large, 1, 128},
        {"floor, straddling light, 32 spp", &fp, &straddle, 1, 32},
        {"floor, two lights, 64 spp", &fp, two, 2, 64},
        {"floor, large light, 64 spp", &fp, &large, 1, 64},
        {"floor, small and large lights, 64 spp", &fp, mixed, 2, 64},
        {"sphere, small and large lights, 32 spp", &sp, mixed, 2, 32},
        {"floor, small light, 8 spp", &fp, &small, 1, 8},
        {"sphere, small light, 64 spp", &sp, &small, 1, 64},
        {"sphere, two lights, 32 spp", &sp, two, 2, 32},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        kdr_shadow_query q = {.n = cases[c].p->count,
                              .points = cases[c].p->p,
                              .normals = cases[c].p->n,
                              .lights = cases[c].l,
                              .nlights = cases[c].nl,
                              .samples = cases[c].spp,
                              .seed = 11,
                              .offset = KDR_OFFSET_AUTO};
        check_policies(cases[c].label, s, &b, &q);
        /* the diagonal offsets render uses */
        q.offset = KDR_OFFSET_DIAGONAL;
        q.epsilon = 1e-4f;
        char l2[96];
        snprintf(l2, sizeof l2, "%s, 1e-4 offsets", cases[c].label);
        check_policies(l2, s, &b, &q);
    }
    free(fp.p), free(fp.n), free(sp.p), free(sp.n);
    kdr_scene_free(s);
    free(b.v);
}

/* A 32x32 grid of points in free space (normals up, nothing above them;
 * row-major, heights 0.5 + (i % 2) * step) toward a light of radius 0.2:
 * every point must be decided lit with no ray traced, bit-identical under
 * every policy, and the grouped walks must enter fewer than a quarter of
 * the nodes that one walk per point enters. */
static void check_free_space_lit(const char *label, float step, uint64_t seed,
                                 const char *point_kind, const char *walks_kind,
                                 const char *not_shared) {
    tri_buf b = {0};
    floor_grid(&b, 16, 0.0f);
    const float lo[3] = {2.0f, 0.0f, 2.0f}, hi[3] = {3.0f, 1.0f, 3.0f};
    soup(&b, 50, lo, hi, 0.2f); /* off to the side */
    kdr_scene *s = build(&b);
    enum { RES = 32 };
    float pts[3 * RES * RES], nrm[3 * RES * RES];
    for (int i = 0; i < RES * RES; i++) {
        pts[3 * i] = -0.125f + 0.25f * (float)(i % RES) / RES;
        pts[3 * i + 1] = 0.5f + step * (float)(i % 2);
        pts[3 * i + 2] = -0.125f + 0.25f * (float)(i / RES) / RES;
        nrm[3 * i] = nrm[3 * i + 2] = 0.0f;
        nrm[3 * i + 1] = 1.0f;
    }
    const kdr_sphere_light light = {{0.0f, 4.0f, 0.0f}, 0.2f}; /* narrow: walks pay */
    kdr_shadow_query q = {.n = RES * RES,
                          .points = pts,
                          .normals = nrm,
                          .lights = &light,
                          .nlights = 1,
                          .samples = 64,
                          .seed = seed,
                          .offset = KDR_OFFSET_AUTO};
    const kdr_shadow_stats sa = check_policies(label, s, &b, &q);
    float v[RES * RES];
    kdr_shadow_stats sw = {0};
    CHECK(kd_shadow_trace_policy(s, &q, 0, q.n, KDR_SHADOW_CONE, KD_WALK_ALWAYS, v,
                                 &sw) == KDR_OK,
          "always");
    for (int i = 0; i < RES * RES; i++)
        CHECK(v[i] == 1.0f, "%s point %d: %.6f", point_kind, i, v[i]);
    CHECK(sa.cones_decided == q.n && sa.rays_traced == 0, "every point decided lit");
    CHECK(sa.nodes_visited * 4 < sw.nodes_visited, "%s %llu nodes, own walks %llu: %s",
          walks_kind, (unsigned long long)sa.nodes_visited,
          (unsigned long long)sw.nodes_visited, not_shared);
    kdr_scene_free(s);
    free(b.v);
}

/* Points in free space at one height: each group's walk finds nothing, so
 * every point is lit with one walk per group instead of one per point. */
static void test_sharing(void) {
    check_free_space_lit("free space, grouped", 0.0f, 3, "free-space", "grouped walks",
                         "not shared");
}

/* Runs that straddle two surfaces: consecutive points alternate between
 * two heights 1 apart (a run's apexes are far too spread for one group
 * cone toward a light of radius 0.2), in free space. Each run is cut in
 * two by position (trace_run), each half shares one walk that finds
 * nothing: every point decided lit with far fewer nodes than own walks.
 * Before runs were cut, every point of such a run walked on its own. */
static void test_split_runs(void) {
    check_free_space_lit("two heights, split runs", 1.0f, 5, "two-height", "split runs",
                         "the halves did not share walks");
}

/* Unwalked points (below CONE_WALK_FROM samples), every route of
 * kd_cone_query.c's trace_chunk: on a small scene every chunk goes to the
 * widest bundles; on one past 2 x UNWALKED_STREAM_BYTES_PER_SAMPLE and
 * UNWALKED_NARROW_MIN_BYTES bytes the 1- and 2-sample chunks go to the
 * interleaved walk far end first, the 3- and 8-sample ones to 8-lane
 * bundles. Every policy and the reference mode agree bit for bit,
 * and equal brute force on one pair in 31, toward a narrow and a wide light
 * (whose samples diverge most) and both in one query, with 1e-4 offsets
 * too. */
static void test_unwalked_routes(void) {
    for (int big = 0; big < 2; big++) {
        tri_buf b = {0};
        floor_grid(&b, big ? 230 : 24, 0.004f);
        const float lo[3] = {-0.8f, 0.05f, -0.8f}, hi[3] = {0.8f, 0.6f, 0.8f};
        soup(&b, 300, lo, hi, 0.12f);
        const float sc[3] = {-0.3f, 0.35f, 0.2f};
        sphere(&b, sc, 0.2f, 12, 24);
        kdr_scene *s = build(&b);
        kdr_tree_stats ts;
        kdr_scene_tree_stats(s, &ts);
        uint64_t need = 2 * UNWALKED_STREAM_BYTES_PER_SAMPLE;
        need = need > UNWALKED_NARROW_MIN_BYTES ? need : UNWALKED_NARROW_MIN_BYTES;
        CHECK(big ? ts.bytes >= need : ts.bytes < UNWALKED_STREAM_BYTES_PER_SAMPLE,
              "unwalked routes: the %s scene takes %llu bytes", big ? "large" : "small",
              (unsigned long long)ts.bytes);
        points fp;
        floor_points(s, 40, 0.95f, &fp);
        const kdr_sphere_light lights[2] = {{{0.3f, 3.0f, 0.2f}, 0.1f},
                                            {{-0.2f, 1.2f, 0.1f}, 0.5f}};
        static const char *const lname[3] = {"narrow light", "wide light", "both lights"};
        static const uint32_t spps[4] = {1, 2, 3, 8};
        for (int l = 0; l < 3; l++) /* l == 2: both lights in one query */
            for (int k = 0; k < 4; k++) {
                const uint32_t spp = spps[k];
                kdr_shadow_query q = {.n = fp.count, .points = fp.p, .normals = fp.n,
                                      .lights = &lights[l == 2 ? 0 : l],
                                      .nlights = l == 2 ? 2 : 1, .samples = spp,
                                      .seed = 17, .offset = KDR_OFFSET_AUTO};
                char label[96];
                snprintf(label, sizeof label, "%s floor, %s, %u spp",
                         big ? "large" : "small", lname[l], spp);
                check_policies(label, s, &b, &q);
                q.offset = KDR_OFFSET_DIAGONAL;
                q.epsilon = 1e-4f;
                snprintf(label, sizeof label, "%s floor, %s, %u spp, 1e-4",
                         big ? "large" : "small", lname[l], spp);
                check_policies(label, s, &b, &q);
            }
        free(fp.p), free(fp.n);
        kdr_scene_free(s);
        free(b.v);
    }
}

int main(void) {
    test_containment();
    test_edges_miss();
    test_answers();
    test_sharing();
    test_split_runs();
    test_clear(); /* the cases above were drawn before it existed */
    test_unwalked_routes(); /* after test_clear, whose cases come first */
    if (failures) {
        fprintf(stderr, "test_cone_group: %d failure(s)\n", failures);
        return 1;
    }
    printf("test_cone_group: all passed\n");
    return 0;
}
