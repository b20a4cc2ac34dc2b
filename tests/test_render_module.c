/*
 * test_render_module.c — render/ and its executor kind, without HTTP:
 * parameters parse or are refused naming themselves; the default framing
 * fills what was not given; bands rendered in any order give the same
 * image (so any number of workers does); a pixel's shadow is the
 * cone-shadow answer for point index = pixel index; a render through the
 * executor with two workers is a PNG that libpng decodes to exactly the
 * serial image; the executor refuses too many pixels (413) and a bad
 * camera (400); a large picture's image is one fresh mapping advised for
 * huge pages that holds every array; the PNG streamed band by band, bands
 * done in any order and from two threads at once, is byte for byte the
 * PNG encoded at once, and is deflated before close when the bands come
 * in order. A plain C program: exits nonzero when
 * a check fails.
 */
#define _POSIX_C_SOURCE 200809L
#include <png.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "kdr_exec.h"
#include "kdr_render.h"
#include "thp_smaps.h"

/* A floor, a box on it and a floating slab: shadows and penumbrae. */
static kdr_scene *make_scene(void) {
    static const float quads[][4][3] = {
        {{-4, 0, -4}, {-4, 0, 4}, {4, 0, 4}, {4, 0, -4}},
        {{-1, 1.5f, -1}, {-1, 1.5f, 1}, {1, 1.5f, 1}, {1, 1.5f, -1}},
        {{-1, 0, 1}, {1, 0, 1}, {1, 1.5f, 1}, {-1, 1.5f, 1}},
        {{1, 0, 1}, {1, 0, -1}, {1, 1.5f, -1}, {1, 1.5f, 1}},
        {{1.5f, 2.5f, -2.5f}, {3, 2, -2.5f}, {3, 2.5f, -1}, {1.5f, 3, -1}},
    };
    const size_t nq = sizeof quads / sizeof quads[0];
    float *t = malloc(nq * 2 * 9 * sizeof(float));
    static const int corner[2][3] = {{0, 1, 2}, {0, 2, 3}};
    for (size_t q = 0; q < nq; q++)
        for (int k = 0; k < 2; k++)
            for (int v = 0; v < 3; v++)
                memcpy(t + (q * 2 + k) * 9 + v * 3, quads[q][corner[k][v]],
                       3 * sizeof(float));
    kdr_build_opts o;
    kdr_build_opts_default(&o);
    kdr_scene *s = NULL;
    CHECK(kdr_scene_build(t, nq * 2, &o, NULL, NULL, &s) == KDR_OK, "build");
    free(t);
    return s;
}

