/*
 * http_daemon.c — the libmicrohttpd daemon's life: the listening address,
 * the threading and polling mode and the per-connection limits it starts
 * with, and a graceful stop (stop accepting, let requests in flight finish
 * within the grace period, then stop their queries and close what is left).
 */
#define _POSIX_C_SOURCE 200809L
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "http_internal.h"
#include "log.h"

/* MHD per-connection memory. libmicrohttpd 0.9.75 mmaps a pool above 32 KiB
 * (malloc at or below), and after every request zeroes the whole pool: at
 * 256 KiB each new connection faulted in 64 fresh pages and unmapped them
 * at close, 196 us of daemon CPU per GET /v1/health on a new connection
 * against 38 us at 32 KiB (perf stat, 3000 probes), and the idle probe's
 * p90 2.8 -> 0.6 ms, keep-alive p99 3.9 -> 0.28 ms (bench/health_probe.py).
 * Bodies arrive in smaller reads; a 60 MB upload cost the same daemon CPU
 * (128 vs 130 ms) and an 8 MB one 10.5 vs 11.0 ms. */
static const size_t CONNECTION_MEMORY = 32 * 1024;
/* After the grace period, how long a shutdown waits for stopped queries. */
static const double STOP_WAIT_S = 10.0;

static void log_mhd(void *cls, const char *fmt, va_list ap) {
    (void)cls;
    char msg[512];
    vsnprintf(msg, sizeof msg, fmt, ap);
    size_t n = strlen(msg);
    while (n && (msg[n - 1] == '\n' || msg[n - 1] == '\r'))
        msg[--n] = '\0';
    kdr_log_warn("http: %s", msg);
}

/* Parses "HOST:PORT" / "[V6]:PORT" into a socket address. */
static int parse_addr(const char *addr, struct sockaddr_storage *ss, int *v6) {
    char host[256];
    const char *colon = strrchr(addr, ':');
    if (!colon || colon == addr || (size_t)(colon - addr) >= sizeof host) return -1;
    char *end;
    errno = 0;
    unsigned long port = strtoul(colon + 1, &end, 10);
    if (errno || end == colon + 1 || *end || port > 65535) return -1;
    memcpy(host, addr, (size_t)(colon - addr));
    host[colon - addr] = '\0';
    memset(ss, 0, sizeof *ss);
    size_t hl = strlen(host);
    if (host[0] == '[' && hl > 2 && host[hl - 1] == ']') {
        struct sockaddr_in6 *s6 = (struct sockaddr_in6 *)ss;
        host[hl - 1] = '\0';
        s6->sin6_family = AF_INET6;
        s6->sin6_port = htons((uint16_t)port);
        *v6 = 1;
        return inet_pton(AF_INET6, host + 1, &s6->sin6_addr) == 1 ? 0 : -1;
    }
    struct sockaddr_in *s4 = (struct sockaddr_in *)ss;
    s4->sin_family = AF_INET;
    s4->sin_port = htons((uint16_t)port);
    *v6 = 0;
    if (!strcmp(host, "localhost")) strcpy(host, "127.0.0.1");
    return inet_pton(AF_INET, host, &s4->sin_addr) == 1 ? 0 : -1;
}

int kdr_http_addr_ok(const char *addr) {
    struct sockaddr_storage ss;
    int v6;
    return parse_addr(addr, &ss, &v6) == 0;
}

