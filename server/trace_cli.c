/*
 * trace_cli.c — kdray-trace: answers one query request file with direct core
 * calls, no HTTP, and prints the response body exactly as kdrayd would. The
 * integration tests compare the daemon's answers with these byte for byte;
 * the service benchmark uses --repeat to time the core in-process.
 *
 *   kdray-trace [--scene PATH] --kind bundle|cone-shadow|frustum
 *               [--mode reference|fast] [--threads T] [--repeat R] REQUEST.json
 *   kdray-trace [--scene PATH] KIND:MODE:REQUEST.json...   (-> REQUEST.json.out)
 *
 * reference (default): one thread, single-ray / per-pixel / per-sample core
 * modes over the whole range; fast: the modes kdrayd uses (bundles, four
 * frusta at a time, cones), split over T threads like the daemon.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_gltf.h"
#include "kdr_protocol.h"
#include "log.h"
#include "pool.h"

typedef struct cli {
    const char *scene_path, *kind;
    int fast;
    unsigned threads, repeat;
    char **requests; /* argv entries: PATH, or KIND:MODE:PATH */
    int nrequests;
} cli;

typedef struct job {
    const kdr_scene *scene;
    int fast;
    kdr_query query;
    kdr_hits hits;
    const kdr_ray_batch *batch;
    const kdr_frustum_request *fr;
    const kdr_shadow_query *sq;
    float *vis;
    kdr_shadow_stats *stats;
    size_t total, per;
    atomic_int rc;
} job;

static char *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    char *p = NULL;
    size_t cap = 0, n = 0, got;
    do {
        if (n == cap) {
            char *q = realloc(p, cap = cap ? 2 * cap : 65536);
            if (!q) break;
            p = q;
        }
        got = fread(p + n, 1, cap - n, f);
        n += got;
    } while (got > 0);
    fclose(f);
    *len = n;
    return p;
}

static void range_of(const job *j, size_t c, size_t *first, size_t *count) {
    *first = c * j->per;
    *count = j->total - *first < j->per ? j->total - *first : j->per;
}

static void bundle_chunk(void *ctx, size_t c) {
    job *j = ctx;
    size_t f, n;
    range_of(j, c, &f, &n);
    int rc = kdr_trace_batch(j->scene, j->batch, f, n, j->query,
                             j->fast ? KDR_TRAV_AUTO : KDR_TRAV_SINGLE, &j->hits, NULL);
    if (rc) atomic_store(&j->rc, rc);
}

static void frustum_chunk(void *ctx, size_t c) {
    job *j = ctx;
    size_t f, n;
    range_of(j, c, &f, &n);
    int rc = kdr_frustum_trace(j->scene, &j->fr->camera, j->fr->tile, f, n, j->query,
                               j->fast ? KDR_FRUSTUM_MULTI4 : KDR_FRUSTUM_RAYS, &j->hits,
                               NULL);
    if (rc) atomic_store(&j->rc, rc);
}

static void shadow_chunk(void *ctx, size_t c) {
    job *j = ctx;
    size_t f, n;
    range_of(j, c, &f, &n);
    int rc = kdr_shadow_trace(j->scene, j->sq, f, n,
                              j->fast ? KDR_SHADOW_CONE : KDR_SHADOW_RAYS, j->vis,
                              &j->stats[c]);
    if (rc) atomic_store(&j->rc, rc);
}

static int hits_alloc(kdr_hits *h, size_t n, kdr_query q) {
    memset(h, 0, sizeof *h);
    size_t m = n ? n : 1;
    if (q == KDR_ANY) return (h->hit = malloc(m)) ? 0 : -1;
    h->t = malloc(m * sizeof(float));
    h->prim = malloc(m * sizeof(int32_t));
    h->u = malloc(m * sizeof(float));
    h->v = malloc(m * sizeof(float));
    return h->t && h->prim && h->u && h->v ? 0 : -1;
}

static void hits_free(kdr_hits *h) {
    free(h->t);
    free(h->prim);
    free(h->u);
    free(h->v);
    free(h->hit);
}

/* Runs the job `repeat` times; logs the best and the mean rate (the mean
 * is what a loaded machine really delivers, comparable to HTTP rates). */
