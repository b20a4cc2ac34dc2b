/*
 * metrics.h — the daemon's Prometheus counters: requests by endpoint and
 * status, rays traced by query kind, a request latency histogram. Every
 * update is a relaxed C11 atomic add, so the request path takes no lock;
 * a scrape reads the counters without stopping anyone (counts may be a few
 * requests apart, as Prometheus allows). The executor keeps its own books
 * (kdr_exec_get_stats); they are rendered here too.
 */
#ifndef KDR_SRV_METRICS_H
#define KDR_SRV_METRICS_H

#include <stdint.h>

#include "kdr_exec.h"
#include "textbuf.h"

typedef enum kdr_endpoint {
    KDR_EP_HEALTH,
    KDR_EP_READY,
    KDR_EP_METRICS,
    KDR_EP_SCENES,
    KDR_EP_SCENE,
    KDR_EP_BUNDLE,
    KDR_EP_CONE_SHADOW,
    KDR_EP_FRUSTUM,
    KDR_EP_RENDER, /* GET .../render.png */
    KDR_EP_PAGE,   /* GET /: the page (page.c) */
    KDR_EP_CLOSEST_POINT,
    KDR_EP_OCCUPANCY,
    KDR_EP_OTHER, /* unknown paths */
    KDR_EP_COUNT
} kdr_endpoint;

typedef enum kdr_ray_kind {
    KDR_RAYS_BUNDLE,
    KDR_RAYS_SHADOW,
    KDR_RAYS_FRUSTUM,
    KDR_RAYS_RENDER, /* a picture's primary, shadow and ao rays */
    KDR_RAYS_POINTS,    /* closest-point: points searched */
    KDR_RAYS_OCCUPANCY, /* occupancy: points x vote rays */
    KDR_RAYS_COUNT
} kdr_ray_kind;

const char *kdr_endpoint_name(kdr_endpoint ep);

/* Records one answered request; latency in seconds. */
void kdr_metrics_request(kdr_endpoint ep, unsigned status, double seconds);
void kdr_metrics_rays(kdr_ray_kind kind, uint64_t rays);
/* Requests currently between first byte and completion. */
void kdr_metrics_inflight(int delta);
long kdr_metrics_inflight_now(void);

/* Appends every counter in Prometheus text format 0.0.4. */
void kdr_metrics_render(kdr_tb *tb);
/* Appends the executor's gauges and counters: queue depth and slots,
 * workers busy, bytes in flight and their limit, admissions refused by
 * reason, deadlines, cancellations, queries stopped by the shutdown, out of
 * memory answers. */
void kdr_metrics_render_exec(kdr_tb *tb, const kdr_exec_stats *s);

#endif
