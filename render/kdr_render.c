/*
 * kdr_render.c — one band of a picture: the frustum query for its primary
 * rays, hit points and eye-facing normals, the cone-shadow query (or ao
 * bundles) at those points, and the shading. The float steps here are the
 * definition tests/test_render.py recomputes from the daemon's answers, so
 * every expression keeps its written order (the build has
 * -ffp-contract=off: no fused multiply-adds).
 *
 * A picture's image (hits, points, normals, visibility, rgb: 47 bytes a
 * pixel, 37 MB at 1024x768) is one block. The bands write it once, into
 * fresh memory each request: with 4 KiB pages that was ~9000 first-touch
 * faults a picture. On Linux a block of 2 MiB or more is its own mapping,
 * 2 MiB-aligned and advised for transparent huge pages (as core/kd_mem.c
 * does for a scene's arrays), so those faults map 2 MiB at a time.
 */
#if defined(__linux__)
#define _DEFAULT_SOURCE /* mmap, MAP_ANONYMOUS, madvise, MADV_HUGEPAGE */
#include <stdint.h>
#include <sys/mman.h>
#endif
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_render.h"

/* Shading constants: a light clay albedo, a little ambient light. */
static const float AMBIENT = 0.12f;
static const float DIFFUSE = 0.88f;
static const float ALBEDO[3] = {0.84f, 0.80f, 0.74f};
/* Rays per ao batch: bounds a band's scratch whatever `samples` is. */
enum { AO_BATCH_RAYS = 16384 };

const char *kdr_render_mode_name(kdr_render_mode m) {
    static const char *const names[] = {"shade", "depth", "normal", "shadow", "ao"};
    return (unsigned)m < 5 ? names[m] : "?";
}

static size_t tiles_x(const kdr_render_params *p) {
    return (p->cam.width + KDR_RENDER_TILE - 1) / KDR_RENDER_TILE;
}
static size_t tiles_y(const kdr_render_params *p) {
    return (p->cam.height + KDR_RENDER_TILE - 1) / KDR_RENDER_TILE;
}
/* Tile rows per band: about KDR_RENDER_BAND_PIXELS pixels, at least one. */
static size_t band_rows(const kdr_render_params *p) {
    size_t per_row = tiles_x(p) * KDR_RENDER_TILE * KDR_RENDER_TILE;
    size_t r = KDR_RENDER_BAND_PIXELS / per_row;
    return r ? r : 1;
}

size_t kdr_render_band_count(const kdr_render_params *p) {
    size_t r = band_rows(p);
    return (tiles_y(p) + r - 1) / r;
}

void kdr_render_band_rows(const kdr_render_params *p, size_t band, uint32_t *y0,
                          uint32_t *y1) {
    const size_t rows = band_rows(p), ty = tiles_y(p);
    const size_t r0 = band * rows < ty ? band * rows : ty;
    const size_t r1 = r0 + rows < ty ? r0 + rows : ty;
    *y0 = (uint32_t)(r0 * KDR_RENDER_TILE < p->cam.height ? r0 * KDR_RENDER_TILE
                                                          : p->cam.height);
    *y1 = (uint32_t)(r1 * KDR_RENDER_TILE < p->cam.height ? r1 * KDR_RENDER_TILE
                                                          : p->cam.height);
}

static size_t pixels(const kdr_render_params *p) {
    return (size_t)p->cam.width * p->cam.height;
}

/* The arrays' offsets in the image's block, each 64-byte aligned. */
typedef struct image_layout {
    size_t t, prim, u, v, points, normals, visibility, rgb, bytes;
} image_layout;

static size_t grow(size_t *at, size_t bytes) {
    size_t off = *at;
    *at += (bytes + 63) & ~(size_t)63;
    return off;
}

static image_layout layout_of(const kdr_render_params *p) {
    size_t n = pixels(p), at = 0;
    image_layout l;
    l.t = grow(&at, n * sizeof(float));
    l.prim = grow(&at, n * sizeof(int32_t));
    l.u = grow(&at, n * sizeof(float));
    l.v = grow(&at, n * sizeof(float));
    l.points = grow(&at, n * 3 * sizeof(float));
    l.normals = grow(&at, n * 3 * sizeof(float));
    l.visibility = grow(&at, n * sizeof(float));
    l.rgb = grow(&at, n * 3);
    l.bytes = at;
    return l;
}

#define HUGE_PAGE ((size_t)2 << 20)