static void test_params(void) {
    kdr_render_params p;
    char err[256];
    kdr_render_params_init(&p);
    CHECK(kdr_render_param(&p, "eye", "1,2.5,-3", err, sizeof err) == 0, "%s", err);
    CHECK(p.cam.eye[1] == 2.5f && (p.set & KDR_RP_EYE), "eye parsed");
    CHECK(kdr_render_param(&p, "light", "0,5,0,0.5", err, sizeof err) == 0, "%s", err);
    CHECK(p.light.radius == 0.5f, "light radius");
    CHECK(kdr_render_param(&p, "mode", "ao", err, sizeof err) == 0 &&
              p.mode == KDR_RENDER_AO,
          "mode");
    static const char *const bad[][2] = {
        {"eye", "1,2"},      {"eye", "1,2,3,4"}, {"eye", "1,2,x"},     {"target", ""},
        {"up", "nan,0,1"},   {"fov", "0"},       {"fov", "180"},       {"fov", "1e99"},
        {"width", "0"},      {"width", "16385"}, {"height", "2.5"},    {"samples", "0"},
        {"samples", "4097"}, {"light", "1,2,3"}, {"light", "1,2,3,0"}, {"mode", "Shade"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        err[0] = '\0';
        CHECK(kdr_render_param(&p, bad[i][0], bad[i][1], err, sizeof err) == -1, "%s=%s",
              bad[i][0], bad[i][1]);
        CHECK(strncmp(err, bad[i][0], strlen(bad[i][0])) == 0 &&
                  err[strlen(bad[i][0])] == ':',
              "error names %s: %s", bad[i][0], err);
    }
    CHECK(kdr_render_param(&p, "zoom", "2", err, sizeof err) == 1 &&
              !strncmp(err, "zoom:", 5),
          "unknown: %s", err);
}

static void test_frame(const kdr_scene *s) {
    kdr_render_params p;
    char err[256];
    kdr_render_params_init(&p);
    CHECK(kdr_render_frame(s, &p, err, sizeof err) == 0, "%s", err);
    CHECK(kdr_camera_validate(&p.cam) == KDR_OK, "framed camera is valid");
    CHECK(p.light.radius > 0 && p.light.center[1] > 3.0f, "light above the scene");
    CHECK(p.far_d > p.near_d, "depth range");
    kdr_render_params_init(&p);
    kdr_render_param(&p, "eye", "0,1,0", err, sizeof err);
    kdr_render_param(&p, "target", "0,1,0", err, sizeof err);
    CHECK(kdr_render_frame(s, &p, err, sizeof err) == -1 && !strncmp(err, "eye:", 4),
          "%s", err);
    kdr_render_params_init(&p);
    kdr_render_param(&p, "eye", "0,9,0", err, sizeof err);
    kdr_render_param(&p, "target", "0,0,0", err, sizeof err);
    CHECK(kdr_render_frame(s, &p, err, sizeof err) == -1 && !strncmp(err, "up:", 3), "%s",
          err);
}

/* The whole image, bands in the given order. */
static void render_serial(const kdr_scene *s, const kdr_render_params *p,
                          kdr_render_image *img, int reverse) {
    CHECK(kdr_render_alloc(p, img) == KDR_OK, "alloc");
    size_t n = kdr_render_band_count(p);
    kdr_render_stats st = {0};
    for (size_t k = 0; k < n; k++)
        CHECK(kdr_render_band(s, p, img, reverse ? n - 1 - k : k, NULL, &st) == KDR_OK,
              "band");
    CHECK(st.pixels == (uint64_t)p->cam.width * p->cam.height, "every pixel once");
}

static kdr_render_params params_of(const kdr_scene *s, const char *mode, const char *w,
                                   const char *h) {
    kdr_render_params p;
    char err[256];
    kdr_render_params_init(&p);
    kdr_render_param(&p, "eye", "5.5,4,6.5", err, sizeof err);
    kdr_render_param(&p, "target", "0,0.8,0", err, sizeof err);
    kdr_render_param(&p, "light", "2.5,6,1.5,0.9", err, sizeof err);
    kdr_render_param(&p, "samples", "16", err, sizeof err);
    kdr_render_param(&p, "mode", mode, err, sizeof err);
    kdr_render_param(&p, "width", w, err, sizeof err);
    kdr_render_param(&p, "height", h, err, sizeof err);
    CHECK(kdr_render_frame(s, &p, err, sizeof err) == 0, "%s", err);
    return p;
}

static void test_bands_and_shadow_index(const kdr_scene *s) {
    static const char *const modes[] = {"shade", "ao", "depth"};
    for (int m = 0; m < 3; m++) {
        /* 300 wide: one band is a single tile row, so there are many bands */
        kdr_render_params p = params_of(s, modes[m], "300", "97");
        CHECK(kdr_render_band_count(&p) > 4, "several bands");
        kdr_render_image a, b;
        render_serial(s, &p, &a, 0);
        render_serial(s, &p, &b, 1);
        CHECK(!memcmp(a.rgb, b.rgb, (size_t)300 * 97 * 3), "%s: band order", modes[m]);
        if (m == 0) {
            /* the visibility of pixel i is the cone-shadow answer for point i */
            const kdr_shadow_query q = {.n = (size_t)300 * 97,
                                        .points = a.points,
                                        .normals = a.normals,
                                        .lights = &p.light,
                                        .nlights = 1,
                                        .samples = p.samples,
                                        .seed = KDR_RENDER_SEED,
                                        .offset = KDR_OFFSET_DIAGONAL,
                                        .epsilon = KDR_RENDER_EPSILON};
            size_t checked = 0, partial = 0;
            for (size_t i = 0; i < q.n; i += 7) {
                if (a.hits.prim[i] < 0) continue;
                float v = -1;
                float *vis = malloc(q.n * sizeof(float));
                CHECK(kdr_shadow_trace(s, &q, i, 1, KDR_SHADOW_RAYS, vis, NULL) == KDR_OK,
                      "trace");
                v = vis[i];
                free(vis);
                CHECK(v == a.visibility[i], "pixel %zu: %g vs %g", i, v, a.visibility[i]);
                checked++;
                partial += v > 0 && v < 1;
            }
            CHECK(checked > 500 && partial > 10, "%zu points, %zu in penumbra", checked,
                  partial);
        }
        kdr_render_free(&a);
        kdr_render_free(&b);
    }
}

static void test_exec(const kdr_scene *s) {
    kdr_exec_config cfg = {.workers = 2, .max_queue = 4, .max_bytes = 256u << 20};
    kdr_exec *ex = kdr_exec_create(&cfg);
    CHECK(ex != NULL, "exec");
    kdr_render_params p = params_of(s, "shade", "321", "203");
    kdr_render_image img;
    render_serial(s, &p, &img, 0);
    kdr_render_params given = p; /* framed already: the executor frames again, same */
    kdr_exec_claim claim = {0};
    CHECK(kdr_exec_admit(ex, &claim, 0) == KDR_ADMIT_OK, "admit");
    kdr_exec_query q = {.kind = KDR_EXEC_RENDER,
                        .mode = KDR_EXEC_FAST,
                        .scene = s,
                        .start = kdr_exec_now(),
                        .claim = &claim,
                        .render = &given};
    CHECK(kdr_exec_submit(ex, &q) == 0, "submit");
    kdr_exec_wait(&q, -1);
    CHECK(q.result.status == 200, "%d %s", q.result.status, q.result.detail);
    CHECK(q.result.content_type && !strcmp(q.result.content_type, "image/png"), "type");
    CHECK(q.result.chunks > 1 && q.result.render.hits > 0, "bands and hits");
    png_image pi;
    memset(&pi, 0, sizeof pi);
    pi.version = PNG_IMAGE_VERSION;
    CHECK(png_image_begin_read_from_memory(&pi, q.result.body.data, q.result.body.len),
          "png header: %s", pi.message);
    CHECK(pi.width == 321 && pi.height == 203, "png size");
    pi.format = PNG_FORMAT_RGB;
    unsigned char *dec = malloc(PNG_IMAGE_SIZE(pi));
    CHECK(png_image_finish_read(&pi, NULL, dec, 0, NULL), "png decode: %s", pi.message);
    CHECK(!memcmp(dec, img.rgb, (size_t)321 * 203 * 3), "decoded PNG equals the image");
    free(dec);
    kdr_exec_query_done(&q);
    kdr_exec_release(ex, &claim);
    kdr_render_free(&img);
    /* too many pixels for max_rays; a camera without a view */
    kdr_exec_query big = {.kind = KDR_EXEC_RENDER,
                          .scene = s,
                          .start = kdr_exec_now(),
                          .render = &given,
                          .max_rays = 1000};
    CHECK(kdr_exec_submit(ex, &big) == 0, "submit");
    kdr_exec_wait(&big, -1);
    CHECK(big.result.status == 413 && strstr(big.result.detail, "width x height"),
          "%d %s", big.result.status, big.result.detail);
    kdr_exec_query_done(&big);
    kdr_render_params flat;
    char err[64];
    kdr_render_params_init(&flat);
    kdr_render_param(&flat, "eye", "1,1,1", err, sizeof err);
    kdr_render_param(&flat, "target", "1,1,1", err, sizeof err);
    kdr_exec_query bad = {
        .kind = KDR_EXEC_RENDER, .scene = s, .start = kdr_exec_now(), .render = &flat};
    CHECK(kdr_exec_submit(ex, &bad) == 0, "submit");
    kdr_exec_wait(&bad, -1);
    CHECK(bad.result.status == 400 && !strncmp(bad.result.detail, "eye:", 4), "%d %s",
          bad.result.status, bad.result.detail);
    kdr_exec_query_done(&bad);
    kdr_exec_destroy(ex);
}

/* The image of a 1024x768 picture: one 2 MiB-aligned block of whole 2 MiB
 * pages (what kdr_render_image_bytes charges), fresh (nothing resident
 * before the bands write it), advised for huge pages from its first byte to
 * its last, and every array 64-byte aligned inside it, in order, apart. */
static void test_image_block(const kdr_scene *s) {
    kdr_render_params p = params_of(s, "shade", "1024", "768");
    kdr_render_image img;
    CHECK(kdr_render_alloc(&p, &img) == KDR_OK, "alloc 1024x768");
    const size_t n = (size_t)1024 * 768;
    const char *b = img.block;
    CHECK(b && ((uintptr_t)b & (THP_HUGE_PAGE - 1)) == 0, "block %p not 2 MiB-aligned",
          (const void *)b);
    CHECK(img.block_len == kdr_render_image_bytes(&p) &&
              img.block_len % THP_HUGE_PAGE == 0,
          "block of %zu bytes, charged %zu", img.block_len, kdr_render_image_bytes(&p));
    const struct {
        const void *p;
        size_t bytes;
    } a[] = {{img.hits.t, n * 4},     {img.hits.prim, n * 4}, {img.hits.u, n * 4},
             {img.hits.v, n * 4},     {img.points, n * 12},   {img.normals, n * 12},
             {img.visibility, n * 4}, {img.rgb, n * 3}};
    const char *end = b;
    for (size_t i = 0; i < sizeof a / sizeof a[0]; i++) {
        const char *q = a[i].p;
        CHECK(q >= end && ((uintptr_t)q & 63) == 0 && q + a[i].bytes <= b + img.block_len,
              "array %zu at offset %td overlaps, is misaligned or leaves the block", i,
              q - b);
        end = q + a[i].bytes;
    }
    char mode[256];
    if (!thp_possible(mode, sizeof mode)) {
        FAIL(THP_OFF_MESSAGE, mode);
    } else {
        const void *ends[2] = {b, b + img.block_len - 1};
        for (int i = 0; i < 2; i++) {
            const thp_vma v = thp_vma_of(ends[i]);
            CHECK(v.found && v.advised, "image byte %p: not in an advised mapping",
                  ends[i]);
            CHECK(v.eligible == 1, "image byte %p: THPeligible %d", ends[i], v.eligible);
        }
        const thp_vma v = thp_vma_of(b);
        CHECK(v.rss_kb == 0,
              "a new image already has %ld kB resident (reused heap memory "
              "stays in 4 KiB pages)",
              v.rss_kb);
    }
    kdr_render_free(&img);
    CHECK(img.block == NULL && img.rgb == NULL, "free clears the image");
}

/* ---- the PNG stream ---------------------------------------------------------------- */

static double fake_now(void) { /* a clock that always moves: any encode counts */
    static atomic_ulong t = 0;
    return (double)atomic_fetch_add(&t, 1);
}

typedef struct marker {
    kdr_render_png_stream *st;
    size_t nbands, parity;
} marker;

static void *mark_half(void *arg) {
    const marker *m = arg;
    for (size_t b = m->parity; b < m->nbands; b += 2)
        kdr_render_png_stream_band(m->st, b, fake_now);
    return NULL;
}

static void test_png_stream(const kdr_scene *s) {
    /* 300 wide: three tile rows a band, 17 bands over 400 rows, so the stream
     * deflates in several batches */
    kdr_render_params p = params_of(s, "shade", "300", "400");
    kdr_render_image img;
    render_serial(s, &p, &img, 0);
    const size_t n = kdr_render_band_count(&p);
    CHECK(n > 10, "many bands");
    uint32_t prev = 0;
    for (size_t b = 0; b < n; b++) {
        uint32_t y0, y1;
        kdr_render_band_rows(&p, b, &y0, &y1);
        CHECK(y0 == prev && y1 > y0, "band %zu rows [%u, %u) follow %u", b, y0, y1, prev);
        prev = y1;
    }
    CHECK(prev == 400, "the bands cover the rows");
    unsigned char *ref = NULL;
    size_t ref_len = 0, cap = 0;
    CHECK(kdr_render_png(&img, &ref, &ref_len, &cap) == KDR_OK, "png");
    for (int order = 0; order < 4; order++) {
        /* 0 in order, 1 reversed, 2 pairs swapped, 3 two threads */
        kdr_render_png_stream *st = NULL;
        CHECK(kdr_render_png_stream_open(&p, &img, &st) == KDR_OK && st, "open");
        if (order == 3) {
            marker m[2] = {{st, n, 0}, {st, n, 1}};
            pthread_t t[2];
            for (int k = 0; k < 2; k++)
                CHECK(pthread_create(&t[k], NULL, mark_half, &m[k]) == 0, "thread");
            for (int k = 0; k < 2; k++)
                pthread_join(t[k], NULL);
        } else {
            for (size_t k = 0; k < n; k++) {
                const size_t b = order == 0 ? k : order == 1 ? n - 1 - k : k ^ 1;
                kdr_render_png_stream_band(st, b < n ? b : k, fake_now);
            }
        }
        if (order == 0)
            CHECK(kdr_render_png_stream_cpu(st) > 0,
                  "bands in order: deflated before close");
        unsigned char *out = NULL;
        size_t len = 0;
        CHECK(kdr_render_png_stream_close(st, fake_now, &out, &len, &cap) == KDR_OK,
              "close");
        CHECK(len == ref_len && out && !memcmp(out, ref, len),
              "order %d: the stream's PNG is the PNG's bytes (%zu vs %zu)", order, len,
              ref_len);
        free(out);
        kdr_render_png_stream_discard(st);
    }
    /* a band never done: close refuses, discard frees (ASan checks) */
    kdr_render_png_stream *st = NULL;
    CHECK(kdr_render_png_stream_open(&p, &img, &st) == KDR_OK, "open");
    for (size_t b = 0; b < n; b++)
        if (b != n / 2) kdr_render_png_stream_band(st, b, NULL);
    unsigned char *out = NULL;
    size_t len = 0;
    CHECK(kdr_render_png_stream_close(st, NULL, &out, &len, &cap) == KDR_EINVAL,
          "close with a band missing");
    kdr_render_png_stream_discard(st);
    /* never closed */
    CHECK(kdr_render_png_stream_open(&p, &img, &st) == KDR_OK, "open");
    kdr_render_png_stream_band(st, 0, NULL);
    kdr_render_png_stream_discard(st);
    free(ref);
    kdr_render_free(&img);
}

int main(void) {
    kdr_scene *s = make_scene();
    test_image_block(s);
    test_params();
    test_frame(s);
    test_bands_and_shadow_index(s);
    test_exec(s);
    test_png_stream(s);
    kdr_scene_free(s);
    if (failures)
        fprintf(stderr, "%d checks failed\n", failures);
    else
        printf("render module: all checks passed\n");
    return failures ? 1 : 0;
}
