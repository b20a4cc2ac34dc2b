/*
 * options.c — kdrayd's flags (see options.h and usage() below). Every flag
 * takes "--flag value" or "--flag=value"; a bad value exits 2 with one line
 * naming the flag and what it accepts. Limits that depend on each other are
 * checked together at the end, so the daemon never starts with a budget in
 * which a request of the allowed size could never be admitted.
 */
#define _POSIX_C_SOURCE 200809L
#include "options.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "kdr_exec.h"
#include "log.h"
#include "server.h"

#ifndef KDRAY_VERSION
#define KDRAY_VERSION "0.0.0"
#endif

static const char *const DEFAULT_LISTEN = "127.0.0.1:8080";
static const size_t DEFAULT_MAX_BODY_MB = 64;
static const size_t DEFAULT_MAX_RAYS = 4194304;
/* Unless given, the in-flight budget is this, or room for this many
 * maximum-size bodies (parse included) if that is more. */
static const size_t DEFAULT_MAX_INFLIGHT_MB = 512;
static const size_t DEFAULT_INFLIGHT_BODIES = 2;
static const size_t DEFAULT_MAX_QUEUE = 64;
static const unsigned DEFAULT_MAX_CONNECTIONS = 512;
static const unsigned MAX_THREADS = 256;
static const size_t MAX_BODY_MB_LIMIT = 4096;
static const size_t MAX_INFLIGHT_MB_LIMIT = (size_t)1 << 20; /* 1 TiB */
static const size_t MAX_QUEUE_LIMIT = 65536;
static const unsigned MAX_CONNECTIONS_LIMIT = 65536;
/* Seconds a connection may go without a byte moving either way: an idle
 * keep-alive client, a body that stops arriving, or a client that stopped
 * reading its (streamed) answer. */
static const unsigned DEFAULT_CONNECTION_TIMEOUT_S = 60;
static const unsigned MAX_CONNECTION_TIMEOUT_S = 86400;
static const double MAX_DEADLINE_MS = 86400000.0;
static const size_t DEFAULT_GRACE_S = 30;
/* Workers run at this nice value above the HTTP threads: with every worker
 * tracing on a shared 2-core box, a /v1/health probe's p90 fell from 4-20 ms
 * to ~1 ms. Workers still get every cycle nobody else wants. */
static const size_t DEFAULT_WORKER_NICE = 10;
static const size_t MAX_GRACE_S = 3600;

