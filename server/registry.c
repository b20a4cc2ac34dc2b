/*
 * registry.c — the scene table and its versions (see registry.h). The
 * table (names, paths) is written on the main thread only, before the HTTP
 * port opens; each entry is then built by one start-up thread, several at
 * once. Each entry's current version pointer and its reload counters
 * change under the registry mutex; readers take the mutex just long enough
 * to copy the pointer and count a reference, so a reload's swap never waits
 * for a query and a query never waits for a build.
 */
#define _POSIX_C_SOURCE 200809L
#include "registry.h"

#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "log.h"
#include "tree_cache.h"

enum { NAME_MAX_LEN = 64, ERR_LEN = 512 };

/* What identifies the bytes of a file without reading them. */
typedef struct file_id {
    dev_t dev;
    ino_t ino;
    off_t size;
    time_t mtime_s;
    long mtime_ns;
} file_id;

typedef struct entry {
    const char *name, *path;
    kdr_scene_version *current; /* under lock */
    file_id id;                 /* of the file current was loaded from */
    int have_id;
    unsigned long reloads_ok, reloads_unchanged, reloads_failed; /* under lock */
} entry;

struct kdr_registry {
    entry *s;
    size_t n, cap;
    pthread_mutex_t lock;
    const char *cache_dir; /* NULL: no tree cache */
    atomic_size_t built;
    atomic_int ready;
    atomic_int threads; /* build threads, for reloads too */
};

kdr_registry *kdr_registry_create(void) {
    kdr_registry *r = calloc(1, sizeof *r);
    if (!r) return NULL;
    pthread_mutex_init(&r->lock, NULL);
    atomic_init(&r->built, 0);
    atomic_init(&r->threads, 1);
    atomic_init(&r->ready, 0);
    return r;
}

void kdr_registry_set_cache_dir(kdr_registry *r, const char *dir) { r->cache_dir = dir; }

static void version_free(kdr_scene_version *v) {
    if (!v) return;
    kdr_scene_free(v->scene); /* before the mapping it may read from */
    kdr_tree_cache_unmap(v->map, v->map_len);
    free(v->ranges);
    free(v->proto_ranges);
    free(v);
}

void kdr_registry_release(kdr_scene_version *v) {
    if (v && atomic_fetch_sub(&v->refs, 1) == 1) version_free(v);
}

void kdr_registry_free(kdr_registry *r) {
    if (!r) return;
    for (size_t i = 0; i < r->n; i++)
        kdr_registry_release(r->s[i].current);
    pthread_mutex_destroy(&r->lock);
    free(r->s);
    free(r);
}

/* Names become URL path segments, so they stay in an unreserved alphabet. */
static int name_ok(const char *name) {
    size_t len = strlen(name);
    if (len == 0 || len > NAME_MAX_LEN) return 0;
    for (size_t i = 0; i < len; i++) {
        char c = name[i];
        int ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                 (c >= '0' && c <= '9') || c == '-' || c == '_' || c == '.';
        if (!ok) return 0;
    }
    return 1;
}

int kdr_registry_add(kdr_registry *r, const char *name, const char *path) {
    if (!name_ok(name) || !path || !*path) return -1;
    for (size_t i = 0; i < r->n; i++)
        if (!strcmp(r->s[i].name, name)) return -1;
    if (r->n == r->cap) {
        size_t cap = r->cap ? 2 * r->cap : 4;
        entry *s = realloc(r->s, cap * sizeof *s);
        if (!s) return -1;
        r->s = s;
        r->cap = cap;
    }
    r->s[r->n++] = (entry){.name = name, .path = path};
    return 0;
}

size_t kdr_registry_count(const kdr_registry *r) { return r->n; }

const char *kdr_registry_name(const kdr_registry *r, size_t i) {
    return i < r->n ? r->s[i].name : NULL;
}

