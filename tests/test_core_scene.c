/*
 * test_core_scene.c — the kd-tree against brute force on real glTF scenes
 * (the bundled default scene, assimp test models): real meshes bring fans,
 * slivers, shared vertices and degenerate triangles that random soups lack.
 * Usage: test_core_scene RAYS FILE.glb... ; exits nonzero on any mismatch.
 */
#include "kdr_gltf.h"
#include "test_core_util.h"

/* A ray from a random point of the (slightly grown) bounds, half of them
 * aimed at a vertex or an edge midpoint of a random triangle. */
static void scene_ray(const kdr_scene *s, size_t i, kdr_ray *r) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    for (int k = 0; k < 3; k++) {
        float ext = b.max[k] - b.min[k];
        r->org[k] = rng_f(b.min[k] - 0.1f * ext, b.max[k] + 0.1f * ext);
        r->dir[k] = rng_f(-1, 1);
    }
    if (i % 2) {
        const float *t = kdr_scene_triangle(s, rng_u32() % kdr_scene_triangle_count(s));
        int a = rng_u32() % 3, c = rng_u32() % 3;
        for (int k = 0; k < 3; k++)
            r->dir[k] = 0.5f * (t[3 * a + k] + t[3 * c + k]) - r->org[k];
    }
    r->tmin = 0.0f;
    r->tmax = INFINITY;
}

int main(int argc, char **argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: %s RAYS FILE.glb...\n", argv[0]);
        return 2;
    }
    const size_t nrays = (size_t)strtoul(argv[1], NULL, 10);
    for (int f = 2; f < argc; f++) {
        kdr_gltf_scene g;
        char err[256];
        if (kdr_gltf_load(argv[f], &g, err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            return 1;
        }
        kdr_scene *s = NULL;
        EXPECT(kdr_scene_build(g.tris, g.ntris, NULL, NULL, NULL, &s) == KDR_OK);
        if (!s)
            return 1;
        size_t bad = 0;
        for (size_t i = 0; i < nrays && g.ntris > 0; i++) {
            kdr_ray r;
            scene_ray(s, i, &r);
            bad += !compare_ray(s, &r);
        }
        printf("%s: %zu triangles, %zu rays, %zu mismatches\n", argv[f], g.ntris,
               nrays, bad);
        EXPECT(bad == 0);
        kdr_scene_free(s);
        kdr_gltf_free(&g);
    }
    return failures != 0;
}
