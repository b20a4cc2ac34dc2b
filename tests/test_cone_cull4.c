/*
 * test_cone_cull4.c — the culls four triangles at a time
 * (core/kd_cone_cull4.c) give every triangle exactly the answer of the
 * scalar ones: the group list's kd_cone_pre_may_block4 against
 * kd_cone_pre_may_block, the walks' kd_cone_tri_sphere4 (one to four
 * triangles) against kd_cone_tri_sphere_may (and the whole cull,
 * kd_cone_tri_may_block, is that test and then kd_cone_tri_rest_may), and
 * the cheap edge test kd_tri_edges_miss4 against kd_tri_edges_miss; for
 * the whole light's cone of a point and for the narrower cones of its
 * cells (random axes inside the light's),
 * against triangles through, beside, under and behind the points at every
 * scale, degenerate ones (no plane) and padded lists of every length mod 4
 * included. Both answers must occur often, so the comparison means
 * something. Without AVX2 the four-wide cull never runs (kd_cone_query.c
 * lays the list out only with it) and this test says so and checks
 * nothing else.
 */
#include "test_cone_util.h"

enum { T = 61 }; /* triangles per list: 15 blocks of 4 and a padded one */

static uint64_t st = 0x9E3779B97F4A7C15ull;
static double urnd(void) {
    st ^= st << 13;
    st ^= st >> 7;
    st ^= st << 17;
    return (double)(st >> 11) * 0x1p-53;
}

/* A triangle near point p at scale `size`: random, or (kind 1) lying in the
 * point's own plane y = p.y, or (kind 2) degenerate (its vertices on a
 * line). */
static void make_tri(const float p[3], float size, int kind, float *t) {
    for (int v = 0; v < 3; v++)
        for (int k = 0; k < 3; k++)
            t[3 * v + k] = p[k] + size * (float)(urnd() - 0.5) + (k == 1 && kind != 1
                                                                   ? size * (float)urnd()
                                                                   : 0.0f);
    if (kind == 1)
        t[1] = t[4] = t[7] = p[1];
    if (kind == 2)
        for (int k = 0; k < 3; k++)
            t[6 + k] = t[k] + 2.0f * (t[3 + k] - t[k]);
}