long kdr_registry_index(const kdr_registry *r, const char *name, size_t len) {
    for (size_t i = 0; i < r->n; i++)
        if (strlen(r->s[i].name) == len && !memcmp(r->s[i].name, name, len))
            return (long)i;
    return -1;
}

kdr_scene_version *kdr_registry_acquire(kdr_registry *r, size_t i) {
    if (i >= r->n) return NULL;
    pthread_mutex_lock(&r->lock);
    kdr_scene_version *v = r->s[i].current;
    if (v) atomic_fetch_add(&v->refs, 1);
    pthread_mutex_unlock(&r->lock);
    return v;
}

/* ---- loading one version ------------------------------------------------------ */

static void build_log(void *user, const char *msg) {
    kdr_log("scene %s: %s", ((const entry *)user)->name, msg);
}

static void log_stats(const entry *e, const kdr_scene_version *v) {
    kdr_tree_stats st;
    kdr_bounds b;
    kdr_scene_tree_stats(v->scene, &st);
    kdr_scene_bounds(v->scene, &b);
    kdr_log("scene %s: %zu triangles, %zu meshes, loaded in %.1f ms; kd-tree %s "
            "in %.1f ms: %llu nodes, %llu leaves (%llu empty), max depth %llu, "
            "%.2f refs/leaf, SAH cost %.2f, %.1f MiB; bounds [%g %g %g]..[%g %g %g]",
            e->name, kdr_scene_triangle_count(v->scene), v->nranges, v->load_ms,
            v->from_cache ? "mapped from the tree cache" : "built", v->build_ms,
            (unsigned long long)st.nodes, (unsigned long long)st.leaves,
            (unsigned long long)st.empty_leaves, (unsigned long long)st.max_depth,
            st.refs_per_leaf, st.sah_cost, (double)st.bytes / (1024.0 * 1024.0), b.min[0],
            b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]);
}

static int identify(const char *path, file_id *id) {
    struct stat st;
    if (stat(path, &st) != 0) return -1;
    *id = (file_id){st.st_dev, st.st_ino, st.st_size, st.st_mtim.tv_sec,
                    st.st_mtim.tv_nsec};
    return 0;
}

static int same_file(const file_id *a, const file_id *b) {
    return a->dev == b->dev && a->ino == b->ino && a->size == b->size &&
           a->mtime_s == b->mtime_s && a->mtime_ns == b->mtime_ns;
}

static kdr_scene_version *new_version(unsigned generation) {
    kdr_scene_version *v = calloc(1, sizeof *v);
    if (!v) return NULL;
    v->generation = generation;
    atomic_init(&v->refs, 1);
    for (size_t k = 0; k < sizeof v->ns_per_ray / sizeof v->ns_per_ray[0]; k++)
        atomic_init(&v->ns_per_ray[k], 0);
    return v;
}

/* The tree of e's file from the cache, or NULL (logged) to build it. */
static kdr_scene_version *from_cache(kdr_registry *r, entry *e,
                                     const kdr_build_opts *opts, const kdr_tree_key *key,
                                     unsigned generation) {
    char why[ERR_LEN];
    int refused = 0;
    kdr_cached_tree t;
    double t0 = kdr_now();
    if (!kdr_tree_cache_load(r->cache_dir, key, opts, &t, &refused, why, sizeof why)) {
        if (refused)
            kdr_log_warn("scene %s: tree cache file refused, rebuilding: %s", e->name,
                         why);
        else
            kdr_log("scene %s: tree cache: %s", e->name, why);
        return NULL;
    }
    kdr_scene_version *v = new_version(generation);
    if (!v) {
        kdr_cached_tree_free(&t);
        return NULL;
    }
    v->scene = t.scene;
    v->ranges = t.ranges;
    v->nranges = t.nranges;
    v->map = t.map;
    v->map_len = t.map_len;
    v->from_cache = 1;
    v->build_ms = (kdr_now() - t0) * 1e3;
    char path[4096];
    kdr_tree_cache_path(r->cache_dir, key, path, sizeof path);
    kdr_log("scene %s: tree mapped from cache %s (%.1f MiB) in %.1f ms, not built",
            e->name, path, (double)t.map_len / (1024.0 * 1024.0), v->build_ms);
    return v;
}

