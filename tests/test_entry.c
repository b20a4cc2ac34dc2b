/*
 * test_entry.c — entry points for rays that share an origin
 * (core/kd_entry.h) against the single walk, ray by ray, bit for bit.
 *
 * For every ray: kd_entry_occluded1 must equal kd_occluded1_fwd (the
 * front-to-back single walk; kdr_occluded1 walks finite rays far end
 * first) and
 * kd_entry_intersect1 must equal kdr_intersect1 (t, u, v, prim bits), with
 * the same work (nodes entered, triangle tests: the replayed levels count
 * as the nodes the single walk steps through, so a walk that starts one
 * level too deep or too shallow, or with another interval, shows here even
 * where the answer survives); kd_entry_descend16 (AVX-512) must return the
 * scalar replay's node, level, interval and stack bits; kdr_trace_batch
 * must give the single answers for batches of runs, and so must the 4-, 8-
 * and 16-lane bundle drivers, whose bundles of one origin replay its path
 * (kb_replay), with the work of the same drivers walking from the root.
 *
 * Rays: test_bundle's twelve sets on its three scenes (random soup;
 * lattice of axis-aligned quads, whose integer split planes hold origins
 * and rays; closed sphere), and sets built for entry points: AO-like runs
 * of 64 rays from points on the scene's triangles (hemisphere and full
 * sphere directions, some components +-0); origins on a split plane of
 * their own path at every depth; origins exactly the slack from such a
 * plane with the direction +-0 on its axis (the crossing is NaN); each
 * with intervals [tmin, tmax] of AO length, zero length (tmin == tmax, at
 * 0 and inside), tmax huge (1e30) and infinite, tmax tiny, and tmin > 0
 * beyond the scene. Exit 1 on any difference.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_entry.h"
#include "kd_stream.h"
#include "kd_traverse_bundle.h"
#include "kd_walk.h"
#include "kdray.h"
#include "test_bundle_sets.h"

static int failures;
static size_t rays_checked, deep_entries, pushed;

static uint64_t rng = 0x2545F4914F6CDD1Dull;
static uint32_t rnd(void) {
    rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
    return (uint32_t)(rng >> 32);
}
static float rnd01(void) { return (float)(rnd() >> 8) * 0x1p-24f; }

static int same_f(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

static void fail(const char *scene, const char *set, size_t i, const char *what) {
    if (failures < 20) fprintf(stderr, "FAIL %s/%s ray %zu: %s\n", scene, set, i, what);
    failures++;
}

/* One ray against the single walk; p is the path of r's origin. */
static void check_ray(const char *scene, const char *set, size_t i, const kdr_scene *s,
                      const kd_entry_path *p, const kdr_ray *r) {
    rays_checked++;
    kdr_trav_stats a = {0}, b = {0};
    const int o1 = kd_occluded1_fwd(s, r, &a);
    const int o2 = kd_entry_occluded1(s, p, r, &b);
    if (o1 != o2) fail(scene, set, i, "occluded differs");
    if (a.nodes_visited != b.nodes_visited || a.tri_tests != b.tri_tests)
        fail(scene, set, i, "any-hit work differs");
    kdr_hit h1, h2;
    memset(&a, 0, sizeof a), memset(&b, 0, sizeof b);
    const int f1 = kdr_intersect1(s, r, &h1, &a);
    const int f2 = kd_entry_intersect1(s, p, r, &h2, &b);
    if (f1 != f2 || !same_f(h1.t, h2.t) || !same_f(h1.u, h2.u) || !same_f(h1.v, h2.v) ||
        h1.prim != h2.prim)
        fail(scene, set, i, "closest hit differs");
    if (a.nodes_visited != b.nodes_visited || a.tri_tests != b.tri_tests)
        fail(scene, set, i, "closest-hit work differs");
    float inv[3], ss[3], tn, tf;
    unsigned neg[3];
    if (!kd_walk_setup(s, r, inv, ss, neg, &tn, &tf)) return;
    float tn2 = tn, tf2 = tf;
    int l1, l2, sp1, sp2;
    kd_todo st1[KD_MAX_DEPTH], st2[KD_MAX_DEPTH];
    const kd_node *e1 =
        kd_entry_descend_scalar(p, r->org, inv, ss, neg, &tn, &tf, &l1, st1, &sp1);
    deep_entries += l1 > 0;
    pushed += (size_t)sp1;
    if (!p->wide) return;
    const kd_node *e2 = kd_entry_descend16(p, inv, ss, &tn2, &tf2, &l2, st2, &sp2);
    int same = e1 == e2 && l1 == l2 && same_f(tn, tn2) && same_f(tf, tf2) && sp1 == sp2;
    for (int k = 0; same && k < sp1; k++)
        same = st1[k].node == st2[k].node && same_f(st1[k].tn, st2[k].tn) &&
               same_f(st1[k].tf, st2[k].tf);
    if (!same) fail(scene, set, i, "kd_entry_descend16 differs from the scalar replay");
}

