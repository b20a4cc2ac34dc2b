/*
 * main.c — kdrayd: flags, start-up order and shutdown.
 *
 * Start-up opens the HTTP port first (health and queries answer 503), then
 * loads and builds the scenes, several at once (min(scenes, --threads)
 * start-up threads, each build itself on --threads threads), then flips the
 * registry to ready. A scene that fails to load ends the process with
 * status 1 (scenes not started yet are skipped): a daemon silently serving
 * fewer scenes than asked is worse than none.
 * SIGINT/SIGTERM are taken by a dedicated sigwait() thread (blocked
 * everywhere else, so no handler ever runs on an HTTP thread); shutdown
 * stops accepting, lets requests in flight finish, and exits 0.
 */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include "log.h"
#include "server.h"

#ifndef KDRAY_VERSION
#define KDRAY_VERSION "0.0.0"
#endif

static const char *const DEFAULT_LISTEN = "127.0.0.1:8080";
static const size_t DEFAULT_MAX_BODY_MB = 64;
static const size_t DEFAULT_MAX_RAYS = 4194304;
static const unsigned MAX_THREADS = 256;
static const size_t MAX_BODY_MB_LIMIT = 4096;
/* Seconds a shutdown waits for requests in flight before closing them. */
static const double SHUTDOWN_GRACE_S = 30.0;
/* A 64K-ray request frees ~5 MiB (body, rays, hits, answer); glibc's
 * default trims that from the thread's arena after every request, so the next
 * one page-faults all of it in again (~13K faults/s, a few % of a 64K base64
 * request). Keep up to TRIM of free heap; only blocks over MMAP (near-limit
 * bodies) are mapped and returned at once. Peak-bounded, not growth. */
static const int MALLOC_TRIM_BYTES = 32 << 20;
static const int MALLOC_MMAP_BYTES = 16 << 20;

typedef struct options {
    const char *listen;
    unsigned threads;
    size_t max_body_mb, max_rays;
    char **scene_args; /* NAME=PATH, pointing into argv */
    size_t nscenes;
} options;

static void usage(FILE *f) {
    fprintf(f,
            "usage: kdrayd [options]\n"
            "Serves batched ray queries (bundle, cone-shadow, frustum) over HTTP/JSON\n"
            "on SAH kd-trees built from glTF scenes at start-up.\n\n"
            "  --scene NAME=PATH   serve PATH (.glb or .gltf) as NAME; repeatable\n"
            "                      (default: the bundled scene as \"default\")\n"
            "  --listen ADDR:PORT  address to listen on (default %s; port 0 picks\n"
            "                      a free port, logged at start-up)\n"
            "  --threads N         HTTP, worker and kd-tree build threads (default:\n"
            "                      number of cores)\n"
            "  --max-body-mb N     largest request body in MiB (default %zu)\n"
            "  --max-rays N        most rays per request (default %zu)\n"
            "  --help, --version\n",
            DEFAULT_LISTEN, DEFAULT_MAX_BODY_MB, DEFAULT_MAX_RAYS);
}

static int bad_flag(const char *fmt, const char *arg) {
    fprintf(stderr, "kdrayd: ");
    fprintf(stderr, fmt, arg);
    fprintf(stderr, " (see kdrayd --help)\n");
    return 2;
}

static int parse_size(const char *s, size_t lo, size_t hi, size_t *out) {
    char *end;
    if (!s || !*s || *s == '-' || *s == '+') return -1;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 10);
    if (errno || *end || v < lo || v > hi) return -1;
    *out = (size_t)v;
    return 0;
}

static unsigned default_threads(void) {
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : n > (long)MAX_THREADS ? MAX_THREADS : (unsigned)n;
}

/* Splits "--flag=value" or takes the next argument; NULL if missing. */
static const char *flag_value(int argc, char **argv, int *i, const char *eq) {
    if (eq) return eq + 1;
    return *i + 1 < argc ? argv[++*i] : NULL;
}

