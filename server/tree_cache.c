/*
 * tree_cache.c — the files of kdrayd's tree cache (see tree_cache.h).
 *
 * File: a 64-byte head (magic, version, key, mesh-range count, image offset
 * and length, checksum of the ranges), the mesh ranges, then the core's
 * tree image at a 64-byte aligned offset. The image carries its own
 * checksum and is validated by kdr_scene_image_open; the ranges are checked
 * here (checksum, and that they tile the scene's triangles).
 *
 * Files are mapped read-only and shared (MAP_SHARED): replicas on one
 * machine that share the directory share the tree's pages. The mapping is
 * placed at a 2 MiB boundary and advised for transparent huge pages
 * (MADV_HUGEPAGE) before the validation reads it (map_huge): then the
 * page cache reads the file in 2 MiB folios and the walks' TLB misses on
 * large trees drop, as for a built tree's arrays (core/kd_mem.c, issue 11;
 * docs/TRAVERSAL.md, docs/OPERATIONS.md). Pages already cached in small
 * pieces (the file read by another program first) stay small. A file is
 * never changed in place once published (writers rename a new file over
 * it), so a mapping stays valid; only someone truncating a cache file by
 * hand under a running daemon could fault it.
 */
#define _GNU_SOURCE
#include "tree_cache.h"

#include <errno.h>
#include <fcntl.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#define CACHE_VERSION 2u
#define HEAD 64u

static const char cache_magic[8] = {'K', 'D', 'R', 'C', 'A', 'C', 'H', 'E'};

typedef struct cache_head {
    char magic[8];
    uint32_t version, nranges;
    uint64_t key[2];
    uint64_t image_off, image_len;
    uint64_t ranges_hash;
    uint8_t pad[8];
} cache_head;

_Static_assert(sizeof(cache_head) == HEAD, "cache head is 64 bytes");
_Static_assert(sizeof(kdr_mesh_range) == 20, "mesh ranges are five uint32");

static uint64_t align64(uint64_t x) { return (x + 63) & ~(uint64_t)63; }

int kdr_tree_cache_prepare(const char *dir, char *why, size_t why_len) {
    struct stat st;
    if (stat(dir, &st) != 0) {
        if (errno != ENOENT || mkdir(dir, 0755) != 0) {
            snprintf(why, why_len, "%s: %s", dir, strerror(errno));
            return -1;
        }
    } else if (!S_ISDIR(st.st_mode)) {
        snprintf(why, why_len, "%s: not a directory", dir);
        return -1;
    }
    if (access(dir, W_OK | X_OK) != 0) {
        snprintf(why, why_len, "%s: not writable: %s", dir, strerror(errno));
        return -1;
    }
    return 0;
}

/* ---- key ----------------------------------------------------------------------- */

int kdr_tree_cache_key(const char *path, const kdr_build_opts *opts, kdr_tree_key *key,
                       char *why, size_t why_len) {
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) != 0) {
        snprintf(why, why_len, "%s: %s", path, strerror(errno));
        if (fd >= 0) close(fd);
        return -1;
    }
    size_t len = (size_t)st.st_size;
    const void *bytes = "";
    void *map = NULL;
    if (len > 0) {
        map = mmap(NULL, len, PROT_READ, MAP_PRIVATE, fd, 0);
        if (map == MAP_FAILED) {
            snprintf(why, why_len, "%s: mmap: %s", path, strerror(errno));
            close(fd);
            return -1;
        }
        bytes = map;
    }
    close(fd);
    /* the options and the version go in as a suffix of the hashed stream */
    /* every option the tree depends on; not opts->threads (the tree is the
     * same on any thread count) */
    uint32_t o[6] = {0, 0, 0, (uint32_t)opts->max_depth, (uint32_t)opts->leaf_size,
                     (uint32_t)opts->exact_max};
    memcpy(&o[0], &opts->isect_cost, 4);
    memcpy(&o[1], &opts->trav_cost, 4);
    memcpy(&o[2], &opts->empty_bonus, 4);
    uint64_t suffix[4] = {CACHE_VERSION, 0, 0, 0};
    memcpy(&suffix[1], o, sizeof o);
    for (int k = 0; k < 2; k++) {
        uint64_t h = kdr_hash64(bytes, len, 0x6b647261795f6b00ull + (uint64_t)k);
        key->h[k] = kdr_hash64(suffix, sizeof suffix, h);
    }
    if (map) munmap(map, len);
    return 0;
}

