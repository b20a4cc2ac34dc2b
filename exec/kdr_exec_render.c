/*
 * kdr_exec_render.c — pictures as an executor kind, so a render is admitted,
 * charged, chunked, timed and stopped like every query. The "parse" frames
 * the caller's parameters on the scene (render/); a chunk is one band of
 * the image (primary rays, shadows or ao, shading: render/kdr_render.c);
 * the PNG is deflated by the workers as the bands end (render/kdr_png.c's
 * stream), and the encode finishes it. Pixels count as rays against the ray limit.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kdr_exec_internal.h"

static int render_parse(kdr_exec_job *j) {
    kdr_render_params *p = &j->k.render.p;
    if (!j->q->render) {
        kdr_exec_fail(j, 500, "render query without parameters");
        return -1;
    }
    *p = *j->q->render;
    char err[200];
    if (kdr_render_frame(j->q->scene, p, err, sizeof err) != 0) {
        kdr_exec_fail(j, 400, "%s", err);
        return -1;
    }
    const size_t max = j->q->max_rays ? j->q->max_rays : KDR_PROTO_DEFAULT_MAX_RAYS;
    const uint64_t px = (uint64_t)p->cam.width * p->cam.height;
    if (px > max) {
        kdr_exec_fail(j, 413, "width x height: %llu pixels exceeds the limit of %zu rays",
                      (unsigned long long)px, max);
        return -1;
    }
    j->nchunks = kdr_render_band_count(p);
    j->work_rays = px * (p->mode == KDR_RENDER_DEPTH || p->mode == KDR_RENDER_NORMAL
                             ? 1
                             : 1 + (uint64_t)p->samples);
    j->parsed_bytes = 0;
    j->answer_estimate = kdr_render_image_bytes(p) + kdr_render_png_max(p) +
                         j->nchunks * sizeof(kdr_render_stats) +
                         j->ex->cfg.workers * kdr_render_scratch_bytes(p);
    j->deadline_ms = 0;
    return 0;
}

static int render_alloc(kdr_exec_job *j) {
    j->k.render.stats = calloc(j->nchunks ? j->nchunks : 1, sizeof(kdr_render_stats));
    if (!j->k.render.stats) return KDR_ENOMEM;
    int rc = kdr_render_alloc(&j->k.render.p, &j->k.render.img);
    if (rc != KDR_OK) return rc;
    return kdr_render_png_stream_open(&j->k.render.p, &j->k.render.img, &j->k.render.png);
}

/* Stages are timed in the worker's CPU time: on a shared machine a wall
 * clock would count the time other processes held the core. */
static double thread_cpu_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static void render_chunk(kdr_exec_job *j, size_t c) {
    int rc = kdr_render_band(j->q->scene, &j->k.render.p, &j->k.render.img, c,
                             thread_cpu_s, &j->k.render.stats[c]);
    kdr_exec_note_rc(j, rc);
    if (rc == KDR_OK) kdr_render_png_stream_band(j->k.render.png, c, thread_cpu_s);
}

static int render_encode(kdr_exec_job *j) {
    kdr_render_stats *sum = &j->q->result.render;
    memset(sum, 0, sizeof *sum);
    for (size_t c = 0; c < j->nchunks; c++) {
        const kdr_render_stats *s = &j->k.render.stats[c];
        sum->pixels += s->pixels;
        sum->hits += s->hits;
        sum->primary_nodes += s->primary_nodes;
        sum->shadow.cones_decided += s->shadow.cones_decided;
        sum->shadow.rays_traced += s->shadow.rays_traced;
        sum->shadow.nodes_visited += s->shadow.nodes_visited;
        sum->ao_rays += s->ao_rays;
        sum->ao_nodes += s->ao_nodes;
        sum->primary_s += s->primary_s;
        sum->shadow_s += s->shadow_s;
        sum->shade_s += s->shade_s;
    }
    unsigned char *png = NULL;
    size_t len = 0, cap = 0;
    int rc = kdr_render_png_stream_close(j->k.render.png, thread_cpu_s, &png, &len, &cap);
    j->q->result.png_s = kdr_render_png_stream_cpu(j->k.render.png);
    if (rc != KDR_OK) {
        kdr_exec_fail(j, 503, "out of memory while encoding the PNG");
        return -1;
    }
    j->q->result.body = (kdr_buf){.data = (char *)png, .len = len, .cap = cap};
    j->q->result.content_type = "image/png";
    j->q->result.rays = sum->pixels + sum->shadow.rays_traced + sum->ao_rays;
    return 0;
}

static void render_release(kdr_exec_job *j) {
    kdr_render_png_stream_discard(j->k.render.png);
    j->k.render.png = NULL;
    kdr_render_free(&j->k.render.img);
    free(j->k.render.stats);
    j->k.render.stats = NULL;
}

static const kdr_exec_kind_ops RENDER = {render_parse,  render_alloc,   render_chunk,
                                         render_encode, render_release, NULL};

const kdr_exec_kind_ops *kdr_exec_render_ops(void) { return &RENDER; }
