/*
 * test_embree.c — the kd-tree's single-ray queries (kdr_intersect1,
 * kdr_occluded1) against Embree 3, ray by ray.
 *
 *   test_embree stress [rays [brute]]  every stress scene x every ray kind
 *                                      and inside rays; with "brute", also
 *                                      bit-exact equality with the
 *                                      brute-force reference
 *   test_embree ladder DIR [max_tris [rays [KINDS]]]
 *                                      the real-scene ladder (DIR/ladder.txt),
 *                                      scenes up to max_tris triangles, rays
 *                                      per ray kind; KINDS a comma list of
 *                                      camera and stress ray kind names
 *                                      (default: all), or "-name,..." for
 *                                      all but those
 *
 * Fails on any unexplained disagreement (see tests/support/compare.h), any
 * ray from inside a closed mesh that misses, (stress brute) any
 * difference from brute force, and (with --caps NAME, anywhere on the
 * line) an explained class over its cap (tests/support/caps.h). Exit 77 when the ladder was never fetched (a
 * failure under ctest, whose scenes_fetch fixture fetches it first).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "caps.h"
#include "compare.h"
#include "kdray.h"
#include "ladder.h"
#include "oracle.h"
#include "stress.h"

#define SEED 20261123u
#define STRESS_RAYS 3000
#define LADDER_RAYS 20000
#define INSIDE_RAYS 4000
#define CAMERA_RES 128
#define SKIP 77

typedef struct suite {
    cmp_tally closest, any;
    uint64_t brute_mismatch, inside_miss, inside_rays, embree_inside_miss;
} suite;

static int hits_equal(const kdr_hit *a, const kdr_hit *b) {
    return a->prim == b->prim && memcmp(&a->t, &b->t, sizeof a->t) == 0 &&
           memcmp(&a->u, &b->u, sizeof a->u) == 0 &&
           memcmp(&a->v, &b->v, sizeof a->v) == 0;
}

/* One ray set on one scene: both queries against Embree, optionally both
 * against brute force. */
static void run_set(const char *label, const stress_scene *s,
                    const kdr_scene *kd, const oracle *o, const kdr_ray *rays,
                    size_t n, int brute, suite *out) {
    cmp_tally c, a;
    cmp_tally_init(&c);
    cmp_tally_init(&a);
    for (size_t i = 0; i < n; i++) {
        const kdr_ray *r = &rays[i];
        kdr_hit kh, eh;
        double e;
        kdr_intersect1(kd, r, &kh, NULL);
        const int eh_hit = oracle_intersect1(o, r, &eh);
        const cmp_class cl = cmp_closest(s->tris, s->ntris, r, &kh, &eh, &e);
        cmp_tally_add(&c, r, cl, e, eh_hit);
        const int ka = kdr_occluded1(kd, r, NULL), ea = oracle_occluded1(o, r);
        cmp_tally_add(&a, r,
                      cmp_occluded(s->tris, s->ntris, r, ka, ea, &kh, &eh),
                      0.0, ea);
        if (brute) {
            kdr_hit bh;
            ref_intersect1(s->tris, s->ntris, r, &bh);
            if (!hits_equal(&bh, &kh) ||
                ref_occluded1(s->tris, s->ntris, r) != ka) {
                if (out->brute_mismatch++ < 10)
                    printf("  %s: kd != brute force: prim %d/%d t %a/%a "
                           "ray org %a %a %a dir %a %a %a tmin %a tmax %a\n",
                           label, kh.prim, bh.prim, kh.t, bh.t, r->org[0],
                           r->org[1], r->org[2], r->dir[0], r->dir[1],
                           r->dir[2], r->tmin, r->tmax);
            }
        }
    }
    char l2[128];
    snprintf(l2, sizeof l2, "%s closest", label);
    cmp_tally_print(stdout, l2, &c);
    cmp_tally_print_bad(stdout, l2, &c);
    snprintf(l2, sizeof l2, "%s any", label);
    cmp_tally_print(stdout, l2, &a);
    cmp_tally_print_bad(stdout, l2, &a);
    cmp_tally_merge(&out->closest, &c);
    cmp_tally_merge(&out->any, &a);
}