static void run(kdr_pool *pool, job *j, kdr_pool_fn fn, size_t rays, unsigned repeat) {
    size_t nchunks = (j->total + j->per - 1) / j->per;
    double best = 1e30, t_start = kdr_now();
    for (unsigned r = 0; r < repeat; r++) {
        double t0 = kdr_now();
        kdr_pool_run(pool, nchunks, fn, j);
        double dt = kdr_now() - t0;
        if (dt < best) best = dt;
    }
    double mean = (kdr_now() - t_start) / repeat;
    if (repeat > 1)
        fprintf(stderr,
                "kdray-trace: %zu rays, %u runs: best %.3f ms, %.3f Mrays/s; mean "
                "%.3f ms, %.3f Mrays/s\n",
                rays, repeat, best * 1e3, (double)rays / best * 1e-6, mean * 1e3,
                (double)rays / mean * 1e-6);
}

static int do_hits(kdr_pool *pool, job *j, kdr_pool_fn fn, size_t n, kdr_encoding enc,
                   unsigned repeat, kdr_buf *out) {
    if (hits_alloc(&j->hits, n, j->query) != 0) return KDR_ENOMEM;
    run(pool, j, fn, n, repeat);
    int rc = atomic_load(&j->rc);
    if (rc == 0) rc = kdr_proto_encode_hits(&j->hits, n, j->query, enc, out);
    hits_free(&j->hits);
    return rc;
}

static int do_bundle(kdr_pool *pool, job *j, const char *body, size_t len, const cli *c,
                     kdr_buf *out, kdr_proto_error *err) {
    kdr_bundle_request br;
    if (kdr_proto_parse_bundle(body, len, (size_t)1 << 32, &br, err)) {
        kdr_bundle_request_free(&br);
        return err->status;
    }
    j->batch = &br.batch;
    j->query = br.query;
    j->total = br.batch.n;
    j->per = c->fast ? KDR_CHUNK_RAYS : br.batch.n;
    int rc = do_hits(pool, j, bundle_chunk, br.batch.n, br.encoding, c->repeat, out);
    kdr_bundle_request_free(&br);
    return rc;
}

static int do_frustum(kdr_pool *pool, job *j, const char *body, size_t len, const cli *c,
                      kdr_buf *out, kdr_proto_error *err) {
    kdr_frustum_request fr;
    if (kdr_proto_parse_frustum(body, len, (size_t)1 << 32, &fr, err)) return err->status;
    j->fr = &fr;
    j->query = fr.query;
    j->total = kdr_frustum_tile_count(&fr.camera, fr.tile);
    j->per = c->fast ? KDR_CHUNK_TILES : j->total;
    return do_hits(pool, j, frustum_chunk, fr.rays, fr.encoding, c->repeat, out);
}

static int do_shadow(kdr_pool *pool, job *j, const char *body, size_t len, const cli *c,
                     kdr_buf *out, kdr_proto_error *err) {
    kdr_shadow_request sr;
    if (kdr_proto_parse_shadow(body, len, (size_t)1 << 32, &sr, err) ||
        kdr_proto_check_shadow_scene(&sr, kdr_scene_diagonal(j->scene), err)) {
        kdr_shadow_request_free(&sr);
        return err->status;
    }
    j->sq = &sr.query;
    j->total = sr.query.n;
    j->per = c->fast ? KDR_CHUNK_POINTS : (sr.query.n ? sr.query.n : 1);
    size_t nchunks = (j->total + j->per - 1) / j->per;
    j->vis = malloc((sr.query.n * sr.query.nlights + 1) * sizeof(float));
    j->stats = calloc(nchunks + 1, sizeof(kdr_shadow_stats));
    int rc = j->vis && j->stats ? 0 : KDR_ENOMEM;
    if (rc == 0) {
        run(pool, j, shadow_chunk, sr.query.n * sr.query.nlights, c->repeat);
        kdr_shadow_stats sum = {0};
        for (size_t i = 0; i < nchunks; i++) {
            sum.cones_decided += j->stats[i].cones_decided;
            sum.rays_traced += j->stats[i].rays_traced;
            sum.nodes_visited += j->stats[i].nodes_visited;
        }
        rc = atomic_load(&j->rc);
        if (rc == 0)
            rc = kdr_proto_encode_shadow(j->vis, sr.query.n, sr.query.nlights,
                                         sr.want_stats ? &sum : NULL, sr.encoding, out);
    }
    free(j->vis);
    free(j->stats);
    kdr_shadow_request_free(&sr);
    return rc;
}

static int usage(void) {
    fprintf(stderr, "usage: kdray-trace [--scene PATH] --kind bundle|cone-shadow|frustum "
                    "[--mode reference|fast] [--threads T] [--repeat R] REQUEST.json\n");
    return 2;
}

