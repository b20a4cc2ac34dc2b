/*
 * bench_cone.c — the "cone" section (kdray_bench_cone; default scenes
 * "default", "engine" and the 1.09M-triangle "engine9"): soft-shadow
 * visibility toward a sphere light, run time against error.
 *
 * Points are the primary hits of a --res x --res camera, with the normal
 * of the triangle hit turned toward the viewer, and shadow rays start at
 * the contract's default ("auto") offset; each scene gets a small light
 * (points mostly lit or in umbra) and a large close one (penumbra-heavy).
 * For each sample count (--samples), in the same run:
 *   kd_cone   kdr_shadow_trace KDR_SHADOW_CONE, as the daemon calls it;
 *   kd_rays   kdr_shadow_trace KDR_SHADOW_RAYS (every sample walks the tree);
 *   embree_*  every rival API for shadow samples: rtcOccluded1 per sample,
 *             rtcOccluded8/16 packets of consecutive samples (a point's
 *             samples share packets; below the width, neighbours fill them).
 * kdray generates the sample rays inside its timed call, so Embree's timed
 * call generates them too, with the same sampler (rival_shadow_job): all
 * methods trace the same rays, hence have the same RMSE, and the ratio at
 * equal error is the time ratio. RMSE is against a --ref-samples reference
 * traced by robust Embree (0: no reference, as in --quick). With --out
 * PREFIX: PREFIX.csv, PREFIX.dat and PREFIX.png (bench/plot_cone.gp).
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bench.h"
#include "kd_cone.h" /* kd_shadow_trace_policy: cone_split's forced walks */
#include "rival.h"

/* The contract's default offset ("auto", API v1.1); CONE_OFFSET
 * KDR_OFFSET_DIAGONAL with CONE_EPSILON is v1's (1e-4 x diagonal). */
#ifndef CONE_OFFSET
#define CONE_OFFSET KDR_OFFSET_AUTO
#endif
#define CONE_EPSILON 1e-4f
#define CONE_MIN_MS 150.0 /* passes are short: keep each sample count this long */
#define CONE_QUICK_MIN_MS 40.0
/* Samples on which Embree's answer may differ from kdray's: fast mode
 * lets a few rays slip through shared edges. */
#define SAMPLE_TOLERANCE 0.001

#ifndef KDRAY_CONE_PLOT
#define KDRAY_CONE_PLOT "bench/plot_cone.gp"
#endif

typedef struct point_set {
    float *p, *n;
    size_t count;
} point_set;

static int camera_points(const kdr_scene *s, int res, point_set *ps) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    const float diag = kdr_scene_diagonal(s);
    const float dir[3] = {0.55f, 0.45f, 0.70f};
    kdr_camera cam = {.up = {0, 1, 0}, .fov_y_deg = 50.0f, .width = (uint32_t)res,
                      .height = (uint32_t)res};
    for (int k = 0; k < 3; k++) {
        cam.target[k] = 0.5f * (b.min[k] + b.max[k]);
        cam.eye[k] = cam.target[k] + 0.9f * diag * dir[k];
    }
    ps->p = malloc((size_t)res * res * 3 * sizeof(float));
    ps->n = malloc((size_t)res * res * 3 * sizeof(float));
    ps->count = 0;
    if (!ps->p || !ps->n)
        return -1;
    for (int y = 0; y < res; y++)
        for (int x = 0; x < res; x++) {
            kdr_ray r;
            kdr_hit h;
            kdr_camera_ray(&cam, (uint32_t)x, (uint32_t)y, &r);
            if (!kdr_intersect1(s, &r, &h, NULL))
                continue;
            const float *t = kdr_scene_triangle(s, (size_t)h.prim);
            float *p = ps->p + 3 * ps->count, *n = ps->n + 3 * ps->count, e1[3], e2[3];
            for (int k = 0; k < 3; k++) {
                /* in double: the hit point's own error stays that of t */
                p[k] = (float)((double)r.org[k] + (double)h.t * r.dir[k]);
                e1[k] = t[3 + k] - t[k];
                e2[k] = t[6 + k] - t[k];
            }
            n[0] = e1[1] * e2[2] - e1[2] * e2[1];
            n[1] = e1[2] * e2[0] - e1[0] * e2[2];
            n[2] = e1[0] * e2[1] - e1[1] * e2[0];
            /* facing the viewer, as a renderer shades the side it sees
             * (API v1.1 uses normals as given) */
            if (n[0] * r.dir[0] + n[1] * r.dir[1] + n[2] * r.dir[2] > 0.0f)
                for (int k = 0; k < 3; k++)
                    n[k] = -n[k];
            ps->count++;
        }
    return 0;
}