int main(void) {
    if (!kdr_cpu_has_avx2()) {
        printf("test_cone_cull4: no AVX2 on this CPU: the four-wide cull does not run; "
               "nothing to compare\n");
        return 0;
    }
    tri_buf b = {0};
    tb_rect(&b, 1, 0.0f, -1.0f, 1.0f, -1.0f, 1.0f);
    kdr_scene *s = build(&b);
    kd_tri_soa soa = {.cap = 64};
    soa.f = malloc(KD_SOA_FIELDS * soa.cap * sizeof *soa.f);
    soa.prim = malloc(soa.cap * sizeof *soa.prim);
    if (!s || !soa.f || !soa.prim) {
        CHECK(0, "set-up failed");
        return 1;
    }
    long kept = 0, dropped = 0, cones = 0, near = 0, far = 0, miss = 0, unsure = 0;
    for (int trial = 0; trial < 400; trial++) {
        const float p[3] = {(float)(urnd() - 0.5), 0.0f, (float)(urnd() - 0.5)};
        const float nrm[3] = {0.0f, 1.0f, 0.0f};
        const double dist = 0.05 + 5.0 * urnd();
        const kdr_sphere_light light = {
            {p[0] + (float)(dist * (urnd() - 0.5)), (float)(0.1 + dist),
             p[2] + (float)(dist * (urnd() - 0.5))},
            (float)(pow(10.0, -3.0 + 2.5 * urnd()) * dist)};
        kdr_shadow_query q = {.n = 1, .points = p, .normals = nrm, .lights = &light,
                              .nlights = 1, .samples = 64, .seed = 1,
                              .offset = trial % 2 ? KDR_OFFSET_AUTO : KDR_OFFSET_DIAGONAL,
                              .epsilon = 1e-4f};
        kd_shadow_frame f;
        if (kd_shadow_frame_init(s, &q, 0, 0, &f) != KDR_OK)
            continue;
        const size_t n = T - (size_t)(trial % 4); /* every padding */
        float tris[9 * T];
        kd_tri_pre pre[T];
        const float scale = (float)pow(10.0, -3.0 + 3.0 * urnd());
        for (size_t t = 0; t < n; t++) {
            const int kind = t % 7 == 3 ? 1 : t % 11 == 5 ? 2 : 0;
            const float size = scale * (float)pow(10.0, 2.0 * urnd() - 1.0);
            float c[3] = {p[0], p[1], p[2]};
            const double along = urnd() * dist; /* somewhere toward the light */
            if (t % 2)
                for (int k = 0; k < 3; k++)
                    c[k] += (float)(along * f.axis[k]);
            make_tri(c, size, kind, tris + 9 * t);
            kd_tri_pre_init(&pre[t], tris + 9 * t, (uint32_t)t);
        }
        kd_tri_soa_fill(&soa, pre, n);
        for (int ci = 0; ci < 4; ci++) {
            kd_cone c;
            if (ci == 0) {
                kd_cone_init(&c, s, &f, NULL, 0.0);
            } else { /* a cell's cone: an axis inside the light's, narrower */
                double ax[3], len = 0.0;
                for (int k = 0; k < 3; k++) {
                    ax[k] = f.axis[k] + f.sin_a * (urnd() - 0.5) * f.b1[k] +
                            f.sin_a * (urnd() - 0.5) * f.b2[k];
                    len += ax[k] * ax[k];
                }
                for (int k = 0; k < 3; k++)
                    ax[k] /= sqrt(len);
                kd_cone_init(&c, s, &f, ax, f.sin_a * urnd());
            }
            if (c.cos_p == 0.0)
                continue;
            cones++;
            { /* the edge test, for the cone's directions (as kd_cone_cells.c's) */
                const double sb = c.sin_p * urnd();
                kd_dir_cone dc;
                kd_dir_cone_set(&dc, c.axis, sqrt((1.0 - sb) * (1.0 + sb)), sb,
                                f.dist - f.radius);
                for (size_t j = 0; j < n; j += 4) {
                    const int m = 1 + (int)((j / 4 + (size_t)trial + (size_t)ci) % 4);
                    const float *four[4];
                    for (int i = 0; i < m; i++)
                        four[i] = tris + 9 * ((j + (size_t)i) % n);
                    const int got4 = kd_tri_edges_miss4(four, m, f.apex, &dc);
                    CHECK((got4 >> m) == 0, "trial %d: edge lanes past %d set", trial, m);
                    for (int i = 0; i < m; i++) {
                        const int want = kd_tri_edges_miss(four[i], f.apex, &dc);
                        CHECK(((got4 >> i) & 1) == want,
                              "trial %d cone %d triangle %zu: four-wide edges %d, scalar %d",
                              trial, ci, (j + (size_t)i) % n, (got4 >> i) & 1, want);
                        miss += want;
                        unsure += !want;
                    }
                }
            }
            for (size_t j = 0; j < n; j += 4) {
                const int four = kd_cone_pre_may_block4(&c, &soa, j);
                for (size_t i = 0; i < 4; i++) {
                    const int want = j + i < n ? kd_cone_pre_may_block(&c, &pre[j + i]) : 0;
                    const int got = (four >> i) & 1;
                    CHECK(got == want, "trial %d cone %d triangle %zu: four-wide %d, scalar %d",
                          trial, ci, j + i, got, want);
                    if (j + i < n) {
                        kept += want;
                        dropped += !want;
                        CHECK(soa.prim[j + i] == pre[j + i].prim, "trial %d: prim %zu moved",
                              trial, j + i);
                    }
                }
            }
            for (size_t j = 0; j < n; j += 4) {
                const int m = 1 + (int)((j / 4 + (size_t)trial) % 4); /* 1 to 4 at once */
                const float *four[4];
                for (int i = 0; i < m; i++)
                    four[i] = tris + 9 * ((j + (size_t)i) % n);
                const int got4 = kd_cone_tri_sphere4(&c, four, m);
                CHECK((got4 >> m) == 0, "trial %d: lanes past %d set", trial, m);
                for (int i = 0; i < m; i++) {
                    const int want = kd_cone_tri_sphere_may(&c, four[i]);
                    CHECK(kd_cone_tri_may_block(&c, four[i]) ==
                              (want && kd_cone_tri_rest_may(&c, four[i])),
                          "trial %d cone %d: the cull is not the sphere and the rest", trial, ci);
                    CHECK(((got4 >> i) & 1) == want,
                          "trial %d cone %d triangle %zu: four-wide sphere %d, scalar %d", trial,
                          ci, (j + (size_t)i) % n, (got4 >> i) & 1, want);
                    near += want;
                    far += !want;
                }
            }
        }
    }
    printf("cull4: %ld cones, %ld triangles kept, %ld dropped by the group cull; "
           "sphere test: %ld kept, %ld dropped; edge test: %ld miss, %ld not proved; each "
           "as the scalar test\n",
           cones, kept, dropped, near, far, miss, unsure);
    CHECK(miss > (miss + unsure) / 20 && unsure > (miss + unsure) / 20,
          "one edge answer is rare (%ld miss, %ld not proved)", miss, unsure);
    CHECK(near > (near + far) / 20 && far > (near + far) / 20,
          "one sphere answer is rare (%ld kept, %ld dropped)", near, far);
    CHECK(cones > 1000, "too few cones (%ld)", cones);
    CHECK(kept > (kept + dropped) / 20 && dropped > (kept + dropped) / 20,
          "one answer is rare (%ld kept, %ld dropped): the comparison says little", kept,
          dropped);
    free(soa.f);
    free(soa.prim);
    kdr_scene_free(s);
    free(b.v);
    if (failures) {
        fprintf(stderr, "test_cone_cull4: %d failure(s)\n", failures);
        return 1;
    }
    printf("test_cone_cull4: all passed\n");
    return 0;
}
