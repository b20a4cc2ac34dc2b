/*
 * stress_scenes.c — the adversarial scenes of stress.h. Meshes are built
 * from an indexed vertex list (each vertex computed once), so every edge
 * shared by two triangles has bit-identical endpoints: the precondition of
 * watertightness that the inside-ray tests rely on.
 */
#include "stress.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define STRESS_PI 3.14159265358979323846

/* ---- RNG ---------------------------------------------------------------- */

void stress_rng_seed(stress_rng *r, uint64_t seed) {
    r->s = seed * 0x9E3779B97F4A7C15ull + 0x632BE59BD9B4E019ull;
}

uint64_t stress_rng_next(stress_rng *r) {
    uint64_t z = (r->s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

float stress_rng_float(stress_rng *r) {
    return (float)(stress_rng_next(r) >> 40) * 0x1p-24f;
}

void stress_rng_dir(stress_rng *r, float d[3]) {
    for (;;) {
        float x = 2 * stress_rng_float(r) - 1, y = 2 * stress_rng_float(r) - 1,
              z = 2 * stress_rng_float(r) - 1;
        float l2 = x * x + y * y + z * z;
        if (l2 > 1e-4f && l2 <= 1.0f) {
            float s = 1.0f / sqrtf(l2);
            d[0] = x * s;
            d[1] = y * s;
            d[2] = z * s;
            return;
        }
    }
}

void stress_tri_point(stress_rng *r, const float *tri, float p[3], float nrm[3]) {
    float a = stress_rng_float(r), c = stress_rng_float(r);
    if (a + c > 1.0f)
        a = 1.0f - a, c = 1.0f - c;
    float e1[3], e2[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = tri[3 + k] - tri[k];
        e2[k] = tri[6 + k] - tri[k];
        p[k] = tri[k] + a * e1[k] + c * e2[k];
    }
    nrm[0] = e1[1] * e2[2] - e1[2] * e2[1];
    nrm[1] = e1[2] * e2[0] - e1[0] * e2[2];
    nrm[2] = e1[0] * e2[1] - e1[1] * e2[0];
}

static float rng_range(stress_rng *r, float lo, float hi) {
    return lo + (hi - lo) * stress_rng_float(r);
}

/* ---- growable triangle list ---------------------------------------------- */

typedef struct builder {
    float *tris;
    size_t n, cap;
    stress_closed *closed;
    size_t nclosed, ccap;
    int failed;
} builder;

static void add_tri(builder *b, const float *p0, const float *p1,
                    const float *p2) {
    if (b->n == b->cap) {
        size_t cap = b->cap ? 2 * b->cap : 256;
        float *t = realloc(b->tris, cap * 9 * sizeof(float));
        if (!t) {
            b->failed = 1;
            return;
        }
        b->tris = t;
        b->cap = cap;
    }
    float *t = b->tris + 9 * b->n++;
    memcpy(t, p0, 3 * sizeof(float));
    memcpy(t + 3, p1, 3 * sizeof(float));
    memcpy(t + 6, p2, 3 * sizeof(float));
}

static void add_closed_range(builder *b, const float inside[3], size_t first,
                             size_t count) {
    if (b->nclosed == b->ccap) {
        size_t cap = b->ccap ? 2 * b->ccap : 16;
        stress_closed *c = realloc(b->closed, cap * sizeof *c);
        if (!c) {
            b->failed = 1;
            return;
        }
        b->closed = c;
        b->ccap = cap;
    }
    stress_closed *c = &b->closed[b->nclosed++];
    memcpy(c->inside, inside, 3 * sizeof(float));
    c->first = first;
    c->count = count;
}

/* The triangles added since `first` enclose `inside`. */
static void add_closed(builder *b, const float inside[3], size_t first) {
    add_closed_range(b, inside, first, b->n - first);
}

/* Quad p0 p1 p2 p3 (in order around it) as two triangles; alternate the
 * diagonal with `flip` so both diagonal directions occur. */
static void add_quad(builder *b, const float *p0, const float *p1,
                     const float *p2, const float *p3, int flip) {
    if (flip) {
        add_tri(b, p0, p1, p3);
        add_tri(b, p1, p2, p3);
    } else {
        add_tri(b, p0, p1, p2);
        add_tri(b, p0, p2, p3);
    }
}

/* ---- closed meshes -------------------------------------------------------- */

static void box(builder *b, const float lo[3], const float hi[3], int closed) {
    float v[8][3];
    for (int i = 0; i < 8; i++) {
        v[i][0] = (i & 1) ? hi[0] : lo[0];
        v[i][1] = (i & 2) ? hi[1] : lo[1];
        v[i][2] = (i & 4) ? hi[2] : lo[2];
    }
    static const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                    {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    size_t first = b->n;
    for (int f = 0; f < 6; f++)
        add_quad(b, v[faces[f][0]], v[faces[f][1]], v[faces[f][2]],
                 v[faces[f][3]], f & 1);
    if (closed) {
        float c[3];
        for (int k = 0; k < 3; k++)
            c[k] = lo[k] + (hi[k] - lo[k]) * 0.5f;
        add_closed(b, c, first);
    }
}

/* A closed surface of revolution-like grid: (nu x nv) vertices with
 * wrap-around in u; rows 0 and nv-1 collapse to poles when `poles`. */
typedef void (*surf_fn)(const float *param, float u, float v, float out[3]);

static void grid_mesh(builder *b, surf_fn f, const float *param, int nu,
                      int nv, int wrap_v, const float inside[3]) {
    float(*pt)[3] = malloc((size_t)nu * (size_t)(nv + 1) * sizeof *pt);
    if (!pt) {
        b->failed = 1;
        return;
    }
    for (int j = 0; j <= nv; j++)
        for (int i = 0; i < nu; i++)
            f(param, (float)i / (float)nu, (float)j / (float)nv,
              pt[j * nu + i]);
    if (wrap_v) /* make the last row the first, bit for bit */
        memcpy(pt[nv * nu], pt[0], (size_t)nu * sizeof *pt);
    size_t first = b->n;
    for (int j = 0; j < nv; j++)
        for (int i = 0; i < nu; i++) {
            const int i1 = (i + 1) % nu;
            const float *a = pt[j * nu + i], *c = pt[(j + 1) * nu + i1];
            const float *bb = pt[j * nu + i1], *d = pt[(j + 1) * nu + i];
            if (!wrap_v && j == 0)
                add_tri(b, a, c, d); /* pole row: skip the zero-area half */
            else if (!wrap_v && j == nv - 1)
                add_tri(b, a, bb, d);
            else
                add_quad(b, a, bb, c, d, (i + j) & 1);
        }
    free(pt);
    add_closed(b, inside, first);
}

/* param: cx cy cz radius */
static void sphere_fn(const float *p, float u, float v, float out[3]) {
    const double th = 2.0 * STRESS_PI * u, ph = STRESS_PI * v;
    out[0] = p[0] + (float)(p[3] * sin(ph) * cos(th));
    out[1] = p[1] + (float)(p[3] * cos(ph));
    out[2] = p[2] + (float)(p[3] * sin(ph) * sin(th));
    if (v == 0.0f || v == 1.0f) { /* exact poles: one vertex for the fan */
        out[0] = p[0];
        out[2] = p[2];
    }
}

/* param: cx cy cz R r */
static void torus_fn(const float *p, float u, float v, float out[3]) {
    const double th = 2.0 * STRESS_PI * u, ph = 2.0 * STRESS_PI * v;
    const double rr = p[3] + p[4] * cos(ph);
    out[0] = p[0] + (float)(rr * cos(th));
    out[1] = p[1] + (float)(p[4] * sin(ph));
    out[2] = p[2] + (float)(rr * sin(th));
}

/* param: cx cy cz radius half_length: a double cone whose many thin side
 * triangles are slivers. */
static void needle_fn(const float *p, float u, float v, float out[3]) {
    const double th = 2.0 * STRESS_PI * u;
    const double r = (v == 0.0f || v == 1.0f) ? 0.0 : p[3];
    out[0] = p[0] + (float)((2.0 * v - 1.0) * p[4]);
    out[1] = p[1] + (float)(r * cos(th));
    out[2] = p[2] + (float)(r * sin(th));
    if (v == 0.0f || v == 1.0f) {
        out[1] = p[1];
        out[2] = p[2];
    }
}

static void sphere(builder *b, const float c[3], float r, int nu, int nv) {
    const float p[4] = {c[0], c[1], c[2], r};
    grid_mesh(b, sphere_fn, p, nu, nv, 0, c);
}

static void torus(builder *b, const float c[3], float R, float r, int nu,
                  int nv) {
    const float p[5] = {c[0], c[1], c[2], R, r};
    const float inside[3] = {c[0] + R, c[1], c[2]};
    grid_mesh(b, torus_fn, p, nu, nv, 1, inside);
}

static void needle(builder *b, const float c[3], float r, float half, int nu) {
    const float p[5] = {c[0], c[1], c[2], r, half};
    grid_mesh(b, needle_fn, p, nu, 2, 0, c);
}

/* ---- scenes ---------------------------------------------------------------- */

static void scene_shared_boxes(builder *b, stress_rng *r) {
    /* a 4x3x2 block of unit boxes: neighbours' faces coincide exactly */
    for (int x = 0; x < 4; x++)
        for (int y = 0; y < 3; y++)
            for (int z = 0; z < 2; z++) {
                const float lo[3] = {(float)x, (float)y, (float)z};
                const float hi[3] = {x + 1.0f, y + 1.0f, z + 1.0f};
                box(b, lo, hi, 1);
            }
    /* half boxes on the likely split planes 0.5 */
    for (int i = 0; i < 6; i++) {
        const float lo[3] = {0.5f * (float)i, -1.0f, 0.5f};
        const float hi[3] = {0.5f * (float)(i + 1), -0.5f, 1.0f};
        box(b, lo, hi, 1);
    }
    (void)r;
}

static void scene_split_lattice(builder *b, stress_rng *r) {
    enum { K = 4 }; /* planes at k/K, k = 0..K, along each axis */
    for (int axis = 0; axis < 3; axis++)
        for (int k = 0; k <= K; k++)
            for (int i = 0; i < K; i++)
                for (int j = 0; j < K; j++) {
                    float q[4][3];
                    const int di[4] = {0, 1, 1, 0}, dj[4] = {0, 0, 1, 1};
                    for (int c = 0; c < 4; c++) {
                        q[c][axis] = (float)k / K;
                        q[c][(axis + 1) % 3] = (float)(i + di[c]) / K;
                        q[c][(axis + 2) % 3] = (float)(j + dj[c]) / K;
                    }
                    add_quad(b, q[0], q[1], q[2], q[3], (i + j + k) & 1);
                }
    /* every cell is enclosed; aim at any lattice vertex */
    for (int c = 0; c < 8; c++) {
        const float in[3] = {(float)(stress_rng_next(r) % K) / K + 0.125f,
                             (float)(stress_rng_next(r) % K) / K + 0.125f,
                             (float)(stress_rng_next(r) % K) / K + 0.125f};
        add_closed_range(b, in, 0, b->n);
    }
}

static void scene_closed_meshes(builder *b, stress_rng *r) {
    const float c0[3] = {0.0f, 0.0f, 0.0f}, c1[3] = {0.5f, 0.5f, 0.5f};
    sphere(b, c0, 1.0f, 24, 12);
    sphere(b, c1, 1e-3f, 8, 6);
    const float c2[3] = {rng_range(r, 2, 3), rng_range(r, -1, 1), 0.0f};
    sphere(b, c2, rng_range(r, 0.3f, 0.8f), 40, 20);
    const float lo[3] = {-3.0f, -0.5f, -0.5f}, hi[3] = {-2.0f, 0.5f, 0.5f};
    box(b, lo, hi, 1);
    const float lo2[3] = {0.5f, -2.0f, 0.0f}, hi2[3] = {1.0f, -1.5f, 0.5f};
    box(b, lo2, hi2, 1);
    const float ct[3] = {0.0f, 2.5f, 0.0f};
    torus(b, ct, 1.0f, 0.25f, 32, 12);
    const float cn[3] = {0.0f, -3.0f, 1.0f};
    needle(b, cn, 0.01f, 1.5f, 200);
}

static void scene_slivers(builder *b, stress_rng *r) {
    for (int i = 0; i < 300; i++) {
        float p[3], q[3], s[3];
        for (int k = 0; k < 3; k++) {
            p[k] = rng_range(r, -1, 1);
            q[k] = p[k] + rng_range(r, -1, 1);
            /* third vertex within 1e-4..1e-6 of the p-q line: a sliver */
            const float w = stress_rng_float(r);
            s[k] = p[k] + w * (q[k] - p[k]);
        }
        s[i % 3] += ldexpf(1.0f, -14 - (int)(stress_rng_next(r) % 7));
        add_tri(b, p, q, s);
    }
    for (int i = 0; i < 60; i++) { /* degenerate triangles */
        float p[3] = {rng_range(r, -1, 1), rng_range(r, -1, 1), 0.5f};
        float q[3] = {p[0] + 1, p[1], p[2]};
        float s[3] = {p[0] + 2, p[1], p[2]};
        if (i % 3 == 0)
            add_tri(b, p, p, q); /* repeated vertex */
        else if (i % 3 == 1)
            add_tri(b, p, q, s); /* collinear, on an axis line */
        else
            add_tri(b, p, p, p); /* a point */
    }
    const float c[3] = {0.0f, 0.0f, 3.0f};
    needle(b, c, 0.002f, 2.0f, 300);
}

static void scene_far_offset(builder *b, stress_rng *r) {
    static const float offs[3] = {1e5f, 1e6f, 1e7f};
    for (int i = 0; i < 3; i++) {
        /* big enough that vertices stay distinct at this offset's ulp */
        const float size = offs[i] * 0x1p-14f;
        const float c[3] = {offs[i], -offs[i] * 0.5f, offs[i] * 0.25f};
        sphere(b, c, size * rng_range(r, 1.0f, 2.0f), 16, 8);
        const float lo[3] = {c[0] + 4 * size, c[1], c[2]};
        const float hi[3] = {c[0] + 5 * size, c[1] + size, c[2] + size};
        box(b, lo, hi, 1);
    }
    const float c0[3] = {1e5f, 1e5f, 1e5f};
    sphere(b, c0, 0.25f, 12, 6); /* 32 ulps: vertices snap to 1/128 */
}

static void scene_multi_scale(builder *b, stress_rng *r) {
    const float f0[3] = {-1e4f, 0, -1e4f}, f1[3] = {1e4f, 0, -1e4f},
                f2[3] = {1e4f, 0, 1e4f}, f3[3] = {-1e4f, 0, 1e4f};
    add_quad(b, f0, f1, f2, f3, 0);
    const float c[3] = {0.0f, 1e-3f, 0.0f};
    sphere(b, c, 5e-4f, 16, 8);
    const float lo[3] = {-2e3f, 0.0f, -2e3f}, hi[3] = {-1e3f, 1e3f, -1e3f};
    box(b, lo, hi, 1);
    const float c2[3] = {rng_range(r, 10, 20), 5.0f, 0.0f};
    sphere(b, c2, 2.0f, 20, 10);
}

static void scene_soup(builder *b, stress_rng *r) {
    for (int i = 0; i < 800; i++) {
        const float size = ldexpf(1.0f, -(int)(stress_rng_next(r) % 10));
        float c[3] = {rng_range(r, -2, 2), rng_range(r, -2, 2),
                      rng_range(r, -2, 2)};
        float p[3][3];
        for (int v = 0; v < 3; v++)
            for (int k = 0; k < 3; k++)
                p[v][k] = c[k] + size * rng_range(r, -1, 1);
        add_tri(b, p[0], p[1], p[2]);
    }
}

static const char *const scene_names[STRESS_NSCENES] = {
    "shared_boxes", "split_lattice", "closed_meshes", "slivers",
    "far_offset",   "multi_scale",   "soup",
};

const char *stress_scene_name(stress_scene_kind kind) {
    return (kind >= 0 && kind < STRESS_NSCENES) ? scene_names[kind] : "?";
}

int stress_scene_make(stress_scene_kind kind, uint64_t seed, stress_scene *out) {
    static void (*const make[STRESS_NSCENES])(builder *, stress_rng *) = {
        scene_shared_boxes, scene_split_lattice, scene_closed_meshes,
        scene_slivers,      scene_far_offset,    scene_multi_scale,
        scene_soup,
    };
    memset(out, 0, sizeof *out);
    if (kind < 0 || kind >= STRESS_NSCENES)
        return -1;
    builder b = {0};
    stress_rng r;
    stress_rng_seed(&r, seed ^ ((uint64_t)kind << 32));
    make[kind](&b, &r);
    if (b.failed) {
        free(b.tris);
        free(b.closed);
        return -1;
    }
    out->kind = kind;
    out->tris = b.tris;
    out->ntris = b.n;
    out->closed = b.closed;
    out->nclosed = b.nclosed;
    return 0;
}

void stress_scene_free(stress_scene *s) {
    free(s->tris);
    free(s->closed);
    memset(s, 0, sizeof *s);
}

int stress_scene_tris(stress_scene_kind kind, uint64_t seed, float **tris,
                      size_t *ntris) {
    stress_scene s;
    if (stress_scene_make(kind, seed, &s) != 0)
        return -1;
    free(s.closed);
    *tris = s.tris;
    *ntris = s.ntris;
    return 0;
}