static void light_for(const kdr_scene *s, int large, kdr_sphere_light *li) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    const float diag = kdr_scene_diagonal(s);
    const float dir[3] = {-0.35f, 0.85f, 0.40f};
    const float dist = large ? 0.55f : 0.9f;
    for (int k = 0; k < 3; k++)
        li->center[k] = 0.5f * (b.min[k] + b.max[k]) + dist * diag * dir[k];
    li->radius = (large ? 0.25f : 0.03f) * diag;
}

/* Keeps only the points outside the light (the query rejects the others). */
static void points_outside(point_set *ps, const kdr_sphere_light *li) {
    size_t out = 0;
    for (size_t i = 0; i < ps->count; i++) {
        double d2 = 0;
        for (int k = 0; k < 3; k++) {
            const double d = ps->p[3 * i + k] - li->center[k];
            d2 += d * d;
        }
        if (d2 > 1.01 * li->radius * li->radius) {
            memmove(ps->p + 3 * out, ps->p + 3 * i, 3 * sizeof(float));
            memmove(ps->n + 3 * out, ps->n + 3 * i, 3 * sizeof(float));
            out++;
        }
    }
    ps->count = out;
}

/* ---- kdray's methods ----------------------------------------------------------- */

typedef struct kd_shadow {
    const kdr_scene *kd;
    const kdr_shadow_query *q;
    kdr_shadow_mode mode;
    float *vis;
    kdr_shadow_stats *stats;
    int rc;
} kd_shadow;

static void kd_shadow_run(void *ctx) {
    kd_shadow *k = ctx;
    const int rc = kdr_shadow_trace(k->kd, k->q, 0, k->q->n, k->mode, k->vis, k->stats);
    k->rc = k->rc ? k->rc : rc;
}

/* ---- plot files ---------------------------------------------------------------- */

static struct {
    FILE *csv, *dat;
    int blocks;
    char titles[1024];
    double lo, hi; /* best Embree time / cone time over n >= 4 */
} g_out = {NULL, NULL, 0, "", INFINITY, 0.0};

static int open_out(const bench_opts *o) {
    if (!o->out_prefix || g_out.csv)
        return 0;
    char f[1100];
    snprintf(f, sizeof f, "%s.csv", o->out_prefix);
    g_out.csv = fopen(f, "w");
    snprintf(f, sizeof f, "%s.dat", o->out_prefix);
    g_out.dat = fopen(f, "w");
    if (!g_out.csv || !g_out.dat) {
        fprintf(stderr, "bench cone: cannot write %s.*\n", o->out_prefix);
        return -1;
    }
    fprintf(g_out.csv,
            "scene,light,method,samples,seconds,rmse,rays,cones_decided,points\n");
    return 0;
}

/* ---- one scene, one light ------------------------------------------------------ */

static double rmse(const float *v, const float *ref, size_t n) {
    double se = 0.0;
    for (size_t i = 0; i < n; i++)
        se += ((double)v[i] - ref[i]) * ((double)v[i] - ref[i]);
    return sqrt(se / (double)n);
}

typedef struct row_out {
    double ms, rmse;
} row_out;