kdr_http *kdr_http_start(kdr_server *srv, const char *addr) {
    struct sockaddr_storage ss;
    int v6 = 0;
    if (parse_addr(addr, &ss, &v6) != 0) {
        kdr_log_error("--listen %s: expected ADDR:PORT (IPv4, localhost or [IPv6])",
                      addr);
        return NULL;
    }
    kdr_http *h = calloc(1, sizeof *h);
    if (!h) return NULL;
    h->srv = srv;
    h->quiesced = MHD_INVALID_SOCKET;
    /* poll(), not epoll: with MHD 0.9.75's epoll mode a client that hangs up
     * in the middle of a body is noticed only at the connection timeout
     * (measured: 7 of 10 hang-ups), so it counts as in flight for a minute. */
    unsigned flags = MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_POLL | MHD_USE_ITC |
                     MHD_ALLOW_SUSPEND_RESUME | MHD_USE_ERROR_LOG |
                     (v6 ? MHD_USE_IPv6 : 0);
    h->watcher = kdr_watcher_start();
    if (!h->watcher) {
        kdr_log_error("cannot start the connection watcher: %s", strerror(errno));
        free(h);
        return NULL;
    }
    /* The logger goes first so that MHD reports option errors through it. */
    /* clang-format off */
    h->d = MHD_start_daemon(flags, 0, NULL, NULL, kdr_http_on_request, h,
        MHD_OPTION_EXTERNAL_LOGGER, log_mhd, (void *)NULL,
        MHD_OPTION_SOCK_ADDR, (const struct sockaddr *)&ss,
        MHD_OPTION_THREAD_POOL_SIZE, (unsigned)srv->http_threads,
        MHD_OPTION_CONNECTION_LIMIT, (unsigned)srv->max_connections,
        MHD_OPTION_NOTIFY_COMPLETED, kdr_http_on_completed, (void *)h,
        MHD_OPTION_CONNECTION_MEMORY_LIMIT, CONNECTION_MEMORY,
        MHD_OPTION_CONNECTION_TIMEOUT, srv->connection_timeout_s,
        MHD_OPTION_END);
    /* clang-format on */
    if (!h->d) {
        kdr_log_error("cannot listen on %s: %s", addr, strerror(errno));
        kdr_watcher_stop(h->watcher);
        free(h);
        return NULL;
    }
    const union MHD_DaemonInfo *info =
        MHD_get_daemon_info(h->d, MHD_DAEMON_INFO_BIND_PORT);
    h->port = info ? info->port : 0;
    return h;
}

unsigned kdr_http_port(const kdr_http *h) { return h->port; }

static void sleep_ms(long ms) {
    struct timespec ts = {ms / 1000, (ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

void kdr_http_quiesce(kdr_http *h) {
    if (!h || h->quiesced != MHD_INVALID_SOCKET) return;
    atomic_store(&h->srv->stopping, 1);
    h->quiesced = MHD_quiesce_daemon(h->d);
}

/* Waits until nothing is in flight or `seconds` pass; what is left. */
static long wait_idle(double seconds) {
    double t0 = kdr_now();
    long left;
    while ((left = kdr_metrics_inflight_now()) > 0 && kdr_now() - t0 < seconds)
        sleep_ms(10);
    return left;
}

/* Waits until the executor holds no query: every stopped query has been
 * finished and its connection resumed. Chunks are bounded, so this ends. */
static void wait_executor(kdr_exec *ex) {
    kdr_exec_stats st;
    for (long ms = 0;; ms += 10) {
        kdr_exec_get_stats(ex, &st);
        if (st.queued + st.running == 0) return;
        if (ms && ms % 10000 == 0)
            kdr_log_warn("shutdown: waiting for %zu quer%s to reach a chunk boundary",
                         st.queued + st.running,
                         st.queued + st.running == 1 ? "y" : "ies");
        sleep_ms(10);
    }
}

void kdr_http_stop(kdr_http *h, double grace_s) {
    if (!h) return;
    kdr_http_quiesce(h);
    long left = wait_idle(grace_s);
    if (left > 0) {
        kdr_log_warn(
            "shutdown: %ld request%s still in flight after %.0f s: stopping their "
            "queries",
            left, left == 1 ? "" : "s", grace_s);
        kdr_exec_shutdown(h->srv->exec);
        wait_executor(h->srv->exec);
        left = wait_idle(STOP_WAIT_S);
        if (left > 0)
            kdr_log_warn("shutdown: closing %ld connection%s", left,
                         left == 1 ? "" : "s");
    }
    /* No query is suspended now (they all finished above), so MHD never has
     * to resume a connection behind the executor's back. */
    MHD_stop_daemon(h->d);
    if (h->quiesced != MHD_INVALID_SOCKET) close(h->quiesced);
    kdr_watcher_stop(h->watcher);
    free(h);
}
