/*
 * tree_cache.h — kdrayd's --cache-dir: built kd-trees kept in files so that
 * a later start (or another replica sharing the directory) maps them
 * instead of building. The core owns the tree bytes and their validation
 * (kdr_scene_image_*, core/kd_image.c); this file owns the files: the key,
 * the file format around the image (the scene's mesh ranges), mmap (at a
 * 2 MiB boundary, advised for huge pages), and atomic publication (temp
 * file, fsync, rename, fsync of the directory), so a reader never sees a
 * half-written file.
 *
 * Key: two 64-bit hashes (different seeds) of the scene file's bytes, mixed
 * with the build options and the cache format version; the file is
 * DIR/<32 hex digits>.kdtree. A changed scene file or other options give
 * another key, hence another file. A file under the right name that is
 * truncated, corrupt or of another version is refused (and replaced by the
 * caller's rebuild), never trusted.
 */
#ifndef KDR_SRV_TREE_CACHE_H
#define KDR_SRV_TREE_CACHE_H

#include <stddef.h>
#include <stdint.h>

#include "kdr_gltf.h"
#include "kdray.h"

typedef struct kdr_tree_key {
    uint64_t h[2];
} kdr_tree_key;

/* A tree mapped from the cache: scene reads from map until unmapped. */
typedef struct kdr_cached_tree {
    kdr_scene *scene;
    kdr_mesh_range *ranges; /* malloc'd copy */
    size_t nranges;
    void *map;
    size_t map_len;
} kdr_cached_tree;

/* Checks that dir is a writable directory, creating it (0755) if missing;
 * -1 with the reason in why. */
int kdr_tree_cache_prepare(const char *dir, char *why, size_t why_len);

/* The key of scene_path's current bytes built with opts; -1 (reason in why)
 * if the file cannot be read. */
int kdr_tree_cache_key(const char *scene_path, const kdr_build_opts *opts,
                       kdr_tree_key *key, char *why, size_t why_len);

/* DIR/<key>.kdtree into buf. */
void kdr_tree_cache_path(const char *dir, const kdr_tree_key *key, char *buf, size_t len);

/* 1: mapped and validated into *out. 0: not usable; why says whether the
 * file is absent ("not cached") or was refused and why (*refused set). */
int kdr_tree_cache_load(const char *dir, const kdr_tree_key *key,
                        const kdr_build_opts *opts, kdr_cached_tree *out, int *refused,
                        char *why, size_t why_len);

/* Writes scene and its ranges under key (atomically replacing any older
 * file); 0, or -1 with the reason in why. *bytes gets the file size. */
int kdr_tree_cache_store(const char *dir, const kdr_tree_key *key,
                         const kdr_build_opts *opts, const kdr_scene *scene,
                         const kdr_mesh_range *ranges, size_t nranges, size_t *bytes,
                         char *why, size_t why_len);

/* Frees the scene, the ranges copy and the mapping. */
void kdr_cached_tree_free(kdr_cached_tree *t);
/* Unmaps a mapping whose scene was freed separately. */
void kdr_tree_cache_unmap(void *map, size_t len);

#endif