/* bench_measure in the methods' order, then in reverse, keeping each
 * method's best. In one fixed order kd_cone always ran right after the
 * Embree passes (and Embree's first API after kd_rays), so at 1-2 spp,
 * where a pass lasts a millisecond, it started with the other engine's
 * data in the caches: on the 1.09M-triangle scene kd_cone's 1-spp pass took
 * 1.47 ms where the same rays as kd_rays took 0.66 ms. Reversed, every
 * method also runs after one of its own kind. */
static void measure_both_orders(bench_method *m, size_t n, int repeat, double min_ms) {
    bench_method r[2 + RIVAL_MAX_APIS + 1];
    bench_measure(m, n, repeat, min_ms);
    for (size_t i = 0; i < n; i++)
        r[i] = m[n - 1 - i];
    bench_measure(r, n, repeat, min_ms);
    for (size_t i = 0; i < n; i++)
        m[n - 1 - i].best_ms = fmin(m[n - 1 - i].best_ms, r[i].best_ms);
}

/* One sample count: every method, interleaved. Fills out[0..2] = kd_cone,
 * kd_rays, best Embree. */
static int one_count(const bench_scene *s, const kdr_shadow_query *q, const float *ref,
                     const char *work, const bench_opts *o, row_out out[3],
                     uint64_t *decided) {
    rival_api apis[RIVAL_MAX_APIS + 1];
    const size_t napi = rival_apis(RIVAL_WORK_SHADOW, apis);
    /* a last, untraced job times the Embree side's sample generation */
    const size_t nr = napi + (o->quick ? 0 : 1), nm = 2 + nr;
    apis[napi] = apis[napi - 1];
    float *vis[2 + RIVAL_MAX_APIS + 1];
    kd_shadow ks[2] = {{s->kd, q, KDR_SHADOW_CONE, NULL, NULL, 0},
                       {s->kd, q, KDR_SHADOW_RAYS, NULL, NULL, 0}};
    rival_shadow_job rj[RIVAL_MAX_APIS + 1];
    bench_method m[2 + RIVAL_MAX_APIS + 1];
    int rc = 0;
    memset(rj, 0, sizeof rj);
    for (size_t i = 0; i < nm; i++)
        rc |= !(vis[i] = malloc(q->n * sizeof(float)));
    for (int i = 0; i < 2 && !rc; i++) {
        ks[i].vis = vis[i];
        m[i] =
            (bench_method){i ? "kd_rays" : "kd_cone", 0, NULL, kd_shadow_run, &ks[i], 0};
    }
    for (size_t i = 0; i < nr && !rc; i++) {
        rc |= rival_shadow_job_init(&rj[i], s->emb, apis[i], s->kd, q, vis[2 + i]);
        m[2 + i] = rival_shadow_job_method(&rj[i]);
        if (i == napi) {
            rj[i].trace = 0;
            snprintf(rj[i].name, sizeof rj[i].name, "raygen_only_shadow");
        }
    }
    if (!rc) {
        measure_both_orders(m, nm, o->repeat, o->quick ? CONE_QUICK_MIN_MS : CONE_MIN_MS);
        kdr_shadow_stats st = {0};
        ks[0].stats = &st;
        if (!isnan(m[0].best_ms))
            kd_shadow_run(&ks[0]); /* untimed: how many cones were decided */
        *decided = st.cones_decided;
        rc = ks[0].rc || ks[1].rc;
    }
    /* the strongest Embree API that ran (best == nm: none did) */
    size_t best = nm;
    for (size_t i = 2; i < 2 + napi && !rc; i++) {
        rc |= rj[i - 2].failed;
        if (!isnan(m[i].best_ms) && (best == nm || m[i].best_ms < m[best].best_ms))
            best = i;
    }
    const size_t samples = q->n * q->samples;
    const int have_rays = !isnan(m[1].best_ms); /* kd_rays: the reference answers */
    for (size_t i = 0; i < nm && !rc; i++) {
        if (isnan(m[i].best_ms))
            continue; /* left out by --method */
        bench_summary_add(s, work, m[i].name, samples, m[i].best_ms, -1);
        if (i == 0 && have_rays && memcmp(vis[0], vis[1], q->n * sizeof(float)))
            bench_fail("%s %s: kd_cone and kd_rays answers differ", s->name, work);
        double diff = 0.0;
        for (size_t p = 0; have_rays && i >= 2 && i < 2 + napi && p < q->n; p++)
            diff += fabs((double)vis[i][p] - vis[1][p]) * q->samples;
        if (diff > SAMPLE_TOLERANCE * (double)samples)
            bench_fail("%s %s: %s disagrees with kd on %.0f of %zu samples", s->name,
                       work, m[i].name, diff, samples);
    }
    if (!rc) {
        const size_t pick[3] = {0, 1, best};
        for (int k = 0; k < 3; k++)
            out[k] = pick[k] < nm && !isnan(m[pick[k]].best_ms)
                         ? (row_out){m[pick[k]].best_ms,
                                     ref ? rmse(vis[pick[k]], ref, q->n) : NAN}
                         : (row_out){NAN, NAN};
        printf("%8u %10.3f %10.3f %10.3f %-30s %8.2fx %8.2fx %9.5f %8.1f%%\n", q->samples,
               out[0].ms, out[1].ms, out[2].ms, best < nm ? m[best].name + 7 : "-",
               out[2].ms / out[0].ms, out[2].ms / out[1].ms, out[0].rmse,
               100.0 * (double)*decided / (double)q->n);
        if (nr > napi && !isnan(m[nm - 1].best_ms))
            printf("%8s Embree's sample generation alone: %.3f ms\n", "",
                   m[nm - 1].best_ms);
    }
    for (size_t i = 0; i < nm; i++)
        free(vis[i]);
    for (size_t i = 0; i < nr; i++)
        rival_shadow_job_free(&rj[i]);
    return rc ? -1 : 0;
}

