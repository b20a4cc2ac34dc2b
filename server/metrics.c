/*
 * metrics.c — process-wide counters behind metrics.h. The counter arrays are
 * globals on purpose: they are the one piece of shared mutable state in the
 * server and each slot is an independent atomic.
 */
#include "metrics.h"

#include <stdatomic.h>
#include <stddef.h>

/* Status codes the daemon can answer with; anything else lands in "other". */
static const unsigned STATUSES[] = {200, 400, 404, 405, 413, 415, 500, 503};
#define NSTATUS (sizeof STATUSES / sizeof STATUSES[0])
#define STATUS_OTHER NSTATUS

/* Latency bucket upper bounds in seconds (Prometheus "le"), then +Inf. */
static const double BUCKETS[] = {0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05,
                                 0.1,    0.25,  0.5,    1.0,   2.5,  5.0,   10.0};
#define NBUCKET (sizeof BUCKETS / sizeof BUCKETS[0])

static const char *const EP_NAMES[KDR_EP_COUNT] = {
    "health",  "ready",  "metrics", "scenes",        "scene",     "bundle", "cone-shadow",
    "frustum", "render", "page",    "closest-point", "occupancy", "other"};
static const char *const RAY_NAMES[KDR_RAYS_COUNT] = {
    "bundle", "cone-shadow", "frustum", "render", "closest-point", "occupancy"};

static atomic_uint_fast64_t requests[KDR_EP_COUNT][NSTATUS + 1];
static atomic_uint_fast64_t latency_buckets[KDR_EP_COUNT][NBUCKET + 1];
static atomic_uint_fast64_t latency_sum_us[KDR_EP_COUNT];
static atomic_uint_fast64_t rays[KDR_RAYS_COUNT];
static atomic_long inflight;

const char *kdr_endpoint_name(kdr_endpoint ep) {
    return ep < KDR_EP_COUNT ? EP_NAMES[ep] : "other";
}

static size_t status_index(unsigned status) {
    for (size_t i = 0; i < NSTATUS; i++)
        if (STATUSES[i] == status) return i;
    return STATUS_OTHER;
}

static size_t bucket_index(double seconds) {
    size_t b = 0;
    while (b < NBUCKET && seconds > BUCKETS[b])
        b++;
    return b;
}

void kdr_metrics_request(kdr_endpoint ep, unsigned status, double seconds) {
    if (ep >= KDR_EP_COUNT) ep = KDR_EP_OTHER;
    if (seconds < 0) seconds = 0;
    atomic_fetch_add_explicit(&requests[ep][status_index(status)], 1,
                              memory_order_relaxed);
    atomic_fetch_add_explicit(&latency_buckets[ep][bucket_index(seconds)], 1,
                              memory_order_relaxed);
    atomic_fetch_add_explicit(&latency_sum_us[ep], (uint_fast64_t)(seconds * 1e6),
                              memory_order_relaxed);
}

void kdr_metrics_rays(kdr_ray_kind kind, uint64_t n) {
    if (kind < KDR_RAYS_COUNT)
        atomic_fetch_add_explicit(&rays[kind], n, memory_order_relaxed);
}

void kdr_metrics_inflight(int delta) {
    atomic_fetch_add_explicit(&inflight, delta, memory_order_relaxed);
}

long kdr_metrics_inflight_now(void) { return atomic_load(&inflight); }

static uint64_t load(atomic_uint_fast64_t *a) {
    return atomic_load_explicit(a, memory_order_relaxed);
}

static void render_requests(kdr_tb *tb) {
    kdr_tb_printf(tb, "# HELP kdray_http_requests_total HTTP requests answered, "
                      "by endpoint and status.\n"
                      "# TYPE kdray_http_requests_total counter\n");
    for (size_t e = 0; e < KDR_EP_COUNT; e++)
        for (size_t s = 0; s <= NSTATUS; s++) {
            uint64_t n = load(&requests[e][s]);
            if (!n) continue;
            if (s == STATUS_OTHER)
                kdr_tb_printf(tb,
                              "kdray_http_requests_total{endpoint=\"%s\","
                              "status=\"other\"} %llu\n",
                              EP_NAMES[e], (unsigned long long)n);
            else
                kdr_tb_printf(tb,
                              "kdray_http_requests_total{endpoint=\"%s\","
                              "status=\"%u\"} %llu\n",
                              EP_NAMES[e], STATUSES[s], (unsigned long long)n);
        }
}

/* Errors are requests with a 4xx/5xx status; exported separately so an
 * alert needs no label arithmetic. */
static void render_errors(kdr_tb *tb) {
    kdr_tb_printf(tb, "# HELP kdray_http_errors_total HTTP requests answered "
                      "with an error status, by endpoint and status.\n"
                      "# TYPE kdray_http_errors_total counter\n");
    for (size_t e = 0; e < KDR_EP_COUNT; e++)
        for (size_t s = 0; s < NSTATUS; s++) {
            uint64_t n = load(&requests[e][s]);
            if (!n || STATUSES[s] < 400) continue;
            kdr_tb_printf(tb,
                          "kdray_http_errors_total{endpoint=\"%s\",status=\"%u\"} "
                          "%llu\n",
                          EP_NAMES[e], STATUSES[s], (unsigned long long)n);
        }
}

