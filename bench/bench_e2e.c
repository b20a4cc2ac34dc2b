/*
 * bench_e2e.c — kdray as a user meets it against Embree at its best in the
 * user's own process (issue 16's end-to-end target). Not a test.
 *
 *   kdray_bench_e2e KDRAYD KDRAY_TRACE [--dir LADDER] [--only NAME]...
 *                   [--rays N] [--repeat R] [--threads T] [--workload W]...
 *
 * For each ladder scene (default haus and engine = 2CylinderEngine) it
 * starts kdrayd with T worker threads (default 2) on the scene (at the
 * HTTP threads' priority, --worker-nice 0, as Embree's threads run here:
 * on a shared machine niced workers would lose the CPU to the neighbours), and for
 * each workload (camera, random, ao_any, shadow: bench.h; N rays, default
 * 1M) it times, interleaved, R passes (default 3, the best kept) of:
 *  - kdrayd: one CBOR bundle request over a keep-alive loopback connection
 *    (float32 typed arrays, aligned so kdrayd reads them in place; one
 *    origin where all rays share it; the workload's query, default fields),
 *    wall time from the first byte sent to the last byte of the answer read;
 *  - Embree: the rival of rival.h (fast scene, high-quality BVH, FTZ/DAZ,
 *    rays converted into its structs before timing) traced by T threads of
 *    this process that take 4096-ray chunks from a shared counter, for every
 *    API rival_apis lists for the work; the fastest is the headline.
 * Both are wall time (T threads each). kdrayd's Server-Timing header splits
 * its time into the body's arrival, parse, trace and encode; the rest is
 * the answer's transfer. kdray-trace on the same request file (the
 * daemon's executor in-process, tracing only) is the in-process reference. kdrayd's and
 * Embree's hit counts must agree within 0.1% (the fast intersectors are not watertight),
 * else the run fails. The last line is the geometric mean over every scene and workload
 * of Embree ms / kdrayd ms (the target: >= 0.5).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "bench.h"
#include "ladder.h"
#include "rival.h"

#define CHUNK 4096
#define MAX_LIST 16

typedef struct opts {
    const char *kdrayd, *trace, *dir;
    const char *only[MAX_LIST], *work[MAX_LIST];
    int nonly, nwork;
    size_t rays;
    int repeat;
    unsigned threads;
} opts;

static double wall_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static void *xmalloc(size_t n) {
    void *p = malloc(n ? n : 1);
    if (!p) {
        fprintf(stderr, "bench_e2e: out of memory\n");
        exit(2);
    }
    return p;
}

/* ---- the daemon ------------------------------------------------------------------ */

typedef struct daemon_proc {
    pid_t pid;
    FILE *log;
    int port;
    pthread_t drain;
} daemon_proc;

static void *drain_log(void *arg) { /* what kdrayd logs while it serves: errors */
    daemon_proc *d = arg;
    char *line = NULL;
    size_t cap = 0;
    while (getline(&line, &cap, d->log) > 0)
        if (!strstr(line, "SIGTERM") && !strstr(line, "shutdown:") &&
            !strstr(line, "stopped (exit 0)"))
            fprintf(stderr, "  kdrayd: %s", line);
    free(line);
    return NULL;
}

static int daemon_start(daemon_proc *d, const opts *o, const char *scene_path) {
    int p[2];
    if (pipe(p) != 0) return -1;
    char threads[16], scene[1100];
    snprintf(threads, sizeof threads, "%u", o->threads);
    snprintf(scene, sizeof scene, "default=%s", scene_path);
    d->pid = fork();
    if (d->pid == 0) {
        dup2(p[1], 2);
        close(p[0]), close(p[1]);
        execl(o->kdrayd, o->kdrayd, "--listen", "127.0.0.1:0", "--threads", threads,
              "--scene", scene, "--max-body-mb", "128", "--max-rays", "16777216",
              "--worker-nice", "0", (char *)NULL);
        perror(o->kdrayd);
        _exit(127);
    }
    close(p[1]);
    d->log = fdopen(p[0], "r");
    d->port = 0;
    char *line = NULL;
    size_t cap = 0;
    int ready = 0;
    while (!ready && getline(&line, &cap, d->log) > 0) {
        const char *at = strstr(line, "listening on http://127.0.0.1:");
        if (at) d->port = atoi(at + strlen("listening on http://127.0.0.1:"));
        ready = strstr(line, "ready:") != NULL;
    }
    free(line);
    if (!ready || !d->port) {
        fprintf(stderr, "bench_e2e: kdrayd did not become ready\n");
        return -1;
    }
    pthread_create(&d->drain, NULL, drain_log, d);
    return 0;
}

