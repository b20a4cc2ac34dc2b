/*
 * test_bundle_sets.c — the scenes and ray sets test_bundle checks every
 * traversal on (declared, with what each is for, in test_bundle_sets.h).
 * Everything random comes from one xorshift64* generator, seeded once, so
 * a run is the same rays every time.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_traverse.h"
#include "test_bundle_sets.h"

#define PI 3.14159265358979323846

/* ---- deterministic random numbers (xorshift64*) --------------------------- */

static uint64_t g_rng = 0x9E3779B97F4A7C15ull;

static uint32_t rnd_u32(void) {
    g_rng ^= g_rng >> 12;
    g_rng ^= g_rng << 25;
    g_rng ^= g_rng >> 27;
    return (uint32_t)((g_rng * 0x2545F4914F6CDD1Dull) >> 32);
}
static float rnd01(void) { return (float)(rnd_u32() >> 8) * 0x1p-24f; }
static float rnd_in(float a, float b) { return a + (b - a) * rnd01(); }
static void rnd_dir(float d[3]) {
    float len;
    do {
        for (int k = 0; k < 3; k++)
            d[k] = rnd_in(-1.0f, 1.0f);
        len = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    } while (len > 1.0f || len < 1e-4f);
}

/* ---- scenes ---------------------------------------------------------------- */


static void put_tri(float *t, const float a[3], const float b[3],
                    const float c[3]) {
    memcpy(t, a, 12);
    memcpy(t + 3, b, 12);
    memcpy(t + 6, c, 12);
}

scene_src make_soup(size_t n) {
    scene_src s = {"soup", malloc(n * 9 * sizeof(float)), n};
    for (size_t i = 0; i < n; i++) {
        float c[3], v[3][3];
        for (int k = 0; k < 3; k++)
            c[k] = rnd_in(-1.0f, 1.0f);
        float size = rnd_in(0.02f, 0.3f);
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 3; k++)
                v[j][k] = c[k] + size * rnd_in(-1.0f, 1.0f);
        put_tri(s.tris + 9 * i, v[0], v[1], v[2]);
    }
    return s;
}

/* Unit quads on an integer lattice, each as two triangles sharing a
 * diagonal: many triangles lie in the planes the SAH build splits on. */
scene_src make_lattice(int cells, float density) {
    size_t cap = (size_t)3 * cells * cells * (cells + 1) * 2;
    scene_src s = {"lattice", malloc(cap * 9 * sizeof(float)), 0};
    for (int axis = 0; axis < 3; axis++)
        for (int a = 0; a <= cells; a++)
            for (int b = 0; b < cells; b++)
                for (int c = 0; c < cells; c++) {
                    if (rnd01() >= density)
                        continue;
                    float p[4][3];
                    const int du[4] = {0, 1, 1, 0}, dv[4] = {0, 0, 1, 1};
                    for (int q = 0; q < 4; q++) {
                        p[q][axis] = (float)a;
                        p[q][(axis + 1) % 3] = (float)(b + du[q]);
                        p[q][(axis + 2) % 3] = (float)(c + dv[q]);
                    }
                    put_tri(s.tris + 9 * s.ntris++, p[0], p[1], p[2]);
                    put_tri(s.tris + 9 * s.ntris++, p[0], p[2], p[3]);
                }
    return s;
}