static void render_latency(kdr_tb *tb) {
    kdr_tb_printf(tb, "# HELP kdray_http_request_duration_seconds Time from a "
                      "request's first byte to its queued answer.\n"
                      "# TYPE kdray_http_request_duration_seconds histogram\n");
    for (size_t e = 0; e < KDR_EP_COUNT; e++) {
        uint64_t cum = 0;
        for (size_t b = 0; b <= NBUCKET; b++) {
            cum += load(&latency_buckets[e][b]);
            if (b < NBUCKET)
                kdr_tb_printf(tb,
                              "kdray_http_request_duration_seconds_bucket{"
                              "endpoint=\"%s\",le=\"%g\"} %llu\n",
                              EP_NAMES[e], BUCKETS[b], (unsigned long long)cum);
            else
                kdr_tb_printf(tb,
                              "kdray_http_request_duration_seconds_bucket{"
                              "endpoint=\"%s\",le=\"+Inf\"} %llu\n",
                              EP_NAMES[e], (unsigned long long)cum);
        }
        kdr_tb_printf(tb,
                      "kdray_http_request_duration_seconds_sum{endpoint=\"%s\"} "
                      "%.6f\n",
                      EP_NAMES[e], (double)load(&latency_sum_us[e]) * 1e-6);
        kdr_tb_printf(tb,
                      "kdray_http_request_duration_seconds_count{endpoint=\"%s\"} "
                      "%llu\n",
                      EP_NAMES[e], (unsigned long long)cum);
    }
}

static void render_rays(kdr_tb *tb) {
    kdr_tb_printf(tb, "# HELP kdray_rays_traced_total Rays answered, by query kind "
                      "(cone-shadow: shadow rays actually traced; closest-point: points; "
                      "occupancy: points x 9 vote rays).\n"
                      "# TYPE kdray_rays_traced_total counter\n");
    for (size_t k = 0; k < KDR_RAYS_COUNT; k++)
        kdr_tb_printf(tb, "kdray_rays_traced_total{kind=\"%s\"} %llu\n", RAY_NAMES[k],
                      (unsigned long long)load(&rays[k]));
}

void kdr_metrics_render(kdr_tb *tb) {
    render_requests(tb);
    render_errors(tb);
    render_latency(tb);
    render_rays(tb);
    kdr_tb_printf(tb,
                  "# HELP kdray_http_requests_in_flight Requests being read "
                  "or answered.\n# TYPE kdray_http_requests_in_flight gauge\n"
                  "kdray_http_requests_in_flight %ld\n",
                  kdr_metrics_inflight_now());
}

static void gauge(kdr_tb *tb, const char *name, const char *help, double v) {
    kdr_tb_printf(tb, "# HELP %s %s\n# TYPE %s gauge\n%s %.17g\n", name, help, name, name,
                  v);
}

static void counter(kdr_tb *tb, const char *name, const char *help, uint64_t v) {
    kdr_tb_printf(tb, "# HELP %s %s\n# TYPE %s counter\n%s %llu\n", name, help, name,
                  name, (unsigned long long)v);
}

void kdr_metrics_render_exec(kdr_tb *tb, const kdr_exec_stats *s) {
    size_t receiving = s->slots_used - s->queued - s->running;
    gauge(tb, "kdray_queue_depth", "Queries waiting for a worker.", (double)s->queued);
    kdr_tb_printf(tb,
                  "# HELP kdray_queries Admitted queries: body still arriving, waiting "
                  "for a worker, or being parsed, traced or encoded.\n"
                  "# TYPE kdray_queries gauge\n"
                  "kdray_queries{state=\"receiving\"} %zu\n"
                  "kdray_queries{state=\"queued\"} %zu\n"
                  "kdray_queries{state=\"running\"} %zu\n",
                  receiving, s->queued, s->running);
    gauge(tb, "kdray_queue_slots",
          "Queries admitted at most at once (--threads + "
          "--max-queue).",
          (double)s->slots);
    gauge(tb, "kdray_workers", "Executor threads (--threads).", s->workers);
    gauge(tb, "kdray_workers_busy", "Executor threads inside a query.", s->busy);
    gauge(tb, "kdray_inflight_bytes",
          "Bytes charged to admitted requests: bodies, parsed "
          "arrays, results and answers (estimated before allocation).",
          (double)s->bytes_used);
    gauge(tb, "kdray_inflight_bytes_limit", "--max-inflight-mb in bytes.",
          (double)s->bytes_max);
    kdr_tb_printf(tb,
                  "# HELP kdray_rejections_total Query requests refused (503, or 413 "
                  "for more than the whole budget), by reason.\n"
                  "# TYPE kdray_rejections_total counter\n"
                  "kdray_rejections_total{reason=\"queue\"} %llu\n"
                  "kdray_rejections_total{reason=\"memory\"} %llu\n"
                  "kdray_rejections_total{reason=\"too_large\"} %llu\n",
                  (unsigned long long)s->rejected_queue,
                  (unsigned long long)s->rejected_memory,
                  (unsigned long long)s->rejected_too_large);
    counter(tb, "kdray_deadlines_total", "Queries stopped by their deadline (503).",
            s->deadlines);
    counter(tb, "kdray_cancellations_total",
            "Queries stopped because the client hung up.", s->cancelled);
    counter(tb, "kdray_shutdown_stopped_total", "Queries stopped by the shutdown (503).",
            s->shutdown);
    counter(tb, "kdray_out_of_memory_total",
            "Queries answered 503 because memory ran out.", s->out_of_memory);
    counter(tb, "kdray_queries_total",
            "Queries the executor finished, whatever the "
            "outcome.",
            s->completed);
    gauge(tb, "kdray_query_seconds_mean",
          "Recent mean time of a query from its first "
          "worker to its encoded answer (behind Retry-After).",
          s->mean_query_s);
}