/* A batch of n rays in runs of one origin through kdr_trace_batch (AUTO;
 * its interleaved walk starts runs at their entries) against
 * kdr_occluded1 / kdr_intersect1. */
static void check_batch(const char *scene, const char *set, const kdr_scene *s,
                        const kdr_ray *rays, size_t n) {
    float *org = malloc(n * 3 * sizeof(float)), *dir = malloc(n * 3 * sizeof(float));
    float *tmin = malloc(n * sizeof(float)), *tmax = malloc(n * sizeof(float));
    uint8_t *hit = malloc(n);
    float *t = malloc(n * sizeof(float)), *u = malloc(n * sizeof(float)),
          *v = malloc(n * sizeof(float));
    int32_t *prim = malloc(n * sizeof(int32_t));
    if (!org || !dir || !tmin || !tmax || !hit || !t || !u || !v || !prim) {
        fail(scene, set, 0, "out of memory");
        goto done;
    }
    for (size_t i = 0; i < n; i++) {
        memcpy(org + 3 * i, rays[i].org, sizeof rays[i].org);
        memcpy(dir + 3 * i, rays[i].dir, sizeof rays[i].dir);
        tmin[i] = rays[i].tmin;
        tmax[i] = rays[i].tmax;
    }
    const kdr_ray_batch b = {.n = n,
                             .org = org,
                             .org_stride = 3,
                             .dir = dir,
                             .tmin = tmin,
                             .tmin_stride = 1,
                             .tmax = tmax,
                             .tmax_stride = 1};
    kdr_hits out = {.hit = hit, .t = t, .u = u, .v = v, .prim = prim};
    /* ways: kdr_trace_batch, then the interleaved walk's 16- and 8-lane
     * forms (their refill starts runs at their entries), plain and staged */
    for (int way = 0; way < 5; way++)
        for (int q = 0; q < 2; q++) {
            const kdr_query query = q ? KDR_CLOSEST : KDR_ANY;
            const int lanes = way == 1 || way == 2 ? 16 : 8;
            const int flags = way == 2 || way == 4 ? KD_STREAM_STAGE : 0;
            if (way && !(lanes == 16 ? kd_cpu_has_avx512() : kdr_cpu_has_avx2()))
                continue;
            kdr_trav_stats st = {0}, ref = {0};
            if (way == 0) {
                if (kdr_trace_batch(s, &b, 0, n, query, KDR_TRAV_AUTO, &out, NULL) !=
                    KDR_OK)
                    fail(scene, set, 0, "kdr_trace_batch failed");
            } else if (lanes == 16) {
                kd_stream_trace16(s, &b, NULL, 0, n, query, flags, &out, &st);
            } else {
                kd_stream_trace8(s, &b, NULL, 0, n, query, flags, &out, &st);
            }
            for (size_t i = 0; i < n; i++) {
                if (!q) {
                    if (hit[i] != (uint8_t)kd_occluded1_fwd(s, &rays[i], &ref))
                        fail(scene, set, i, way ? "stream any hit" : "batch any hit");
                    continue;
                }
                kdr_hit h;
                kdr_intersect1(s, &rays[i], &h, &ref);
                if (!same_f(h.t, t[i]) || !same_f(h.u, u[i]) || !same_f(h.v, v[i]) ||
                    h.prim != prim[i])
                    fail(scene, set, i, way ? "stream closest hit" : "batch closest hit");
            }
            if (way && (st.rays != ref.rays || st.nodes_visited != ref.nodes_visited ||
                        st.tri_tests != ref.tri_tests))
                fail(scene, set, 0, "stream work sums differ from the single walk's");
        }
    /* the bundle drivers (4, 8, 16 lanes, no fallback): bundles of one
     * origin replay the top of their walk along its path once a run of
     * them has it (kb_replay); answers equal the single walk's, and the
     * work equals the same driver's with every walk from the root */
    typedef void (*bundle_fn)(const kdr_scene *, const kdr_ray_batch *, size_t, size_t,
                              kdr_query, int, kdr_hits *, kdr_trav_stats *);
    static const bundle_fn fns[3] = {kd_bundle4_trace, kd_bundle8_trace, kd_bundle16_trace};
    for (int w = 0; w < 3; w++) {
        if ((w == 1 && !kdr_cpu_has_avx2()) || (w == 2 && !kd_cpu_has_avx512()))
            continue;
        for (int q = 0; q < 2; q++) {
            const kdr_query query = q ? KDR_CLOSEST : KDR_ANY;
            kdr_trav_stats st[2] = {{0}, {0}};
            for (int root = 1; root >= 0; root--) {
                fns[w](s, &b, 0, n, query, root ? KB_ROOT : 0, &out, &st[root]);
                for (size_t i = 0; i < n; i++) {
                    if (!q) {
                        if (hit[i] != (uint8_t)kdr_occluded1(s, &rays[i], NULL))
                            fail(scene, set, i, "bundle any hit");
                        continue;
                    }
                    kdr_hit h;
                    kdr_intersect1(s, &rays[i], &h, NULL);
                    if (!same_f(h.t, t[i]) || !same_f(h.u, u[i]) || !same_f(h.v, v[i]) ||
                        h.prim != prim[i])
                        fail(scene, set, i, "bundle closest hit");
                }
            }
            if (st[0].rays != st[1].rays || st[0].nodes_visited != st[1].nodes_visited ||
                st[0].tri_tests != st[1].tri_tests)
                fail(scene, set, (size_t)w, "bundle work with entries differs from the root's");
        }
    }
done:
    free(org), free(dir), free(tmin), free(tmax), free(hit), free(t), free(u), free(v),
        free(prim);
}