size_t kdr_render_image_bytes(const kdr_render_params *p) {
    /* hits t, prim, u, v; points, normals; visibility; rgb; a block of
     * 2 MiB or more is mapped in whole 2 MiB pages */
    size_t bytes = layout_of(p).bytes;
    return bytes >= HUGE_PAGE ? (bytes + HUGE_PAGE - 1) / HUGE_PAGE * HUGE_PAGE : bytes;
}

size_t kdr_render_png_max(const kdr_render_params *p) {
    /* stored deflate blocks at worst: 5 bytes per 16 KiB, plus the filter
     * byte of each row, the headers and chunk framing */
    size_t raw = pixels(p) * 3 + p->cam.height;
    return raw + raw / 16384 * 5 + (raw / 8192 + 1) * 12 + 1024;
}

size_t kdr_render_scratch_bytes(const kdr_render_params *p) {
    size_t dirs = (size_t)p->cam.width * 3 * sizeof(float);
    size_t ao = p->mode == KDR_RENDER_AO ? AO_BATCH_RAYS * (6 * sizeof(float) + 1) +
                                               AO_BATCH_RAYS * sizeof(float)
                                         : 0;
    return dirs + ao;
}

/* bytes in a 2 MiB-aligned mapping of whole 2 MiB pages, advised for huge
 * pages before anything touches it; NULL when it cannot be mapped */