static void daemon_stop(daemon_proc *d) {
    kill(d->pid, SIGTERM);
    waitpid(d->pid, NULL, 0);
    pthread_join(d->drain, NULL);
    fclose(d->log);
}

/* ---- HTTP/1.1 over one keep-alive connection ------------------------------------- */

static int http_connect(int port) {
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    const int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    struct sockaddr_in a = {.sin_family = AF_INET,
                            .sin_port = htons((uint16_t)port),
                            .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    if (connect(fd, (struct sockaddr *)&a, sizeof a) != 0) {
        perror("bench_e2e: connect");
        close(fd);
        return -1;
    }
    return fd;
}

static int write_all(int fd, const void *p, size_t n) {
    const char *c = p;
    while (n) {
        const ssize_t k = send(fd, c, n, MSG_NOSIGNAL);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) return -1;
        c += k, n -= (size_t)k;
    }
    return 0;
}

typedef struct inbuf {
    char *p;
    size_t len, cap, pos; /* pos: parse position */
} inbuf;

static int fill(int fd, inbuf *b, size_t want) { /* until len - pos >= want */
    while (b->len - b->pos < want) {
        if (b->cap - b->len < 65536) {
            b->cap = b->cap * 2 + 65536;
            b->p = realloc(b->p, b->cap);
            if (!b->p) return -1;
        }
        /* one byte stays free: the header scan NUL-terminates */
        const ssize_t k = recv(fd, b->p + b->len, b->cap - b->len - 1, 0);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) return -1;
        b->len += (size_t)k;
    }
    return 0;
}

/* Milliseconds from the first byte sent to the answer's last byte read,
 * and kdrayd's own account of them. */
typedef struct times {
    double done;
    double srv[5]; /* Server-Timing: body, queue, parse, trace, encode (ms) */
} times;

/* POSTs body; reads the whole answer (by its Content-Length) into *ans.
 * Returns the HTTP status, -1 on a transport error. */
static int http_post(int fd, const char *path, const unsigned char *body, size_t len,
                     inbuf *in, unsigned char **ans, size_t *anslen, times *tm) {
    const double t0 = wall_ms();
    char head[512];
    const int hn = snprintf(head, sizeof head,
                            "POST %s HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: "
                            "application/cbor\r\nAccept: application/cbor\r\n"
                            "Content-Length: %zu\r\n\r\n",
                            path, len);
    if (write_all(fd, head, (size_t)hn) || write_all(fd, body, len)) return -1;
    in->len = in->pos = 0;
    char *end;
    for (;;) {
        if (fill(fd, in, in->len - in->pos + 1)) return -1;
        in->p[in->len] = 0; /* fill leaves room */
        if ((end = strstr(in->p, "\r\n\r\n"))) break;
    }
    const int status = atoi(in->p + 9);
    const char *st = strcasestr(in->p, "\r\nserver-timing:");
    static const char *const names[5] = {
        "body;dur=", "queue;dur=", "parse;dur=", "trace;dur=", "encode;dur="};
    for (int k = 0; k < 5; k++) {
        const char *at = st && st < end ? strstr(st, names[k]) : NULL;
        tm->srv[k] = at && at < end ? atof(at + strlen(names[k])) : NAN;
    }
    const char *cl = strcasestr(in->p, "\r\ncontent-length:");
    in->pos = (size_t)(end + 4 - in->p);
    if (cl && cl < end) {
        const size_t n = strtoull(cl + 17, NULL, 10);
        if (fill(fd, in, n)) return -1;
        *ans = (unsigned char *)in->p + in->pos;
        *anslen = n;
        tm->done = wall_ms() - t0;
        return status;
    }
    return -1; /* kdrayd always sends Content-Length */
}