/* Intervals every entry set cycles through (reach: the AO length). */
static void interval(kdr_ray *r, size_t i, float reach) {
    switch (i % 8) {
    case 0:
        r->tmin = 1e-4f * reach, r->tmax = reach;
        break;
    case 1:
        r->tmin = r->tmax = 0.0f;
        break;
    case 2:
        r->tmin = r->tmax = 0.5f * reach;
        break;
    case 3:
        r->tmin = 0.0f, r->tmax = 1e30f;
        break;
    case 4:
        r->tmin = 0.0f, r->tmax = INFINITY;
        break;
    case 5:
        r->tmin = 0.0f, r->tmax = 1e-6f * reach;
        break;
    case 6:
        r->tmin = 40.0f * reach, r->tmax = INFINITY;
        break;
    default:
        r->tmin = 1e-3f * reach, r->tmax = 0.1f * reach;
        break;
    }
}

static void random_dir(float d[3], int zeros) {
    do {
        for (int k = 0; k < 3; k++)
            d[k] = 2.0f * rnd01() - 1.0f;
    } while (d[0] == 0.0f && d[1] == 0.0f && d[2] == 0.0f);
    if (zeros && rnd() % 3 == 0) d[rnd() % 3] = (rnd() & 1) ? -0.0f : 0.0f;
}

/* The walk's slack for an origin (kd_walk_setup's, in its operations). */
static float slack_of(const kdr_scene *s, const float o[3]) {
    float m = s->root_mag;
    for (int k = 0; k < 3; k++)
        m = fabsf(o[k]) > m ? fabsf(o[k]) : m;
    return m * KD_SLACK_REL;
}

/* Runs of 64 rays per origin: kind 0 points on triangles, 1 an origin moved
 * onto a split plane of its own path, 2 moved to the slack from one with
 * direction +-0 on that axis. */
