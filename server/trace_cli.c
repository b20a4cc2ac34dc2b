/*
 * trace_cli.c — kdray-trace: answers query request files through the same
 * executor as kdrayd (exec/: parse, chunks over worker threads, encode),
 * without HTTP, and prints each response body exactly as kdrayd would. The
 * integration tests compare the daemon's answers with these byte for byte;
 * the service benchmark uses --repeat to time the tracing in-process.
 *
 *   kdray-trace [--scene PATH] --kind bundle|cone-shadow|frustum|closest-point|occupancy
 *               [--mode reference|fast] [--threads T] [--repeat R]
 *               [--content-type TYPE] [--accept TYPE] REQUEST.json|REQUEST.cbor
 *   kdray-trace [--scene PATH] KIND:MODE:REQUEST.json...   (-> REQUEST.json.out)
 *
 * reference (default): single-ray / per-pixel / per-sample core modes;
 * fast: the modes kdrayd uses (bundles, four frusta at a time, cones). T
 * workers split every request into the daemon's chunks (the answer does not
 * depend on T), and the kd-tree is built on T threads (the same tree as on
 * one). With --repeat R the request runs R times and the best and
 * mean tracing time (chunks only: no parse, no encode) are printed.
 * A file whose name ends in ".cbor" is read as application/cbor, any other
 * as application/json; --content-type and --accept take the values of the
 * HTTP headers and mean what they mean to kdrayd (without --accept the
 * answer has the body's media type).
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_default_scene.h"
#include "kdr_exec.h"
#include "kdr_gltf.h"

typedef struct cli {
    const char *scene_path, *kind;
    const char *content_type, *accept; /* NULL: by file name / as the body */
    int fast;
    unsigned threads, repeat;
    char **requests; /* argv entries: PATH, or KIND:MODE:PATH */
    int nrequests;
} cli;

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

static int kind_of(const char *name, kdr_exec_kind *out) {
    if (!strcmp(name, "bundle"))
        *out = KDR_EXEC_BUNDLE;
    else if (!strcmp(name, "frustum"))
        *out = KDR_EXEC_FRUSTUM;
    else if (!strcmp(name, "cone-shadow"))
        *out = KDR_EXEC_CONE_SHADOW;
    else if (!strcmp(name, "closest-point"))
        *out = KDR_EXEC_CLOSEST_POINT;
    else if (!strcmp(name, "occupancy"))
        *out = KDR_EXEC_OCCUPANCY;
    else
        return -1;
    return 0;
}

/* The number of rays the timing line divides by: bundle rays, frustum
 * pixels, cone-shadow points x lights (as before the executor existed). */
static size_t rays_of(kdr_exec_kind kind, kdr_media media, const char *body, size_t len) {
    kdr_proto_error err;
    size_t n = 0;
    const size_t max = (size_t)1 << 32;
    if (kind == KDR_EXEC_BUNDLE) {
        kdr_bundle_request r;
        if (!kdr_proto_parse_bundle_as(media, body, len, max, &r, &err)) n = r.batch.n;
        kdr_bundle_request_free(&r);
    } else if (kind == KDR_EXEC_FRUSTUM) {
        kdr_frustum_request r;
        if (!kdr_proto_parse_frustum_as(media, body, len, max, &r, &err)) n = r.rays;
    } else if (kind == KDR_EXEC_OCCUPANCY) {
        kdr_occupancy_request r;
        if (!kdr_proto_parse_occupancy_as(media, body, len, max, &r, &err)) n = r.n;
        kdr_occupancy_request_free(&r);
    } else if (kind == KDR_EXEC_CLOSEST_POINT) {
        kdr_closest_request r;
        if (!kdr_proto_parse_closest_as(media, body, len, max, &r, &err)) n = r.n;
        kdr_closest_request_free(&r);
    } else {
        kdr_shadow_request r;
        if (!kdr_proto_parse_shadow_as(media, body, len, max, &r, &err))
            n = r.query.n * r.query.nlights;
        kdr_shadow_request_free(&r);
    }
    return n;
}

/* The body's media type: --content-type, else by the file name. */
static kdr_media media_of(const cli *c, const char *path) {
    if (c->content_type) return kdr_proto_media_of(c->content_type);
    size_t n = strlen(path);
    return n >= 5 && !strcmp(path + n - 5, ".cbor") ? KDR_MEDIA_CBOR : KDR_MEDIA_JSON;
}

/* Runs the request `repeat` times; keeps the last answer in *q; logs the
 * best and the mean tracing rate (the mean is what a loaded machine really
 * delivers, comparable to HTTP rates). */
static void run(kdr_exec *ex, kdr_exec_query *q, unsigned repeat) {
    double best = 1e30, sum = 0;
    for (unsigned r = 0; r < repeat; r++) {
        if (r) kdr_exec_query_done(q);
        if (kdr_exec_submit(ex, q) != 0) {
            q->result.status = 503;
            snprintf(q->result.detail, sizeof q->result.detail, "out of memory");
            return;
        }
        kdr_exec_wait(q, -1);
        if (q->result.status != 200) return;
        double dt = q->result.trace_s;
        sum += dt;
        if (dt < best) best = dt;
    }
    if (repeat > 1) {
        size_t rays = rays_of(q->kind, q->media, q->body, q->len);
        double mean = sum / repeat;
        fprintf(stderr,
                "kdray-trace: %zu rays, %u runs: best %.3f ms, %.3f Mrays/s; mean "
                "%.3f ms, %.3f Mrays/s\n",
                rays, repeat, best * 1e3, (double)rays / best * 1e-6, mean * 1e3,
                (double)rays / mean * 1e-6);
    }
}