/* Returns -1 to go on, or an exit status (0 for --help/--version). */
static int parse_one(options *o, int argc, char **argv, int *i) {
    const char *a = argv[*i];
    const char *eq = strncmp(a, "--", 2) ? NULL : strchr(a, '=');
    size_t name_len = eq ? (size_t)(eq - a) : strlen(a);
#define IS(flag) (name_len == strlen(flag) && !strncmp(a, flag, name_len))
    if (IS("--help") && !eq) return usage(stdout), 0;
    if (IS("--version") && !eq) return printf("kdrayd %s\n", KDRAY_VERSION), 0;
    if (!IS("--scene") && !IS("--listen") && !IS("--threads") && !IS("--max-body-mb") &&
        !IS("--max-rays"))
        return bad_flag("unknown argument %s", a);
    const char *v = flag_value(argc, argv, i, eq);
    if (!v) return bad_flag("%s needs a value", a);
    size_t n;
    if (IS("--scene")) {
        const char *sep = strchr(v, '=');
        if (!sep || sep == v || !sep[1])
            return bad_flag("--scene %s: expected NAME=PATH", v);
        o->scene_args[o->nscenes++] = (char *)v; /* v is argv storage */
    } else if (IS("--listen")) {
        if (!kdr_http_addr_ok(v))
            return bad_flag("--listen %s: expected ADDR:PORT (IPv4, localhost or [IPv6])",
                            v);
        o->listen = v;
    } else if (IS("--threads")) {
        if (parse_size(v, 1, MAX_THREADS, &n))
            return bad_flag("--threads %s: expected 1..256", v);
        o->threads = (unsigned)n;
    } else if (IS("--max-body-mb")) {
        if (parse_size(v, 1, MAX_BODY_MB_LIMIT, &n))
            return bad_flag("--max-body-mb %s: expected 1..4096", v);
        o->max_body_mb = n;
    } else if (parse_size(v, 1, (size_t)1 << 32, &o->max_rays)) {
        return bad_flag("--max-rays %s: expected 1..4294967296", v);
    }
#undef IS
    return -1;
}

static int parse_flags(options *o, int argc, char **argv) {
    *o = (options){.listen = DEFAULT_LISTEN,
                   .threads = default_threads(),
                   .max_body_mb = DEFAULT_MAX_BODY_MB,
                   .max_rays = DEFAULT_MAX_RAYS};
    o->scene_args = calloc((size_t)argc + 1, sizeof *o->scene_args);
    if (!o->scene_args) return 1;
    for (int i = 1; i < argc; i++) {
        int rc = parse_one(o, argc, argv, &i);
        if (rc >= 0) return rc;
    }
    return -1;
}

/* Fills the registry from --scene flags, or the bundled default. */
static int add_scenes(kdr_registry *r, const options *o) {
    if (o->nscenes == 0) return kdr_registry_add(r, "default", KDRAY_DEFAULT_SCENE);
    for (size_t i = 0; i < o->nscenes; i++) {
        char *arg = o->scene_args[i], *sep = strchr(arg, '=');
        *sep = '\0';
        if (kdr_registry_add(r, arg, sep + 1) != 0) {
            fprintf(stderr,
                    "kdrayd: --scene %s: name must be unique, 1-64 chars of "
                    "[A-Za-z0-9._-] (see kdrayd --help)\n",
                    arg);
            return 2;
        }
    }
    return 0;
}

/* ---- signals ------------------------------------------------------------ */

typedef struct sig_waiter {
    sigset_t set;
    kdr_server *srv;
    pthread_t thread;
} sig_waiter;

/* SIGUSR1 is the main thread's silent "wake up and return" after a failed
 * start-up; SIGINT/SIGTERM are shutdown requests. */
static void *signal_main(void *arg) {
    sig_waiter *w = arg;
    int sig = 0;
    while (sigwait(&w->set, &sig) != 0) {
    }
    if (sig != SIGUSR1)
        kdr_log("received %s: shutting down", sig == SIGINT ? "SIGINT" : "SIGTERM");
    atomic_store(&w->srv->stopping, 1);
    return NULL;
}

static int start_signals(sig_waiter *w, kdr_server *srv) {
    w->srv = srv;
    sigemptyset(&w->set);
    sigaddset(&w->set, SIGINT);
    sigaddset(&w->set, SIGTERM);
    sigaddset(&w->set, SIGUSR1);
    signal(SIGPIPE, SIG_IGN); /* a client hanging up is not our death */
    if (pthread_sigmask(SIG_BLOCK, &w->set, NULL) != 0) return -1;
    return pthread_create(&w->thread, NULL, signal_main, w) == 0 ? 0 : -1;
}

/* Returns once a shutdown signal came, or at once (silently) if wake. */
static void wait_signal(sig_waiter *w, int wake) {
    if (wake) pthread_kill(w->thread, SIGUSR1);
    pthread_join(w->thread, NULL);
}

/* ---- start-up ----------------------------------------------------------- */

/* The scenes still to build, shared by the start-up threads. */
typedef struct build_queue {
    kdr_server *srv;
    atomic_size_t next;
    atomic_int failed;
} build_queue;

