/*
 * scene_info.c — kdray-scene-info: loads a glTF file the way kdrayd does,
 * builds its kd-tree with the default SAH parameters and prints what a user
 * (or a benchmark log) wants to know before serving it: triangle count,
 * bounds, the mesh ranges and the kd-tree statistics, with load and build
 * times. Exit status 0 on success, 1 on a load or build error (the error
 * line goes to stderr).
 */
#include <stdio.h>
#include <string.h>

#include "kdr_gltf.h"
#include "kdray.h"

/* More ranges than this are summarised rather than listed. */
#define MAX_LISTED_RANGES 16

static void usage(void) {
    fprintf(stderr, "usage: kdray-scene-info [--ranges] PATH.glb|PATH.gltf\n"
                    "  prints triangle count, bounds and kd-tree statistics\n");
}

static void print_ranges(const kdr_gltf_scene *g, int all) {
    size_t n = g->nranges;
    size_t shown = (all || n <= MAX_LISTED_RANGES) ? n : MAX_LISTED_RANGES;
    printf("meshes:        %zu (node, mesh, primitive) ranges\n", n);
    for (size_t i = 0; i < shown; i++) {
        const kdr_mesh_range *r = &g->ranges[i];
        printf("  node %u mesh %u primitive %u: triangles [%u, %u)\n", r->node, r->mesh,
               r->primitive, r->first_prim, r->first_prim + r->count);
    }
    if (shown < n) printf("  ... %zu more (--ranges lists all)\n", n - shown);
}

static void print_tree(const kdr_scene *scene) {
    kdr_bounds b;
    kdr_tree_stats st;
    kdr_scene_bounds(scene, &b);
    kdr_scene_tree_stats(scene, &st);
    printf("bounds:        min [%g, %g, %g] max [%g, %g, %g]\n", b.min[0], b.min[1],
           b.min[2], b.max[0], b.max[1], b.max[2]);
    printf("diagonal:      %g\n", kdr_scene_diagonal(scene));
    printf("kd-tree:       %llu nodes, %llu leaves (%llu empty), max depth %llu\n",
           (unsigned long long)st.nodes, (unsigned long long)st.leaves,
           (unsigned long long)st.empty_leaves, (unsigned long long)st.max_depth);
    printf("               %llu refs, %.2f refs/leaf, SAH cost %.2f, %.1f MiB\n",
           (unsigned long long)st.refs, st.refs_per_leaf, st.sah_cost,
           (double)st.bytes / (1024.0 * 1024.0));
    printf("build:         %.1f ms\n", st.build_ms);
}

int main(int argc, char **argv) {
    int all = 0;
    const char *path = NULL;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--ranges") == 0)
            all = 1;
        else if (argv[i][0] == '-') {
            usage();
            return 2;
        } else
            path = argv[i];
    }
    if (!path) {
        usage();
        return 2;
    }

    char err[512];
    kdr_gltf_scene g;
    if (kdr_gltf_load(path, &g, err, sizeof err) != 0) {
        fprintf(stderr, "kdray-scene-info: %s\n", err);
        return 1;
    }
    printf("file:          %s\n", path);
    printf("triangles:     %zu\n", g.ntris);
    printf("load:          %.1f ms\n", g.load_ms);
    print_ranges(&g, all);

    kdr_build_opts opts;
    kdr_build_opts_default(&opts);
    kdr_scene *scene = NULL;
    int rc = kdr_scene_build(g.tris, g.ntris, &opts, NULL, NULL, &scene);
    kdr_gltf_free(&g);
    if (rc != KDR_OK) {
        fprintf(stderr, "kdray-scene-info: %s: kd-tree build failed: %s\n", path,
                kdr_strerror(rc));
        return 1;
    }
    print_tree(scene);
    kdr_scene_free(scene);
    return 0;
}
