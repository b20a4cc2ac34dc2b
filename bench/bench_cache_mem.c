/*
 * bench_cache_mem.c — what kdrayd's way of mapping a cached tree does for
 * the walks (issue 11). The same tree is stored twice (two files, same
 * bytes), both files are dropped from the page cache (POSIX_FADV_DONTNEED:
 * a first start after a reboot), and each is opened one way:
 *   plain:  mmap read-only and shared wherever the kernel puts it, no
 *           advice (tree_cache.c before issue 11);
 *   advised: kdr_tree_cache_load (map_huge: 2 MiB boundary, MADV_HUGEPAGE
 *           before the validation reads the file).
 * Both scenes trace the same random rays (closest and any-hit) in
 * alternating rounds; the answers must be identical. Prints each open's
 * time (validation included), how much of each mapping is in 2 MiB pages
 * (smaps FilePmdMapped) and the per-round CPU-time ratio. A measurement,
 * not a test. --warm leaves the files cached as written (the daemon's own
 * store, then a restart).
 *
 *   kdray-bench-cache-mem SCENE.glb [--rays N] [--rounds R] [--warm]
 */
#define _GNU_SOURCE
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "kdr_gltf.h"
#include "kdray.h"
#include "test_util.h"
#include "thp_smaps.h"
#include "tree_cache.h"