/* ---- CBOR request and answer ----------------------------------------------------- */

typedef struct obuf {
    unsigned char *p;
    size_t len, cap;
} obuf;

static void put(obuf *b, const void *p, size_t n) {
    if (b->len + n > b->cap) {
        b->cap = (b->len + n) * 2;
        b->p = realloc(b->p, b->cap);
        if (!b->p) {
            fprintf(stderr, "bench_e2e: out of memory\n");
            exit(2);
        }
    }
    memcpy(b->p + b->len, p, n);
    b->len += n;
}

static void head(obuf *b, int major, uint64_t n) {
    unsigned char h[9];
    int k = 0;
    if (n < 24) {
        h[k++] = (unsigned char)(major << 5 | (int)n);
    } else {
        const int size = n < 256 ? 1 : n < 65536 ? 2 : n < 1ull << 32 ? 4 : 8;
        h[k++] = (unsigned char)(major << 5 | (size == 1   ? 24
                                               : size == 2 ? 25
                                               : size == 4 ? 26
                                                           : 27));
        for (int i = size - 1; i >= 0; i--)
            h[k++] = (unsigned char)(n >> (8 * i));
    }
    put(b, h, (size_t)k);
}

static void text(obuf *b, const char *s) {
    head(b, 3, strlen(s));
    put(b, s, strlen(s));
}

static void f32(obuf *b, float f) {
    uint32_t u;
    memcpy(&u, &f, 4);
    const unsigned char h[5] = {0xfa, (unsigned char)(u >> 24), (unsigned char)(u >> 16),
                                (unsigned char)(u >> 8), (unsigned char)u};
    put(b, h, 5);
}

/* key: tag 85 over n floats, preceded by a padding member when needed so
 * that the payload starts at a multiple of 4 (kdrayd then reads it in place). */
static void typed(obuf *b, const char *key, const float *v, size_t n) {
    obuf probe = {0};
    text(&probe, key);
    put(&probe, "\xd8\x55", 2);
    head(&probe, 2, 4 * n);
    const size_t at = b->len + probe.len;
    free(probe.p);
    if (at % 4) { /* "_p": "x..." adds 4 + k bytes: k = 4 - at % 4 aligns */
        text(b, "_p");
        text(b, "xxx" + (at % 4 - 1));
    }
    text(b, key);
    put(b, "\xd8\x55", 2);
    head(b, 2, 4 * n);
    put(b, v, 4 * n);
}

static void request_body(obuf *b, const bench_workload *w) {
    const size_t norg = w->group == 0 ? 1 : w->n; /* one origin, or one a ray */
    float *org = xmalloc(norg * 12);
    for (size_t i = 0; i < norg; i++)
        memcpy(org + 3 * i, w->rays[i].org, 12);
    b->len = 0;
    put(b, "\xbf", 1); /* indefinite-length map: the pads come and go */
    text(b, "query");
    text(b, w->query == KDR_ANY ? "any" : "closest");
    text(b, "tmin");
    f32(b, w->tmin);
    if (!isinf(w->tmax)) {
        text(b, "tmax");
        f32(b, w->tmax);
    }
    typed(b, "origins", org, 3 * norg);
    typed(b, "directions", w->dir, 3 * w->n);
    put(b, "\xff", 1);
    free(org);
}

static void vec3(obuf *b, const char *key, const float v[3]) {
    text(b, key);
    head(b, 4, 3);
    for (int k = 0; k < 3; k++)
        f32(b, v[k]);
}

/* The frustum query for a camera workload's camera: the same pixels' rays
 * (kdr_camera_ray), generated by kdrayd, the answer row-major. */
static void frustum_body(obuf *b, const kdr_camera *cam) {
    b->len = 0;
    put(b, "\xa2", 1);
    text(b, "camera");
    put(b, "\xa6", 1);
    vec3(b, "eye", cam->eye);
    vec3(b, "target", cam->target);
    vec3(b, "up", cam->up);
    text(b, "fov_y_deg");
    f32(b, cam->fov_y_deg);
    text(b, "width");
    head(b, 0, cam->width);
    text(b, "height");
    head(b, 0, cam->height);
    text(b, "tile");
    head(b, 0, 8);
}