static int one_light(const bench_scene *s, const rival *robust, point_set *ps, int large,
                     const bench_opts *o) {
    const char *lname = large ? "large" : "small";
    kdr_sphere_light li;
    light_for(s->kd, large, &li);
    points_outside(ps, &li);
    kdr_shadow_query q = {.n = ps->count, .points = ps->p, .normals = ps->n,
                          .lights = &li, .nlights = 1, .seed = 0x5eed,
                          .offset = CONE_OFFSET, .epsilon = CONE_EPSILON};
    float *ref = robust ? malloc(q.n * sizeof *ref) : NULL;
    printf("\n%s, %s light: %zu points", s->name, lname, q.n);
    if (ref) {
        rival_shadow_job rj;
        rival_api apis[RIVAL_MAX_APIS]; /* the widest coherent packets */
        const rival_api api = apis[rival_apis(RIVAL_WORK_SHADOW, apis) - 1];
        q.samples = (uint32_t)o->ref_samples;
        q.seed = 0xfeedbeef; /* independent of the measured estimates */
        const double t0 = bench_cpu_ms();
        if (rival_shadow_job_init(&rj, robust, api, s->kd, &q, ref) ||
            rival_shadow_job_once(&rj)) {
            rival_shadow_job_free(&rj);
            free(ref);
            return -1;
        }
        rival_shadow_job_free(&rj);
        size_t lit = 0, dark = 0;
        for (size_t i = 0; i < q.n; i++)
            lit += ref[i] == 1.0f, dark += ref[i] == 0.0f;
        printf(", lit %.1f%%, umbra %.1f%%, penumbra %.1f%% (reference: %d spp, robust "
               "Embree, %.1f s)",
               100.0 * lit / q.n, 100.0 * dark / q.n, 100.0 * (q.n - lit - dark) / q.n,
               o->ref_samples, (bench_cpu_ms() - t0) / 1e3);
        q.seed = 0x5eed;
    }
    printf("\n%8s %10s %10s %10s %-30s %9s %9s %9s %9s\n", "samples", "cone ms",
           "kd rays ms", "Embree ms", "strongest Embree API", "x Embree", "rays/Emb",
           "rmse", "decided");
    row_out res[BENCH_MAX_SAMPLES][3];
    int rc = 0, nrows = 0;
    for (int k = 0; k < o->nsamples && !rc; k++, nrows++) {
        char work[64];
        uint64_t decided = 0;
        q.samples = o->samples[k];
        snprintf(work, sizeof work, "shadow_%s_%uspp", lname, q.samples);
        rc = one_count(s, &q, ref, work, o, res[k], &decided);
        if (!rc && q.samples >= 4) {
            g_out.lo = fmin(g_out.lo, res[k][2].ms / res[k][0].ms);
            g_out.hi = fmax(g_out.hi, res[k][2].ms / res[k][0].ms);
        }
        static const char *const mname[3] = {"kd_cone", "kd_rays", "embree_best"};
        for (int m = 0; m < 3 && !rc && g_out.csv; m++)
            fprintf(g_out.csv, "%s,%s,%s,%u,%.6g,%.6g,%zu,%llu,%zu\n", s->name, lname,
                    mname[m], q.samples, res[k][m].ms / 1e3, res[k][m].rmse,
                    q.n * q.samples, (unsigned long long)(m ? 0 : decided), q.n);
    }
    if (!rc && g_out.dat && ref) {
        static const char *const series[3] = {"kd_cone", "kd_rays", "embree_best_API"};
        for (int m = 2; m >= 0; m--) { /* plot_cone.gp: Embree, kd rays, cone */
            fprintf(g_out.dat, "seconds %s\n", series[m]);
            for (int j = 0; j < nrows; j++)
                fprintf(g_out.dat, "%.6g %.6g\n", res[j][m].ms / 1e3, res[j][m].rmse);
            fprintf(g_out.dat, "\n\n");
        }
        const size_t used = strlen(g_out.titles);
        snprintf(g_out.titles + used, sizeof g_out.titles - used, "%s%s_%s_light",
                 used ? " " : "", s->name, lname);
        g_out.blocks++;
    }
    free(ref);
    return rc;
}

