/*
 * test_embree_ref.c — checks the test machinery itself, without the
 * kd-tree: on every stress scene and ray kind, the brute-force reference
 * (core/kd_tri.h over all triangles) must agree with Embree up to proven
 * boundary cases, and every ray from inside a closed region must hit. If
 * this fails, the oracle, the generator or the judge is wrong, not the
 * kd-tree. With --caps NAME the explained classes are bounded too
 * (tests/support/caps.h).
 *
 *   test_embree_ref [--caps NAME]
 */
#include <stdio.h>
#include <stdlib.h>

#include "caps.h"
#include "compare.h"
#include "oracle.h"
#include "stress.h"

#define RAYS_PER_KIND 2000
#define INSIDE_RAYS 2000
#define SEED 12345u

static int check_scene(stress_scene_kind kind, cmp_tally *all) {
    stress_scene s;
    if (stress_scene_make(kind, SEED, &s) != 0)
        return 1;
    oracle_opts oo;
    oracle_opts_judge(&oo);
    oracle *o = oracle_create(s.tris, s.ntris, &oo);
    kdr_ray *rays = malloc(RAYS_PER_KIND * sizeof *rays);
    int fail = !o || !rays;
    for (int rk = 0; !fail && rk < STRESS_NRAYS; rk++) {
        cmp_tally t;
        char label[96];
        cmp_tally_init(&t);
        stress_rays(&s, (stress_ray_kind)rk, SEED, RAYS_PER_KIND, rays);
        for (size_t i = 0; i < RAYS_PER_KIND; i++) {
            kdr_hit ref, em;
            double e;
            ref_intersect1(s.tris, s.ntris, &rays[i], &ref);
            int h = oracle_intersect1(o, &rays[i], &em);
            const cmp_class c =
                cmp_closest(s.tris, s.ntris, &rays[i], &ref, &em, &e);
            cmp_tally_add(&t, &rays[i], c, e, h);
        }
        snprintf(label, sizeof label, "%s/%s", stress_scene_name(kind),
                 stress_ray_name((stress_ray_kind)rk));
        cmp_tally_print(stdout, label, &t);
        cmp_tally_print_bad(stdout, label, &t);
        cmp_tally_merge(all, &t);
    }
    kdr_ray *in = malloc(INSIDE_RAYS * sizeof *in);
    size_t nin = in ? stress_inside_rays(&s, SEED, INSIDE_RAYS, in) : 0;
    size_t missed = 0;
    for (size_t i = 0; i < nin; i++) {
        kdr_hit h;
        if (!ref_intersect1(s.tris, s.ntris, &in[i], &h)) {
            if (missed++ == 0)
                printf("  inside ray missed: org %a %a %a dir %a %a %a\n",
                       in[i].org[0], in[i].org[1], in[i].org[2], in[i].dir[0],
                       in[i].dir[1], in[i].dir[2]);
        }
    }
    printf("%-34s inside rays %zu missed %zu\n", stress_scene_name(kind), nin,
           missed);
    fail |= missed != 0;
    free(in);
    free(rays);
    oracle_free(o);
    stress_scene_free(&s);
    return fail;
}

int main(int argc, char **argv) {
    const char *caps = caps_arg(&argc, argv);
    cmp_tally all;
    int fail = 0;
    if (argc > 1) {
        fprintf(stderr, "usage: %s [--caps NAME]\n", argv[0]);
        return 2;
    }
    cmp_tally_init(&all);
    for (int k = 0; k < STRESS_NSCENES; k++)
        fail |= check_scene((stress_scene_kind)k, &all);
    cmp_tally_print(stdout, "TOTAL brute force vs Embree", &all);
    const unsigned long long bad = cmp_tally_unexplained(&all);
    printf("unexplained: %llu\n", bad);
    fail |= caps_check(stdout, caps, "TOTAL brute force vs Embree", &all) != 0;
    return fail || bad != 0;
}