/* The argument of the item head at *p (advancing it); -1 if malformed. */
static int64_t arg(const unsigned char **p, const unsigned char *end, int *major) {
    if (*p >= end) return -1;
    const int ib = *(*p)++;
    *major = ib >> 5;
    const int ai = ib & 31;
    if (ai < 24) return ai;
    if (ai > 27) return -1;
    const int size = 1 << (ai - 24);
    if (end - *p < size) return -1;
    uint64_t v = 0;
    for (int i = 0; i < size; i++)
        v = v << 8 | *(*p)++;
    return (int64_t)v;
}

/* Rays hit in kdrayd's answer (prim >= 0 or hit == 1); -1 if unreadable. */
static long answer_hits(const unsigned char *p, size_t len, size_t n) {
    const unsigned char *end = p + len;
    int major;
    int64_t members = arg(&p, end, &major);
    if (major != 5) return -1;
    while (members-- > 0) {
        const int64_t kl = arg(&p, end, &major);
        if (major != 3 || kl < 0 || end - p < kl) return -1;
        const int is_prim = kl == 4 && !memcmp(p, "prim", 4);
        const int is_hit = kl == 3 && !memcmp(p, "hit", 3);
        p += kl;
        int64_t v = arg(&p, end, &major);
        if (major == 0) continue; /* count */
        if (major != 6 || (v = arg(&p, end, &major)) < 0 || major != 2 || end - p < v)
            return -1;
        if (is_prim && (size_t)v == 4 * n) {
            long hits = 0;
            for (size_t i = 0; i < n; i++) {
                int32_t q;
                memcpy(&q, p + 4 * i, 4);
                hits += q >= 0;
            }
            return hits;
        }
        if (is_hit && (size_t)v == n) {
            long hits = 0;
            for (size_t i = 0; i < n; i++)
                hits += p[i] != 0;
            return hits;
        }
        p += v;
    }
    return -1;
}

/* ---- Embree in this process, T threads ------------------------------------------- */

typedef struct emb_pass {
    bench_method *m;
    size_t nchunks;
    atomic_size_t next;
} emb_pass;

static void *emb_worker(void *arg) {
    emb_pass *e = arg;
    const rival_fp fp = rival_fp_enter();
    size_t i;
    while ((i = atomic_fetch_add(&e->next, 1)) < e->nchunks)
        e->m[i].run(e->m[i].ctx);
    rival_fp_leave(fp);
    return NULL;
}

/* One API's jobs over the workload's rays in CHUNK-ray pieces. They are
 * made for each pass and freed after it (all APIs at once would hold 80
 * bytes a ray each); their making and the conversion are untimed. */
typedef struct emb_api {
    rival_api api;
    char name[64];
    double best_ms;
    long hits; /* of the last pass */
} emb_api;

static int emb_pass_once(emb_api *a, const rival *emb, const bench_workload *w,
                         unsigned threads) {
    const size_t nchunks = (w->n + CHUNK - 1) / CHUNK;
    rival_job *jobs = xmalloc(nchunks * sizeof *jobs);
    bench_method *m = xmalloc(nchunks * sizeof *m);
    for (size_t c = 0; c < nchunks; c++) {
        const size_t k = c + 1 < nchunks ? CHUNK : w->n - c * CHUNK;
        if (rival_job_init(&jobs[c], emb, a->api, w->query, w->rays + c * CHUNK, k) !=
            0) {
            fprintf(stderr, "bench_e2e: rival job: out of memory\n");
            exit(2);
        }
        m[c] = rival_job_method(&jobs[c]);
        if (m[c].prepare) m[c].prepare(m[c].ctx);
    }
    snprintf(a->name, sizeof a->name, "%s", jobs[0].name);
    emb_pass e = {m, nchunks, 0};
    pthread_t th[64];
    const double t0 = wall_ms();
    for (unsigned k = 1; k < threads; k++)
        pthread_create(&th[k], NULL, emb_worker, &e);
    emb_worker(&e);
    for (unsigned k = 1; k < threads; k++)
        pthread_join(th[k], NULL);
    const double ms = wall_ms() - t0;
    if (ms < a->best_ms) a->best_ms = ms;
    uint8_t hit[CHUNK];
    a->hits = 0;
    for (size_t c = 0; c < nchunks; c++) {
        rival_job_answers(&jobs[c], hit, NULL);
        for (size_t i = 0; i < jobs[c].n; i++)
            a->hits += hit[i];
        rival_job_free(&jobs[c]);
    }
    free(jobs), free(m);
    return 0;
}