static int cone_run(const bench_scene *s, const bench_opts *o) {
    if (open_out(o))
        return -1;
    rival *robust =
        o->ref_samples ? rival_create(s->tris, s->ntris, 1, RIVAL_QUALITY) : NULL;
    if (o->ref_samples && !robust)
        return -1;
    printf("\n== %s: %zu triangles, cone shadows from %dx%d camera hits\n", s->name,
           s->ntris, o->res, o->res);
    int rc = 0;
    for (int large = 0; large < 2 && !rc; large++) {
        point_set ps;
        rc = camera_points(s->kd, o->res, &ps) || one_light(s, robust, &ps, large, o);
        free(ps.p);
        free(ps.n);
    }
    rival_free(robust);
    fflush(stdout);
    return rc;
}

static void cone_finish(const bench_opts *o) {
    if (g_out.hi > 0)
        printf("\n== cone: kd_cone against the strongest Embree API at equal samples "
               "(= equal rays, equal RMSE), 4 spp and up: %.2fx .. %.2fx\n",
               g_out.lo, g_out.hi);
    if (!g_out.csv)
        return;
    fclose(g_out.csv);
    fclose(g_out.dat);
    g_out.csv = g_out.dat = NULL;
    char cmd[2048];
    snprintf(cmd, sizeof cmd,
             "gnuplot -e \"datafile='%s.dat'; outfile='%s.png'; nblocks=%d; "
             "titles='%s'\" %s",
             o->out_prefix, o->out_prefix, g_out.blocks, g_out.titles, KDRAY_CONE_PLOT);
    if (g_out.blocks && system(cmd) == 0)
        printf("wrote %s.csv, %s.dat, %s.png\n", o->out_prefix, o->out_prefix,
               o->out_prefix);
    else
        printf("wrote %s.csv, %s.dat (no PNG: %s)\n", o->out_prefix, o->out_prefix,
               g_out.blocks ? "gnuplot failed" : "no reference, no RMSE");
}