void kdr_tree_cache_path(const char *dir, const kdr_tree_key *key, char *buf,
                         size_t len) {
    snprintf(buf, len, "%s/%016llx%016llx.kdtree", dir, (unsigned long long)key->h[0],
             (unsigned long long)key->h[1]);
}

/* ---- load ------------------------------------------------------------------------ */

static int ranges_tile(const kdr_mesh_range *r, size_t n, size_t ntris) {
    uint64_t next = 0;
    for (size_t i = 0; i < n; i++) {
        if (r[i].first_prim != next) return 0;
        next += r[i].count;
    }
    return next == ntris;
}

#define HUGE_PAGE ((size_t)2 << 20)

/* fd mapped read-only and shared at a 2 MiB boundary (file offset 0 there,
 * so the file's 2 MiB pieces line up with huge pages), advised for huge
 * pages before anything touches it; MAP_FAILED on error. The mapping is
 * exactly len bytes (page-rounded): kdr_tree_cache_unmap(map, len) frees
 * it. */
static void *map_huge(int fd, size_t len) {
    /* reserve room to align in, then map the file over the aligned part */
    unsigned char *raw = mmap(NULL, len + HUGE_PAGE, PROT_NONE,
                              MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (raw == MAP_FAILED) return MAP_FAILED;
    const size_t page = (size_t)sysconf(_SC_PAGESIZE);
    const size_t body = (len + page - 1) & ~(page - 1);
    unsigned char *p =
        (unsigned char *)(((uintptr_t)raw + HUGE_PAGE - 1) & ~(uintptr_t)(HUGE_PAGE - 1));
    if (mmap(p, len, PROT_READ, MAP_SHARED | MAP_FIXED, fd, 0) == MAP_FAILED) {
        const int err = errno;
        munmap(raw, len + HUGE_PAGE);
        errno = err;
        return MAP_FAILED;
    }
    /* the reservation was [raw, raw + body + HUGE_PAGE); keep [p, p + body) */
    if (p > raw) munmap(raw, (size_t)(p - raw));
    munmap(p + body, (size_t)(raw + HUGE_PAGE - p));
    (void)madvise(p, body, MADV_HUGEPAGE); /* a hint: without THP, small pages */
    return p;
}

void kdr_tree_cache_unmap(void *map, size_t len) {
    if (map) munmap(map, len);
}

void kdr_cached_tree_free(kdr_cached_tree *t) {
    if (!t) return;
    kdr_scene_free(t->scene);
    free(t->ranges);
    kdr_tree_cache_unmap(t->map, t->map_len);
    memset(t, 0, sizeof *t);
}

/* Checks the mapped file around the image; NULL if it is sound. */
static const char *check_file(const unsigned char *p, size_t len, const kdr_tree_key *key,
                              cache_head *h) {
    if (len < HEAD) return "truncated header";
    memcpy(h, p, sizeof *h);
    if (memcmp(h->magic, cache_magic, sizeof h->magic) != 0)
        return "not a kdray cache file";
    if (h->version != CACHE_VERSION) return "other cache format version";
    if (h->key[0] != key->h[0] || h->key[1] != key->h[1])
        return "key differs from its name (stale)";
    const uint64_t ranges_end = HEAD + (uint64_t)h->nranges * sizeof(kdr_mesh_range);
    if (h->image_off != align64(ranges_end) || h->image_len > len ||
        h->image_off != len - h->image_len)
        return "sizes do not match the file (truncated?)";
    if (kdr_hash64(p + HEAD, (size_t)(ranges_end - HEAD), h->key[0]) != h->ranges_hash)
        return "mesh ranges checksum mismatch";
    return NULL;
}

int kdr_tree_cache_load(const char *dir, const kdr_tree_key *key,
                        const kdr_build_opts *opts, kdr_cached_tree *out, int *refused,
                        char *why, size_t why_len) {
    char path[4096];
    memset(out, 0, sizeof *out);
    *refused = 0;
    kdr_tree_cache_path(dir, key, path, sizeof path);
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        if (errno == ENOENT)
            snprintf(why, why_len, "not cached (%s)", path);
        else
            *refused = 1, snprintf(why, why_len, "%s: %s", path, strerror(errno));
        return 0;
    }
    struct stat st;
    if (fstat(fd, &st) != 0 || st.st_size < (off_t)HEAD) {
        *refused = 1;
        snprintf(why, why_len, "%s: truncated header", path);
        close(fd);
        return 0;
    }
    size_t len = (size_t)st.st_size;
    void *map = map_huge(fd, len);
    close(fd);
    if (map == MAP_FAILED) {
        *refused = 1;
        snprintf(why, why_len, "%s: mmap: %s", path, strerror(errno));
        return 0;
    }
    cache_head h;
    const char *bad = check_file(map, len, key, &h);
    kdr_scene *scene = NULL;
    if (!bad) {
        const char *img_why = NULL;
        int rc = kdr_scene_image_open((const unsigned char *)map + h.image_off,
                                      (size_t)h.image_len, opts, &scene, &img_why);
        if (rc != KDR_OK) bad = img_why ? img_why : kdr_strerror(rc);
    }
    kdr_mesh_range *ranges = NULL;
    if (!bad) {
        ranges = malloc(h.nranges ? h.nranges * sizeof *ranges : 1);
        if (!ranges)
            bad = "out of memory";
        else {
            memcpy(ranges, (const unsigned char *)map + HEAD, h.nranges * sizeof *ranges);
            if (!ranges_tile(ranges, h.nranges, kdr_scene_triangle_count(scene)))
                bad = "mesh ranges do not tile the triangles";
        }
    }
    if (bad) {
        *refused = 1;
        snprintf(why, why_len, "%s: %s", path, bad);
        kdr_scene_free(scene);
        free(ranges);
        munmap(map, len);
        return 0;
    }
    *out = (kdr_cached_tree){scene, ranges, h.nranges, map, len};
    return 1;
}

