/*
 * main.c — kdrayd: start-up order, signals, reloads and shutdown.
 *
 * Start-up opens the HTTP port first (health and queries answer 503), then
 * loads and builds the scenes, several at once (min(scenes, --threads)
 * start-up threads, each build itself on --threads threads), then flips
 * the registry to ready and tells systemd (READY=1 when run as a Type=notify
 * unit). A scene that fails to load ends the process with status 1 (scenes
 * not started yet are skipped): a daemon silently serving fewer scenes than
 * asked is worse than none.
 *
 * Signals are taken by a dedicated sigwait() thread (blocked everywhere
 * else, so no handler ever runs on an HTTP or worker thread), which only
 * raises flags for the main thread. The main thread, idle once the scenes
 * are built, carries out a SIGHUP (reopen the access log, rebuild changed
 * scene files in the background of serving, swap them in) and a
 * SIGINT/SIGTERM (stop accepting, let requests in flight finish, exit 0).
 */
#define _GNU_SOURCE /* gettid: a thread's own nice value */
#include <errno.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include "kdr_default_scene.h"
#include "log.h"
#include "notify.h"
#include "options.h"
#include "server.h"
#include "tree_cache.h"

#ifndef KDRAY_VERSION
#define KDRAY_VERSION "0.0.0"
#endif

/* Descriptors beyond the connections: listen socket, logs, scene files. */
static const rlim_t SPARE_FILES = 64;
/* A 64K-ray request frees ~5 MiB (body, rays, hits, answer); glibc's
 * default trims that from the thread's arena after every request, so the next
 * one page-faults all of it in again (~13K faults/s, a few % of a 64K base64
 * request). Keep up to TRIM of free heap; only blocks over MMAP (near-limit
 * bodies) are mapped and returned at once. Peak-bounded, not growth.
 * A 1M-ray request's answer (16.8 MB in CBOR) and body (24 MiB) are
 * huge-page blocks (kdr_block_alloc) of 18-28 MiB with the alignment: at a
 * 16 MiB MMAP they were mapped and unmapped per request, so every request
 * faulted them in again. 32 MiB is glibc's largest fixed threshold (half
 * a non-main arena's 64 MiB heap). TRIM 128 MiB keeps glibc from deleting
 * a worker arena's freed heap (it does when the heap's free space plus the
 * arena's unused reserve pass TRIM): ten 1M-ray "transport only" requests
 * faulted 2827 times at 128 MiB, 22405 at 32 MiB, 6101 before (perf stat
 * -e page-faults). Idle RSS stays at the largest request's working set. */
static const int MALLOC_TRIM_BYTES = 128 << 20;
static const int MALLOC_MMAP_BYTES = 32 << 20;

/* Fills the registry from --scene flags, or the bundled default. */
static int add_scenes(kdr_registry *r, const kdr_options *o, char *default_path,
                      size_t default_len) {
    if (o->nscenes == 0) {
        kdr_default_scene_path(default_path, default_len);
        return kdr_registry_add(r, "default", default_path);
    }
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

typedef struct sig_state {
    sigset_t set;
    kdr_server *srv;
    pthread_t thread;
    pthread_mutex_t m;
    pthread_cond_t cv; /* reload or stop was raised */
    int reload, stop;
} sig_state;

/* SIGUSR1 is the main thread's silent "return now" after a failed start-up;
 * SIGINT/SIGTERM are shutdown requests; SIGHUP asks for a reload. */
static void *signal_main(void *arg) {
    sig_state *w = arg;
    for (;;) {
        int sig = 0;
        if (sigwait(&w->set, &sig) != 0) continue;
        pthread_mutex_lock(&w->m);
        if (sig == SIGHUP) {
            kdr_log("received SIGHUP: reloading changed scenes");
            w->reload = 1;
        } else {
            if (sig != SIGUSR1)
                kdr_log("received %s: shutting down",
                        sig == SIGINT ? "SIGINT" : "SIGTERM");
            w->stop = 1;
            atomic_store(&w->srv->stopping, 1);
        }
        pthread_cond_signal(&w->cv);
        pthread_mutex_unlock(&w->m);
        if (sig != SIGHUP) return NULL;
    }
}

static int start_signals(sig_state *w, kdr_server *srv) {
    w->srv = srv;
    w->reload = w->stop = 0;
    pthread_mutex_init(&w->m, NULL);
    pthread_cond_init(&w->cv, NULL);
    sigemptyset(&w->set);
    sigaddset(&w->set, SIGINT);
    sigaddset(&w->set, SIGTERM);
    sigaddset(&w->set, SIGHUP);
    sigaddset(&w->set, SIGUSR1);
    signal(SIGPIPE, SIG_IGN); /* a client hanging up is not our death */
    if (pthread_sigmask(SIG_BLOCK, &w->set, NULL) != 0) return -1;
    return pthread_create(&w->thread, NULL, signal_main, w) == 0 ? 0 : -1;
}

/* Ends the signal thread (at once, silently, unless a stop already did). */
static void end_signals(sig_state *w) {
    pthread_mutex_lock(&w->m);
    int stopped = w->stop;
    pthread_mutex_unlock(&w->m);
    if (!stopped) pthread_kill(w->thread, SIGUSR1);
    pthread_join(w->thread, NULL);
    pthread_cond_destroy(&w->cv);
    pthread_mutex_destroy(&w->m);
}

/* ---- start-up, reloads ---------------------------------------------------- */

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
    char status[96];
    snprintf(status, sizeof status, "READY=1\nSTATUS=serving %zu scene%s", n,
             n == 1 ? "" : "s");
    kdr_notify(status);
    return 0;
}

