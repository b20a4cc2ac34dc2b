/*
 * test_cone_trees.c — cone-shadow queries on busy trees: a random soup
 * against brute force and against Embree on the same sample rays, cones
 * placed on the tree's actual split planes, and the SIMD packet tests
 * (kd_cone_packet_*) lane by lane against the scalar triangle test.
 *
 *   test_cone_trees [--caps NAME]   NAME: bound the explained classes of
 *                                   the Embree comparison (support/caps.h)
 */
#include "caps.h"
#include "oracle.h"
#include "test_cone_util.h"

static const char *g_caps; /* --caps NAME, or NULL */

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

int main(int argc, char **argv) {
    g_caps = caps_arg(&argc, argv);
    if (argc > 1) {
        fprintf(stderr, "usage: %s [--caps NAME]\n", argv[0]);
        return 2;
    }
    test_soup_vs_embree();
    test_adversarial();
    test_packets();
    return check_exit("test_cone_trees");
}