/* Stores v's tree under key unless the file changed while it was loaded
 * (then the tree belongs to no key we know). Failures are only logged. */
static void to_cache(kdr_registry *r, entry *e, const kdr_build_opts *opts,
                     const kdr_tree_key *key, const kdr_scene_version *v) {
    char why[ERR_LEN], path[4096];
    kdr_tree_key again;
    if (kdr_tree_cache_key(e->path, opts, &again, why, sizeof why) != 0 ||
        again.h[0] != key->h[0] || again.h[1] != key->h[1]) {
        kdr_log_warn("scene %s: %s changed while it was loaded; tree not cached", e->name,
                     e->path);
        return;
    }
    size_t bytes = 0;
    double t0 = kdr_now();
    kdr_tree_cache_path(r->cache_dir, key, path, sizeof path);
    if (kdr_tree_cache_store(r->cache_dir, key, opts, v->scene, v->ranges, v->nranges,
                             &bytes, why, sizeof why) != 0)
        kdr_log_warn("scene %s: tree not cached: %s", e->name, why);
    else
        kdr_log("scene %s: tree stored in cache %s (%.1f MiB) in %.1f ms", e->name, path,
                (double)bytes / (1024.0 * 1024.0), (kdr_now() - t0) * 1e3);
}

/* Loads and builds e's file as a new version (one reference, the caller's),
 * or maps it from the tree cache; NULL with the reason in why. */
/* The mesh table in the protocol's form (the answers' "mesh" field), for
 * a version built or mapped from the cache alike. -1 out of memory. */
static int set_proto_ranges(kdr_scene_version *v) {
    v->proto_ranges = calloc(v->nranges ? v->nranges : 1, sizeof *v->proto_ranges);
    if (!v->proto_ranges) return -1;
    for (size_t i = 0; i < v->nranges; i++)
        v->proto_ranges[i] = (kdr_proto_mesh_range){
            v->ranges[i].node, v->ranges[i].mesh, v->ranges[i].primitive,
            v->ranges[i].first_prim, v->ranges[i].count};
    return 0;
}

static kdr_scene_version *load_version(kdr_registry *r, entry *e, unsigned generation,
                                       int threads, char *why, size_t why_len) {
    kdr_build_opts opts;
    kdr_build_opts_default(&opts);
    opts.threads = threads; /* not part of the cache key: same tree on any count */
    kdr_tree_key key;
    int keyed = 0;
    if (r->cache_dir) {
        char kwhy[ERR_LEN];
        keyed = kdr_tree_cache_key(e->path, &opts, &key, kwhy, sizeof kwhy) == 0;
        if (!keyed) {
            snprintf(why, why_len, "%s", kwhy);
            return NULL;
        }
        kdr_scene_version *v = from_cache(r, e, &opts, &key, generation);
        if (v && set_proto_ranges(v) != 0) {
            version_free(v);
            snprintf(why, why_len, "out of memory");
            return NULL;
        }
        if (v) return v;
    }
    kdr_gltf_scene g;
    char err[ERR_LEN] = "";
    if (kdr_gltf_load(e->path, &g, err, sizeof err) != 0) {
        snprintf(why, why_len, "%s", err[0] ? err : "load failed");
        return NULL;
    }
    kdr_scene_version *v = new_version(generation);
    if (!v) {
        kdr_gltf_free(&g);
        snprintf(why, why_len, "out of memory");
        return NULL;
    }
    double t0 = kdr_now();
    int rc = kdr_scene_build(g.tris, g.ntris, &opts, build_log, e, &v->scene);
    v->build_ms = (kdr_now() - t0) * 1e3;
    v->load_ms = g.load_ms;
    v->ranges = g.ranges;
    v->nranges = g.nranges;
    g.ranges = NULL;
    g.nranges = 0;
    kdr_gltf_free(&g);
    if (rc == KDR_OK && set_proto_ranges(v) != 0) rc = KDR_ENOMEM;
    if (rc != KDR_OK) {
        snprintf(why, why_len, "kd-tree build failed: %s", kdr_strerror(rc));
        version_free(v);
        return NULL;
    }
    if (keyed) to_cache(r, e, &opts, &key, v);
    return v;
}

