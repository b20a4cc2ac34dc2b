/*
 * e2e_wire.c — how kdray_bench_e2e talks to kdrayd (e2e_wire.h): the child
 * process and its log, HTTP/1.1 on one keep-alive loopback connection, and
 * the CBOR bodies written and answers read by hand (major types and
 * lengths only: what the benchmark sends and kdrayd answers, no general
 * decoder), so that the client costs as little as a user's would.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "e2e_wire.h"
#include "test_util.h"

double wall_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

/* ---- the daemon ------------------------------------------------------------------ */

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

int daemon_start(daemon_proc *d, const char *kdrayd, unsigned threads,
                 const char *scene_path) {
    int p[2];
    if (pipe(p) != 0) return -1;
    char nthreads[16], scene[1100];
    snprintf(nthreads, sizeof nthreads, "%u", threads);
    snprintf(scene, sizeof scene, "default=%s", scene_path);
    d->pid = fork();
    if (d->pid == 0) {
        dup2(p[1], 2);
        close(p[0]), close(p[1]);
        execl(kdrayd, kdrayd, "--listen", "127.0.0.1:0", "--threads", nthreads, "--scene",
              scene, "--max-body-mb", "128", "--max-rays", "16777216", "--worker-nice",
              "0", (char *)NULL);
        perror(kdrayd);
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

void daemon_stop(daemon_proc *d) {
    kill(d->pid, SIGTERM);
    waitpid(d->pid, NULL, 0);
    pthread_join(d->drain, NULL);
    fclose(d->log);
}

/* ---- HTTP/1.1 over one keep-alive connection ------------------------------------- */

int http_connect(int port) {
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

int http_post(int fd, const char *path, const unsigned char *body, size_t len, inbuf *in,
              unsigned char **ans, size_t *anslen, times *tm) {
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
    put(b, h, cbor_head(h, (unsigned)major, n));
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

void request_body(obuf *b, const bench_workload *w) {
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

void frustum_body(obuf *b, const kdr_camera *cam) {
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

long answer_hits(const unsigned char *p, size_t len, size_t n) {
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