static void run_inside(const char *label, const stress_scene *s,
                       const kdr_scene *kd, const oracle *o, suite *out) {
    kdr_ray *rays = malloc(INSIDE_RAYS * sizeof *rays);
    if (!rays)
        return;
    const size_t n = stress_inside_rays(s, SEED, INSIDE_RAYS, rays);
    uint64_t miss = 0, emiss = 0;
    for (size_t i = 0; i < n; i++) {
        kdr_hit h;
        const int ok = kdr_intersect1(kd, &rays[i], &h, NULL) &&
                       kdr_occluded1(kd, &rays[i], NULL);
        if (!ok && miss++ == 0)
            printf("  %s: inside ray missed: org %a %a %a dir %a %a %a\n",
                   label, rays[i].org[0], rays[i].org[1], rays[i].org[2],
                   rays[i].dir[0], rays[i].dir[1], rays[i].dir[2]);
        emiss += !oracle_intersect1(o, &rays[i], &h);
    }
    if (n)
        printf("%-34s inside rays %zu kd missed %llu (embree missed %llu)\n",
               label, n, (unsigned long long)miss, (unsigned long long)emiss);
    out->inside_rays += n;
    out->inside_miss += miss;
    out->embree_inside_miss += emiss;
    free(rays);
}

static int build_both(const stress_scene *s, kdr_scene **kd, oracle **o) {
    int rc = kdr_scene_build(s->tris, s->ntris, NULL, NULL, NULL, kd);
    if (rc != KDR_OK) {
        printf("kdr_scene_build: %s\n", kdr_strerror(rc));
        return -1;
    }
    oracle_opts oo;
    oracle_opts_judge(&oo);
    *o = oracle_create(s->tris, s->ntris, &oo);
    if (!*o) {
        kdr_scene_free(*kd);
        return -1;
    }
    return 0;
}

static int run_stress(size_t nrays, int brute, suite *out) {
    kdr_ray *rays = malloc(nrays * sizeof *rays);
    if (!rays)
        return -1;
    for (int k = 0; k < STRESS_NSCENES; k++) {
        stress_scene s;
        kdr_scene *kd;
        oracle *o;
        if (stress_scene_make((stress_scene_kind)k, SEED, &s) != 0 ||
            build_both(&s, &kd, &o) != 0) {
            free(rays);
            return -1;
        }
        for (int rk = 0; rk < STRESS_NRAYS; rk++) {
            char label[96];
            snprintf(label, sizeof label, "%s/%s", stress_scene_name(s.kind),
                     stress_ray_name((stress_ray_kind)rk));
            stress_rays(&s, (stress_ray_kind)rk, SEED + (uint64_t)rk, nrays,
                        rays);
            run_set(label, &s, kd, o, rays, nrays, brute, out);
        }
        run_inside(stress_scene_name(s.kind), &s, kd, o, out);
        oracle_free(o);
        kdr_scene_free(kd);
        stress_scene_free(&s);
    }
    free(rays);
    return 0;
}

/* Camera rays over the whole scene from outside its bounds. */
static void camera_rays(const kdr_scene *kd, kdr_ray *rays, size_t n) {
    kdr_bounds b;
    kdr_scene_bounds(kd, &b);
    const float diag = kdr_scene_diagonal(kd);
    kdr_camera cam = {.up = {0, 1, 0}, .fov_y_deg = 50.0f,
                      .width = CAMERA_RES, .height = CAMERA_RES};
    static const float view[3] = {0.55f, 0.35f, 0.75f};
    for (int k = 0; k < 3; k++) {
        cam.target[k] = 0.5f * (b.min[k] + b.max[k]);
        cam.eye[k] = cam.target[k] + diag * view[k];
    }
    for (size_t i = 0; i < n; i++) {
        const uint32_t p = (uint32_t)(i % (CAMERA_RES * CAMERA_RES));
        kdr_camera_ray(&cam, p % CAMERA_RES, p / CAMERA_RES, &rays[i]);
    }
}

/* Whether ray kind `name` is selected by the KINDS argument. */
static int kind_wanted(const char *kinds, const char *name) {
    if (!kinds || !*kinds)
        return 1;
    const int negate = kinds[0] == '-';
    const char *p = kinds + negate;
    const size_t n = strlen(name);
    int listed = 0;
    while (*p) {
        const size_t len = strcspn(p, ",");
        listed |= len == n && strncmp(p, name, n) == 0;
        p += len + (p[len] == ',');
    }
    return negate ? !listed : listed;
}