int kdr_registry_build(kdr_registry *r, size_t i, int threads) {
    entry *e = &r->s[i];
    char why[ERR_LEN];
    kdr_log("scene %s: loading %s", e->name, e->path);
    e->have_id = identify(e->path, &e->id) == 0;
    atomic_store(&r->threads, threads); /* the same from every start-up thread */
    kdr_scene_version *v = load_version(r, e, 1, threads, why, sizeof why);
    if (!v) {
        kdr_log_error("scene %s: %s", e->name, why);
        return -1;
    }
    log_stats(e, v);
    pthread_mutex_lock(&r->lock);
    e->current = v;
    pthread_mutex_unlock(&r->lock);
    atomic_fetch_add(&r->built, 1);
    return 0;
}

void kdr_registry_set_ready(kdr_registry *r) {
    atomic_store_explicit(&r->ready, 1, memory_order_release);
}

int kdr_registry_ready(const kdr_registry *r) {
    return atomic_load_explicit(&((kdr_registry *)r)->ready, memory_order_acquire);
}

size_t kdr_registry_built(const kdr_registry *r) {
    return atomic_load(&((kdr_registry *)r)->built);
}

/* ---- reload ---------------------------------------------------------------------- */

/* 0 reloaded or unchanged, -1 failed (old version kept). */
static int reload_one(kdr_registry *r, entry *e) {
    char why[ERR_LEN];
    file_id id;
    unsigned gen = e->current ? e->current->generation : 0; /* only we write it */
    if (identify(e->path, &id) != 0) {
        kdr_log_error("scene %s: reload failed, keeping generation %u: %s: %s", e->name,
                      gen, e->path, strerror(errno));
        pthread_mutex_lock(&r->lock);
        e->reloads_failed++;
        pthread_mutex_unlock(&r->lock);
        return -1;
    }
    if (e->have_id && same_file(&id, &e->id)) {
        kdr_log("scene %s: %s unchanged, generation %u kept", e->name, e->path, gen);
        pthread_mutex_lock(&r->lock);
        e->reloads_unchanged++;
        pthread_mutex_unlock(&r->lock);
        return 0;
    }
    kdr_log("scene %s: reloading %s", e->name, e->path);
    kdr_scene_version *v =
        load_version(r, e, gen + 1, atomic_load(&r->threads), why, sizeof why);
    if (!v) {
        kdr_log_error("scene %s: reload failed, keeping generation %u: %s", e->name, gen,
                      why);
        pthread_mutex_lock(&r->lock);
        e->reloads_failed++;
        pthread_mutex_unlock(&r->lock);
        return -1;
    }
    log_stats(e, v);
    pthread_mutex_lock(&r->lock);
    kdr_scene_version *old = e->current;
    e->current = v;
    e->reloads_ok++;
    pthread_mutex_unlock(&r->lock);
    e->id = id;
    e->have_id = 1;
    long in_use = old ? atomic_load(&old->refs) - 1 : 0;
    if (in_use > 0)
        kdr_log("scene %s: generation %u serving; generation %u is freed when the %ld "
                "quer%s still on it end",
                e->name, gen + 1, gen, in_use, in_use == 1 ? "y" : "ies");
    else
        kdr_log("scene %s: generation %u serving; generation %u freed", e->name, gen + 1,
                gen);
    kdr_registry_release(old);
    return 0;
}