/* A closed UV sphere: each vertex computed once, so edges match exactly. */
scene_src make_sphere(int rings, int segs) {
    float(*v)[3] = malloc(sizeof(float[3]) * (size_t)(rings + 1) * segs);
    for (int r = 0; r <= rings; r++)
        for (int g = 0; g < segs; g++) {
            double th = PI * r / rings, ph = 2.0 * PI * g / segs;
            float *p = v[r * segs + g];
            p[0] = (float)(sin(th) * cos(ph));
            p[1] = (float)cos(th);
            p[2] = (float)(sin(th) * sin(ph));
        }
    scene_src s = {"sphere", malloc(sizeof(float) * 9 * 2 * rings * segs), 0};
    for (int r = 0; r < rings; r++)
        for (int g = 0; g < segs; g++) {
            int g1 = (g + 1) % segs;
            float *a = v[r * segs + g], *b = v[r * segs + g1];
            float *c = v[(r + 1) * segs + g1], *d = v[(r + 1) * segs + g];
            put_tri(s.tris + 9 * s.ntris++, a, b, c);
            put_tri(s.tris + 9 * s.ntris++, a, c, d);
        }
    free(v);
    return s;
}

/* ---- ray sets -------------------------------------------------------------- */


rayset rays_alloc(const char *name, int shared_org) {
    rayset r = {name, NRAYS, malloc(3 * NRAYS * sizeof(float)),
                malloc(3 * NRAYS * sizeof(float)), malloc(NRAYS * sizeof(float)),
                malloc(NRAYS * sizeof(float)), shared_org};
    for (size_t i = 0; i < NRAYS; i++) {
        r.tmin[i] = 0.0f;
        r.tmax[i] = INFINITY;
    }
    return r;
}

void rays_free(rayset *r) {
    free(r->org);
    free(r->dir);
    free(r->tmin);
    free(r->tmax);
}

static void rnd_point(const kdr_bounds *b, float margin, float p[3]) {
    for (int k = 0; k < 3; k++) {
        float ext = b->max[k] - b->min[k];
        p[k] = rnd_in(b->min[k] - margin * ext, b->max[k] + margin * ext);
    }
}

/* A pinhole camera outside the scene looking at its centre. */
rayset rays_camera(const kdr_bounds *b) {
    rayset r = rays_alloc("camera", 1);
    float c[3], eye[3];
    for (int k = 0; k < 3; k++)
        c[k] = 0.5f * (b->min[k] + b->max[k]);
    eye[0] = c[0] + 1.1f * (b->max[0] - b->min[0]);
    eye[1] = c[1] + 0.4f * (b->max[1] - b->min[1]);
    eye[2] = c[2] + 1.3f * (b->max[2] - b->min[2]);
    memcpy(r.org, eye, sizeof eye);
    const int w = 48; /* rows of 48 pixels, 32 rows */
    for (size_t i = 0; i < r.n; i++) {
        float sx = ((float)(i % w) + 0.5f) / w - 0.5f;
        float sy = ((float)(i / w) + 0.5f) / (r.n / w) - 0.5f;
        for (int k = 0; k < 3; k++)
            r.dir[3 * i + k] = c[k] - eye[k];
        r.dir[3 * i + 0] += sx * (b->max[0] - b->min[0]);
        r.dir[3 * i + 1] += sy * (b->max[1] - b->min[1]);
        r.dir[3 * i + 2] -= sx * (b->max[2] - b->min[2]);
    }
    return r;
}

/* All directions from one point inside the scene: every sign mix. */
rayset rays_omni(const kdr_bounds *b) {
    rayset r = rays_alloc("omni", 1);
    rnd_point(b, -0.2f, r.org);
    for (size_t i = 0; i < r.n; i++)
        rnd_dir(r.dir + 3 * i);
    return r;
}

rayset rays_distinct(const kdr_bounds *b) {
    rayset r = rays_alloc("distinct", 0);
    for (size_t i = 0; i < r.n; i++) {
        rnd_point(b, 0.1f, r.org + 3 * i);
        rnd_dir(r.dir + 3 * i);
    }
    return r;
}