/* ---- kdray-trace: the executor in-process ----------------------------------------- */

/* Mean tracing ms of R runs of the request file in-process, -1 on failure. */
static double trace_ms(const opts *o, const char *scene, const char *kind,
                       const char *file) {
    char cmd[4096];
    snprintf(cmd, sizeof cmd,
             "'%s' --scene '%s' --kind %s --mode fast --threads %u --repeat %d "
             "'%s' 2>&1 >/dev/null",
             o->trace, scene, kind, o->threads, o->repeat < 3 ? 3 : o->repeat, file);
    FILE *f = popen(cmd, "r");
    if (!f) return -1;
    char line[1024];
    double best = -1;
    while (fgets(line, sizeof line, f)) {
        const char *at = strstr(line, "best ");
        if (at && strstr(line, "kdray-trace:")) best = atof(at + 5);
    }
    return pclose(f) == 0 ? best : -1;
}

/* ---- one scene ---------------------------------------------------------------- */

typedef struct result {
    double ratio_sum_log;
    double trace_sum_log; /* of Embree ms / kdrayd's trace step (Server-Timing) */
    double best_sum_log; /* of Embree ms / kdrayd's faster endpoint (frustum or bundle) */
    int rows, fail;
} result;

/* One kdrayd request of a workload: its body, its best pass, its hits. */
typedef struct kd_req {
    const char *label, *path, *kind;
    obuf body;
    times best;
    long hits;
} kd_req;

static int post_once(int fd, inbuf *in, kd_req *r, size_t n, const char *scene) {
    unsigned char *ans = NULL;
    size_t anslen = 0;
    times tm = {0};
    const int st = http_post(fd, r->path, r->body.p, r->body.len, in, &ans, &anslen, &tm);
    if (st != 200) {
        fprintf(stderr, "bench_e2e: %s %s: HTTP %d %.*s\n", scene, r->label, st,
                st > 0 ? (int)(anslen < 300 ? anslen : 300) : 0,
                st > 0 ? (const char *)ans : "");
        return -1;
    }
    if (tm.done < r->best.done) r->best = tm;
    r->hits = answer_hits(ans, anslen, n);
    return 0;
}

static void print_row(const ladder_entry *e, const kd_req *r, size_t n,
                      const emb_api *emb, double inproc) {
    const double *v = r->best.srv;
    printf("%-7s %-7s %7zu %5.1f %-24s %7.1f %7.1f %6.1f %6.1f %6.1f %6.1f %6.1f %7.1f "
           "%5.0f%% %6.3f\n",
           e->name, r->label, n, r->body.len / 1048576.0, emb->name + 7, emb->best_ms,
           r->best.done, v[0], v[1] + v[2], v[3], v[4],
           r->best.done - v[0] - v[1] - v[2] - v[3] - v[4], inproc,
           100.0 * (1.0 - v[3] / r->best.done), emb->best_ms / r->best.done);
}

/* The workload as a CBOR bundle (the headline: the same rays both sides)
 * and, for camera rays, also as the frustum query of the same camera
 * (kdrayd's other way to answer them); interleaved with every Embree API. */