static int usage(void) {
    fprintf(
        stderr,
        "usage: kdray-trace [--scene PATH] --kind "
        "bundle|cone-shadow|frustum|closest-point|occupancy "
        "[--mode reference|fast] [--threads T] [--repeat R]\n"
        "                   [--content-type TYPE] [--accept TYPE] REQUEST.json|.cbor\n"
        "       kdray-trace [--scene PATH] [--threads T] KIND:MODE:REQUEST.json...\n"
        "A .cbor file is read as application/cbor, others as application/json;\n"
        "--content-type and --accept work as the HTTP headers do for kdrayd.\n");
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
        else if (!strcmp(a, "--content-type"))
            c->content_type = v;
        else if (!strcmp(a, "--accept"))
            c->accept = v;
        else
            return -1;
    }
    if (!c->nrequests || c->threads < 1 || c->repeat < 1) return -1;
    return 0;
}

/* The scene and its glTF ranges (for the "mesh" field), as kdrayd has them. */
typedef struct trace_scene {
    kdr_scene *scene;
    kdr_proto_mesh_range *meshes;
    size_t nmeshes;
} trace_scene;

static int load_scene(const char *path, unsigned threads, trace_scene *out) {
    kdr_gltf_scene g;
    char err[512];
    memset(out, 0, sizeof *out);
    if (kdr_gltf_load(path, &g, err, sizeof err)) {
        fprintf(stderr, "kdray-trace: %s\n", err);
        return -1;
    }
    kdr_build_opts opts;
    kdr_build_opts_default(&opts);
    opts.threads = (int)threads; /* the same tree on any count */
    int rc = kdr_scene_build(g.tris, g.ntris, &opts, NULL, NULL, &out->scene);
    out->meshes = calloc(g.nranges ? g.nranges : 1, sizeof *out->meshes);
    if (!rc && !out->meshes) rc = KDR_ENOMEM;
    for (size_t i = 0; !rc && i < g.nranges; i++)
        out->meshes[i] = (kdr_proto_mesh_range){
            g.ranges[i].node, g.ranges[i].mesh, g.ranges[i].primitive,
            g.ranges[i].first_prim, g.ranges[i].count};
    out->nmeshes = g.nranges;
    kdr_gltf_free(&g);
    if (rc) fprintf(stderr, "kdray-trace: build: %s\n", kdr_strerror(rc));
    return rc ? -1 : 0;
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

/* Answers one request: a plain PATH goes to stdout with --kind/--mode; a
 * KIND:MODE:PATH spec (several per run share one scene build) goes to
 * PATH.out. Returns 0 or 1. */
static int answer_one(kdr_exec *ex, const trace_scene *ts, cli c, char *spec) {
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
    kdr_exec_kind kind;
    if (!c.kind || kind_of(c.kind, &kind) != 0) return usage(), 1;
    kdr_media media = media_of(&c, path);
    if (media == KDR_MEDIA_OTHER) {
        fprintf(stderr,
                "kdray-trace: --content-type %s: expected application/json or "
                "application/cbor\n",
                c.content_type);
        return 1;
    }
    size_t len = 0;
    char *body = read_file(path, &len);
    if (!body) {
        perror(path);
        return 1;
    }
    kdr_exec_query q = {.kind = kind,
                        .mode = c.fast ? KDR_EXEC_FAST : KDR_EXEC_REFERENCE,
                        .scene = ts->scene,
                        .meshes = ts->meshes,
                        .nmeshes = ts->nmeshes,
                        .body = body,
                        .len = len,
                        .media = media,
                        .answer_media = kdr_proto_answer_media(c.accept, media),
                        .max_rays = (size_t)1 << 32,
                        .start = kdr_exec_now()};
    run(ex, &q, c.repeat);
    int rc = q.result.status == 200 ? write_out(k ? path : NULL, &q.result.body) : 1;
    if (q.result.status != 200)
        fprintf(stderr, "kdray-trace: %s: %d %s\n", path, q.result.status,
                q.result.detail);
    if (q.job) kdr_exec_query_done(&q);
    free(body);
    return rc ? 1 : 0;
}

int main(int argc, char **argv) {
    cli c;
    char default_path[4096];
    if (parse_cli(&c, argc, argv)) return usage();
    if (!c.scene_path)
        c.scene_path = kdr_default_scene_path(default_path, sizeof default_path);
    trace_scene ts;
    const int loaded = load_scene(c.scene_path, c.threads, &ts) == 0;
    kdr_exec_config cfg = {c.threads, (size_t)c.nrequests, 0, NULL, NULL};
    kdr_exec *ex = loaded ? kdr_exec_create(&cfg) : NULL;
    int rc = !loaded || !ex;
    for (int i = 0; i < c.nrequests && !rc; i++)
        rc = answer_one(ex, &ts, c, c.requests[i]);
    kdr_exec_destroy(ex);
    kdr_scene_free(ts.scene);
    free(ts.meshes);
    return rc;
}