/* Coherent rays from nearby, distinct origins: bundles stay together. */
rayset rays_nearby(const kdr_bounds *b) {
    rayset r = rays_alloc("nearby", 0);
    float base[3] = {0, 0, 0}, d[3] = {1, 0, 0};
    for (size_t i = 0; i < r.n; i++) {
        if (i % 8 == 0) {
            rnd_point(b, 0.0f, base);
            rnd_dir(d);
        }
        for (int k = 0; k < 3; k++) {
            r.org[3 * i + k] = base[k] + 0.01f * rnd_in(-1, 1) * (b->max[k] - b->min[k]);
            r.dir[3 * i + k] = d[k] + 0.05f * rnd_in(-1, 1);
        }
    }
    return r;
}

/* Direction components replaced by +0.0 or -0.0; origins on the lattice's
 * integer planes when the scene is one. */
rayset rays_zeros(const kdr_bounds *b, int integer_org) {
    rayset r = rays_alloc("zeros", 0);
    for (size_t i = 0; i < r.n; i++) {
        float *o = r.org + 3 * i, *d = r.dir + 3 * i;
        rnd_point(b, 0.05f, o);
        if (integer_org)
            for (int k = 0; k < 3; k++)
                if (rnd_u32() & 1)
                    o[k] = floorf(o[k]);
        rnd_dir(d);
        int nz = 1 + (int)(rnd_u32() % 2);
        for (int z = 0; z < nz; z++)
            d[rnd_u32() % 3] = (rnd_u32() & 1) ? -0.0f : 0.0f;
    }
    return r;
}

/* Origins exactly on split planes of random interior nodes; a third of the
 * rays lie in their plane (direction component +0 or -0). */
rayset rays_on_splits(const kdr_scene *s, const kdr_bounds *b, int shared) {
    rayset r = rays_alloc(shared ? "split-shared" : "split-planes", shared);
    size_t n_org = shared ? 1 : r.n;
    for (size_t i = 0; i < n_org; i++) {
        float *o = r.org + 3 * i;
        rnd_point(b, 0.0f, o);
        for (int tries = 0; tries < 64 && s->nnodes > 1; tries++) {
            const kd_node *n = &s->nodes[rnd_u32() % s->nnodes];
            if (!kd_is_leaf(n)) {
                o[kd_axis(n)] = n->u.split;
                break;
            }
        }
    }
    for (size_t i = 0; i < r.n; i++) {
        float *d = r.dir + 3 * i;
        rnd_dir(d);
        if (rnd_u32() % 3 == 0)
            d[rnd_u32() % 3] = (rnd_u32() & 1) ? -0.0f : 0.0f;
    }
    return r;
}

/* The walk's positional slack for an origin (kd_walk_setup's). */
static float walk_slack(const kdr_scene *s, const float o[3]) {
    float m = s->root_mag;
    for (int k = 0; k < 3; k++)
        m = fabsf(o[k]) > m ? fabsf(o[k]) : m;
    return m * KD_SLACK_REL;
}

/* Rays lying in a plane parallel to a split plane at exactly the slack
 * from it (direction component +-0 on the split axis, origin where
 * split - org -/+ slack is exactly 0): the crossing 0 * inf is a NaN, so
 * this is where a walk's "NaN visits both children" rule shows. For the
 * slack to be a round number the origin sits outside the box on another
 * axis, at a power of two P above the scene's magnitude (slack P * 2^-16),
 * and aims back into the box. */
rayset rays_slack_planes(const kdr_scene *s, const kdr_bounds *b) {
    rayset r = rays_alloc("slack-planes", 0);
    float p2 = 1.0f;
    while (p2 <= s->root_mag)
        p2 *= 2.0f;
    for (size_t i = 0; i < r.n; i++) {
        float *o = r.org + 3 * i, *d = r.dir + 3 * i;
        rnd_point(b, 0.0f, o);
        rnd_dir(d);
        const kd_node *n = NULL;
        for (int tries = 0; tries < 64 && s->nnodes > 1 && !n; tries++) {
            n = &s->nodes[rnd_u32() % s->nnodes];
            n = kd_is_leaf(n) ? NULL : n;
        }
        if (!n)
            continue;
        const int k = kd_axis(n), j = (k + 1 + (int)(rnd_u32() & 1)) % 3;
        const float sgn = (rnd_u32() & 1) ? 1.0f : -1.0f;
        o[j] = sgn * p2;
        d[j] = -sgn * fabsf(d[j]) - 0.1f * sgn;
        d[k] = (rnd_u32() & 1) ? -0.0f : 0.0f;
        const float sl = walk_slack(s, o);
        /* exact: sl is a power of two at least 2^7 ulps of the split */
        o[k] = (rnd_u32() & 1) ? n->u.split + sl : n->u.split - sl;
    }
    return r;
}

