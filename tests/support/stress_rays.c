/*
 * stress_rays.c — the adversarial rays of stress.h. Aimed rays use
 * dir = target - origin, so the aim point sits at t = 1 and the interval
 * tests can put tmin or tmax exactly on it.
 */
#include <float.h>
#include <math.h>
#include <string.h>

#include "stress.h"

/* Fraction of the scene extent added around it for random origins. */
#define ORIGIN_PAD 0.2f
/* Denormal-direction rays keep one component at least this large. */
#define DIR_MIN_NORMAL 0x1p-20f

typedef struct ray_ctx {
    const stress_scene *s;
    stress_rng rng;
    float lo[3], hi[3];
} ray_ctx;

static const char *const ray_names[STRESS_NRAYS] = {
    "random",        "at_vertices", "at_edges",  "axis",
    "from_vertices", "denormal",    "intervals", "mixed",
};

const char *stress_ray_name(stress_ray_kind kind) {
    return (kind >= 0 && kind < STRESS_NRAYS) ? ray_names[kind] : "?";
}

static float urange(ray_ctx *c, float lo, float hi) {
    return lo + (hi - lo) * stress_rng_float(&c->rng);
}

static size_t pick(ray_ctx *c, size_t n) {
    return n ? (size_t)(stress_rng_next(&c->rng) % n) : 0;
}

static void scene_box(ray_ctx *c) {
    const stress_scene *s = c->s;
    for (int k = 0; k < 3; k++) {
        c->lo[k] = s->ntris ? INFINITY : -1.0f;
        c->hi[k] = s->ntris ? -INFINITY : 1.0f;
    }
    for (size_t i = 0; i < 3 * s->ntris; i++)
        for (int k = 0; k < 3; k++) {
            c->lo[k] = fminf(c->lo[k], s->tris[3 * i + k]);
            c->hi[k] = fmaxf(c->hi[k], s->tris[3 * i + k]);
        }
    for (int k = 0; k < 3; k++) {
        const float pad = ORIGIN_PAD * (c->hi[k] - c->lo[k]) + 1e-3f;
        c->lo[k] -= pad;
        c->hi[k] += pad;
    }
}

static void random_origin(ray_ctx *c, float o[3]) {
    for (int k = 0; k < 3; k++)
        o[k] = urange(c, c->lo[k], c->hi[k]);
}

static void random_vertex(ray_ctx *c, size_t first, size_t count, float p[3]) {
    const float *t = c->s->tris + 9 * (first + pick(c, count));
    memcpy(p, t + 3 * pick(c, 3), 3 * sizeof(float));
}

static void random_edge_mid(ray_ctx *c, size_t first, size_t count,
                            float p[3]) {
    const float *t = c->s->tris + 9 * (first + pick(c, count));
    const size_t a = pick(c, 3), b = (a + 1) % 3;
    for (int k = 0; k < 3; k++)
        p[k] = (t[3 * a + k] + t[3 * b + k]) * 0.5f;
}

static void basic(kdr_ray *r) {
    r->tmin = 0.0f;
    r->tmax = INFINITY;
}

static void fix_zero_dir(ray_ctx *c, kdr_ray *r) {
    if (r->dir[0] == 0.0f && r->dir[1] == 0.0f && r->dir[2] == 0.0f)
        stress_rng_dir(&c->rng, r->dir);
}

/* Origin either anywhere around the scene or at a random power-of-two
 * distance from the target, so both far and close approaches occur. */
static void aim(ray_ctx *c, const float target[3], kdr_ray *r) {
    if (stress_rng_next(&c->rng) & 1) {
        random_origin(c, r->org);
    } else {
        float d[3], ext = 0.0f;
        stress_rng_dir(&c->rng, d);
        for (int k = 0; k < 3; k++)
            ext = fmaxf(ext, c->hi[k] - c->lo[k]);
        const float dist = ldexpf(ext, -(int)pick(c, 16));
        for (int k = 0; k < 3; k++)
            r->org[k] = target[k] + dist * d[k];
    }
    for (int k = 0; k < 3; k++)
        r->dir[k] = target[k] - r->org[k];
    basic(r);
    fix_zero_dir(c, r);
}

static void ray_random(ray_ctx *c, kdr_ray *r) {
    random_origin(c, r->org);
    stress_rng_dir(&c->rng, r->dir);
    basic(r);
}

static void ray_at_vertex(ray_ctx *c, kdr_ray *r) {
    float p[3];
    random_vertex(c, 0, c->s->ntris, p);
    aim(c, p, r);
}

static void ray_at_edge(ray_ctx *c, kdr_ray *r) {
    float p[3];
    random_edge_mid(c, 0, c->s->ntris, p);
    aim(c, p, r);
}

/* A coordinate likely to be a split plane or a face plane. */
static float nice_coord(ray_ctx *c, int k) {
    float v[3];
    switch (pick(c, 5)) {
    case 0: return 0.0f;
    case 1: return 0.25f * (float)((int)pick(c, 9) - 4);
    case 2: return pick(c, 2) ? c->lo[k] : c->hi[k];
    case 3: random_vertex(c, 0, c->s->ntris, v); return v[k];
    default: return urange(c, c->lo[k], c->hi[k]);
    }
}