/* ---- store --------------------------------------------------------------------------
 */

static int write_all(int fd, const void *buf, size_t len) {
    const unsigned char *p = buf;
    while (len > 0) {
        ssize_t w = write(fd, p, len);
        if (w < 0) {
            if (errno == EINTR) continue;
            return -1;
        }
        p += w;
        len -= (size_t)w;
    }
    return 0;
}

int kdr_tree_cache_store(const char *dir, const kdr_tree_key *key,
                         const kdr_build_opts *opts, const kdr_scene *scene,
                         const kdr_mesh_range *ranges, size_t nranges, size_t *bytes,
                         char *why, size_t why_len) {
    static atomic_uint counter;
    char path[4096], tmp[4200];
    kdr_tree_cache_path(dir, key, path, sizeof path);
    snprintf(tmp, sizeof tmp, "%s/.tmp.%ld.%u.kdtree", dir, (long)getpid(),
             atomic_fetch_add(&counter, 1));
    if (nranges > UINT32_MAX) {
        snprintf(why, why_len, "too many mesh ranges");
        return -1;
    }
    const size_t ranges_bytes = nranges * sizeof *ranges;
    const size_t image_off = (size_t)align64(HEAD + ranges_bytes);
    const size_t image_len = kdr_scene_image_size(scene);
    unsigned char *buf = NULL;
    if (posix_memalign((void **)&buf, 64, image_off + image_len) != 0) {
        snprintf(why, why_len, "out of memory");
        return -1;
    }
    memset(buf, 0, image_off);
    if (ranges_bytes) memcpy(buf + HEAD, ranges, ranges_bytes);
    cache_head h = {.version = CACHE_VERSION,
                    .nranges = (uint32_t)nranges,
                    .key = {key->h[0], key->h[1]},
                    .image_off = image_off,
                    .image_len = image_len};
    memcpy(h.magic, cache_magic, sizeof h.magic);
    h.ranges_hash = kdr_hash64(buf + HEAD, ranges_bytes, key->h[0]);
    memcpy(buf, &h, sizeof h);
    int rc = kdr_scene_image_write(scene, opts, buf + image_off, image_len);
    if (rc != KDR_OK) {
        snprintf(why, why_len, "image: %s", kdr_strerror(rc));
        free(buf);
        return -1;
    }
    int fd = open(tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    const char *step = "create";
    int ok = fd >= 0;
    if (ok) ok = write_all(fd, buf, image_off + image_len) == 0 || (step = "write", 0);
    if (ok) ok = fsync(fd) == 0 || (step = "fsync", 0);
    int err = errno;
    if (fd >= 0 && close(fd) != 0 && ok) ok = 0, step = "close", err = errno;
    if (ok) ok = rename(tmp, path) == 0 || (step = "rename", err = errno, 0);
    free(buf);
    if (!ok) {
        snprintf(why, why_len, "%s %s: %s", step, tmp, strerror(err));
        unlink(tmp);
        return -1;
    }
    /* the rename itself is durable once the directory is synced */
    int dfd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd >= 0) {
        fsync(dfd);
        close(dfd);
    }
    *bytes = image_off + image_len;
    return 0;
}
