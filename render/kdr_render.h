/*
 * kdr_render.h — pictures from the kdray core: a camera, a light and a mode
 * in, an RGB image and its PNG out. Pure computation over a built scene (no
 * HTTP, no globals; the PNG goes through libpng into memory). kdrayd runs a
 * render through its executor (exec/), one band of the image per chunk.
 *
 * The picture is defined by the public queries, so anyone can recompute it
 * from the daemon's own answers (tests/test_render.py does):
 *  - primary: the frustum query of the camera (closest hits, tile 8);
 *  - the hit point of pixel p is eye + t*d (float, d = the pixel's
 *    kdr_camera_ray direction), its normal the triangle's geometric normal
 *    (e1 x e2 normalised, e1 = p1 - p0, e2 = p2 - p0) turned toward the eye;
 *  - shadow: the cone-shadow query with those points and normals, one light,
 *    `samples`, seed KDR_RENDER_SEED, epsilon KDR_RENDER_EPSILON, the point
 *    index of pixel p being p itself (y * width + x), so the answer does not
 *    depend on how the image is cut into bands;
 *  - shade: k = AMBIENT + (DIFFUSE * max(0, n.l/|l|)) * visibility, each
 *    channel (k * albedo) * 255 + 0.5 truncated; misses get a vertical
 *    background ramp. The exact float steps are in kdr_render.c.
 * Modes depth, normal and shadow show one ingredient each; ao replaces the
 * light by ambient occlusion: `samples` cosine-weighted hemisphere rays per
 * hit point, traced as bundles on the any-hit path.
 *
 * Threads: kdr_render_band may run for different bands of one image on any
 * number of threads at once (bands write disjoint pixels).
 */
#ifndef KDR_RENDER_H
#define KDR_RENDER_H

#include <stddef.h>
#include <stdint.h>

#include "kdray.h"