static void reload(kdr_server *srv) {
    kdr_notify("RELOADING=1\nSTATUS=reloading scenes");
    if (kdr_access_log_reopen(&srv->access_log) != 0)
        kdr_log_error("--access-log %s: cannot reopen: %s", srv->access_log.path,
                      strerror(errno));
    double t0 = kdr_now();
    size_t failed = kdr_registry_reload(srv->registry);
    size_t n = kdr_registry_count(srv->registry);
    if (failed)
        kdr_log("reload: done in %.1f ms; %zu of %zu scene%s kept the previous version "
                "(see above)",
                (kdr_now() - t0) * 1e3, failed, n, n == 1 ? "" : "s");
    else
        kdr_log("reload: done in %.1f ms; %zu scene%s current", (kdr_now() - t0) * 1e3, n,
                n == 1 ? "" : "s");
    kdr_notify(failed
                   ? "READY=1\nSTATUS=serving; the last reload kept old scenes (see log)"
                   : "READY=1\nSTATUS=serving");
}

/* Waits for signals after start-up; returns when a stop was asked for. */
static void serve_until_stopped(sig_state *w, kdr_server *srv) {
    for (;;) {
        pthread_mutex_lock(&w->m);
        while (!w->stop && !w->reload)
            pthread_cond_wait(&w->cv, &w->m);
        int stop = w->stop, again = w->reload;
        w->reload = 0;
        pthread_mutex_unlock(&w->m);
        if (stop) return;
        if (again) reload(srv);
    }
}

/* Each connection is a descriptor: make room for them. */
static void raise_file_limit(unsigned connections) {
    struct rlimit rl;
    rlim_t want = (rlim_t)connections + SPARE_FILES;
    if (getrlimit(RLIMIT_NOFILE, &rl) != 0 || rl.rlim_cur >= want) return;
    rl.rlim_cur = rl.rlim_max == RLIM_INFINITY || rl.rlim_max > want ? want : rl.rlim_max;
    if (setrlimit(RLIMIT_NOFILE, &rl) != 0 || rl.rlim_cur < want)
        kdr_log_warn("open files limited to %llu: fewer than --max-connections %u + %llu",
                     (unsigned long long)rl.rlim_cur, connections,
                     (unsigned long long)SPARE_FILES);
}

/* Each worker lowers its own priority (Linux: setpriority on a thread id
 * applies to that thread only). Raising a nice value needs no privilege;
 * a seccomp filter may still refuse it, which is logged once. */
static void lower_worker_priority(void *ctx) {
    const kdr_server *srv = ctx;
    static atomic_int warned;
    if (srv->worker_nice <= 0) return;
    pid_t tid = (pid_t)syscall(SYS_gettid);
    int now = getpriority(PRIO_PROCESS, (id_t)tid);
    if (setpriority(PRIO_PROCESS, (id_t)tid, now + srv->worker_nice) != 0 &&
        atomic_exchange(&warned, 1) == 0)
        kdr_log_warn("--worker-nice %d: cannot lower the workers' priority: %s",
                     srv->worker_nice, strerror(errno));
}

static void tune_malloc(void) {
#ifdef __GLIBC__
    mallopt(M_TRIM_THRESHOLD, MALLOC_TRIM_BYTES);
    mallopt(M_MMAP_THRESHOLD, MALLOC_MMAP_BYTES);
#endif
}

