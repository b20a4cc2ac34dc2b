/*
 * registry.h — the scenes kdrayd serves: name, source path, the loaded mesh
 * ranges and the built kd-tree. The table is filled from the command line
 * before the HTTP port opens; scenes are then built (several at once, each
 * entry by one thread) while the port already answers 503. An entry's own
 * `built` flag (release/acquire) publishes it to the metrics page; requests
 * see scenes only through kdr_registry_ready(), after which every entry is
 * read-only and shared by all threads.
 */
#ifndef KDR_SRV_REGISTRY_H
#define KDR_SRV_REGISTRY_H

#include <stdatomic.h>
#include <stddef.h>

#include "kdr_gltf.h"
#include "kdray.h"
#include "textbuf.h"

typedef struct kdr_served_scene {
    const char *name; /* points into argv or a literal */
    const char *path;
    kdr_scene *scene;
    kdr_mesh_range *ranges;
    size_t nranges;
    double load_ms, build_ms;
    atomic_int built; /* 1 once the fields above are final (release) */
} kdr_served_scene;

typedef struct kdr_registry kdr_registry;

kdr_registry *kdr_registry_create(void);
void kdr_registry_free(kdr_registry *r);
/* Adds an unbuilt scene; -1 if the name is a duplicate or invalid. */
int kdr_registry_add(kdr_registry *r, const char *name, const char *path);
size_t kdr_registry_count(const kdr_registry *r);

/* Loads and builds scene i with `threads` build threads (kdr_build_opts),
 * logging its statistics. Returns 0, or -1 after logging a one-line error.
 * Different entries may be built by different threads at the same time. */
int kdr_registry_build(kdr_registry *r, size_t i, int threads);
/* Marks every scene built: queries may start. */
void kdr_registry_set_ready(kdr_registry *r);
int kdr_registry_ready(const kdr_registry *r);
size_t kdr_registry_built(const kdr_registry *r);

/* After ready: the scene called name (length len), or NULL. */
const kdr_served_scene *kdr_registry_find(const kdr_registry *r, const char *name,
                                          size_t len);
const kdr_served_scene *kdr_registry_at(const kdr_registry *r, size_t i);

/* Appends build-time and size gauges of every built scene. */
void kdr_registry_render_metrics(const kdr_registry *r, kdr_tb *tb);

#endif