static void ray_axis(ray_ctx *c, kdr_ray *r) {
    const int a = (int)pick(c, 3);
    for (int k = 0; k < 3; k++) {
        r->org[k] = k == a ? urange(c, c->lo[k], c->hi[k]) : nice_coord(c, k);
        r->dir[k] = (stress_rng_next(&c->rng) & 1) ? -0.0f : 0.0f;
    }
    r->dir[a] = (stress_rng_next(&c->rng) & 1) ? -1.0f : 1.0f;
    if (pick(c, 4) == 0) /* a 45-degree diagonal in an axis plane */
        r->dir[(a + 1) % 3] = (stress_rng_next(&c->rng) & 1) ? -1.0f : 1.0f;
    basic(r);
}

static void ray_from_vertex(ray_ctx *c, kdr_ray *r) {
    if (stress_rng_next(&c->rng) & 1)
        random_vertex(c, 0, c->s->ntris, r->org);
    else
        random_edge_mid(c, 0, c->s->ntris, r->org);
    stress_rng_dir(&c->rng, r->dir);
    basic(r);
}

static float odd_component(ray_ctx *c) {
    const float sign = (stress_rng_next(&c->rng) & 1) ? -1.0f : 1.0f;
    switch (pick(c, 3)) {
    case 0: return sign * 0.0f;
    case 1: return sign * ldexpf(1.0f, -127 - (int)pick(c, 23)); /* denormal */
    default: return sign * FLT_MIN;
    }
}

static void ray_denormal(ray_ctx *c, kdr_ray *r) {
    if (stress_rng_next(&c->rng) & 1)
        ray_at_vertex(c, r);
    else
        ray_axis(c, r);
    const int k = (int)pick(c, 3);
    r->dir[k] = odd_component(c);
    if (pick(c, 2))
        r->dir[(k + 1) % 3] = odd_component(c);
    /* keep one ordinary component: a direction of FLT_MIN size
     * underflows Embree's (and any renderer's) products */
    const float big = fmaxf(fabsf(r->dir[0]), fmaxf(fabsf(r->dir[1]),
                                                      fabsf(r->dir[2])));
    if (big < DIR_MIN_NORMAL)
        r->dir[(k + 2) % 3] = (stress_rng_next(&c->rng) & 1) ? -1.0f : 1.0f;
}

static void ray_interval(ray_ctx *c, kdr_ray *r) {
    if (stress_rng_next(&c->rng) & 1)
        ray_at_vertex(c, r);
    else
        ray_at_edge(c, r);
    switch (pick(c, 6)) {
    case 0: r->tmin = r->tmax = 1.0f; break;
    case 1: r->tmax = 1.0f; break;
    case 2: r->tmin = 1.0f; break;
    case 3: r->tmax = nextafterf(1.0f, 0.0f); break;
    case 4: r->tmin = nextafterf(1.0f, 2.0f); break;
    default: r->tmin = r->tmax = urange(c, 0.0f, 2.0f); break;
    }
}

typedef void (*ray_fn)(ray_ctx *, kdr_ray *);
static const ray_fn ray_fns[STRESS_NRAYS - 1] = {
    ray_random, ray_at_vertex,  ray_at_edge,  ray_axis,
    ray_from_vertex, ray_denormal, ray_interval,
};

void stress_rays(const stress_scene *s, stress_ray_kind kind, uint64_t seed,
                 size_t n, kdr_ray *out) {
    ray_ctx c = {.s = s};
    stress_rng_seed(&c.rng, seed ^ ((uint64_t)kind << 40) ^ 0x5eedull);
    scene_box(&c);
    for (size_t i = 0; i < n; i++) {
        stress_ray_kind k = kind;
        if (k == STRESS_RAYS_MIXED || k < 0 || k > STRESS_RAYS_MIXED)
            k = (stress_ray_kind)pick(&c, STRESS_NRAYS - 1);
        if (s->ntris == 0)
            k = STRESS_RAYS_RANDOM;
        ray_fns[k](&c, &out[i]);
    }
}

size_t stress_inside_rays(const stress_scene *s, uint64_t seed, size_t n,
                          kdr_ray *out) {
    if (s->nclosed == 0)
        return 0;
    ray_ctx c = {.s = s};
    stress_rng_seed(&c.rng, seed ^ 0x1a5d1d3ull);
    scene_box(&c);
    for (size_t i = 0; i < n; i++) {
        const stress_closed *m = &s->closed[pick(&c, s->nclosed)];
        kdr_ray *r = &out[i];
        float p[3];
        memcpy(r->org, m->inside, sizeof r->org);
        basic(r);
        switch (pick(&c, 3)) {
        case 0: random_vertex(&c, m->first, m->count, p); break;
        case 1: random_edge_mid(&c, m->first, m->count, p); break;
        default: stress_rng_dir(&c.rng, r->dir); continue;
        }
        for (int k = 0; k < 3; k++)
            r->dir[k] = p[k] - r->org[k];
        fix_zero_dir(&c, r);
    }
    return n;
}
