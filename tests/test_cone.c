/*
 * test_cone.c — cone-shadow queries (core/kd_cone*.c), the contract's side:
 * bad queries refused, the sample rays' definition, analytic visibilities
 * (a roof, an open light, a half-plane integrated numerically), normals
 * and offsets as API v1.1 defines them, and any split of the point range
 * giving the same answers. Every scene here also goes through check_modes
 * (test_cone_util.h): cone == rays == brute force sample by sample.
 * Embree and the tree's own split planes: test_cone_trees.c; the
 * one-triangle proofs: test_cone_proofs.c.
 */
#include "test_cone_util.h"

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

/* The sampler's batch form (kd_shadow_frame_rays: four samples at once in
 * double lanes where AVX2 runs) gives kd_shadow_frame_ray's rays bit for
 * bit: runs from any first sample and of any length (lanes and the scalar
 * tail), lists of indices in any order, lights near and far, tiny and
 * wide, with and without the offset along each ray. */
static void test_batch_rays(void) {
    const float pts[6] = {0.5f, -0.25f, 0.0f, 1e5f, -3e4f, 7.0f};
    const float nrm[6] = {0, 0, 1, 0, 0, 0};
    const kdr_sphere_light lights[4] = {{{3, 4, 12}, 1.0f},
                                        {{0.5f, -0.25f, 2.0f}, 1.9f},
                                        {{-7, 0, 0}, 1e-3f},
                                        {{1e5f, 2e5f, -1e5f}, 3e4f}};
    const uint32_t counts[] = {1, 3, 4, 5, 16, 63, 64, 4096};
    static kdr_ray a[4096], b[4096];
    static uint32_t idx[4096];
    for (int with_normals = 0; with_normals < 2; with_normals++)
        for (size_t c = 0; c < sizeof counts / sizeof *counts; c++) {
            const uint32_t n = counts[c];
            kdr_shadow_query q = make_query(pts, 2, lights, 4, n);
            q.normals = with_normals ? nrm : NULL;
            for (size_t i = 0; i < 2; i++)
                for (size_t l = 0; l < 4; l++) {
                    kd_shadow_frame f;
                    CHECK(kd_shadow_frame_init(NULL, &q, i, l, &f) == KDR_OK, "frame");
                    for (uint32_t s = 0; s < n; s++)
                        kd_shadow_frame_ray(&f, s, n, &a[s]);
                    kd_shadow_frame_rays(&f, NULL, 0, n, n, b);
                    CHECK(memcmp(a, b, n * sizeof *a) == 0, "run of %u (point %zu, light %zu)",
                          n, i, l);
                    const uint32_t s0 = n > 5 ? n / 3 : 0, m = n - s0;
                    kd_shadow_frame_rays(&f, NULL, s0, m, n, b);
                    CHECK(memcmp(a + s0, b, m * sizeof *a) == 0, "run from %u of %u", s0, n);
                    for (uint32_t s = 0; s < n; s++)
                        idx[s] = (s * 2654435761u) % n; /* a permutation where n is odd */
                    kd_shadow_frame_rays(&f, idx, 0, n, n, b);
                    for (uint32_t s = 0; s < n; s++)
                        CHECK(memcmp(&a[idx[s]], &b[s], sizeof *a) == 0,
                              "list entry %u (sample %u of %u)", s, idx[s], n);
                }
        }
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
     * from CONE_WALK_WIDE_FROM on, AUTO walks too; above the contract's
     * 4096 it never does, and 4096 samples must not walk) */
    const uint32_t spp[4] = {1, 4, 31,
                             CONE_WALK_WIDE_FROM < KD_SHADOW_MAX_SAMPLES ? CONE_WALK_WIDE_FROM
                                                                         : KD_SHADOW_MAX_SAMPLES};
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
    if (argc > 1) {
        fprintf(stderr, "usage: %s\n", argv[0]);
        return 2;
    }
    test_invalid();
    test_ray_definition();
    test_batch_rays();
    test_analytic();
    test_normals();
    test_offsets();
    test_ranges();
    return check_exit("test_cone");
}
