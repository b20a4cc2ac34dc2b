/*
 * bench_render.c — kdray-bench-render: the cost of a picture (render/) on
 * one thread, by stage, and what the shadow stage would cost as a single
 * cone-shadow call over the same hit points in row order (so the render's
 * per-band calls in 4x4 squares are measured against the plain query in
 * the order a client would likely send). Thread CPU time, best of
 * --repeat. Not a test: it prints, it asserts nothing.
 *
 * With --threads N (N > 1) the bands are claimed from one counter by N
 * threads, as kdrayd's executor claims a render's chunks, and a second line
 * shows the picture's wall time (bands, then the PNG on one thread), the
 * CPU summed over the threads, each thread's share, and the tail: how long
 * the first thread to run out of bands waited for the last one. That line
 * is what tells a slow picture's causes apart (more CPU per band when two
 * run at once, an uneven split, or a long last band). It is printed for
 * the PNG encoded after the bands ("png at end") and for the PNG streamed
 * band by band as kdrayd does ("png stream": the workers deflate the done
 * prefix as they go, render/kdr_png.c), the two alternated picture by
 * picture in this one process, with the ratio of their median walls.
 *
 * Usage: kdray-bench-render [--width W] [--height H] [--samples S]
 *                           [--mode M] [--repeat N] [--threads N] SCENE.glb...
 */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kdr_gltf.h"
#include "kdr_render.h"