const bench_section bench_cone_section = {"cone", cone_run, cone_finish};

/* ---- where the time goes (section "cone_split") ------------------------------- */

/* The same points, lights and samples as "cone", broken down (issue 12,
 * item 1): the share of points lit / in umbra / in penumbra (kd_rays'
 * answers at that sample count), what one sample costs the single-ray walk
 * (nodes and triangle tests, from kdr_occluded1's counters, by class), and
 * the query under each walk policy: the daemon's (auto), no walks (every
 * sample to the any-hit bundles) and forced walks, timed (CPU, best of
 * --repeat rounds of at least SPLIT_MIN_MS) with rays traced and nodes per
 * point; then each point alone under a forced walk (no light state carried
 * from its neighbours), to see what a walk decides in each class. Every
 * policy's answers must equal kd_rays' (bench_fail otherwise). No Embree:
 * its per-sample time is the "cone" section's table. */

#define SPLIT_MIN_MS 60.0

enum { CLS_LIT, CLS_UMBRA, CLS_PEN, CLS_N };
static const char *const cls_name[CLS_N] = {"lit", "umbra", "penumbra"};

static int cls_of(float v) { return v == 1.0f ? CLS_LIT : v == 0.0f ? CLS_UMBRA : CLS_PEN; }

typedef struct split_row {
    double ms;
    kdr_shadow_stats st;
} split_row;

/* Times kd_shadow_trace_policy over every point (best round); its stats
 * from one more untimed call; its answers compared with ref. */
static int split_policy(const bench_scene *s, const kdr_shadow_query *q, kdr_shadow_mode mode,
                        kd_walk_policy pol, int repeat, const float *ref, float *vis,
                        split_row *row) {
    row->ms = INFINITY;
    for (int r = 0; r < repeat; r++) {
        const double t0 = bench_cpu_ms();
        int calls = 0;
        do {
            if (kd_shadow_trace_policy(s->kd, q, 0, q->n, mode, pol, vis, NULL))
                return -1;
            calls++;
        } while (bench_cpu_ms() - t0 < SPLIT_MIN_MS);
        row->ms = fmin(row->ms, (bench_cpu_ms() - t0) / calls);
    }
    memset(&row->st, 0, sizeof row->st);
    if (kd_shadow_trace_policy(s->kd, q, 0, q->n, mode, pol, vis, &row->st))
        return -1;
    if (ref && memcmp(vis, ref, q->n * sizeof *vis)) {
        bench_fail("%s cone_split %u spp: walk policy %d differs from kd_rays", s->name,
                   q->samples, (int)pol);
        return -1;
    }
    return 0;
}

