/*
 * kdr_png.c — the picture as PNG through Debian's libpng, into memory,
 * either at once (kdr_render_png) or as a stream fed band by band while
 * later bands still trace (kdr_render_png_stream_*).
 *
 * Speed over size: zlib level 1 and no row filter. Measured on this box
 * (libpng 1.6.39, process CPU time, mean of 5, re-encoding the 1024x768
 * pictures of docs/img): default scene 4.95 ms / 145,700 bytes, against
 * 31.2 ms / 124,608 bytes for libpng's defaults (level 6, adaptive filters),
 * 15.7 ms for level 1 with adaptive filters and 6.7 ms with the sub filter
 * (both larger: 192-195 KB); on engine9 5.5 ms / 161,883 bytes against
 * 26.8 ms / 174,762 bytes. zlib's Z_RLE and Z_HUFFMAN_ONLY are no help
 * here: 1.38 MB and 16-18 ms for the default picture (Python's zlib, same
 * library). The bytes go over loopback or a LAN, where 20 KB more costs
 * less than 25 ms.
 *
 * The stream: encoded at once after the bands, those 5 ms were a serial
 * tail on every picture while the other worker sat idle. Bands are claimed
 * in order, so the rows finished so far are nearly always a prefix; the
 * worker that finishes a band deflates the done prefix once it holds
 * PNG_BATCH_ROWS rows (or reaches the last row), if no other worker is
 * encoding (a try-lock: a worker never waits for the encoder). The rows go through the
 * same libpng calls png_write_png makes (info, one row at a time, end), so the bytes are
 * those of kdr_render_png.
 */
#include <png.h>
#include <pthread.h>
#include <setjmp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_render.h"

typedef struct sink {
    unsigned char *data;
    size_t len, cap;
    int oom;
} sink;

static void put(png_structp png, png_bytep bytes, png_size_t n) {
    sink *s = png_get_io_ptr(png);
    if (s->oom) return;
    if (s->len + n > s->cap) {
        size_t cap = s->cap ? s->cap : 65536;
        while (cap < s->len + n)
            cap *= 2;
        unsigned char *p = realloc(s->data, cap);
        if (!p) {
            s->oom = 1;
            png_error(png, "out of memory");
        }
        s->data = p;
        s->cap = cap;
    }
    memcpy(s->data + s->len, bytes, n);
    s->len += n;
}

static void flush(png_structp png) { (void)png; }

/* libpng reports errors by longjmp; its warnings are not ours to print. */
static void quiet(png_structp png, png_const_charp msg) {
    (void)png;
    (void)msg;
}

int kdr_render_png(const kdr_render_image *img, unsigned char **out, size_t *len,
                   size_t *cap) {
    sink *volatile s = calloc(1, sizeof *s);
    png_bytep *volatile rows =
        malloc((img->height ? img->height : 1) * sizeof(png_bytep));
    png_structp png = NULL;
    png_infop info = NULL;
    volatile int rc = KDR_ENOMEM;
    if (!s || !rows) goto done;
    png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, quiet);
    if (!png) goto done;
    info = png_create_info_struct(png);
    if (!info) goto done;
    if (setjmp(png_jmpbuf(png))) goto done;
    png_set_write_fn(png, s, put, flush);
    png_set_IHDR(png, info, img->width, img->height, 8, PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_set_compression_level(png, 1);
    png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_NONE);
    for (uint32_t y = 0; y < img->height; y++)
        rows[y] = img->rgb + (size_t)y * img->width * 3;
    png_set_rows(png, info, rows);
    png_write_png(png, info, PNG_TRANSFORM_IDENTITY, NULL);
    rc = KDR_OK;
done:
    png_destroy_write_struct(png ? &png : NULL, info ? &info : NULL);
    if (rc == KDR_OK) {
        *out = s->data;
        *len = s->len;
        *cap = s->cap;
    } else if (s) {
        free(s->data);
    }
    free(s);
    free(rows);
    return rc;
}

/* ---- the stream ------------------------------------------------------------------ */

struct kdr_render_png_stream {
    const kdr_render_params *p;
    const kdr_render_image *img;
    size_t nbands;
    atomic_uchar *done; /* per band: its pixels are final */
    pthread_mutex_t mu; /* held by the one worker encoding */
    size_t next;        /* first band not yet encoded (under mu) */
    int failed;         /* libpng failed (under mu): the rest is skipped */
    png_structp png;
    png_infop info;
    sink s;
    double cpu_s; /* time spent encoding, by now() */
};

