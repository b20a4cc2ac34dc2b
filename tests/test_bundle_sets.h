/*
 * test_bundle_sets.h — the scenes and ray sets of test_bundle (its
 * test_bundle_sets.c): generated scenes (a random soup, an integer lattice
 * of axis-aligned quads, a closed tessellated sphere) and NRAYS-ray sets
 * built to break bundles (shared and distinct origins, zero components,
 * origins on split planes, the walk's slack planes, aimed rays, odd
 * intervals, ends on split planes, shadow rays toward a small light). All draw from one deterministic generator, so the order of
 * the calls fixes the rays.
 */
#ifndef TEST_BUNDLE_SETS_H
#define TEST_BUNDLE_SETS_H

#include <stddef.h>
#include <stdint.h>

#include "kdray.h"

#define NRAYS 1536

typedef struct scene_src {
    const char *name;
    float *tris;
    size_t ntris;
} scene_src;

typedef struct rayset {
    const char *name;
    size_t n;
    float *org, *dir, *tmin, *tmax;
    int shared_org;
} rayset;

scene_src make_soup(size_t n);
scene_src make_lattice(int cells, float density);
scene_src make_sphere(int rings, int segs);
rayset rays_alloc(const char *name, int shared_org);
void rays_free(rayset *r);
rayset rays_camera(const kdr_bounds *b);
rayset rays_omni(const kdr_bounds *b);
rayset rays_distinct(const kdr_bounds *b);
rayset rays_nearby(const kdr_bounds *b);
rayset rays_zeros(const kdr_bounds *b, int integer_org);
rayset rays_on_splits(const kdr_scene *s, const kdr_bounds *b, int shared);
rayset rays_slack_planes(const kdr_scene *s, const kdr_bounds *b);
rayset rays_aimed(const scene_src *src, const kdr_bounds *b, int shared);
rayset rays_intervals(const kdr_bounds *b, int shared);
rayset rays_ends_on_splits(const kdr_scene *s, const kdr_bounds *b);
rayset rays_light(const kdr_bounds *b);
/* Every set above for one scene, in a fixed order (the exactness tests
 * of test_bundle and test_all_stream run all of them): out[0..RAYS_NSETS). */
#define RAYS_NSETS 14
void rays_every_set(const scene_src *src, const kdr_scene *s, const kdr_bounds *b,
                    int integer_org, rayset out[RAYS_NSETS]);
/* Builds src's tree and hands every set of rays_every_set() to check, one
 * at a time (freed after). Returns 1 if the build failed (after saying
 * so on stderr), else 0. */
typedef void (*rays_check_fn)(const char *scene, const kdr_scene *s, rayset *rs);
int rays_check_every_set(const scene_src *src, int integer_org, rays_check_fn check);

#endif