static int serve(kdr_server *srv, const kdr_options *o) {
    sig_state sw;
    /* Signals first: every thread created later inherits the blocked mask. */
    if (start_signals(&sw, srv) != 0) {
        kdr_log_error("cannot set up signal handling");
        return 1;
    }
    kdr_exec_config cfg = {srv->threads, o->max_queue, srv->max_inflight,
                           lower_worker_priority, srv};
    srv->exec = kdr_exec_create(&cfg);
    if (!srv->exec) {
        kdr_log_error("cannot start %u worker threads: %s", srv->threads,
                      strerror(errno));
        end_signals(&sw);
        return 1;
    }
    raise_file_limit(srv->max_connections);
    char deadline[32] = "none";
    if (srv->deadline_ms > 0)
        snprintf(deadline, sizeof deadline, "%.0f ms", srv->deadline_ms);
    kdr_log("kdrayd %s starting: %zu scene%s, %u worker threads (nice +%d), %u HTTP "
            "threads, queue %zu, in flight %zu MiB, max body %zu MiB, max rays %zu, "
            "deadline %s, %u connections (idle timeout %u s), %s bundles",
            KDRAY_VERSION, kdr_registry_count(srv->registry),
            kdr_registry_count(srv->registry) == 1 ? "" : "s", srv->threads,
            srv->worker_nice, srv->http_threads, o->max_queue, o->max_inflight_mb,
            o->max_body_mb, srv->max_rays, deadline, srv->max_connections,
            srv->connection_timeout_s,
            kdr_cpu_has_avx2() ? "8-wide (AVX2)" : "4-wide");
    kdr_http *h = kdr_http_start(srv, o->listen);
    int status = 1;
    if (h) {
        const char *colon = strrchr(o->listen, ':');
        kdr_log("listening on http://%.*s:%u (503 until every scene is built)",
                (int)(colon - o->listen), o->listen, kdr_http_port(h));
        status = build_scenes(srv);
        if (status == 0) serve_until_stopped(&sw, srv);
        kdr_notify("STOPPING=1\nSTATUS=shutting down");
        kdr_log("shutdown: %ld request%s in flight", kdr_metrics_inflight_now(),
                kdr_metrics_inflight_now() == 1 ? "" : "s");
        kdr_http_stop(h, o->grace_s);
    }
    end_signals(&sw);
    kdr_log("stopped (exit %d)", status);
    return status;
}

int main(int argc, char **argv) {
    kdr_options o;
    char default_path[4096];
    int rc = kdr_options_parse(&o, argc, argv);
    kdr_server srv = {.max_body = 0};
    tune_malloc();
    atomic_init(&srv.stopping, 0);
    srv.access_log.fd = -1;
    srv.registry = kdr_registry_create();
    if (rc < 0 && !srv.registry) rc = 1;
    if (rc < 0)
        rc = add_scenes(srv.registry, &o, default_path, sizeof default_path) ? 2 : -1;
    if (rc < 0 && o.access_log &&
        kdr_access_log_open(&srv.access_log, o.access_log) != 0) {
        fprintf(stderr, "kdrayd: --access-log %s: %s (see kdrayd --help)\n", o.access_log,
                strerror(errno));
        rc = 2;
    }
    if (rc < 0 && o.cache_dir) {
        char why[512];
        if (kdr_tree_cache_prepare(o.cache_dir, why, sizeof why) != 0) {
            fprintf(stderr, "kdrayd: --cache-dir %s (see kdrayd --help)\n", why);
            rc = 2;
        } else {
            kdr_registry_set_cache_dir(srv.registry, o.cache_dir);
        }
    }
    if (rc < 0) {
        kdr_log_set_level((kdr_log_level)o.log_level);
        srv.threads = o.threads;
        srv.http_threads = o.http_threads;
        srv.max_body = o.max_body_mb << 20;
        srv.max_rays = o.max_rays;
        srv.max_inflight = o.max_inflight_mb << 20;
        srv.max_connections = o.max_connections;
        srv.connection_timeout_s = o.connection_timeout_s;
        srv.deadline_ms = o.deadline_ms;
        srv.worker_nice = o.worker_nice;
        rc = serve(&srv, &o);
    }
    kdr_exec_destroy(srv.exec);
    kdr_registry_free(srv.registry);
    kdr_access_log_close(&srv.access_log);
    kdr_options_free(&o);
    return rc;
}