static int split_count(const bench_scene *s, kdr_shadow_query *q, const bench_opts *o,
                       float *ref, float *vis) {
    const size_t n = q->n;
    split_row rays, rows[3];
    if (split_policy(s, q, KDR_SHADOW_RAYS, KD_WALK_AUTO, o->repeat, NULL, ref, &rays))
        return -1;
    size_t npts[CLS_N] = {0};
    uint64_t nodes[CLS_N] = {0}, tests[CLS_N] = {0};
    for (size_t i = 0; i < n; i++) { /* the single-ray walk's work per sample */
        const int c = cls_of(ref[i]);
        npts[c]++;
        for (uint32_t k = 0; k < q->samples; k++) {
            kdr_ray r;
            kdr_trav_stats ts = {0};
            if (kdr_shadow_ray(s->kd, q, i, 0, k, &r))
                return -1;
            kdr_occluded1(s->kd, &r, &ts);
            nodes[c] += ts.nodes_visited;
            tests[c] += ts.tri_tests;
        }
    }
    static const kd_walk_policy pols[3] = {KD_WALK_AUTO, KD_WALK_NEVER, KD_WALK_ALWAYS};
    static const char *const pname[3] = {"auto", "never", "always"};
    for (int p = 0; p < 3; p++)
        if (split_policy(s, q, KDR_SHADOW_CONE, pols[p], o->repeat, ref, vis, &rows[p]))
            return -1;
    printf("\n%u spp, %zu points: lit %.1f%%, umbra %.1f%%, penumbra %.1f%% (kd_rays' "
           "answers); kd_rays %.3f ms\n",
           q->samples, n, 100.0 * npts[CLS_LIT] / n, 100.0 * npts[CLS_UMBRA] / n,
           100.0 * npts[CLS_PEN] / n, rays.ms);
    for (int c = 0; c < CLS_N; c++)
        if (npts[c])
            printf("  single-ray walk per sample, %-8s points: %6.1f nodes %6.1f "
                   "triangle tests\n",
                   cls_name[c], (double)nodes[c] / (npts[c] * (double)q->samples),
                   (double)tests[c] / (npts[c] * (double)q->samples));
    printf("  %-8s %9s %9s %12s %12s %9s\n", "policy", "ms", "x auto", "rays/point",
           "nodes/point", "decided");
    for (int p = 0; p < 3; p++)
        printf("  %-8s %9.3f %8.2fx %12.1f %12.1f %8.1f%%\n", pname[p], rows[p].ms,
               rows[0].ms / rows[p].ms, (double)rows[p].st.rays_traced / n,
               (double)rows[p].st.nodes_visited / n,
               100.0 * (double)rows[p].st.cones_decided / n);
    /* each point alone, forced to walk: what the walk decides per class */
    size_t dec[CLS_N] = {0};
    uint64_t traced[CLS_N] = {0}, walked[CLS_N] = {0};
    for (size_t i = 0; i < n; i++) {
        kdr_shadow_stats st = {0};
        if (kd_shadow_trace_policy(s->kd, q, i, 1, KDR_SHADOW_CONE, KD_WALK_ALWAYS, vis, &st))
            return -1;
        if (vis[i] != ref[i]) {
            bench_fail("%s cone_split %u spp: point %zu alone differs from kd_rays",
                       s->name, q->samples, i);
            return -1;
        }
        const int c = cls_of(ref[i]);
        dec[c] += st.cones_decided;
        traced[c] += st.rays_traced;
        walked[c] += st.nodes_visited;
    }
    for (int c = 0; c < CLS_N; c++)
        if (npts[c])
            printf("  alone, forced walk, %-8s points: %5.1f%% decided, %6.1f rays traced "
                   "and %7.1f nodes a point\n",
                   cls_name[c], 100.0 * dec[c] / npts[c], (double)traced[c] / npts[c],
                   (double)walked[c] / npts[c]);
    return 0;
}

static int split_run(const bench_scene *s, const bench_opts *o) {
    printf("\n== %s: %zu triangles, where cone-shadow time goes (%dx%d camera hits)\n",
           s->name, s->ntris, o->res, o->res);
    int rc = 0;
    for (int large = 0; large < 2 && !rc; large++) {
        point_set ps;
        kdr_sphere_light li;
        rc = camera_points(s->kd, o->res, &ps);
        if (!rc) {
            light_for(s->kd, large, &li);
            points_outside(&ps, &li);
            printf("\n%s, %s light", s->name, large ? "large" : "small");
        }
        kdr_shadow_query q = {.n = ps.count, .points = ps.p, .normals = ps.n,
                              .lights = &li, .nlights = 1, .seed = 0x5eed,
                              .offset = CONE_OFFSET, .epsilon = CONE_EPSILON};
        float *ref = rc ? NULL : malloc(q.n * sizeof *ref);
        float *vis = rc ? NULL : malloc(q.n * sizeof *vis);
        rc = rc || !ref || !vis;
        for (int k = 0; k < o->nsamples && !rc; k++) {
            q.samples = o->samples[k];
            rc = split_count(s, &q, o, ref, vis);
        }
        free(ref);
        free(vis);
        free(ps.p);
        free(ps.n);
    }
    fflush(stdout);
    return rc;
}

const bench_section bench_cone_split_section = {"cone_split", split_run, NULL};