#ifdef __cplusplus
extern "C" {
#endif

#define KDR_RENDER_TILE 8u        /* frustum tile of the primary rays */
#define KDR_RENDER_SHADOW_TILE 4u /* shadow points go square by square */
#define KDR_RENDER_SEED 1u        /* cone-shadow and ao sample seed */
#define KDR_RENDER_EPSILON                                                               \
    1e-4f                           /* shadow offset, times the scene diagonal           \
                                       (KDR_OFFSET_DIAGONAL, a numeric                   \
                                       "epsilon" in the API) */
#define KDR_RENDER_MAX_SAMPLES 4096 /* as the cone-shadow query */
#define KDR_RENDER_MAX_SIDE 16384   /* width and height, as the frustum query */

typedef enum kdr_render_mode {
    KDR_RENDER_SHADE = 0, /* Lambert with the soft shadow */
    KDR_RENDER_DEPTH,     /* distance along the ray, near bright */
    KDR_RENDER_NORMAL,    /* the eye-facing normal as a colour */
    KDR_RENDER_SHADOW,    /* the light's visibility alone */
    KDR_RENDER_AO,        /* ambient occlusion (bundles, any hit) */
} kdr_render_mode;

/* Which parameters the caller set; the rest kdr_render_frame fills in. */
enum {
    KDR_RP_EYE = 1 << 0,
    KDR_RP_TARGET = 1 << 1,
    KDR_RP_UP = 1 << 2,
    KDR_RP_FOV = 1 << 3,
    KDR_RP_WIDTH = 1 << 4,
    KDR_RP_HEIGHT = 1 << 5,
    KDR_RP_LIGHT = 1 << 6,
    KDR_RP_SAMPLES = 1 << 7,
    KDR_RP_MODE = 1 << 8,
};

typedef struct kdr_render_params {
    kdr_camera cam;
    kdr_sphere_light light;
    uint32_t samples;
    kdr_render_mode mode;
    unsigned set;        /* KDR_RP_* given by the caller */
    float near_d, far_d; /* depth mode's range (set by kdr_render_frame) */
    float ao_radius;     /* ao rays' length (set by kdr_render_frame) */
} kdr_render_params;

/* Everything unset, defaults for what has no scene-dependent value. */
void kdr_render_params_init(kdr_render_params *p);
/* Parses one query parameter (eye, target, up: "x,y,z"; fov: degrees;
 * width, height; light: "x,y,z,radius"; samples; mode). 0 on success; -1
 * with err naming the parameter and what it expects; 1 for an unknown name
 * (err says so too). */
int kdr_render_param(kdr_render_params *p, const char *name, const char *value, char *err,
                     size_t errlen);
/* Fills what the caller left unset from the scene's bounds (a view that
 * frames the whole scene, a light above it) and checks the result. 0, or -1
 * with err naming the parameter at fault. */
int kdr_render_frame(const kdr_scene *scene, kdr_render_params *p, char *err,
                     size_t errlen);

/* Statistics and stage times of one band, summed over bands by the caller. */
typedef struct kdr_render_stats {
    uint64_t pixels, hits;
    uint64_t primary_nodes;  /* frustum traversal nodes over all primary rays */
    kdr_shadow_stats shadow; /* cone-shadow statistics */
    uint64_t ao_rays;        /* ao hemisphere rays traced */
    uint64_t ao_nodes;
    double primary_s, shadow_s, shade_s; /* each stage's time by now() */
} kdr_render_stats;

/* The image and the per-pixel arrays a render keeps (row-major). */
typedef struct kdr_render_image {
    uint32_t width, height;
    kdr_hits hits;           /* primary closest hits */
    float *points, *normals; /* 3 per pixel, valid where prim >= 0 */
    float *visibility;       /* 1 per pixel */
    uint8_t *rgb;            /* 3 per pixel */
    void *block;             /* the one allocation the arrays above share */
    size_t block_len;        /* its mapped length; 0: malloc'd */
} kdr_render_image;

/* Bytes kdr_render_alloc takes for p's image, and the most a PNG of it can
 * take (what the caller charges before allocating). */
size_t kdr_render_image_bytes(const kdr_render_params *p);
size_t kdr_render_png_max(const kdr_render_params *p);
/* Bytes of scratch one kdr_render_band call allocates at most (ao only). */
size_t kdr_render_scratch_bytes(const kdr_render_params *p);
int kdr_render_alloc(const kdr_render_params *p, kdr_render_image *img);
void kdr_render_free(kdr_render_image *img);

/* Bands: whole rows of primary tiles, about KDR_RENDER_BAND_PIXELS each. */
#define KDR_RENDER_BAND_PIXELS 8192u
size_t kdr_render_band_count(const kdr_render_params *p);
/* The pixel rows [*y0, *y1) of band b (b < kdr_render_band_count). */
void kdr_render_band_rows(const kdr_render_params *p, size_t band, uint32_t *y0,
                          uint32_t *y1);
/* Renders band b (primary, shadow or ao, shade). now() times the stages
 * (seconds on any clock, e.g. the thread's CPU time; NULL: not timed).
 * KDR_OK or a core error. */
int kdr_render_band(const kdr_scene *scene, const kdr_render_params *p,
                    kdr_render_image *img, size_t band, double (*now)(void),
                    kdr_render_stats *stats);

/* PNG of the image (8-bit RGB, zlib level 1, no filter: see kdr_png.c)
 * into *out (malloc'd, *len bytes). KDR_OK or KDR_ENOMEM. */
int kdr_render_png(const kdr_render_image *img, unsigned char **out, size_t *len,
                   size_t *cap);

/* The same PNG (the same bytes) as a stream, encoded while the bands are
 * still being rendered: open before the first band; after each band call
 * kdr_render_png_stream_band from the thread that rendered it (any number
 * of threads at once: the worker that gets the encoder deflates the done
 * prefix of bands, the others return at once); close once every band is
 * done (it encodes what is left and hands over the bytes, KDR_OK, KDR_ENOMEM,
 * or KDR_EINVAL when a band was never marked done); then discard, which
 * also ends a stream that is never closed. now() times the encoding
 * (NULL: not timed); kdr_render_png_stream_cpu sums it over threads. The
 * stream reads p and img's rgb and keeps pointers to both. */
typedef struct kdr_render_png_stream kdr_render_png_stream;
int kdr_render_png_stream_open(const kdr_render_params *p, const kdr_render_image *img,
                               kdr_render_png_stream **out);
void kdr_render_png_stream_band(kdr_render_png_stream *st, size_t band,
                                double (*now)(void));
int kdr_render_png_stream_close(kdr_render_png_stream *st, double (*now)(void),
                                unsigned char **out, size_t *len, size_t *cap);
double kdr_render_png_stream_cpu(const kdr_render_png_stream *st);
void kdr_render_png_stream_discard(kdr_render_png_stream *st);

const char *kdr_render_mode_name(kdr_render_mode m);

#ifdef __cplusplus
}
#endif
#endif /* KDR_RENDER_H */
