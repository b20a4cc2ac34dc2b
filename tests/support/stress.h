/*
 * stress.h — a deterministic, seeded generator of adversarial scenes and
 * rays for the accuracy tests: geometry that defeats careless kd-tree
 * builds and triangle tests (coincident and shared faces, triangles lying in
 * the likely split planes, closed meshes, slivers and degenerate triangles,
 * far offsets, mixed scales) and rays that hit exactly the hard places
 * (vertices, edge midpoints, split planes, exact and negative zeros,
 * denormal directions, closed interval ends, tmin == tmax, tmax = +inf).
 *
 * Same kind + same seed = the same floats on every machine (integer RNG,
 * no libm in coordinates except sin/cos for curved meshes, computed once
 * per vertex and shared by all triangles using it, so closed meshes stay
 * closed bit for bit).
 */
#ifndef KDRAY_TEST_STRESS_H
#define KDRAY_TEST_STRESS_H

#include <stddef.h>
#include <stdint.h>

#include "kdray.h"

typedef enum stress_scene_kind {
    STRESS_SHARED_BOXES = 0, /* unit boxes sharing (coincident) faces */
    STRESS_SPLIT_LATTICE,    /* quads in planes at k/4: a closed cell lattice */
    STRESS_CLOSED_MESHES,    /* spheres, boxes, tori, a sliver needle */
    STRESS_SLIVERS,          /* slivers + zero-area, collinear, repeated verts */
    STRESS_FAR_OFFSET,       /* small closed meshes 1e5..1e7 from the origin */
    STRESS_MULTI_SCALE,      /* 1e4-wide floor, 1e-3 sphere, 1e3 box */
    STRESS_SOUP,             /* random triangles of random sizes */
    STRESS_NSCENES
} stress_scene_kind;

/* A closed region: every ray starting at `inside` hits some triangle.
 * Triangles [first, first+count) are the ones worth aiming at (their
 * vertices and edge midpoints). */
typedef struct stress_closed {
    float inside[3];
    size_t first, count;
} stress_closed;

typedef struct stress_scene {
    stress_scene_kind kind;
    float *tris; /* 9 * ntris */
    size_t ntris;
    stress_closed *closed;
    size_t nclosed;
} stress_scene;

const char *stress_scene_name(stress_scene_kind kind);
/* 0 on success, -1 on allocation failure. */
int stress_scene_make(stress_scene_kind kind, uint64_t seed, stress_scene *out);
void stress_scene_free(stress_scene *s);
/* Convenience form: just the triangles (caller frees *tris with free()). */
int stress_scene_tris(stress_scene_kind kind, uint64_t seed, float **tris,
                      size_t *ntris);

typedef enum stress_ray_kind {
    STRESS_RAYS_RANDOM = 0,   /* random origins around the scene, random dirs */
    STRESS_RAYS_AT_VERTICES,  /* aimed exactly at vertices (hit near t = 1) */
    STRESS_RAYS_AT_EDGES,     /* aimed at edge midpoints */
    STRESS_RAYS_AXIS,         /* axis-aligned, along split planes, 0 and -0.0 */
    STRESS_RAYS_FROM_VERTICES,/* origins exactly on vertices / edge midpoints */
    STRESS_RAYS_DENORMAL,     /* aimed, with denormal / signed-zero components */
    STRESS_RAYS_INTERVALS,    /* aimed, tmin/tmax at 1 (the aim point), equal */
    STRESS_RAYS_MIXED,        /* all of the above */
    STRESS_NRAYS
} stress_ray_kind;

const char *stress_ray_name(stress_ray_kind kind);
/* Fills out[0..n) (no NaN, direction never all-zero, tmin >= 0). */
void stress_rays(const stress_scene *s, stress_ray_kind kind, uint64_t seed,
                 size_t n, kdr_ray *out);
/* Rays from inside the scene's closed regions toward their vertices, edge
 * midpoints and random directions (tmin 0, tmax +inf): each must hit.
 * Returns the number written (0 if the scene has no closed region). */
size_t stress_inside_rays(const stress_scene *s, uint64_t seed, size_t n,
                          kdr_ray *out);

/* Deterministic RNG shared by tests and benchmarks (splitmix64). */
typedef struct stress_rng {
    uint64_t s;
} stress_rng;
void stress_rng_seed(stress_rng *r, uint64_t seed);
uint64_t stress_rng_next(stress_rng *r);
float stress_rng_float(stress_rng *r); /* [0, 1) */
/* Uniform direction on the unit sphere. */
void stress_rng_dir(stress_rng *r, float d[3]);
/* A uniform point p of triangle tri (9 floats; two draws, folded into the
 * triangle) and its geometric normal e1 x e2, not normalised: the surface
 * points of the benchmarks' AO and shadow rays. */
void stress_tri_point(stress_rng *r, const float *tri, float p[3], float nrm[3]);

#endif /* KDRAY_TEST_STRESS_H */