static double cpu_now(void) {
    struct timespec t;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static double wall_now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

typedef struct run {
    kdr_render_stats st;
    double total, png, one_call;
} run;

/* ---- the bands on several threads ---------------------------------------------- */

enum { MAX_THREADS = 64 };

typedef struct par_job {
    const kdr_scene *scene;
    const kdr_render_params *p;
    kdr_render_image *img;
    size_t nbands;
    atomic_size_t next;
    atomic_int failed;
    kdr_render_png_stream *png; /* NULL: the PNG after the bands */
} par_job;

typedef struct par_worker {
    par_job *job;
    kdr_render_stats st;
    double cpu, end; /* thread CPU spent on bands; wall clock when it ran out */
    size_t bands;
} par_worker;

static void *par_main(void *arg) {
    par_worker *w = arg;
    par_job *j = w->job;
    const double c0 = cpu_now();
    for (size_t b; (b = atomic_fetch_add(&j->next, 1)) < j->nbands;) {
        if (kdr_render_band(j->scene, j->p, j->img, b, cpu_now, &w->st) != KDR_OK)
            atomic_store(&j->failed, 1);
        else if (j->png)
            kdr_render_png_stream_band(j->png, b, cpu_now);
        w->bands++;
    }
    w->cpu = cpu_now() - c0;
    w->end = wall_now();
    return NULL;
}

typedef struct par_run {
    double wall, bands_wall, png, png_after, cpu, tail, cpu_min, cpu_max;
    size_t bands_min, bands_max;
} par_run;

/* One picture on `threads` threads; the PNG after the last band (on the
 * thread that finished last, as the executor's encode), or streamed. */
static int par_one(const kdr_scene *s, const kdr_render_params *p, int threads,
                   int stream, par_run *r) {
    kdr_render_image img;
    if (kdr_render_alloc(p, &img) != KDR_OK) return -1;
    par_job j = {.scene = s, .p = p, .img = &img, .nbands = kdr_render_band_count(p)};
    const double t0 = wall_now();
    if (stream && kdr_render_png_stream_open(p, &img, &j.png) != KDR_OK) {
        kdr_render_free(&img);
        return -1;
    }
    atomic_init(&j.next, 0);
    atomic_init(&j.failed, 0);
    par_worker w[MAX_THREADS];
    pthread_t tid[MAX_THREADS];
    memset(w, 0, sizeof w);
    int started = 0;
    for (; started < threads; started++) {
        w[started].job = &j;
        if (pthread_create(&tid[started], NULL, par_main, &w[started]) != 0) break;
    }
    for (int k = 0; k < started; k++)
        pthread_join(tid[k], NULL);
    const double t1 = wall_now();
    unsigned char *png = NULL;
    size_t len, cap;
    const double c1 = cpu_now();
    const int rc = j.png ? kdr_render_png_stream_close(j.png, cpu_now, &png, &len, &cap)
                         : kdr_render_png(&img, &png, &len, &cap);
    r->png_after = cpu_now() - c1;
    r->png = j.png ? kdr_render_png_stream_cpu(j.png) : r->png_after;
    kdr_render_png_stream_discard(j.png);
    r->wall = wall_now() - t0;
    r->bands_wall = t1 - t0;
    free(png);
    kdr_render_free(&img);
    if (started < threads || rc != KDR_OK || atomic_load(&j.failed)) return -1;
    double first_end = w[0].end;
    r->cpu = 0;
    r->cpu_min = r->cpu_max = w[0].cpu;
    r->bands_min = r->bands_max = w[0].bands;
    for (int k = 0; k < threads; k++) {
        r->cpu += w[k].cpu;
        first_end = w[k].end < first_end ? w[k].end : first_end;
        r->cpu_min = w[k].cpu < r->cpu_min ? w[k].cpu : r->cpu_min;
        r->cpu_max = w[k].cpu > r->cpu_max ? w[k].cpu : r->cpu_max;
        r->bands_min = w[k].bands < r->bands_min ? w[k].bands : r->bands_min;
        r->bands_max = w[k].bands > r->bands_max ? w[k].bands : r->bands_max;
    }
    r->tail = t1 - first_end;
    return 0;
}

static int one_run(const kdr_scene *s, const kdr_render_params *p, run *r) {
    kdr_render_image img;
    if (kdr_render_alloc(p, &img) != KDR_OK) return -1;
    memset(r, 0, sizeof *r);
    double t0 = cpu_now();
    for (size_t b = 0; b < kdr_render_band_count(p); b++)
        if (kdr_render_band(s, p, &img, b, cpu_now, &r->st) != KDR_OK) return -1;
    double t1 = cpu_now();
    unsigned char *png = NULL;
    size_t len, cap;
    if (kdr_render_png(&img, &png, &len, &cap) != KDR_OK) return -1;
    r->png = cpu_now() - t1;
    r->total = t1 - t0;
    free(png);
    if (p->mode == KDR_RENDER_SHADE || p->mode == KDR_RENDER_SHADOW) {
        /* the same points, compacted, in one call */
        size_t n = 0, N = (size_t)p->cam.width * p->cam.height;
        float *pts = malloc(N * 3 * sizeof(float)), *nrm = malloc(N * 3 * sizeof(float));
        float *vis = malloc(N * sizeof(float));
        if (!pts || !nrm || !vis) return -1;
        for (size_t i = 0; i < N; i++)
            if (img.hits.prim[i] >= 0) {
                memcpy(pts + 3 * n, img.points + 3 * i, 3 * sizeof(float));
                memcpy(nrm + 3 * n, img.normals + 3 * i, 3 * sizeof(float));
                n++;
            }
        kdr_shadow_query q = {.n = n,
                              .points = pts,
                              .normals = nrm,
                              .lights = &p->light,
                              .nlights = 1,
                              .samples = p->samples,
                              .seed = KDR_RENDER_SEED,
                              .offset = KDR_OFFSET_DIAGONAL, /* as render's */
                              .epsilon = KDR_RENDER_EPSILON};
        double c0 = cpu_now();
        int rc = kdr_shadow_trace(s, &q, 0, n, KDR_SHADOW_CONE, vis, NULL);
        r->one_call = cpu_now() - c0;
        free(pts);
        free(nrm);
        free(vis);
        if (rc != KDR_OK) return -1;
    }
    kdr_render_free(&img);
    return 0;
}

int main(int argc, char **argv) {
    kdr_render_params p;
    kdr_render_params_init(&p);
    char err[256];
    const char *w = "1024", *h = "768", *samples = "64", *mode = "shade";
    int repeat = 3, threads = 1, first = 1;
    for (; first < argc && argv[first][0] == '-' && first + 1 < argc; first += 2) {
        const char *f = argv[first], *v = argv[first + 1];
        if (!strcmp(f, "--width"))
            w = v;
        else if (!strcmp(f, "--height"))
            h = v;
        else if (!strcmp(f, "--samples"))
            samples = v;
        else if (!strcmp(f, "--mode"))
            mode = v;
        else if (!strcmp(f, "--repeat"))
            repeat = atoi(v) > 0 ? atoi(v) : 1;
        else if (!strcmp(f, "--threads"))
            threads = atoi(v) < 1 ? 1 : atoi(v) > MAX_THREADS ? MAX_THREADS : atoi(v);
        else
            break;
    }
    if (first >= argc) {
        fprintf(stderr,
                "usage: kdray-bench-render [--width W] [--height H] [--samples S] "
                "[--mode M] [--repeat N] [--threads N] SCENE.glb...\n");
        return 2;
    }
    const char *names[] = {"width", "height", "samples", "mode"};
    const char *vals[] = {w, h, samples, mode};
    for (int i = 0; i < 4; i++)
        if (kdr_render_param(&p, names[i], vals[i], err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            return 2;
        }
    printf("%-12s %9s %9s %9s %9s %9s %9s %12s %10s\n", "scene", "tris", "total_ms",
           "primary", "shadow", "shade", "png", "1call_shadow", "shadow_rays");
    for (int a = first; a < argc; a++) {
        kdr_gltf_scene g;
        if (kdr_gltf_load(argv[a], &g, err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            return 1;
        }
        kdr_build_opts o;
        kdr_build_opts_default(&o);
        kdr_scene *s = NULL;
        if (kdr_scene_build(g.tris, g.ntris, &o, NULL, NULL, &s) != KDR_OK) return 1;
        kdr_render_params q = p;
        if (kdr_render_frame(s, &q, err, sizeof err) != 0) {
            fprintf(stderr, "%s\n", err);
            return 1;
        }
        run best = {0}, r;
        for (int k = 0; k < repeat; k++) {
            if (one_run(s, &q, &r) != 0) return 1;
            if (k == 0 || r.total < best.total) best = r;
        }
        const char *base = strrchr(argv[a], '/');
        printf("%-12.12s %9zu %9.1f %9.1f %9.1f %9.1f %9.1f %12.1f %10llu\n",
               base ? base + 1 : argv[a], g.ntris, best.total * 1e3,
               best.st.primary_s * 1e3, best.st.shadow_s * 1e3, best.st.shade_s * 1e3,
               best.png * 1e3, best.one_call * 1e3,
               (unsigned long long)(best.st.shadow.rays_traced + best.st.ao_rays));
        if (threads > 1) {
            /* median wall of --repeat pictures each way, alternated */
            par_run pr[2][64];
            const int n = repeat < 64 ? repeat : 64;
            for (int k = 0; k < n; k++)
                for (int m = 0; m < 2; m++)
                    if (par_one(s, &q, threads, (k + m) % 2, &pr[(k + m) % 2][k]) != 0)
                        return 1;
            double med[2];
            for (int v = 0; v < 2; v++) {
                par_run *x = pr[v];
                for (int k = 1; k < n; k++) /* insertion sort by wall time */
                    for (int m = k; m > 0 && x[m].wall < x[m - 1].wall; m--) {
                        par_run t = x[m];
                        x[m] = x[m - 1];
                        x[m - 1] = t;
                    }
                const par_run *md = &x[n / 2];
                med[v] = md->wall;
                printf("  %d threads, png %s, median of %d: wall %.1f ms (bands %.1f, "
                       "png %.1f CPU, %.1f of it after the bands), "
                       "CPU %.1f ms summed (per thread %.1f-%.1f, %zu-%zu bands), "
                       "tail %.1f ms; fastest wall %.1f ms\n",
                       threads, v ? "stream" : "at end", n, md->wall * 1e3,
                       md->bands_wall * 1e3, md->png * 1e3, md->png_after * 1e3,
                       md->cpu * 1e3, md->cpu_min * 1e3, md->cpu_max * 1e3, md->bands_min,
                       md->bands_max, md->tail * 1e3, x[0].wall * 1e3);
            }
            printf("  median wall, png stream / png at end: %.3f\n", med[1] / med[0]);
        }
        kdr_scene_free(s);
        kdr_gltf_free(&g);
    }
    return 0;
}