static void usage(FILE *f) {
    fprintf(
        f,
        "usage: kdrayd [options]\n"
        "Serves batched ray queries (bundle, cone-shadow, frustum) over HTTP/JSON\n"
        "on SAH kd-trees built from glTF scenes at start-up.\n\n"
        "Scenes and network:\n"
        "  --scene NAME=PATH     serve PATH (.glb or .gltf) as NAME; repeatable\n"
        "                        (default: the bundled scene as \"default\")\n"
        "  --listen ADDR:PORT    address to listen on (default %s; port 0 picks\n"
        "                        a free port, logged at start-up)\n"
        "  --max-connections N   HTTP connections at once (default %u)\n"
        "  --http-threads N      threads that read requests and write answers; they\n"
        "                        never trace (default: number of cores, at least 2)\n"
        "  --connection-timeout-s N  close a connection when no byte has moved\n"
        "                        either way for N seconds: an idle keep-alive client,\n"
        "                        a stalled body, or a client that stopped reading its\n"
        "                        answer (its query is cancelled, its memory and slot\n"
        "                        freed) (1..86400, default %u)\n"
        "Work and admission:\n"
        "  --threads N           worker threads that parse, trace and encode queries,\n"
        "                        and kd-tree build threads (default: number of cores)\n"
        "  --worker-nice N       the workers' nice value above the HTTP threads, so\n"
        "                        probes and small requests are answered at once while\n"
        "                        they trace (0..19, default %zu)\n"
        "  --max-queue N         queries admitted beyond one per worker; more get 503\n"
        "                        with Retry-After (default %zu)\n"
        "  --max-inflight-mb N   memory budget of admitted queries: bodies, parsed\n"
        "                        arrays, results, answers, charged before they are\n"
        "                        allocated; over it: 503 with Retry-After (default %zu,\n"
        "                        or %zu x --max-body-mb x 3 if more; at least\n"
        "                        3 x --max-body-mb)\n"
        "  --max-body-mb N       largest request body in MiB (default %zu)\n"
        "  --max-rays N          most rays per request (default %zu)\n"
        "  --deadline-ms N       stop a query that runs longer than N ms after its\n"
        "                        first byte, between chunks, with a 503 (default: none;\n"
        "                        a request's \"deadline_ms\" can only shorten it)\n"
        "  --shutdown-grace-s N  on SIGTERM, let requests in flight run this long,\n"
        "                        then stop their queries with a 503 (default %zu)\n"
        "Trees:\n"
        "  --cache-dir DIR       keep built kd-trees in DIR (created if missing) and\n"
        "                        map them at the next start or reload instead of\n"
        "                        building; keyed by the scene file's bytes and the\n"
        "                        build options; a damaged file is rebuilt; replicas\n"
        "                        may share DIR (default: no cache)\n"
        "Logs:\n"
        "  --access-log FILE|-   one line per request: time, client, method, path,\n"
        "                        status, rays, bytes in, bytes out, ms (\"-\": stdout;\n"
        "                        reopened on SIGHUP)\n"
        "  --log-level LEVEL     error, warn, info (default) or debug (per-request\n"
        "                        refusals, deadlines and hang-ups)\n"
        "  --help, --version\n\n"
        "Signals: SIGHUP re-reads changed scene files (the old tree serves until\n"
        "the new one is built; a file that fails keeps the old one) and reopens the\n"
        "access log; SIGINT/SIGTERM stop accepting, finish requests in flight\n"
        "(--shutdown-grace-s) and exit 0.\n"
        "Endpoints: /v1/health (alive, scenes built), /v1/ready (503 while starting,\n"
        "stopping or saturated), /metrics, "
        "/v1/scenes[/NAME[/bundle|cone-shadow|frustum]].\n",
        DEFAULT_LISTEN, DEFAULT_MAX_CONNECTIONS, DEFAULT_CONNECTION_TIMEOUT_S,
        DEFAULT_WORKER_NICE, DEFAULT_MAX_QUEUE,
        DEFAULT_MAX_INFLIGHT_MB, DEFAULT_INFLIGHT_BODIES, DEFAULT_MAX_BODY_MB,
        DEFAULT_MAX_RAYS, DEFAULT_GRACE_S);
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

static const char *const FLAGS[] = {"--scene",
                                    "--listen",
                                    "--threads",
                                    "--http-threads",
                                    "--connection-timeout-s",
                                    "--max-body-mb",
                                    "--max-rays",
                                    "--max-inflight-mb",
                                    "--max-queue",
                                    "--deadline-ms",
                                    "--max-connections",
                                    "--access-log",
                                    "--log-level",
                                    "--shutdown-grace-s",
                                    "--worker-nice",
                                    "--cache-dir",
                                    NULL};

static int known(const char *a, size_t len) {
    for (int k = 0; FLAGS[k]; k++)
        if (len == strlen(FLAGS[k]) && !strncmp(a, FLAGS[k], len)) return 1;
    return 0;
}

/* One flag with its value v; -1 to go on or an exit status. */
static int take(kdr_options *o, const char *flag, const char *v) {
    size_t n;
    if (!strcmp(flag, "--scene")) {
        const char *sep = strchr(v, '=');
        if (!sep || sep == v || !sep[1])
            return bad_flag("--scene %s: expected NAME=PATH", v);
        o->scene_args[o->nscenes++] = (char *)v; /* v is argv storage */
    } else if (!strcmp(flag, "--listen")) {
        if (!kdr_http_addr_ok(v))
            return bad_flag("--listen %s: expected ADDR:PORT (IPv4, localhost or [IPv6])",
                            v);
        o->listen = v;
    } else if (!strcmp(flag, "--threads")) {
        if (parse_size(v, 1, MAX_THREADS, &n))
            return bad_flag("--threads %s: expected 1..256", v);
        o->threads = (unsigned)n;
    } else if (!strcmp(flag, "--http-threads")) {
        if (parse_size(v, 1, MAX_THREADS, &n))
            return bad_flag("--http-threads %s: expected 1..256", v);
        o->http_threads = (unsigned)n;
    } else if (!strcmp(flag, "--max-body-mb")) {
        if (parse_size(v, 1, MAX_BODY_MB_LIMIT, &o->max_body_mb))
            return bad_flag("--max-body-mb %s: expected 1..4096", v);
    } else if (!strcmp(flag, "--max-rays")) {
        if (parse_size(v, 1, (size_t)1 << 32, &o->max_rays))
            return bad_flag("--max-rays %s: expected 1..4294967296", v);
    } else if (!strcmp(flag, "--max-inflight-mb")) {
        if (parse_size(v, 1, MAX_INFLIGHT_MB_LIMIT, &o->max_inflight_mb))
            return bad_flag("--max-inflight-mb %s: expected 1..1048576", v);
    } else if (!strcmp(flag, "--max-queue")) {
        if (parse_size(v, 0, MAX_QUEUE_LIMIT, &o->max_queue))
            return bad_flag("--max-queue %s: expected 0..65536", v);
    } else if (!strcmp(flag, "--max-connections")) {
        if (parse_size(v, 1, MAX_CONNECTIONS_LIMIT, &n))
            return bad_flag("--max-connections %s: expected 1..65536", v);
        o->max_connections = (unsigned)n;
    } else if (!strcmp(flag, "--connection-timeout-s")) {
        if (parse_size(v, 1, MAX_CONNECTION_TIMEOUT_S, &n))
            return bad_flag("--connection-timeout-s %s: expected 1..86400", v);
        o->connection_timeout_s = (unsigned)n;
    } else if (!strcmp(flag, "--deadline-ms")) {
        if (parse_size(v, 0, (size_t)MAX_DEADLINE_MS, &n))
            return bad_flag("--deadline-ms %s: expected 0 (none)..86400000", v);
        o->deadline_ms = (double)n;
    } else if (!strcmp(flag, "--worker-nice")) {
        if (parse_size(v, 0, 19, &n))
            return bad_flag("--worker-nice %s: expected 0..19", v);
        o->worker_nice = (int)n;
    } else if (!strcmp(flag, "--shutdown-grace-s")) {
        if (parse_size(v, 0, MAX_GRACE_S, &n))
            return bad_flag("--shutdown-grace-s %s: expected 0..3600", v);
        o->grace_s = (double)n;
    } else if (!strcmp(flag, "--cache-dir")) {
        if (!*v) return bad_flag("--cache-dir %s: expected a directory", v);
        o->cache_dir = v;
    } else if (!strcmp(flag, "--access-log")) {
        if (!*v) return bad_flag("--access-log %s: expected a file name or -", v);
        o->access_log = v;
    } else {
        int level = kdr_log_parse_level(v);
        if (level < 0)
            return bad_flag("--log-level %s: expected error, warn, info or debug", v);
        o->log_level = level;
    }
    return -1;
}

static int parse_one(kdr_options *o, int argc, char **argv, int *i) {
    const char *a = argv[*i];
    const char *eq = strncmp(a, "--", 2) ? NULL : strchr(a, '=');
    size_t name_len = eq ? (size_t)(eq - a) : strlen(a);
    if (!eq && !strcmp(a, "--help")) return usage(stdout), 0;
    if (!eq && !strcmp(a, "--version")) return printf("kdrayd %s\n", KDRAY_VERSION), 0;
    if (!known(a, name_len)) return bad_flag("unknown argument %s", a);
    char flag[32];
    snprintf(flag, sizeof flag, "%.*s", (int)name_len, a);
    const char *v = flag_value(argc, argv, i, eq);
    if (!v) return bad_flag("%s needs a value", flag);
    return take(o, flag, v);
}

/* Limits that depend on each other. */
static int check_together(kdr_options *o) {
    size_t floor_mb = o->max_body_mb * (1 + KDR_EXEC_PARSE_BYTES_PER_BODY_BYTE);
    if (o->max_inflight_mb == 0) {
        size_t mb = DEFAULT_INFLIGHT_BODIES * floor_mb;
        o->max_inflight_mb = mb > DEFAULT_MAX_INFLIGHT_MB ? mb : DEFAULT_MAX_INFLIGHT_MB;
    } else if (o->max_inflight_mb < floor_mb) {
        char v[96];
        snprintf(v, sizeof v, "%zu is below 3 x --max-body-mb = %zu", o->max_inflight_mb,
                 floor_mb);
        return bad_flag("--max-inflight-mb %s: a body of the maximum size could never be "
                        "admitted",
                        v);
    }
    return -1;
}

int kdr_options_parse(kdr_options *o, int argc, char **argv) {
    *o = (kdr_options){.listen = DEFAULT_LISTEN,
                       .threads = default_threads(),
                       .http_threads = default_threads() < 2 ? 2 : default_threads(),
                       .max_body_mb = DEFAULT_MAX_BODY_MB,
                       .max_rays = DEFAULT_MAX_RAYS,
                       .max_queue = DEFAULT_MAX_QUEUE,
                       .max_connections = DEFAULT_MAX_CONNECTIONS,
                       .connection_timeout_s = DEFAULT_CONNECTION_TIMEOUT_S,
                       .grace_s = (double)DEFAULT_GRACE_S,
                       .worker_nice = (int)DEFAULT_WORKER_NICE,
                       .log_level = KDR_LOG_INFO};
    o->scene_args = calloc((size_t)argc + 1, sizeof *o->scene_args);
    if (!o->scene_args) return 1;
    for (int i = 1; i < argc; i++) {
        int rc = parse_one(o, argc, argv, &i);
        if (rc >= 0) return rc;
    }
    return check_together(o);
}

void kdr_options_free(kdr_options *o) {
    free(o->scene_args);
    o->scene_args = NULL;
}
