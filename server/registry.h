/*
 * registry.h — the scenes kdrayd serves. Each name maps to its current
 * version: one load + kd-tree build of its file, reference-counted. The
 * table of names is filled from the command line before the HTTP port
 * opens and never changes afterwards; scenes are then built, several at
 * once (each entry by one start-up thread), while the port already answers
 * 503, and requests see them only once
 * kdr_registry_ready() (a release/acquire flag) says all are built.
 *
 * Reload (SIGHUP): kdr_registry_reload() re-reads every scene file whose
 * identity (device, inode, size, modification time) changed, builds the new
 * version on the calling thread while the old one keeps serving, and swaps
 * the pointer under a mutex held only for the swap. A query holds the
 * version it started on until it ends (acquire/release), so queries in
 * flight finish on the old tree, which is freed when its last one ends. A
 * file that no longer loads or builds keeps the old version and is logged.
 */
#ifndef KDR_SRV_REGISTRY_H
#define KDR_SRV_REGISTRY_H

#include <stdatomic.h>
#include <stddef.h>

#include "kdr_gltf.h"
#include "kdr_protocol.h"
#include "kdray.h"
#include "textbuf.h"

/* One built version of a scene; read-only and shared once published. */
typedef struct kdr_scene_version {
    kdr_scene *scene;
    kdr_mesh_range *ranges;
    kdr_proto_mesh_range *proto_ranges; /* the same, for the "mesh" field */
    size_t nranges;
    double load_ms, build_ms;
    unsigned generation; /* 1 for the start-up build, +1 per reload */
    int from_cache;      /* mapped from --cache-dir instead of built */
    void *map;           /* the cache file scene reads from, or NULL */
    size_t map_len;
    atomic_long refs;
    /* Running mean cost of one ray of work, in ns of one thread, per query
     * kind (bundle, cone-shadow, frustum; 0 = not measured yet): how much a
     * query of N rays would hold an HTTP thread if answered inline; render
     * is measured too, per pixel x (1 + samples), though never inlined). */
    atomic_uint ns_per_ray[6]; /* by kdr_exec_kind */
} kdr_scene_version;

typedef struct kdr_registry kdr_registry;

kdr_registry *kdr_registry_create(void);
/* Keeps built trees in dir (--cache-dir, see tree_cache.h) and maps them
 * from there when a scene file's bytes and the build options match; dir
 * must outlive the registry. Set before the first build. */
void kdr_registry_set_cache_dir(kdr_registry *r, const char *dir);
/* Frees the table and the current versions; none may still be acquired. */
void kdr_registry_free(kdr_registry *r);
/* Adds an unbuilt scene; -1 if the name is a duplicate or invalid. name and
 * path must outlive the registry. */
int kdr_registry_add(kdr_registry *r, const char *name, const char *path);
size_t kdr_registry_count(const kdr_registry *r);
const char *kdr_registry_name(const kdr_registry *r, size_t i);
/* Index of the scene called name (length len), or -1. */
long kdr_registry_index(const kdr_registry *r, const char *name, size_t len);

/* Loads and builds scene i (start-up) with `threads` build threads
 * (kdr_build_opts; reloads use the same count), or maps it from the tree
 * cache, logging its statistics. 0, or -1 after logging a one-line error.
 * Different entries may be built by different threads at the same time. */
int kdr_registry_build(kdr_registry *r, size_t i, int threads);
/* Marks every scene built: queries may start. */
void kdr_registry_set_ready(kdr_registry *r);
int kdr_registry_ready(const kdr_registry *r);
size_t kdr_registry_built(const kdr_registry *r);

/* The current version of scene i, or NULL if it is not built yet; hold it
 * for as long as it is used, then release it. */
kdr_scene_version *kdr_registry_acquire(kdr_registry *r, size_t i);
void kdr_registry_release(kdr_scene_version *v);

/* Re-reads every scene file (see above); returns the number that failed.
 * Not concurrent with itself or with kdr_registry_build. */
size_t kdr_registry_reload(kdr_registry *r);

/* Appends build-time, size, generation and reload gauges of every built
 * scene. */
void kdr_registry_render_metrics(kdr_registry *r, kdr_tb *tb);

#endif