static void entry_set(const char *scene, const scene_src *src, const kdr_scene *s,
                      int kind) {
    static const char *names[] = {"entry-surface", "entry-on-split", "entry-slack-plane"};
    const size_t per = 64, norg = 24, n = per * norg;
    kdr_ray *rays = malloc(n * sizeof *rays);
    if (!rays) {
        fail(scene, names[kind], 0, "out of memory");
        return;
    }
    const float reach = 0.1f * kdr_scene_diagonal(s);
    kd_entry_path p;
    for (size_t g = 0; g < norg; g++) {
        float o[3], w[3] = {rnd01(), rnd01(), 0};
        if (w[0] + w[1] > 1.0f) w[0] = 1.0f - w[0], w[1] = 1.0f - w[1];
        w[2] = 1.0f - w[0] - w[1];
        const float *tri = src->tris + 9 * (rnd() % src->ntris);
        for (int k = 0; k < 3; k++)
            o[k] = w[0] * tri[k] + w[1] * tri[3 + k] + w[2] * tri[6 + k];
        int axis = -1;
        if (kind) {
            kd_entry_path_init(s, o, &p);
            if (p.depth > 0) {
                const int lv = (int)(rnd() % (unsigned)p.depth);
                axis = p.lv[lv].axis;
                o[axis] = p.lv[lv].split;
                if (kind == 2) {
                    /* a = split - org = +-slack exactly where the slack is
                     * a power of two and the split a multiple of it */
                    const float sl = slack_of(s, o);
                    o[axis] = p.lv[lv].split + ((rnd() & 1) ? sl : -sl);
                }
            }
        }
        kd_entry_path_init(s, o, &p);
        for (size_t j = 0; j < per; j++) {
            kdr_ray *r = &rays[g * per + j];
            memcpy(r->org, o, sizeof o);
            random_dir(r->dir, 1);
            if (kind == 2 && axis >= 0) r->dir[axis] = (rnd() & 1) ? -0.0f : 0.0f;
            if (r->dir[0] == 0.0f && r->dir[1] == 0.0f && r->dir[2] == 0.0f)
                r->dir[(axis + 1) % 3] = 1.0f;
            interval(r, j, reach);
            check_ray(scene, names[kind], g * per + j, s, &p, r);
        }
    }
    check_batch(scene, names[kind], s, rays, n);
    free(rays);
}

static void check_scene(const scene_src *src, int integer) {
    kdr_scene *s = NULL;
    if (kdr_scene_build(src->tris, src->ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "FAIL: building %s\n", src->name);
        failures++;
        return;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s, &bb);
    rayset sets[RAYS_NSETS];
    rays_every_set(src, s, &bb, integer, sets);
    kd_entry_path p;
    for (size_t k = 0; k < RAYS_NSETS; k++) {
        const rayset *rs = &sets[k];
        kdr_ray *rays = malloc(rs->n * sizeof *rays);
        for (size_t i = 0; rays && i < rs->n; i++) {
            const float *o = rs->org + (rs->shared_org ? 0 : 3 * i);
            kdr_ray *r = &rays[i];
            for (int c = 0; c < 3; c++)
                r->org[c] = o[c], r->dir[c] = rs->dir[3 * i + c];
            r->tmin = rs->tmin[i];
            r->tmax = rs->tmax[i];
            if (i == 0 || !rs->shared_org) kd_entry_path_init(s, r->org, &p);
            check_ray(src->name, rs->name, i, s, &p, r);
        }
        if (rays) check_batch(src->name, rs->name, s, rays, rs->n);
        free(rays);
        rays_free(&sets[k]);
    }
    for (int kind = 0; kind < 3; kind++)
        entry_set(src->name, src, s, kind);
    kdr_scene_free(s);
}

int main(void) {
    scene_src scenes[] = {make_soup(3000), make_lattice(6, 0.3f), make_sphere(24, 48)};
    for (size_t k = 0; k < sizeof scenes / sizeof scenes[0]; k++) {
        check_scene(&scenes[k], k == 1);
        free(scenes[k].tris);
    }
    printf("entry: %zu rays, %zu entered below the root, %zu entries pushed on the way,"
           " %d failures\n",
           rays_checked, deep_entries, pushed, failures);
    /* a test whose rays all start at the root would prove nothing */
    if (deep_entries * 4 < rays_checked) {
        fprintf(stderr, "FAIL: only %zu of %zu rays entered below the root\n",
                deep_entries, rays_checked);
        failures++;
    }
    return failures ? 1 : 0;
}
