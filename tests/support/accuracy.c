/*
 * accuracy.c — the accuracy suite's driver, the per-ray judge, and the
 * single-ray and bundle runners. Bundles are fed both per-ray origins and
 * (for the watertightness probes) one shared origin, the two layouts the
 * HTTP bundle query produces.
 */
#include "accuracy_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const kind_names[ACC_NKINDS] = {
    "single", "bundle4", "bundle8", "frustum_multi4", "frustum_single",
    "cone_shadow",
};

const char *acc_kind_name(acc_kind k) {
    return (k >= 0 && k < ACC_NKINDS) ? kind_names[k] : "?";
}

void acc_opts_default(acc_opts *o) {
    o->seed = 20261123u;
    o->rays = 1000;
    o->cameras = 1;
    o->points = 48;
    o->samples = 32;
}

static int hit_same(const kdr_hit *a, const kdr_hit *b) {
    return a->prim == b->prim && memcmp(&a->t, &b->t, sizeof a->t) == 0 &&
           memcmp(&a->u, &b->u, sizeof a->u) == 0 &&
           memcmp(&a->v, &b->v, sizeof a->v) == 0;
}

void acc_judge(const stress_scene *s, const kdr_scene *kd, const oracle *o,
               const kdr_ray *r, const kdr_hit *kd_closest, int kd_any,
               int check_single, acc_result *res) {
    kdr_hit em;
    double e;
    const int em_hit = oracle_intersect1(o, r, &em);
    const cmp_class c = cmp_closest(s->tris, s->ntris, r, kd_closest, &em, &e);
    cmp_tally_add(&res->closest, r, c, e, em_hit);
    const int em_any = oracle_occluded1(o, r);
    const cmp_class ca = cmp_occluded(s->tris, s->ntris, r, kd_any, em_any,
                                      kd_closest, &em);
    cmp_tally_add(&res->any, r, ca, 0.0, em_any);
    int differs = 1;
    if (check_single) {
        kdr_hit h;
        kdr_intersect1(kd, r, &h, NULL);
        differs = !hit_same(&h, kd_closest) ||
                  kdr_occluded1(kd, r, NULL) != kd_any;
        if (differs && res->not_single++ == 0) {
            res->first_not_single = *r;
            res->first_not_single_scene = stress_scene_name(s->kind);
        }
    }
    if (differs && (cmp_is_unexplained(c) || cmp_is_unexplained(ca)))
        res->own_unexplained++;
}

/* ---- single rays ---------------------------------------------------------- */

static void run_single(const stress_scene *s, const kdr_scene *kd,
                       const oracle *o, const kdr_ray *rays, size_t n,
                       acc_result *res) {
    for (size_t i = 0; i < n; i++) {
        kdr_hit h;
        kdr_intersect1(kd, &rays[i], &h, NULL);
        acc_judge(s, kd, o, &rays[i], &h, kdr_occluded1(kd, &rays[i], NULL), 0,
                  res);
    }
}

static void inside_single(const kdr_scene *kd, const kdr_ray *rays, size_t n,
                          acc_result *res) {
    for (size_t i = 0; i < n; i++) {
        kdr_hit h;
        res->inside++;
        res->inside_miss += !kdr_intersect1(kd, &rays[i], &h, NULL) ||
                            !kdr_occluded1(kd, &rays[i], NULL);
    }
}

/* ---- bundles --------------------------------------------------------------- */

typedef struct batch_buf {
    float *org, *dir, *tmin, *tmax, *t, *u, *v;
    int32_t *prim;
    uint8_t *hit;
} batch_buf;

static void batch_free(batch_buf *b) {
    free(b->org); free(b->dir); free(b->tmin); free(b->tmax);
    free(b->t); free(b->u); free(b->v); free(b->prim); free(b->hit);
}

static int batch_alloc(batch_buf *b, size_t n) {
    memset(b, 0, sizeof *b);
    b->org = malloc(3 * n * sizeof(float));
    b->dir = malloc(3 * n * sizeof(float));
    b->tmin = malloc(n * sizeof(float));
    b->tmax = malloc(n * sizeof(float));
    b->t = malloc(n * sizeof(float));
    b->u = malloc(n * sizeof(float));
    b->v = malloc(n * sizeof(float));
    b->prim = malloc(n * sizeof(int32_t));
    b->hit = malloc(n);
    if (b->org && b->dir && b->tmin && b->tmax && b->t && b->u && b->v &&
        b->prim && b->hit)
        return 0;
    batch_free(b);
    return -1;
}

