/*
 * test_tree_cache_mem.c — a tree loaded from kdrayd's cache is mapped for
 * huge pages (server/tree_cache.c, map_huge; issue 11). A scene built here
 * is stored in a temporary cache directory and loaded back; the mapping
 * must start on a 2 MiB boundary, be read-only and shared (replicas share
 * the page cache's copy), carry the MADV_HUGEPAGE advice ("hg" in smaps'
 * VmFlags: it makes the page cache read the file in 2 MiB folios), and
 * hold the loaded scene's arrays; the loaded tree answers rays exactly
 * like the built one. THPeligible is not checked: smaps reports 0 for
 * file mappings on this kernel (6.18) even where FilePmdMapped shows the
 * file mapped in 2 MiB pages. Like test_core_mem, it FAILS where THP is
 * off (mode never). (The cache's file format, damage and publication are
 * tested through kdrayd by test_server_cache.py.)
 */
#define _POSIX_C_SOURCE 200809L
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "kd_internal.h"
#include "kdray.h"
#include "test_util.h"
#include "thp_smaps.h"
#include "tree_cache.h"

static uint64_t rng_state = 0x2545f4914f6cdd1dull;
static float rnd(float lo, float hi) {
    return lo + (hi - lo) * (float)(xorshift64(&rng_state) >> 40) * 0x1p-24f;
}

static int inside(const void *p, size_t n, const void *map, size_t len) {
    const char *a = p, *m = map;
    return a >= m && a + n <= m + len;
}

static void check_loaded(const kdr_cached_tree *t, const kdr_scene *built) {
    CHECK(((uintptr_t)t->map & (THP_HUGE_PAGE - 1)) == 0, "loaded at %p: not 2 MiB-aligned",
          t->map);
    const void *ends[2] = {t->map, (const char *)t->map + t->map_len - 1};
    for (int i = 0; i < 2; i++) {
        const thp_vma v = thp_vma_of(ends[i]);
        CHECK(v.found, "%p not in /proc/self/smaps", ends[i]);
        CHECK(v.advised, "%p (of %zu bytes): mapping lacks the 'hg' VmFlag", ends[i],
              t->map_len);
        CHECK(strcmp(v.perms, "r--s") == 0, "%p: mapping is %s, not r--s (read-only, shared)",
              ends[i], v.perms);
    }
    const kdr_scene *s = t->scene;
    CHECK(s->ntris == built->ntris && s->nnodes == built->nnodes && s->nrefs == built->nrefs,
          "loaded counts %zu/%zu/%zu, built %zu/%zu/%zu", s->ntris, s->nnodes, s->nrefs,
          built->ntris, built->nnodes, built->nrefs);
    CHECK(inside(s->tris, 36 * s->ntris, t->map, t->map_len) &&
              inside(s->nodes, 8 * s->nnodes, t->map, t->map_len) &&
              inside(s->refs, 4 * s->nrefs, t->map, t->map_len),
          "the loaded scene's arrays are not in the loaded memory");
    int differ = 0;
    for (int i = 0; i < 2000; i++) {
        kdr_ray r = {{rnd(-1, 2), rnd(-1, 2), -1}, {rnd(-.5f, .5f), rnd(-.5f, .5f), 1}, 0, 1e30f};
        kdr_hit a, b;
        int ha = kdr_intersect1(built, &r, &a, NULL), hb = kdr_intersect1(s, &r, &b, NULL);
        differ += ha != hb || memcmp(&a, &b, sizeof a) != 0;
    }
    CHECK(differ == 0, "%d of 2000 rays differ between built and loaded tree", differ);
}

int main(void) {
    char mode[256];
    if (!thp_possible(mode, sizeof mode)) {
        FAIL(THP_OFF_MESSAGE, mode);
        return check_exit("test_tree_cache_mem");
    }
    char dir[] = "/tmp/kdray-cache-mem-XXXXXX";
    if (!mkdtemp(dir)) {
        FAIL("mkdtemp failed\n");
        return check_exit("test_tree_cache_mem");
    }
    /* enough triangles that the file spans several 2 MiB pages */
    const size_t n = 100000;
    float *tris = malloc(9 * n * sizeof *tris);
    if (!tris) abort();
    for (size_t i = 0; i < n; i++) {
        const float c[3] = {rnd(0, 1), rnd(0, 1), rnd(0, 1)};
        for (int k = 0; k < 9; k++) tris[9 * i + k] = c[k % 3] + rnd(-0.004f, 0.004f);
    }
    kdr_build_opts opts;
    kdr_build_opts_default(&opts);
    kdr_scene *built = NULL;
    int rc = kdr_scene_build(tris, n, &opts, NULL, NULL, &built);
    CHECK(rc == KDR_OK, "build: %s", kdr_strerror(rc));
    const kdr_tree_key key = {{0x1234, 0x5678}};
    const kdr_mesh_range range = {0, 0, 0, 0, (uint32_t)n};
    char why[512] = "";
    size_t bytes = 0;
    if (rc == KDR_OK) {
        CHECK(kdr_tree_cache_store(dir, &key, &opts, built, &range, 1, &bytes, why,
                                   sizeof why) == 0,
              "store: %s", why);
        CHECK(bytes >= 2 * THP_HUGE_PAGE, "cache file of %zu bytes: too small to test", bytes);
        kdr_cached_tree t;
        int refused = 0;
        const int loaded =
            kdr_tree_cache_load(dir, &key, &opts, &t, &refused, why, sizeof why);
        CHECK(loaded == 1, "load: %s (refused %d)", why, refused);
        if (loaded == 1) {
            CHECK(t.map_len == bytes, "loaded %zu bytes of a %zu-byte file", t.map_len, bytes);
            check_loaded(&t, built);
            kdr_cached_tree_free(&t);
        }
        char path[4096];
        kdr_tree_cache_path(dir, &key, path, sizeof path);
        unlink(path);
    }
    rmdir(dir);
    kdr_scene_free(built);
    free(tris);
    return check_exit("test_tree_cache_mem");
}
