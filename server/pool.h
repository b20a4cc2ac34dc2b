/*
 * pool.h — the job pool that splits one large query across worker threads.
 * A job is "run fn(ctx, c) for every chunk c in [0, nchunks)"; the calling
 * thread works on its own job too, so a pool of T-1 workers gives one
 * request T-way parallelism and a pool of 0 workers runs jobs inline.
 * Several requests may submit jobs at once; workers serve them in order.
 * Chunks must write disjoint outputs: the core's range arguments exist for
 * exactly that, which keeps every answer identical to a single-threaded one.
 */
#ifndef KDR_SRV_POOL_H
#define KDR_SRV_POOL_H

#include <stddef.h>

/* Work per chunk, shared by kdrayd (query.c) and kdray-trace: large enough
 * to amortise the pool hand-off, small enough that a 2-core machine balances
 * a 64K-ray request. Frustum chunks are a multiple of 4 tiles so that the
 * 4-frusta grouping is never cut. Both programs must split alike: a
 * cone-shadow call carries state from point to point (each light's last
 * blocker and walk back-off), so its kdr_shadow_stats depend on where the
 * point chunks start (the visibilities never do), and the integration test
 * compares the daemon's stats with kdray-trace's. */
enum { KDR_CHUNK_RAYS = 4096, KDR_CHUNK_TILES = 16, KDR_CHUNK_POINTS = 64 };

typedef struct kdr_pool kdr_pool;
typedef void (*kdr_pool_fn)(void *ctx, size_t chunk);

/* NULL on failure (errno set). */
kdr_pool *kdr_pool_create(unsigned workers);
/* Returns when every chunk has run. Thread-safe. */
void kdr_pool_run(kdr_pool *pool, size_t nchunks, kdr_pool_fn fn, void *ctx);
/* Joins the workers; no job may be running. NULL-safe. */
void kdr_pool_destroy(kdr_pool *pool);

#endif