/* Traces rays[0..n) as one batch (shared origin when `shared`), closest and
 * any, into b. Returns the worse status of the two calls. */
static int trace_batch(const kdr_scene *kd, const kdr_ray *rays, size_t n,
                       int shared, kdr_trav_mode mode, batch_buf *b) {
    for (size_t i = 0; i < n; i++) {
        memcpy(b->org + 3 * i, rays[i].org, 3 * sizeof(float));
        memcpy(b->dir + 3 * i, rays[i].dir, 3 * sizeof(float));
        b->tmin[i] = rays[i].tmin;
        b->tmax[i] = rays[i].tmax;
    }
    const kdr_ray_batch batch = {n, b->org, shared ? 0 : 3, b->dir,
                                 b->tmin, 1, b->tmax, 1};
    kdr_hits closest = {b->t, b->prim, b->u, b->v, NULL};
    kdr_hits any = {NULL, NULL, NULL, NULL, b->hit};
    int rc = kdr_trace_batch(kd, &batch, 0, n, KDR_CLOSEST, mode, &closest, NULL);
    int rc2 = kdr_trace_batch(kd, &batch, 0, n, KDR_ANY, mode, &any, NULL);
    return rc != KDR_OK ? rc : rc2;
}

static void run_bundle(const stress_scene *s, const kdr_scene *kd,
                       const oracle *o, const kdr_ray *rays, size_t n,
                       kdr_trav_mode mode, acc_result *res) {
    batch_buf b;
    if (batch_alloc(&b, n) != 0 || trace_batch(kd, rays, n, 0, mode, &b) != 0) {
        res->errors++;
        batch_free(&b);
        return;
    }
    for (size_t i = 0; i < n; i++) {
        const kdr_hit h = {b.t[i], b.u[i], b.v[i], b.prim[i]};
        acc_judge(s, kd, o, &rays[i], &h, b.hit[i], 1, res);
    }
    batch_free(&b);
}

/* Inside rays of one closed region share their origin: the fast path. */
static void inside_bundle(const kdr_scene *kd, const kdr_ray *rays, size_t n,
                          kdr_trav_mode mode, acc_result *res) {
    batch_buf b;
    if (batch_alloc(&b, n) != 0 || trace_batch(kd, rays, n, 1, mode, &b) != 0) {
        res->errors++;
        batch_free(&b);
        return;
    }
    for (size_t i = 0; i < n; i++) {
        res->inside++;
        res->inside_miss += b.prim[i] < 0 || !b.hit[i];
    }
    batch_free(&b);
}

/* ---- driver -------------------------------------------------------------------- */

/* Inside rays of closed region c only (so that they share one origin). */
static size_t region_rays(const stress_scene *s, size_t c, uint64_t seed,
                          size_t n, kdr_ray *out) {
    stress_scene one = *s;
    one.closed = &s->closed[c];
    one.nclosed = 1;
    return stress_inside_rays(&one, seed + c, n, out);
}

static void run_rays(acc_kind k, const stress_scene *s, const kdr_scene *kd,
                     const oracle *o, const acc_opts *opt, kdr_ray *rays,
                     acc_result *res) {
    const kdr_trav_mode mode =
        k == ACC_BUNDLE8 ? KDR_TRAV_BUNDLE8 : KDR_TRAV_BUNDLE4;
    for (int rk = 0; rk < STRESS_NRAYS; rk++) {
        stress_rays(s, (stress_ray_kind)rk, opt->seed + (uint64_t)rk, opt->rays,
                    rays);
        if (k == ACC_SINGLE)
            run_single(s, kd, o, rays, opt->rays, res);
        else
            run_bundle(s, kd, o, rays, opt->rays, mode, res);
    }
    for (size_t c = 0; c < s->nclosed; c++) {
        const size_t n = region_rays(s, c, opt->seed, opt->rays / 4 + 1, rays);
        if (k == ACC_SINGLE)
            inside_single(kd, rays, n, res);
        else
            inside_bundle(kd, rays, n, mode, res);
    }
}