static int run_workload(const opts *o, const ladder_entry *e, const kdr_scene *kd,
                        const rival *emb, int fd, const char *wname, result *res) {
    bench_workload w;
    if (bench_workload_make(&w, kd, wname, o->rays) != 0) {
        fprintf(stderr, "bench_e2e: workload %s: unknown or out of memory\n", wname);
        return -1;
    }
    kd_req req[2] = {
        {.label = wname, .path = "/v1/scenes/default/bundle", .kind = "bundle"},
        {.label = "cam-fru", .path = "/v1/scenes/default/frustum", .kind = "frustum"}};
    for (int k = 0; k < 2; k++)
        req[k].best.done = INFINITY, req[k].hits = -1;
    const int nreq = w.work == RIVAL_WORK_CAMERA ? 2 : 1;
    request_body(&req[0].body, &w);
    if (nreq == 2) frustum_body(&req[1].body, &w.cam);

    rival_api apis[RIVAL_MAX_APIS];
    const size_t napis = rival_apis((rival_work)w.work, apis);
    emb_api ea[RIVAL_MAX_APIS];
    for (size_t a = 0; a < napis; a++)
        ea[a] = (emb_api){.api = apis[a], .best_ms = INFINITY};

    inbuf in = {0};
    int rc = 0;
    for (int pass = 0; pass < o->repeat && rc == 0; pass++) {
        for (size_t a = 0; a < napis; a++)
            emb_pass_once(&ea[a], emb, &w, o->threads);
        for (int k = 0; k < nreq && rc == 0; k++)
            rc = post_once(fd, &in, &req[k], w.n, e->name);
    }
    size_t best = 0;
    for (size_t a = 1; a < napis; a++)
        if (ea[a].best_ms < ea[best].best_ms) best = a;
    double fastest = INFINITY;
    for (int k = 0; k < nreq && rc == 0; k++) {
        char file[] = "/tmp/kdray-e2e-XXXXXX.cbor";
        const int tfd = mkstemps(file, 5);
        const int wrote = tfd >= 0 && write(tfd, req[k].body.p, req[k].body.len) ==
                                          (ssize_t)req[k].body.len;
        if (tfd >= 0) close(tfd);
        const double inproc = wrote ? trace_ms(o, e->path, req[k].kind, file) : -1;
        unlink(file);
        print_row(e, &req[k], w.n, &ea[best], inproc);
        const double diff = fabs((double)req[k].hits - (double)ea[best].hits);
        if (req[k].hits < 0 || diff > 0.001 * (double)w.n) {
            fprintf(stderr, "bench_e2e: %s %s: kdrayd hit %ld rays, Embree %ld\n",
                    e->name, req[k].label, req[k].hits, ea[best].hits);
            res->fail = 1;
        }
        if (req[k].best.done < fastest) fastest = req[k].best.done;
    }
    fflush(stdout);
    if (rc == 0) {
        const double *v = req[0].best.srv;
        res->ratio_sum_log += log(ea[best].best_ms / req[0].best.done);
        res->trace_sum_log += log(ea[best].best_ms / v[3]);
        res->best_sum_log += log(ea[best].best_ms / fastest);
        res->rows++;
    }
    free(in.p), free(req[0].body.p), free(req[1].body.p);
    bench_workload_free(&w);
    return rc;
}

static int run_scene(const opts *o, const ladder_entry *e, result *res) {
    char err[512];
    float *tris;
    size_t ntris;
    if (ladder_load(e, &tris, &ntris, err, sizeof err) != 0) {
        fprintf(stderr, "bench_e2e: %s\n", err);
        return -1;
    }
    kdr_scene *kd = NULL;
    if (kdr_scene_build(tris, ntris, NULL, NULL, NULL, &kd) != KDR_OK) return -1;
    rival *emb = rival_create(tris, ntris, 0, RIVAL_QUALITY);
    daemon_proc d;
    if (!emb || daemon_start(&d, o, e->path) != 0) return -1;
    const int fd = http_connect(d.port);
    int rc = fd < 0 ? -1 : 0;
    for (int k = 0; k < o->nwork && rc == 0; k++)
        rc = run_workload(o, e, kd, emb, fd, o->work[k], res);
    if (fd >= 0) close(fd);
    daemon_stop(&d);
    rival_free(emb);
    kdr_scene_free(kd);
    free(tris);
    return rc;
}