/* Rays aimed exactly at vertices and edge midpoints (edge functions of 0
 * and the double-precision fallback), from one shared point or from
 * distinct points. */
rayset rays_aimed(const scene_src *src, const kdr_bounds *b, int shared) {
    rayset r = rays_alloc(shared ? "aimed-shared" : "aimed", shared);
    rnd_point(b, 0.0f, r.org);
    for (size_t i = 0; i < r.n; i++) {
        float *o = r.org + (shared ? 0 : 3 * i), *d = r.dir + 3 * i;
        if (!shared)
            rnd_point(b, 0.1f, o);
        const float *tri = src->tris + 9 * (rnd_u32() % src->ntris);
        int a = (int)(rnd_u32() % 3), c = (a + 1) % 3, mid = (int)(rnd_u32() & 1);
        for (int k = 0; k < 3; k++) {
            float p = mid ? 0.5f * (tri[3 * a + k] + tri[3 * c + k]) : tri[3 * a + k];
            d[k] = p - o[k];
        }
    }
    return r;
}

/* Odd intervals and inputs the bundles must hand to single rays. Shared:
 * one origin for all (the chunks stay with bundles, so kd_batch_live's
 * four-at-a-time test meets them), an inf direction component instead of
 * an inf origin, and some zero directions. */
rayset rays_intervals(const kdr_bounds *b, int shared) {
    rayset r = rays_alloc(shared ? "intervals-shared" : "intervals", shared);
    float diag = 0.0f;
    for (int k = 0; k < 3; k++)
        diag += (b->max[k] - b->min[k]) * (b->max[k] - b->min[k]);
    diag = sqrtf(diag);
    for (size_t i = 0; i < r.n; i++) {
        rnd_point(b, 0.05f, r.org + 3 * (shared ? 0 : i));
        rnd_dir(r.dir + 3 * i);
        float a = rnd_in(0.0f, diag), c = rnd_in(0.0f, diag);
        switch (rnd_u32() % 8) {
        case 0: r.tmin[i] = c, r.tmax[i] = a < c ? a : c * 0.5f; break; /* empty */
        case 1: r.tmin[i] = r.tmax[i] = a; break;
        case 2: r.tmin[i] = -a; break;
        case 3: r.tmin[i] = a < c ? a : c, r.tmax[i] = a < c ? c : a; break;
        case 4: r.tmax[i] = a; break;
        case 5: r.dir[3 * i + rnd_u32() % 3] = NAN; break;
        case 6: (shared ? r.dir : r.org)[3 * i + rnd_u32() % 3] = INFINITY; break;
        default:
            if (shared && (rnd_u32() & 1))
                r.dir[3 * i] = r.dir[3 * i + 1] = r.dir[3 * i + 2] = 0.0f;
            break;
        }
    }
    return r;
}

/* Rays whose end o + tmax d lies on a split plane of a random interior
 * node (tmax solved on the split axis, so the end is on the plane or
 * within rounding of it, inside the walk's slack); a quarter have tmax
 * +inf instead (no finite end) and an eighth start at tmin > 0. Origins
 * anywhere around the box, some outside it. */