int kdr_render_png_stream_open(const kdr_render_params *p, const kdr_render_image *img,
                               kdr_render_png_stream **out) {
    *out = NULL;
    kdr_render_png_stream *volatile st = calloc(1, sizeof *st);
    if (!st) return KDR_ENOMEM;
    st->p = p;
    st->img = img;
    st->nbands = kdr_render_band_count(p);
    st->done = calloc(st->nbands ? st->nbands : 1, sizeof *st->done);
    if (!st->done || pthread_mutex_init(&st->mu, NULL) != 0) {
        free(st->done);
        free(st);
        return KDR_ENOMEM;
    }
    for (size_t b = 0; b < st->nbands; b++)
        atomic_init(&st->done[b], 0);
    st->png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, quiet);
    if (st->png) st->info = png_create_info_struct(st->png);
    if (!st->info || setjmp(png_jmpbuf(st->png))) {
        kdr_render_png_stream_discard(st);
        return KDR_ENOMEM;
    }
    png_set_write_fn(st->png, &st->s, put, flush);
    png_set_IHDR(st->png, st->info, img->width, img->height, 8, PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_set_compression_level(st->png, 1);
    png_set_filter(st->png, PNG_FILTER_TYPE_BASE, PNG_FILTER_NONE);
    png_write_info(st->png, st->info);
    *out = st;
    return KDR_OK;
}

/* Rows deflated at a time: a band's 8 rows at once cost 7.6 ms of CPU
 * against 5.0 for the whole image after the bands (zlib's ~256 KB of state
 * and the tracer's data evict each other); 96-256 rows cost 5.1-5.4 ms
 * (kdray-bench-render --threads 2 --repeat 9, default scene). The last
 * rows wait for close or for the last band, whichever comes first. */
enum { PNG_BATCH_ROWS = 128 };

/* Encodes the done prefix from st->next on, if it holds PNG_BATCH_ROWS
 * rows or `all`; the caller holds st->mu. */
static void encode_prefix(kdr_render_png_stream *st, double (*now)(void), int all) {
    if (st->failed) return;
    const double t0 = now ? now() : 0;
    if (setjmp(png_jmpbuf(st->png))) {
        st->failed = 1;
        return;
    }
    const size_t stride = (size_t)st->img->width * 3;
    size_t end = st->next;
    while (end < st->nbands && atomic_load_explicit(&st->done[end], memory_order_acquire))
        end++;
    uint32_t y0, y1, e0, e1;
    kdr_render_band_rows(st->p, st->next < st->nbands ? st->next : 0, &y0, &y1);
    kdr_render_band_rows(st->p, end ? end - 1 : 0, &e0, &e1);
    /* near the end the batches shrink to what is still to come, so the
     * last band's worker has few rows left to deflate while the others
     * wait */
    const uint32_t pending = e1 - y0, left = st->img->height - e1;
    if (!all && (end == st->next || (pending < PNG_BATCH_ROWS && pending < left))) return;
    for (uint32_t y = y0; end > st->next && y < e1; y++)
        png_write_row(st->png, st->img->rgb + (size_t)y * stride);
    st->next = end;
    if (now) st->cpu_s += now() - t0;
}

void kdr_render_png_stream_band(kdr_render_png_stream *st, size_t band,
                                double (*now)(void)) {
    if (band >= st->nbands) return;
    atomic_store_explicit(&st->done[band], 1, memory_order_release);
    /* A worker that finds the lock taken leaves its band to the holder, who
     * looks again after letting go, or to a later band's worker, or to
     * kdr_render_png_stream_close. */
    while (pthread_mutex_trylock(&st->mu) == 0) {
        const size_t from = st->next;
        encode_prefix(st, now, 0);
        const size_t next = st->next;
        pthread_mutex_unlock(&st->mu);
        if (next == from || next >= st->nbands ||
            !atomic_load_explicit(&st->done[next], memory_order_acquire))
            break;
    }
}

int kdr_render_png_stream_close(kdr_render_png_stream *st, double (*now)(void),
                                unsigned char **out, size_t *len, size_t *cap) {
    pthread_mutex_lock(&st->mu);
    encode_prefix(st, now, 1);
    int rc = st->failed ? KDR_ENOMEM : st->next < st->nbands ? KDR_EINVAL : KDR_OK;
    if (rc == KDR_OK) {
        const double t0 = now ? now() : 0;
        if (setjmp(png_jmpbuf(st->png)))
            rc = KDR_ENOMEM;
        else
            png_write_end(st->png, st->info);
        if (now) st->cpu_s += now() - t0;
    }
    pthread_mutex_unlock(&st->mu);
    if (rc == KDR_OK) {
        *out = st->s.data;
        *len = st->s.len;
        *cap = st->s.cap;
        st->s.data = NULL;
    }
    return rc;
}

double kdr_render_png_stream_cpu(const kdr_render_png_stream *st) { return st->cpu_s; }

void kdr_render_png_stream_discard(kdr_render_png_stream *st) {
    if (!st) return;
    if (st->png) png_destroy_write_struct(&st->png, st->info ? &st->info : NULL);
    pthread_mutex_destroy(&st->mu);
    free(st->s.data);
    free(st->done);
    free(st);
}