static double cpu_ms(void) {
    struct timespec t;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static double wall_ms(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static uint64_t rng = 0x9e3779b97f4a7c15ull;
static float rnd(float lo, float hi) {
    return lo + (hi - lo) * (float)(xorshift64(&rng) >> 40) * 0x1p-24f;
}

/* CPU ms to trace every ray closest-hit and any-hit; sums answers into *sig. */
static double trace(const kdr_scene *s, const kdr_ray *rays, size_t n, uint64_t *sig) {
    uint64_t h = 0;
    const double t0 = cpu_ms();
    for (size_t i = 0; i < n; i++) {
        kdr_hit hit;
        kdr_intersect1(s, &rays[i], &hit, NULL);
        h = h * 31 + (uint64_t)(uint32_t)hit.prim;
        h = h * 31 + (uint64_t)kdr_occluded1(s, &rays[i], NULL);
    }
    *sig = h;
    return cpu_ms() - t0;
}

static int cmp_double(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Stores the tree under key; the file's path into path. */
static int store(const char *dir, const kdr_tree_key *key, const kdr_build_opts *opts,
                 const kdr_scene *built, const kdr_gltf_scene *g, int warm, char *path,
                 size_t *bytes) {
    char why[512];
    if (kdr_tree_cache_store(dir, key, opts, built, g->ranges, g->nranges, bytes, why,
                             sizeof why) != 0) {
        fprintf(stderr, "store: %s\n", why);
        return -1;
    }
    kdr_tree_cache_path(dir, key, path, 4096);
    if (!warm) {
        int fd = open(path, O_RDONLY | O_CLOEXEC);
        if (fd < 0 || posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED) != 0) {
            perror(path);
            return -1;
        }
        close(fd);
    }
    return 0;
}

int main(int argc, char **argv) {
    if (argc < 2 || strcmp(argv[1], "--help") == 0) {
        fprintf(stderr, "usage: %s SCENE.glb [--rays N] [--rounds R] [--warm]\n", argv[0]);
        return argc < 2 ? 2 : 0;
    }
    size_t nrays = 262144;
    int rounds = 5, warm = 0;
    for (int i = 2; i < argc; i++) {
        if (strcmp(argv[i], "--warm") == 0) warm = 1;
        else if (i + 1 < argc && strcmp(argv[i], "--rays") == 0)
            nrays = strtoul(argv[++i], NULL, 10);
        else if (i + 1 < argc && strcmp(argv[i], "--rounds") == 0) rounds = atoi(argv[++i]);
        else {
            fprintf(stderr, "unknown flag %s\n", argv[i]);
            return 2;
        }
    }
    if (rounds < 1 || rounds > 99 || nrays == 0) {
        fprintf(stderr, "--rounds 1..99, --rays > 0\n");
        return 2;
    }
    char err[512], why[512];
    kdr_gltf_scene g;
    if (kdr_gltf_load(argv[1], &g, err, sizeof err) != 0) {
        fprintf(stderr, "%s: %s\n", argv[1], err);
        return 1;
    }
    kdr_build_opts opts;
    kdr_build_opts_default(&opts);
    opts.threads = 2;
    kdr_scene *built = NULL;
    int rc = kdr_scene_build(g.tris, g.ntris, &opts, NULL, NULL, &built);
    if (rc != KDR_OK) {
        fprintf(stderr, "build: %s\n", kdr_strerror(rc));
        return 1;
    }
    char dir[] = "/tmp/kdray-bench-cache-mem-XXXXXX";
    if (!mkdtemp(dir)) {
        perror("mkdtemp");
        return 1;
    }
    const kdr_tree_key key_plain = {{0x6b64, 0x706c61696e}}, key_adv = {{0x6b64, 0x616476}};
    char path_plain[4096], path_adv[4096];
    size_t bytes = 0;
    if (store(dir, &key_plain, &opts, built, &g, warm, path_plain, &bytes) != 0 ||
        store(dir, &key_adv, &opts, built, &g, warm, path_adv, &bytes) != 0)
        return 1;

    /* plain: the file's layout as tree_cache.c writes it (64-byte head, the
     * mesh ranges, the image at the next 64-byte boundary to the end) */
    double t0 = wall_ms();
    int fd = open(path_plain, O_RDONLY | O_CLOEXEC);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) != 0) {
        perror(path_plain);
        return 1;
    }
    const size_t len = (size_t)st.st_size;
    unsigned char *map = mmap(NULL, len, PROT_READ, MAP_SHARED, fd, 0);
    close(fd);
    if (map == MAP_FAILED) {
        perror("mmap");
        return 1;
    }
    const size_t image_off = (64 + g.nranges * sizeof(kdr_mesh_range) + 63) & ~(size_t)63;
    kdr_scene *plain = NULL;
    const char *img_why = NULL;
    rc = kdr_scene_image_open(map + image_off, len - image_off, &opts, &plain, &img_why);
    if (rc != KDR_OK) {
        fprintf(stderr, "image open: %s\n", img_why ? img_why : kdr_strerror(rc));
        return 1;
    }
    const double plain_ms = wall_ms() - t0;

    t0 = wall_ms();
    kdr_cached_tree t;
    int refused = 0;
    if (kdr_tree_cache_load(dir, &key_adv, &opts, &t, &refused, why, sizeof why) != 1) {
        fprintf(stderr, "load: %s\n", why);
        return 1;
    }
    const double adv_ms = wall_ms() - t0;

    kdr_bounds b;
    kdr_scene_bounds(built, &b);
    kdr_ray *rays = malloc(nrays * sizeof *rays);
    if (!rays) return 1;
    for (size_t i = 0; i < nrays; i++) {
        kdr_ray *r = &rays[i];
        for (int k = 0; k < 3; k++) {
            r->org[k] = rnd(b.min[k], b.max[k]);
            r->dir[k] = rnd(-1, 1);
        }
        r->tmin = 0;
        r->tmax = 1e30f;
    }
    uint64_t sig_plain, sig_adv;
    trace(plain, rays, nrays, &sig_plain); /* untimed: warms both alike */
    trace(t.scene, rays, nrays, &sig_adv);
    printf("%s: %zu triangles, cache file %.1f MiB, page cache %s\n", argv[1], g.ntris,
           bytes / 1048576.0, warm ? "as written (--warm)" : "dropped before opening");
    printf("  plain  : %6.1f ms to open, at %p, FilePmdMapped %ld kB\n", plain_ms,
           (void *)map, thp_smaps_kb(map, "FilePmdMapped"));
    printf("  advised: %6.1f ms to open, at %p, FilePmdMapped %ld kB\n", adv_ms, t.map,
           thp_smaps_kb(t.map, "FilePmdMapped"));
    double ratio[99];
    int differ = sig_plain != sig_adv;
    for (int r = 0; r < rounds; r++) {
        uint64_t a, c;
        const double ms_plain = trace(plain, rays, nrays, &a);
        const double ms_adv = trace(t.scene, rays, nrays, &c);
        differ |= a != c || a != sig_plain;
        ratio[r] = ms_plain / ms_adv;
        printf("  round %d: plain %.1f ms, advised %.1f ms CPU (%zu random rays, closest + "
               "any-hit): advised %.3fx\n", r + 1, ms_plain, ms_adv, nrays, ratio[r]);
    }
    qsort(ratio, (size_t)rounds, sizeof *ratio, cmp_double);
    printf("  speed advised / plain: median %.3f (%.3f-%.3f), answers %s\n",
           ratio[rounds / 2], ratio[0], ratio[rounds - 1], differ ? "DIFFER" : "identical");
    kdr_cached_tree_free(&t);
    kdr_scene_free(plain);
    munmap(map, len);
    unlink(path_plain);
    unlink(path_adv);
    rmdir(dir);
    kdr_scene_free(built);
    free(rays);
    kdr_gltf_free(&g);
    return differ;
}