rayset rays_ends_on_splits(const kdr_scene *s, const kdr_bounds *b) {
    rayset r = rays_alloc("ends-on-splits", 0);
    for (size_t i = 0; i < r.n; i++) {
        float *o = r.org + 3 * i, *d = r.dir + 3 * i, e[3];
        rnd_point(b, 0.3f, o);
        rnd_point(b, 0.0f, e);
        int axis = (int)(rnd_u32() % 3);
        for (int tries = 0; tries < 64 && s->nnodes > 1; tries++) {
            const kd_node *n = &s->nodes[rnd_u32() % s->nnodes];
            if (!kd_is_leaf(n)) {
                axis = kd_axis(n);
                e[axis] = n->u.split;
                break;
            }
        }
        for (int k = 0; k < 3; k++)
            d[k] = e[k] - o[k];
        if (d[axis] == 0.0f)
            d[axis] = 1.0f;
        r.tmax[i] = (e[axis] - o[axis]) / d[axis];
        if (!(r.tmax[i] >= 0.0f))
            r.tmax[i] = 1.0f;
        switch (rnd_u32() % 8) {
        case 0: case 1: r.tmax[i] = INFINITY; break;
        case 2: r.tmin[i] = rnd_in(0.0f, r.tmax[i]); break;
        default: break;
        }
    }
    return r;
}

/* Shadow rays: per-ray origins around the box toward random points of a
 * small ball (a light) just above it, [1e-4, 1]: ends that cluster, which
 * kdr_trace_batch walks far end first (kd_batch_far_first). */
rayset rays_light(const kdr_bounds *b) {
    rayset r = rays_alloc("light", 0);
    float c[3], rad = 0.0f;
    for (int k = 0; k < 3; k++) {
        c[k] = 0.5f * (b->min[k] + b->max[k]);
        rad += (b->max[k] - b->min[k]) * (b->max[k] - b->min[k]);
    }
    rad = 0.03f * sqrtf(rad);
    c[1] = b->max[1] + 4.0f * rad;
    for (size_t i = 0; i < r.n; i++) {
        float *o = r.org + 3 * i, *d = r.dir + 3 * i, u[3];
        rnd_point(b, 0.0f, o);
        rnd_dir(u);
        for (int k = 0; k < 3; k++)
            d[k] = c[k] + rad * u[k] - o[k];
        r.tmin[i] = 1e-4f;
        r.tmax[i] = 1.0f;
    }
    return r;
}

void rays_every_set(const scene_src *src, const kdr_scene *s, const kdr_bounds *b,
                    int integer_org, rayset out[RAYS_NSETS]) {
    int k = 0;
    out[k++] = rays_camera(b);
    out[k++] = rays_omni(b);
    out[k++] = rays_distinct(b);
    out[k++] = rays_nearby(b);
    out[k++] = rays_zeros(b, integer_org);
    out[k++] = rays_on_splits(s, b, 0);
    out[k++] = rays_on_splits(s, b, 1);
    out[k++] = rays_intervals(b, 0);
    out[k++] = rays_intervals(b, 1);
    out[k++] = rays_aimed(src, b, 0);
    out[k++] = rays_aimed(src, b, 1);
    out[k++] = rays_slack_planes(s, b);
    out[k++] = rays_ends_on_splits(s, b);
    out[k++] = rays_light(b);
}

int rays_check_every_set(const scene_src *src, int integer_org, rays_check_fn check) {
    kdr_scene *s = NULL;
    if (kdr_scene_build(src->tris, src->ntris, NULL, NULL, NULL, &s) != KDR_OK) {
        fprintf(stderr, "FAIL: building %s\n", src->name);
        return 1;
    }
    kdr_bounds bb;
    kdr_scene_bounds(s, &bb);
    rayset sets[RAYS_NSETS];
    rays_every_set(src, s, &bb, integer_org, sets);
    for (size_t k = 0; k < RAYS_NSETS; k++) {
        check(src->name, s, &sets[k]);
        rays_free(&sets[k]);
    }
    kdr_scene_free(s);
    return 0;
}