size_t kdr_registry_reload(kdr_registry *r) {
    size_t failed = 0;
    for (size_t i = 0; i < r->n; i++)
        failed += reload_one(r, &r->s[i]) != 0;
    return failed;
}

/* ---- metrics ------------------------------------------------------------------------
 */

typedef struct scene_row {
    double build_s, load_s;
    size_t triangles;
    unsigned generation;
    int from_cache;
    unsigned long ok, unchanged, failed;
} scene_row;

static int row_of(kdr_registry *r, size_t i, scene_row *row) {
    kdr_scene_version *v = kdr_registry_acquire(r, i);
    if (!v) return 0;
    pthread_mutex_lock(&r->lock);
    *row = (scene_row){v->build_ms * 1e-3,
                       v->load_ms * 1e-3,
                       kdr_scene_triangle_count(v->scene),
                       v->generation,
                       v->from_cache,
                       r->s[i].reloads_ok,
                       r->s[i].reloads_unchanged,
                       r->s[i].reloads_failed};
    pthread_mutex_unlock(&r->lock);
    kdr_registry_release(v);
    return 1;
}

void kdr_registry_render_metrics(kdr_registry *r, kdr_tb *tb) {
    scene_row *rows = calloc(r->n ? r->n : 1, sizeof *rows);
    int *have = calloc(r->n ? r->n : 1, sizeof *have);
    if (!rows || !have) {
        free(rows);
        free(have);
        return;
    }
    for (size_t i = 0; i < r->n; i++)
        have[i] = row_of(r, i, &rows[i]);
#define GAUGE(NAME, HELP, FMT, EXPR)                                                     \
    do {                                                                                 \
        kdr_tb_printf(tb, "# HELP " NAME " " HELP "\n# TYPE " NAME " gauge\n");          \
        for (size_t i = 0; i < r->n; i++)                                                \
            if (have[i])                                                                 \
                kdr_tb_printf(tb, NAME "{scene=\"%s\"} " FMT "\n", r->s[i].name, EXPR);  \
    } while (0)
    GAUGE("kdray_scene_build_seconds", "Wall time of the kd-tree build, per scene.",
          "%.6f", rows[i].build_s);
    GAUGE("kdray_scene_load_seconds", "Wall time of the glTF load, per scene.", "%.6f",
          rows[i].load_s);
    GAUGE("kdray_scene_triangles", "Triangles per scene.", "%zu", rows[i].triangles);
    GAUGE("kdray_scene_generation",
          "Version of the scene being served (1 at start-up, +1 "
          "per successful reload).",
          "%u", rows[i].generation);
    GAUGE("kdray_scene_from_cache",
          "1 if the served tree was mapped from --cache-dir instead of built.", "%d",
          rows[i].from_cache);
#undef GAUGE
    kdr_tb_printf(tb, "# HELP kdray_scene_reloads_total SIGHUP reloads per scene, by "
                      "result.\n# TYPE kdray_scene_reloads_total counter\n");
    for (size_t i = 0; i < r->n; i++) {
        if (!have[i]) continue;
        kdr_tb_printf(tb,
                      "kdray_scene_reloads_total{scene=\"%s\",result=\"reloaded\"} %lu\n",
                      r->s[i].name, rows[i].ok);
        kdr_tb_printf(
            tb, "kdray_scene_reloads_total{scene=\"%s\",result=\"unchanged\"} %lu\n",
            r->s[i].name, rows[i].unchanged);
        kdr_tb_printf(tb,
                      "kdray_scene_reloads_total{scene=\"%s\",result=\"failed\"} %lu\n",
                      r->s[i].name, rows[i].failed);
    }
    kdr_tb_printf(tb,
                  "# HELP kdray_ready 1 once every scene is built.\n"
                  "# TYPE kdray_ready gauge\nkdray_ready %d\n",
                  kdr_registry_ready(r));
    free(rows);
    free(have);
}
