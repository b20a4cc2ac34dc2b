/*
 * kd_scene.c — the small things around a built scene: error strings, the
 * tuned default build options, accessors and freeing. The build itself is
 * in kd_build*.c, the walks in kd_traverse_*.c.
 */
#include <stdlib.h>
#include <string.h>

#include "kd_internal.h"


const char *kdr_strerror(int status) {
    switch (status) {
    case KDR_OK:
        return "success";
    case KDR_ENOMEM:
        return "out of memory";
    case KDR_EINVAL:
        return "invalid argument";
    case KDR_ERANGE:
        return "size over a hard limit";
    case KDR_EIMAGE:
        return "invalid tree image";
    default:
        return "unknown error";
    }
}

void kdr_build_opts_default(kdr_build_opts *opts) {
    if (!opts)
        return;
    opts->isect_cost = KD_ISECT_COST;
    opts->trav_cost = KD_TRAV_COST;
    opts->empty_bonus = KD_EMPTY_BONUS;
    opts->max_depth = 0;
    opts->leaf_size = KD_LEAF_SIZE;
    opts->exact_max = KD_EXACT_MAX;
    opts->threads = 0;
}

void kdr_scene_free(kdr_scene *scene) {
    if (!scene)
        return;
    if (!scene->borrowed) {
        kd_mem_free(scene->tris);
        kd_mem_free(scene->nodes);
        kd_mem_free(scene->refs);
    }
    free(scene);
}

size_t kdr_scene_triangle_count(const kdr_scene *scene) {
    return scene ? scene->ntris : 0;
}

void kdr_scene_bounds(const kdr_scene *scene, kdr_bounds *out) {
    if (!out)
        return;
    if (scene)
        *out = scene->bounds;
    else
        memset(out, 0, sizeof *out);
}

void kdr_scene_tree_stats(const kdr_scene *scene, kdr_tree_stats *out) {
    if (!out)
        return;
    if (scene)
        *out = scene->stats;
    else
        memset(out, 0, sizeof *out);
}

float kdr_scene_diagonal(const kdr_scene *scene) {
    return scene ? scene->diagonal : 0.0f;
}

const float *kdr_scene_triangle(const kdr_scene *scene, size_t prim) {
    if (!scene || prim >= scene->ntris)
        return NULL;
    return scene->tris + 9 * prim;
}
