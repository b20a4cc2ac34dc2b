/*
 * registry.c — the scene table. Entries are added on the main thread, then
 * each is built by one start-up thread (kdr_registry_build, several at
 * once); an entry's `built` flag and the table's ready flag are release
 * stores, read by the HTTP threads with acquire loads.
 */
#include "registry.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"

enum { NAME_MAX_LEN = 64, ERR_LEN = 512 };

struct kdr_registry {
    kdr_served_scene *s;
    size_t n, cap;
    atomic_size_t built;
    atomic_int ready;
};

kdr_registry *kdr_registry_create(void) {
    kdr_registry *r = calloc(1, sizeof *r);
    if (r) {
        atomic_init(&r->built, 0);
        atomic_init(&r->ready, 0);
    }
    return r;
}

void kdr_registry_free(kdr_registry *r) {
    if (!r) return;
    for (size_t i = 0; i < r->n; i++) {
        kdr_scene_free(r->s[i].scene);
        free(r->s[i].ranges);
    }
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
        kdr_served_scene *s = realloc(r->s, cap * sizeof *s);
        if (!s) return -1;
        r->s = s;
        r->cap = cap;
    }
    r->s[r->n] = (kdr_served_scene){.name = name, .path = path};
    atomic_init(&r->s[r->n].built, 0);
    r->n++;
    return 0;
}

size_t kdr_registry_count(const kdr_registry *r) { return r->n; }

static void build_log(void *user, const char *msg) {
    kdr_log("scene %s: %s", ((const kdr_served_scene *)user)->name, msg);
}

static void log_stats(const kdr_served_scene *s) {
    kdr_tree_stats st;
    kdr_bounds b;
    kdr_scene_tree_stats(s->scene, &st);
    kdr_scene_bounds(s->scene, &b);
    kdr_log("scene %s: %zu triangles, %zu meshes, loaded in %.1f ms; kd-tree built "
            "in %.1f ms: %llu nodes, %llu leaves (%llu empty), max depth %llu, "
            "%.2f refs/leaf, SAH cost %.2f, %.1f MiB; bounds [%g %g %g]..[%g %g %g]",
            s->name, kdr_scene_triangle_count(s->scene), s->nranges, s->load_ms,
            s->build_ms, (unsigned long long)st.nodes, (unsigned long long)st.leaves,
            (unsigned long long)st.empty_leaves, (unsigned long long)st.max_depth,
            st.refs_per_leaf, st.sah_cost, (double)st.bytes / (1024.0 * 1024.0), b.min[0],
            b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]);
}

int kdr_registry_build(kdr_registry *r, size_t i, int threads) {
    kdr_served_scene *s = &r->s[i];
    char err[ERR_LEN] = "";
    kdr_gltf_scene g;
    kdr_log("scene %s: loading %s", s->name, s->path);
    if (kdr_gltf_load(s->path, &g, err, sizeof err) != 0) {
        kdr_log("error: scene %s: %s", s->name, err[0] ? err : "load failed");
        return -1;
    }
    kdr_build_opts opts;
    kdr_build_opts_default(&opts);
    opts.threads = threads;
    double t0 = kdr_now();
    int rc = kdr_scene_build(g.tris, g.ntris, &opts, build_log, s, &s->scene);
    s->build_ms = (kdr_now() - t0) * 1e3;
    s->load_ms = g.load_ms;
    s->ranges = g.ranges;
    s->nranges = g.nranges;
    g.ranges = NULL;
    g.nranges = 0;
    kdr_gltf_free(&g);
    if (rc != KDR_OK) {
        kdr_log("error: scene %s: kd-tree build failed: %s", s->name, kdr_strerror(rc));
        return -1;
    }
    log_stats(s);
    atomic_store_explicit(&s->built, 1, memory_order_release);
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

const kdr_served_scene *kdr_registry_find(const kdr_registry *r, const char *name,
                                          size_t len) {
    for (size_t i = 0; i < r->n; i++)
        if (strlen(r->s[i].name) == len && !memcmp(r->s[i].name, name, len))
            return &r->s[i];
    return NULL;
}

const kdr_served_scene *kdr_registry_at(const kdr_registry *r, size_t i) {
    return i < r->n ? &r->s[i] : NULL;
}

/* An entry not yet flagged built may be in the middle of a build on a
 * start-up thread: only flagged entries are read. */
static int entry_built(const kdr_registry *r, size_t i) {
    return atomic_load_explicit(&((kdr_registry *)r)->s[i].built, memory_order_acquire);
}

void kdr_registry_render_metrics(const kdr_registry *r, kdr_tb *tb) {
    const size_t nb = r->n;
    kdr_tb_printf(tb, "# HELP kdray_scene_build_seconds Wall time of the kd-tree "
                      "build, per scene.\n# TYPE kdray_scene_build_seconds gauge\n");
    for (size_t i = 0; i < nb; i++)
        if (entry_built(r, i))
            kdr_tb_printf(tb, "kdray_scene_build_seconds{scene=\"%s\"} %.6f\n",
                          r->s[i].name, r->s[i].build_ms * 1e-3);
    kdr_tb_printf(tb, "# HELP kdray_scene_load_seconds Wall time of the glTF load, "
                      "per scene.\n# TYPE kdray_scene_load_seconds gauge\n");
    for (size_t i = 0; i < nb; i++)
        if (entry_built(r, i))
            kdr_tb_printf(tb, "kdray_scene_load_seconds{scene=\"%s\"} %.6f\n",
                          r->s[i].name, r->s[i].load_ms * 1e-3);
    kdr_tb_printf(tb, "# HELP kdray_scene_triangles Triangles per scene.\n"
                      "# TYPE kdray_scene_triangles gauge\n");
    for (size_t i = 0; i < nb; i++)
        if (entry_built(r, i))
            kdr_tb_printf(tb, "kdray_scene_triangles{scene=\"%s\"} %zu\n",
                          r->s[i].name, kdr_scene_triangle_count(r->s[i].scene));
    kdr_tb_printf(tb,
                  "# HELP kdray_ready 1 once every scene is built.\n"
                  "# TYPE kdray_ready gauge\nkdray_ready %d\n",
                  kdr_registry_ready(r));
}