static int run_scene(acc_kind k, const stress_scene *s, const acc_opts *opt,
                     acc_result *res) {
    kdr_scene *kd = NULL;
    if (kdr_scene_build(s->tris, s->ntris, NULL, NULL, NULL, &kd) != KDR_OK)
        return -1;
    oracle_opts oo;
    oracle_opts_judge(&oo);
    oracle *o = oracle_create(s->tris, s->ntris, &oo);
    kdr_ray *rays = malloc((opt->rays + 1) * sizeof *rays);
    int rc = (!o || !rays) ? -1 : 0;
    if (rc == 0) {
        if (k == ACC_FRUSTUM_MULTI4 || k == ACC_FRUSTUM_SINGLE)
            rc = acc_run_frustum(s, kd, o,
                                 k == ACC_FRUSTUM_MULTI4 ? KDR_FRUSTUM_MULTI4
                                                         : KDR_FRUSTUM_SINGLE,
                                 opt, res);
        else if (k == ACC_CONE)
            rc = acc_run_cone(s, kd, o, opt, res);
        else
            run_rays(k, s, kd, o, opt, rays, res);
    }
    free(rays);
    oracle_free(o);
    kdr_scene_free(kd);
    return rc;
}

int acc_run(acc_kind k, const acc_opts *opt, acc_result *res) {
    for (int sk = 0; sk < STRESS_NSCENES; sk++) {
        stress_scene s;
        if (stress_scene_make((stress_scene_kind)sk, opt->seed, &s) != 0)
            return -1;
        const int rc = run_scene(k, &s, opt, res);
        stress_scene_free(&s);
        if (rc != 0)
            return -1;
    }
    return 0;
}

uint64_t acc_failures(const acc_result *r) {
    return r->own_unexplained + r->not_single + r->inside_miss + r->errors +
           r->vis_mismatch;
}

/* ---- printing -------------------------------------------------------------------- */

void acc_print_header(FILE *f) {
    fprintf(f, "| %-14s | %8s | %7s | %6s | %8s | %8s | %10s | %10s | %10s | "
               "%13s | %6s | %9s |\n",
            "query", "rays", "tie", "bound.", "ill-cond", "max t err",
            "unexpl. cl", "unexpl. any", "not single", "inside miss", "errors",
            "vis mism.");
    fprintf(f, "|%s|%s|%s|%s|%s|%s|%s|%s|%s|%s|%s|%s|\n", "----------------",
            "----------", "---------", "--------", "----------", "----------",
            "------------", "------------", "------------", "---------------",
            "--------", "-----------");
}

static uint64_t boundary_count(const cmp_tally *t) {
    return t->n[CMP_BOUNDARY] + t->n[CMP_INTERVAL_END] + t->n[CMP_PARALLEL];
}

void acc_print_row(FILE *f, acc_kind k, const acc_result *r) {
    const cmp_tally *c = k == ACC_CONE ? &r->any : &r->closest;
    char inside[32];
    snprintf(inside, sizeof inside, "%llu/%llu",
             (unsigned long long)r->inside_miss, (unsigned long long)r->inside);
    fprintf(f, "| %-14s | %8llu | %7llu | %6llu | %8llu | %8.2e | %10llu | "
               "%10llu | %10llu | %13s | %6llu | %9llu |\n",
            acc_kind_name(k), (unsigned long long)c->rays,
            (unsigned long long)c->n[CMP_TIE],
            (unsigned long long)(boundary_count(&r->closest) +
                                 boundary_count(&r->any)),
            (unsigned long long)c->n[CMP_ILL_COND], c->max_t_err,
            (unsigned long long)cmp_tally_unexplained(&r->closest),
            (unsigned long long)cmp_tally_unexplained(&r->any),
            (unsigned long long)r->not_single, inside,
            (unsigned long long)r->errors,
            (unsigned long long)r->vis_mismatch);
}

void acc_print_details(FILE *f, acc_kind k, const acc_result *r) {
    char label[64];
    snprintf(label, sizeof label, "%s closest", acc_kind_name(k));
    cmp_tally_print(f, label, &r->closest);
    cmp_tally_print_bad(f, label, &r->closest);
    snprintf(label, sizeof label, "%s any", acc_kind_name(k));
    cmp_tally_print(f, label, &r->any);
    cmp_tally_print_bad(f, label, &r->any);
    if (r->not_single) {
        const kdr_ray *x = &r->first_not_single;
        fprintf(f, "  %s first answer differing from kdr_intersect1/"
                   "kdr_occluded1 (scene %s): org %a %a %a dir %a %a %a "
                   "tmin %a tmax %a\n",
                acc_kind_name(k), r->first_not_single_scene, x->org[0], x->org[1], x->org[2], x->dir[0],
                x->dir[1], x->dir[2], x->tmin, x->tmax);
    }
    if (k == ACC_CONE)
        fprintf(f, "  cone pairs %llu, Embree fraction differs %llu\n",
                (unsigned long long)r->pairs,
                (unsigned long long)r->frac_differs);
}