static void usage(void) {
    fprintf(stderr, "usage: kdray_bench_e2e KDRAYD KDRAY_TRACE [--dir LADDER] "
                    "[--only NAME]... [--workload W]... [--rays N] [--repeat R] "
                    "[--threads T]\n");
}

int main(int argc, char **argv) {
    opts o = {.dir = ladder_default_dir(), .rays = 1048576, .repeat = 3, .threads = 2};
    int npos = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--help")) return usage(), 0;
        if (a[0] != '-') {
            if (npos == 0)
                o.kdrayd = a;
            else if (npos == 1)
                o.trace = a;
            npos++;
            continue;
        }
        if (!v) return usage(), 2;
        i++;
        if (!strcmp(a, "--dir"))
            o.dir = v;
        else if (!strcmp(a, "--only") && o.nonly < MAX_LIST)
            o.only[o.nonly++] = v;
        else if (!strcmp(a, "--workload") && o.nwork < MAX_LIST)
            o.work[o.nwork++] = v;
        else if (!strcmp(a, "--rays"))
            o.rays = strtoull(v, NULL, 10);
        else if (!strcmp(a, "--repeat"))
            o.repeat = atoi(v);
        else if (!strcmp(a, "--threads"))
            o.threads = (unsigned)atoi(v);
        else
            return usage(), 2;
    }
    if (npos != 2 || !o.dir || o.repeat < 1 || o.threads < 1 || o.threads > 64 || !o.rays)
        return usage(), 2;
    if (!o.nonly) o.only[o.nonly++] = "haus", o.only[o.nonly++] = "engine";
    if (!o.nwork) {
        static const char *const dflt[] = {"camera", "random", "ao_any", "shadow"};
        for (int k = 0; k < 4; k++)
            o.work[o.nwork++] = dflt[k];
    }
    char err[512];
    ladder_entry *v;
    const int n = ladder_read(o.dir, &v, err, sizeof err);
    if (n < 0) {
        fprintf(stderr, "bench_e2e: %s\n", err);
        return 2;
    }
    rival_print_setup(stdout);
    printf("kdrayd --threads %u over loopback (CBOR bundles, keep-alive) against Embree "
           "in this process with %u threads (4096-ray chunks); wall ms, best of %d\n",
           o.threads, o.threads, o.repeat);
    printf("%-7s %-7s %7s %5s %-24s %7s %7s %6s %6s %6s %6s %6s %7s %6s %6s\n", "scene",
           "work", "rays", "MiB", "Embree's best API", "Embree", "kdrayd", "body",
           "parse", "trace", "encode", "rest", "inproc", "other", "ratio");
    result res = {0};
    int rc = 0;
    for (int k = 0; k < o.nonly; k++) {
        int found = 0;
        for (int i = 0; i < n; i++)
            if (!strcmp(v[i].name, o.only[k])) {
                found = 1;
                if (run_scene(&o, &v[i], &res) != 0) rc = 1;
            }
        if (!found) {
            fprintf(stderr, "bench_e2e: no ladder scene %s\n", o.only[k]);
            rc = 1;
        }
    }
    free(v);
    if (res.rows)
        printf("geometric mean of Embree ms / kdrayd ms over %d rows: %.3f (target >= "
               "0.5)\n",
               res.rows, exp(res.ratio_sum_log / res.rows));
    if (res.rows)
        printf("the same with kdrayd's time cut to its trace step (no transport, no "
               "codecs): %.3f\nthe same with camera rays asked as a frustum query "
               "where that is faster (cam-fru rows): %.3f\n",
               exp(res.trace_sum_log / res.rows), exp(res.best_sum_log / res.rows));
    printf("(ms; kdrayd: from the first byte sent to the answer's last byte read, and "
           "how kdrayd's Server-Timing header splits it: body = the request's arrival, "
           "parse = queue + parse, trace = first chunk to last, encode; rest = the "
           "answer's transfer and what no step covers; inproc: kdray-trace's best "
           "tracing time of the same request file, %u threads, run after the passes; "
           "other: the share of kdrayd's time that is not tracing)\n",
           o.threads);
    if (res.fail) printf("bench_e2e: FAILED (hit counts disagree)\n");
    return rc || res.fail;
}