static void *map_block(size_t bytes, size_t *len) {
#if defined(__linux__)
    if (bytes < HUGE_PAGE || bytes > SIZE_MAX / 2) return NULL;
    size_t whole = (bytes + HUGE_PAGE - 1) & ~(HUGE_PAGE - 1);
    size_t reserve = whole + HUGE_PAGE;
    char *raw =
        mmap(NULL, reserve, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (raw == MAP_FAILED) return NULL;
    char *b = (char *)(((uintptr_t)raw + HUGE_PAGE - 1) & ~(uintptr_t)(HUGE_PAGE - 1));
    if (b > raw) munmap(raw, (size_t)(b - raw));
    if (raw + reserve > b + whole)
        munmap(b + whole, (size_t)(raw + reserve - (b + whole)));
    (void)madvise(b, whole, MADV_HUGEPAGE); /* a hint: without it, 4 KiB pages */
    *len = whole;
    return b;
#else
    (void)bytes;
    (void)len;
    return NULL;
#endif
}

int kdr_render_alloc(const kdr_render_params *p, kdr_render_image *img) {
    memset(img, 0, sizeof *img);
    image_layout l = layout_of(p);
    img->width = p->cam.width;
    img->height = p->cam.height;
    char *b = map_block(l.bytes, &img->block_len);
    if (!b) {
        img->block_len = 0;
        b = malloc(l.bytes ? l.bytes : 1);
        if (!b) return KDR_ENOMEM;
    }
    img->block = b;
    img->hits.t = (float *)(b + l.t);
    img->hits.prim = (int32_t *)(b + l.prim);
    img->hits.u = (float *)(b + l.u);
    img->hits.v = (float *)(b + l.v);
    img->points = (float *)(b + l.points);
    img->normals = (float *)(b + l.normals);
    img->visibility = (float *)(b + l.visibility);
    img->rgb = (uint8_t *)(b + l.rgb);
    return KDR_OK;
}

void kdr_render_free(kdr_render_image *img) {
#if defined(__linux__)
    if (img->block && img->block_len)
        munmap(img->block, img->block_len);
    else
#endif
        free(img->block);
    memset(img, 0, sizeof *img);
}

/* ---- geometry ------------------------------------------------------------------- */

/* Point and eye-facing unit normal of every hit pixel of rows [y0, y1). */
static void hit_geometry(const kdr_scene *scene, const kdr_render_params *p,
                         kdr_render_image *img, uint32_t y0, uint32_t y1, float *dirs) {
    const uint32_t w = p->cam.width;
    for (uint32_t y = y0; y < y1; y++) {
        kdr_camera_row_dirs(&p->cam, y, 0, w, dirs);
        for (uint32_t x = 0; x < w; x++) {
            const size_t i = (size_t)y * w + x;
            const int32_t prim = img->hits.prim[i];
            if (prim < 0) continue;
            const float *d = dirs + 3 * (size_t)x, t = img->hits.t[i];
            float *pt = img->points + 3 * i, *n = img->normals + 3 * i;
            for (int c = 0; c < 3; c++)
                pt[c] = p->cam.eye[c] + t * d[c];
            const float *v = kdr_scene_triangle(scene, (size_t)prim);
            const float e1[3] = {v[3] - v[0], v[4] - v[1], v[5] - v[2]};
            const float e2[3] = {v[6] - v[0], v[7] - v[1], v[8] - v[2]};
            n[0] = e1[1] * e2[2] - e1[2] * e2[1];
            n[1] = e1[2] * e2[0] - e1[0] * e2[2];
            n[2] = e1[0] * e2[1] - e1[1] * e2[0];
            const float len = sqrtf((n[0] * n[0] + n[1] * n[1]) + n[2] * n[2]);
            if (len > 0.0f && isfinite(len)) {
                n[0] = n[0] / len;
                n[1] = n[1] / len;
                n[2] = n[2] / len;
            } else {
                n[0] = n[1] = n[2] = 0.0f; /* a sliver: no normal, lit by ambient */
            }
            if ((d[0] * n[0] + d[1] * n[1]) + d[2] * n[2] > 0.0f) {
                n[0] = -n[0];
                n[1] = -n[1];
                n[2] = -n[2];
            }
        }
    }
}

/* ---- shadow ------------------------------------------------------------------- */

/* Visibility of the light from every hit pixel of rows [y0, y1): one
 * cone-shadow call for the band, its hit pixels passed square by square
 * (KDR_RENDER_SHADOW_TILE pixels a side, rows inside a square) through
 * kdr_shadow_trace_order, so that runs of consecutive points are compact
 * on the screen and their cones share walks (kd_cone_group.c); point index
 * = pixel index, so each pixel keeps its samples and its answer whatever
 * the order. A point inside the light (the core refuses it) counts as
 * lit. */
static int shadow_rows(const kdr_scene *scene, const kdr_render_params *p,
                       kdr_render_image *img, uint32_t y0, uint32_t y1,
                       kdr_shadow_stats *st) {
    const uint32_t w = p->cam.width, T = KDR_RENDER_SHADOW_TILE;
    const kdr_shadow_query q = {.n = pixels(p),
                                .points = img->points,
                                .normals = img->normals,
                                .lights = &p->light,
                                .nlights = 1,
                                .samples = p->samples,
                                .seed = KDR_RENDER_SEED,
                                .offset = KDR_OFFSET_DIAGONAL,
                                .epsilon = KDR_RENDER_EPSILON};
    size_t *order = malloc((size_t)(y1 - y0) * w * sizeof *order), n = 0;
    if (!order) return KDR_ENOMEM;
    for (uint32_t ty = y0; ty < y1; ty += T)
        for (uint32_t tx = 0; tx < w; tx += T)
            for (uint32_t y = ty; y < ty + T && y < y1; y++)
                for (uint32_t x = tx; x < tx + T && x < w; x++) {
                    const size_t i = (size_t)y * w + x;
                    if (img->hits.prim[i] >= 0) order[n++] = i;
                }
    int rc =
        kdr_shadow_trace_order(scene, &q, order, n, KDR_SHADOW_CONE, img->visibility, st);
    for (size_t k = 0; rc == KDR_EINVAL && k < n; k++) {
        /* some point is refused: each alone, the refused ones lit */
        int r1 = kdr_shadow_trace(scene, &q, order[k], 1, KDR_SHADOW_CONE,
                                  img->visibility, st);
        if (r1 == KDR_EINVAL)
            img->visibility[order[k]] = 1.0f;
        else if (r1 != KDR_OK) {
            free(order);
            return r1;
        }
        if (k + 1 == n) rc = KDR_OK;
    }
    free(order);
    return rc;
}

/* ---- ambient occlusion ------------------------------------------------------------ */

/* A counter-based hash to [0,1): the same ray whatever the thread or band. */
static float hash01(uint64_t a, uint64_t b) {
    uint64_t z = a * 0x9E3779B97F4A7C15ull + b * 0xD1B54A32D192ED03ull + KDR_RENDER_SEED;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return (float)(z >> 40) * (1.0f / 16777216.0f);
}

/* Cosine-weighted direction s of `samples` about unit normal n. */
static void ao_dir(const float n[3], size_t pixel, uint32_t s, uint32_t samples,
                   float out[3]) {
    const float a[3] = {fabsf(n[0]) > 0.5f ? 0.0f : 1.0f,
                        fabsf(n[0]) > 0.5f ? 1.0f : 0.0f, 0.0f};
    float t[3] = {a[1] * n[2] - a[2] * n[1], a[2] * n[0] - a[0] * n[2],
                  a[0] * n[1] - a[1] * n[0]};
    const float tl = sqrtf(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
    for (int c = 0; c < 3; c++)
        t[c] /= tl;
    const float b[3] = {n[1] * t[2] - n[2] * t[1], n[2] * t[0] - n[0] * t[2],
                        n[0] * t[1] - n[1] * t[0]};
    const float u1 = ((float)s + hash01(pixel, 2 * (uint64_t)s)) / (float)samples;
    const float u2 = hash01(pixel, 2 * (uint64_t)s + 1);
    const float r = sqrtf(u1), phi = 6.2831853f * u2;
    const float cx = r * cosf(phi), cy = r * sinf(phi), cz = sqrtf(1.0f - u1);
    for (int c = 0; c < 3; c++)
        out[c] = t[c] * cx + b[c] * cy + n[c] * cz;
}

typedef struct ao_batch {
    float *org, *dir, *tmax;
    uint8_t *hit;
    size_t *owner; /* pixel of each ray */
    size_t n;
} ao_batch;

static int ao_flush(const kdr_scene *scene, ao_batch *b, kdr_render_image *img,
                    kdr_render_stats *st) {
    if (b->n == 0) return KDR_OK;
    kdr_ray_batch rb = {.n = b->n,
                        .org = b->org,
                        .org_stride = 3,
                        .dir = b->dir,
                        .tmin = NULL,
                        .tmin_stride = 0,
                        .tmax = b->tmax,
                        .tmax_stride = 1};
    static const float zero = 0.0f;
    rb.tmin = &zero;
    kdr_hits h = {.hit = b->hit};
    kdr_trav_stats ts = {0};
    int rc = kdr_trace_batch(scene, &rb, 0, b->n, KDR_ANY, KDR_TRAV_AUTO, &h, &ts);
    if (rc != KDR_OK) return rc;
    for (size_t k = 0; k < b->n; k++)
        if (b->hit[k]) img->visibility[b->owner[k]] -= 1.0f;
    st->ao_rays += b->n;
    st->ao_nodes += ts.nodes_visited;
    b->n = 0;
    return KDR_OK;
}

static int ao_rows(const kdr_scene *scene, const kdr_render_params *p,
                   kdr_render_image *img, uint32_t y0, uint32_t y1,
                   kdr_render_stats *st) {
    ao_batch b = {0};
    b.org = malloc(AO_BATCH_RAYS * 3 * sizeof(float));
    b.dir = malloc(AO_BATCH_RAYS * 3 * sizeof(float));
    b.tmax = malloc(AO_BATCH_RAYS * sizeof(float));
    b.hit = malloc(AO_BATCH_RAYS);
    b.owner = malloc(AO_BATCH_RAYS * sizeof(size_t));
    int rc = b.org && b.dir && b.tmax && b.hit && b.owner ? KDR_OK : KDR_ENOMEM;
    const float off = KDR_RENDER_EPSILON * kdr_scene_diagonal(scene);
    const size_t first = (size_t)y0 * p->cam.width, last = (size_t)y1 * p->cam.width;
    for (size_t i = first; rc == KDR_OK && i < last; i++) {
        if (img->hits.prim[i] < 0) continue;
        const float *n = img->normals + 3 * i, *pt = img->points + 3 * i;
        img->visibility[i] = (float)p->samples; /* unoccluded rays, counted down */
        if (n[0] == 0.0f && n[1] == 0.0f && n[2] == 0.0f) continue;
        for (uint32_t s = 0; rc == KDR_OK && s < p->samples; s++) {
            size_t k = b.n++;
            for (int c = 0; c < 3; c++)
                b.org[3 * k + c] = pt[c] + n[c] * off;
            ao_dir(n, i, s, p->samples, b.dir + 3 * k);
            b.tmax[k] = p->ao_radius;
            b.owner[k] = i;
            if (b.n == AO_BATCH_RAYS) rc = ao_flush(scene, &b, img, st);
        }
    }
    if (rc == KDR_OK) rc = ao_flush(scene, &b, img, st);
    for (size_t i = first; rc == KDR_OK && i < last; i++)
        if (img->hits.prim[i] >= 0) img->visibility[i] /= (float)p->samples;
    free(b.org);
    free(b.dir);
    free(b.tmax);
    free(b.hit);
    free(b.owner);
    return rc;
}

/* ---- shading -------------------------------------------------------------------- */

static uint8_t to8(float v) { /* v >= 0 */
    v = v * 255.0f + 0.5f;
    return v >= 255.0f ? 255 : (uint8_t)v;
}

static void shade_pixel(const kdr_render_params *p, const kdr_render_image *img, size_t i,
                        uint8_t *out) {
    const float *pt = img->points + 3 * i, *n = img->normals + 3 * i;
    switch (p->mode) {
    case KDR_RENDER_DEPTH: {
        /* t is in units of |d|: the distance is t * |d| */
        float d[3];
        kdr_camera_row_dirs(&p->cam, (uint32_t)(i / p->cam.width),
                            (uint32_t)(i % p->cam.width), 1, d);
        const float dist =
            img->hits.t[i] * sqrtf((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]);
        float g = (p->far_d - dist) / (p->far_d - p->near_d);
        g = g < 0.0f ? 0.0f : g > 1.0f ? 1.0f : g;
        out[0] = out[1] = out[2] = to8(g);
        return;
    }
    case KDR_RENDER_NORMAL:
        for (int c = 0; c < 3; c++)
            out[c] = to8(n[c] * 0.5f + 0.5f);
        return;
    case KDR_RENDER_SHADOW:
        out[0] = out[1] = out[2] = to8(AMBIENT + DIFFUSE * img->visibility[i]);
        return;
    case KDR_RENDER_AO:
        for (int c = 0; c < 3; c++)
            out[c] = to8(img->visibility[i] * ALBEDO[c]);
        return;
    case KDR_RENDER_SHADE:
    default: {
        const float l[3] = {p->light.center[0] - pt[0], p->light.center[1] - pt[1],
                            p->light.center[2] - pt[2]};
        const float ll = sqrtf((l[0] * l[0] + l[1] * l[1]) + l[2] * l[2]);
        float ndl = ((n[0] * l[0] + n[1] * l[1]) + n[2] * l[2]) / ll;
        if (!(ndl > 0.0f)) ndl = 0.0f;
        const float k = AMBIENT + (DIFFUSE * ndl) * img->visibility[i];
        for (int c = 0; c < 3; c++)
            out[c] = to8(k * ALBEDO[c]);
        return;
    }
    }
}

/* Misses: a ramp from a slate blue at the top to a darker one below. */
static void background(uint32_t y, uint32_t h, uint8_t *out) {
    const uint32_t k = (uint32_t)((24ull * y) / h);
    out[0] = (uint8_t)(58 - k);
    out[1] = (uint8_t)(66 - k);
    out[2] = (uint8_t)(82 - k);
}

static void shade_rows(const kdr_render_params *p, kdr_render_image *img, uint32_t y0,
                       uint32_t y1) {
    const uint32_t w = p->cam.width;
    for (uint32_t y = y0; y < y1; y++)
        for (uint32_t x = 0; x < w; x++) {
            const size_t i = (size_t)y * w + x;
            if (img->hits.prim[i] < 0)
                background(y, p->cam.height, img->rgb + 3 * i);
            else
                shade_pixel(p, img, i, img->rgb + 3 * i);
        }
}

/* ---- a band ------------------------------------------------------------------- */

int kdr_render_band(const kdr_scene *scene, const kdr_render_params *p,
                    kdr_render_image *img, size_t band, double (*now)(void),
                    kdr_render_stats *st) {
    const size_t rows = band_rows(p), tx = tiles_x(p);
    const size_t r0 = band * rows, r1 = r0 + rows < tiles_y(p) ? r0 + rows : tiles_y(p);
    if (r0 >= r1) return KDR_EINVAL;
    uint32_t y0, y1;
    kdr_render_band_rows(p, band, &y0, &y1);
    double t0 = now ? now() : 0;
    kdr_trav_stats ts = {0};
    int rc = kdr_frustum_trace(scene, &p->cam, KDR_RENDER_TILE, r0 * tx, (r1 - r0) * tx,
                               KDR_CLOSEST, KDR_FRUSTUM_MULTI4, &img->hits, &ts);
    if (rc != KDR_OK) return rc;
    float *dirs = malloc((size_t)p->cam.width * 3 * sizeof(float));
    if (!dirs) return KDR_ENOMEM;
    hit_geometry(scene, p, img, y0, y1, dirs);
    free(dirs);
    st->pixels += (uint64_t)(y1 - y0) * p->cam.width;
    st->primary_nodes += ts.nodes_visited;
    for (size_t i = (size_t)y0 * p->cam.width; i < (size_t)y1 * p->cam.width; i++)
        st->hits += img->hits.prim[i] >= 0;
    double t1 = now ? now() : 0;
    if (p->mode == KDR_RENDER_SHADE || p->mode == KDR_RENDER_SHADOW)
        rc = shadow_rows(scene, p, img, y0, y1, &st->shadow);
    else if (p->mode == KDR_RENDER_AO)
        rc = ao_rows(scene, p, img, y0, y1, st);
    if (rc != KDR_OK) return rc;
    double t2 = now ? now() : 0;
    shade_rows(p, img, y0, y1);
    double t3 = now ? now() : 0;
    st->primary_s += t1 - t0;
    st->shadow_s += t2 - t1;
    st->shade_s += t3 - t2;
    return KDR_OK;
}