static int parse_cli(cli *c, int argc, char **argv) {
    *c = (cli){.threads = 1, .repeat = 1, .requests = argv};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (a[0] != '-') {
            c->requests[c->nrequests++] = argv[i];
            continue;
        }
        if (!v) return -1;
        i++;
        if (!strcmp(a, "--scene"))
            c->scene_path = v;
        else if (!strcmp(a, "--kind"))
            c->kind = v;
        else if (!strcmp(a, "--mode"))
            c->fast = !strcmp(v, "fast");
        else if (!strcmp(a, "--threads"))
            c->threads = (unsigned)atoi(v);
        else if (!strcmp(a, "--repeat"))
            c->repeat = (unsigned)atoi(v);
        else
            return -1;
    }
#ifdef KDRAY_DEFAULT_SCENE
    if (!c->scene_path) c->scene_path = KDRAY_DEFAULT_SCENE;
#endif
    if (!c->scene_path || !c->nrequests || c->threads < 1 || c->repeat < 1) return -1;
    return 0;
}

static kdr_scene *load_scene(const char *path) {
    kdr_gltf_scene g;
    char err[512];
    if (kdr_gltf_load(path, &g, err, sizeof err)) {
        fprintf(stderr, "kdray-trace: %s\n", err);
        return NULL;
    }
    kdr_scene *s = NULL;
    kdr_build_opts opts;
    kdr_build_opts_default(&opts);
    int rc = kdr_scene_build(g.tris, g.ntris, &opts, NULL, NULL, &s);
    kdr_gltf_free(&g);
    if (rc) fprintf(stderr, "kdray-trace: build: %s\n", kdr_strerror(rc));
    return rc ? NULL : s;
}

/* Writes the answer to stdout (path NULL) or to path + ".out". */
static int write_out(const char *path, const kdr_buf *out) {
    FILE *f = stdout;
    char name[4096];
    if (path) {
        snprintf(name, sizeof name, "%s.out", path);
        if (!(f = fopen(name, "wb"))) {
            perror(name);
            return 1;
        }
    }
    int bad = fwrite(out->data, 1, out->len, f) != out->len;
    if (path) bad |= fclose(f) != 0;
    return bad;
}

static int dispatch(kdr_pool *pool, job *j, const cli *c, const char *body, size_t len,
                    kdr_buf *out, kdr_proto_error *err) {
    if (!strcmp(c->kind, "bundle")) return do_bundle(pool, j, body, len, c, out, err);
    if (!strcmp(c->kind, "frustum")) return do_frustum(pool, j, body, len, c, out, err);
    if (!strcmp(c->kind, "cone-shadow"))
        return do_shadow(pool, j, body, len, c, out, err);
    return kdr_proto_error_set(err, 404, "unknown kind %s", c->kind);
}

/* Answers one request: a plain PATH goes to stdout with --kind/--mode; a
 * KIND:MODE:PATH spec (several per run share one scene build) goes to
 * PATH.out. Returns 0 or 1. */
static int answer_one(kdr_pool *pool, const kdr_scene *scene, cli c, char *spec) {
    char *path = spec, *k = NULL, *m = NULL;
    if (strchr(spec, ':') && strchr(strchr(spec, ':') + 1, ':')) {
        k = spec;
        m = strchr(spec, ':');
        *m++ = '\0';
        path = strchr(m, ':');
        *path++ = '\0';
        c.kind = k;
        c.fast = !strcmp(m, "fast");
    }
    if (!c.kind) {
        usage();
        return 1;
    }
    size_t len = 0;
    char *body = read_file(path, &len);
    if (!body) {
        perror(path);
        return 1;
    }
    job j = {.scene = scene, .fast = c.fast};
    atomic_init(&j.rc, 0);
    kdr_buf out;
    kdr_buf_init(&out);
    kdr_proto_error err = {0};
    int rc = dispatch(pool, &j, &c, body, len, &out, &err);
    if (rc == 0)
        rc = write_out(k ? path : NULL, &out);
    else if (err.status)
        fprintf(stderr, "kdray-trace: %s: %d %s\n", path, err.status, err.detail);
    else
        fprintf(stderr, "kdray-trace: %s: core error %s\n", path, kdr_strerror(rc));
    kdr_buf_free(&out);
    free(body);
    return rc ? 1 : 0;
}

int main(int argc, char **argv) {
    cli c;
    if (parse_cli(&c, argc, argv)) return usage();
    kdr_scene *scene = load_scene(c.scene_path);
    kdr_pool *pool = kdr_pool_create(c.threads - 1);
    int rc = !scene || !pool;
    for (int i = 0; i < c.nrequests && !rc; i++)
        rc = answer_one(pool, scene, c, c.requests[i]);
    kdr_pool_destroy(pool);
    kdr_scene_free(scene);
    return rc;
}