static int run_ladder_scene(const ladder_entry *e, size_t nrays,
                            const char *kinds, suite *out) {
    char err[512];
    stress_scene s = {.kind = STRESS_SOUP};
    if (ladder_load(e, &s.tris, &s.ntris, err, sizeof err) != 0) {
        printf("%s\n", err);
        return -1;
    }
    kdr_scene *kd;
    oracle *o;
    kdr_ray *rays = malloc(nrays * sizeof *rays);
    if (!rays || build_both(&s, &kd, &o) != 0) {
        free(rays);
        free(s.tris);
        return -1;
    }
    printf("%s: %zu triangles\n", e->name, s.ntris);
    char label[160];
    if (kind_wanted(kinds, "camera")) {
        camera_rays(kd, rays, nrays);
        snprintf(label, sizeof label, "%s/camera", e->name);
        run_set(label, &s, kd, o, rays, nrays, 0, out);
    }
    for (int rk = 0; rk < STRESS_RAYS_MIXED; rk++) {
        if (!kind_wanted(kinds, stress_ray_name((stress_ray_kind)rk)))
            continue;
        stress_rays(&s, (stress_ray_kind)rk, SEED + (uint64_t)rk, nrays, rays);
        snprintf(label, sizeof label, "%s/%s", e->name,
                 stress_ray_name((stress_ray_kind)rk));
        run_set(label, &s, kd, o, rays, nrays, 0, out);
    }
    free(rays);
    oracle_free(o);
    kdr_scene_free(kd);
    free(s.tris);
    return 0;
}

static int run_ladder(const char *dir, size_t max_tris, size_t nrays,
                      const char *kinds, suite *out) {
    ladder_entry *v;
    char err[512];
    const int n = ladder_read(dir, &v, err, sizeof err);
    if (n < 0) {
        printf("%s\n", err);
        return SKIP;
    }
    int rc = 0, ran = 0;
    for (int i = 0; i < n && rc == 0; i++) {
        if (v[i].triangles > max_tris)
            continue;
        rc = run_ladder_scene(&v[i], nrays, kinds, out);
        ran++;
    }
    free(v);
    printf("ladder: %d scenes\n", ran);
    return rc != 0 || ran == 0 ? -1 : 0;
}

int main(int argc, char **argv) {
    suite s;
    memset(&s, 0, sizeof s);
    cmp_tally_init(&s.closest);
    cmp_tally_init(&s.any);
    int rc;
    const char *caps = caps_arg(&argc, argv);
    if (argc >= 2 && strcmp(argv[1], "stress") == 0) {
        rc = run_stress(argc >= 3 ? strtoul(argv[2], NULL, 10) : STRESS_RAYS,
                        argc >= 4 && strcmp(argv[3], "brute") == 0, &s);
    } else if (argc >= 3 && strcmp(argv[1], "ladder") == 0) {
        rc = run_ladder(argv[2],
                        argc >= 4 ? strtoul(argv[3], NULL, 10) : (size_t)-1,
                        argc >= 5 ? strtoul(argv[4], NULL, 10) : LADDER_RAYS,
                        argc >= 6 ? argv[5] : NULL, &s);
        if (rc == SKIP)
            return SKIP;
    } else {
        fprintf(stderr,
                "usage: %s [--caps NAME] stress [rays [brute]] | "
                "ladder DIR [max_tris [rays [KINDS]]]\n",
                argv[0]);
        return 2;
    }
    cmp_tally_print(stdout, "TOTAL closest", &s.closest);
    cmp_tally_print(stdout, "TOTAL any", &s.any);
    const uint64_t bad = cmp_tally_unexplained(&s.closest) +
                         cmp_tally_unexplained(&s.any);
    printf("unexplained %llu, brute-force mismatches %llu, inside misses "
           "%llu of %llu (embree %llu)\n",
           (unsigned long long)bad, (unsigned long long)s.brute_mismatch,
           (unsigned long long)s.inside_miss,
           (unsigned long long)s.inside_rays,
           (unsigned long long)s.embree_inside_miss);
    const int over = caps_check(stdout, caps, "TOTAL closest", &s.closest) +
                     caps_check(stdout, caps, "TOTAL any", &s.any);
    return rc != 0 || bad != 0 || s.brute_mismatch != 0 || s.inside_miss != 0 ||
           over != 0;
}