/* Takes scenes from the queue until none is left, one fails, or a signal
 * asks to stop. Each build uses every thread the daemon may use: when
 * several run at once they share the cores, and the last large one still
 * gets all of them. */
static void *build_worker(void *arg) {
    build_queue *q = arg;
    const size_t n = kdr_registry_count(q->srv->registry);
    for (;;) {
        if (atomic_load(&q->failed) || atomic_load(&q->srv->stopping)) break;
        const size_t i = atomic_fetch_add(&q->next, 1);
        if (i >= n) break;
        if (kdr_registry_build(q->srv->registry, i, (int)q->srv->threads) != 0)
            atomic_store(&q->failed, 1);
    }
    return NULL;
}

/* Builds every scene; 1 if one failed, 0 otherwise (also when a signal
 * cut the start-up short). */
static int build_scenes(kdr_server *srv) {
    double t0 = kdr_now();
    size_t n = kdr_registry_count(srv->registry);
    build_queue q = {.srv = srv};
    atomic_init(&q.next, 0);
    atomic_init(&q.failed, 0);
    size_t helpers = (n < srv->threads ? n : srv->threads) - 1, started = 0;
    pthread_t *th = helpers ? calloc(helpers, sizeof *th) : NULL;
    for (; th && started < helpers; started++)
        if (pthread_create(&th[started], NULL, build_worker, &q) != 0) break;
    build_worker(&q);
    for (size_t i = 0; i < started; i++) pthread_join(th[i], NULL);
    free(th);
    if (atomic_load(&q.failed)) return 1;
    if (atomic_load(&srv->stopping)) return 0;
    kdr_registry_set_ready(srv->registry);
    kdr_log("ready: %zu scene%s built in %.1f ms", n, n == 1 ? "" : "s",
            (kdr_now() - t0) * 1e3);
    return 0;
}

static void tune_malloc(void) {
#ifdef __GLIBC__
    mallopt(M_TRIM_THRESHOLD, MALLOC_TRIM_BYTES);
    mallopt(M_MMAP_THRESHOLD, MALLOC_MMAP_BYTES);
#endif
}

static int serve(kdr_server *srv, const options *o) {
    sig_waiter sw;
    /* Signals first: every thread created later inherits the blocked mask. */
    if (start_signals(&sw, srv) != 0) {
        kdr_log("error: cannot set up signal handling");
        return 1;
    }
    srv->pool = kdr_pool_create(srv->threads - 1);
    if (!srv->pool) {
        kdr_log("error: cannot start %u worker threads", srv->threads - 1);
        wait_signal(&sw, 1);
        return 1;
    }
    kdr_log("kdrayd %s starting: %zu scene%s, %u threads, max body %zu MiB, max "
            "rays %zu, %s bundles",
            KDRAY_VERSION, kdr_registry_count(srv->registry),
            kdr_registry_count(srv->registry) == 1 ? "" : "s", srv->threads,
            o->max_body_mb, srv->max_rays,
            kdr_cpu_has_avx2() ? "8-wide (AVX2)" : "4-wide");
    kdr_http *h = kdr_http_start(srv, o->listen);
    int status = 1;
    if (h) {
        const char *colon = strrchr(o->listen, ':');
        kdr_log("listening on http://%.*s:%u (503 until every scene is built)",
                (int)(colon - o->listen), o->listen, kdr_http_port(h));
        status = build_scenes(srv);
        wait_signal(&sw, status != 0);
        kdr_log("shutdown: %ld request%s in flight", kdr_metrics_inflight_now(),
                kdr_metrics_inflight_now() == 1 ? "" : "s");
        kdr_http_stop(h, SHUTDOWN_GRACE_S);
    } else {
        wait_signal(&sw, 1);
    }
    kdr_log("stopped (exit %d)", status);
    return status;
}

int main(int argc, char **argv) {
    options o;
    int rc = parse_flags(&o, argc, argv);
    kdr_server srv = {.max_body = 0};
    tune_malloc();
    atomic_init(&srv.stopping, 0);
    srv.registry = kdr_registry_create();
    if (rc < 0 && !srv.registry) rc = 1;
    if (rc < 0) rc = add_scenes(srv.registry, &o) ? 2 : -1;
    if (rc < 0) {
        srv.threads = o.threads;
        srv.max_body = o.max_body_mb << 20;
        srv.max_rays = o.max_rays;
        rc = serve(&srv, &o);
    }
    kdr_pool_destroy(srv.pool);
    kdr_registry_free(srv.registry);
    free(o.scene_args);
    return rc;
}
