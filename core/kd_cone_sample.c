/*
 * kd_cone_sample.c — THE definition of a cone-shadow sample ray
 * (kdr_shadow_ray). Every shadow mode and every test oracle draws its rays
 * from here, so "cone traversal equals per-ray sampling" can be checked bit
 * for bit.
 *
 * Sampling: uniform in solid angle over the cap of half-angle
 * alpha = asin(r/D) around the direction to the light centre. cos(theta) is
 * 1D-stratified (sample s takes stratum [s, s+1)/n with a hashed jitter) and
 * the azimuth follows a golden-ratio lattice rotated per (point, light): a
 * spherical-Fibonacci-like point set that is well spread for any n, not only
 * squares. All randomness is a counter-based hash of (seed, point, light,
 * sample): no state, thread-safe, reproducible.
 *
 * Offset (shared/API.md v1.1): the distance is a bound on the float error
 * of the point itself (KDR_OFFSET_AUTO: a few ulps of its largest
 * coordinate, as renderers offset spawned rays, so far-flung parts of a
 * scene get starts as close to their surfaces as parts near the origin) or
 * epsilon times the scene diagonal (v1). With a normal the start moves
 * along the normal AS GIVEN: the caller says which side of the surface the
 * point is on, and a normal facing away from the light means the surface
 * itself is between them (v1 turned normals toward the light; the contract
 * does not). Each coordinate is rounded away from the point (pbrt-v3 does
 * the same), so the start lies at least the offset off the plane through
 * the point. Without normals (or with a zero normal) each ray's origin
 * moves the same distance along the ray itself.
 */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>

#include "kd_cone.h"
#include "kd_internal.h"
#include "simd.h"

/* Odd constants that decorrelate the hash inputs (golden ratio, splitmix). */
#define SAMPLE_KEY_POINT 0x9e3779b97f4a7c15ull
#define SAMPLE_KEY_LIGHT 0xc2b2ae3d27d4eb4full
#define SAMPLE_KEY_SAMPLE 0x165667b19e3779f9ull
#define SAMPLE_KEY_PHI 0x27d4eb2f165667c5ull
#define GOLDEN_FRACTION 0.6180339887498948482
#define TWO_PI 6.283185307179586477

/* splitmix64's finaliser: a bijective 64-bit mix. */
static uint64_t mix64(uint64_t z) {
    z += 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/* Uniform in [0, 1) with 53 bits. */
static double unit_double(uint64_t h) { return (double)(h >> 11) * 0x1p-53; }

static int finite3(const float *v) {
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

/* Duff et al.'s branch-free orthonormal basis around a unit vector. */
static void basis_around(const double n[3], double b1[3], double b2[3]) {
    const double sign = n[2] >= 0.0 ? 1.0 : -1.0;
    const double a = -1.0 / (sign + n[2]);
    const double b = n[0] * n[1] * a;
    b1[0] = 1.0 + sign * n[0] * n[0] * a;
    b1[1] = sign * b;
    b1[2] = -sign * n[0];
    b2[0] = b;
    b2[1] = sign + n[1] * n[1] * a;
    b2[2] = -n[1];
}

/* The offset distance of point p (kdr_shadow_offset); not finite only for
 * an epsilon * diagonal that overflows. */
static float offset_of(const kdr_scene *scene, const kdr_shadow_query *q,
                       const float *p) {
    if (q->offset == KDR_OFFSET_DIAGONAL)
        return q->epsilon * kdr_scene_diagonal(scene);
    float m = FLT_MIN; /* ulp(FLT_MIN) = 2^-149 for points nearer 0 */
    for (int k = 0; k < 3; k++)
        m = fmaxf(m, fabsf(p[k]));
    int e;
    frexpf(m, &e); /* m = f * 2^e, f in [0.5, 1): ulp(m) = 2^(e-24) */
    return ldexpf((float)KDR_OFFSET_AUTO_ULPS, e - 24);
}

/* Moves the apex off along the normal as given, each coordinate rounded
 * away from the point; returns 0 when there is no usable normal and the
 * offset must go along each ray instead. */
static int offset_along_normal(const float *nrm, float off, float apex[3]) {
    double n[3] = {nrm[0], nrm[1], nrm[2]};
    double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(len > 0.0))
        return 0;
    for (int k = 0; k < 3; k++) {
        const double want = (double)apex[k] + n[k] * ((double)off / len);
        float a = (float)want;
        if ((double)a < want && want > apex[k])
            a = nextafterf(a, INFINITY);
        else if ((double)a > want && want < apex[k])
            a = nextafterf(a, -INFINITY);
        apex[k] = a;
    }
    return 1;
}

/* cos and sin of 2 pi frac(s GOLDEN_FRACTION), the unrotated azimuth
 * lattice, for every sample index the contract allows (samples <= 4096):
 * filled once per process, so a sample's azimuth costs two products of
 * this row with the frame's rotation instead of a sincos. */
static _Alignas(32) double g_cos[KD_SHADOW_MAX_SAMPLES], g_sin[KD_SHADOW_MAX_SAMPLES];
static pthread_once_t g_lattice_once = PTHREAD_ONCE_INIT;

static void lattice_fill(void) {
    for (uint32_t s = 0; s < KD_SHADOW_MAX_SAMPLES; s++) {
        const double phi = (double)s * GOLDEN_FRACTION;
        const double a = TWO_PI * (phi - (double)(int64_t)phi);
        g_cos[s] = cos(a);
        g_sin[s] = sin(a);
    }
}

int kd_shadow_frame_init(const kdr_scene *scene, const kdr_shadow_query *q,
                         size_t i, size_t l, kd_shadow_frame *f) {
    const float *p = q->points + 3 * i;
    const kdr_sphere_light *light = &q->lights[l];
    if (!finite3(p) || !finite3(light->center) || !isfinite(light->radius) ||
        !(light->radius > 0.0f))
        return KDR_EINVAL;
    if (q->offset != KDR_OFFSET_AUTO &&
        (q->offset != KDR_OFFSET_DIAGONAL || !isfinite(q->epsilon) || q->epsilon < 0.0f))
        return KDR_EINVAL;
    if (q->normals && !finite3(q->normals + 3 * i))
        return KDR_EINVAL;
    const float off = offset_of(scene, q, p);
    if (!isfinite(off))
        return KDR_EINVAL;
    for (int k = 0; k < 3; k++) {
        f->apex[k] = p[k];
        f->center[k] = light->center[k];
    }
    f->along = off;
    if (q->normals && offset_along_normal(q->normals + 3 * i, off, f->apex))
        f->along = 0.0f;
    if (!finite3(f->apex))
        return KDR_EINVAL;
    double w[3], d2 = 0.0;
    for (int k = 0; k < 3; k++) {
        w[k] = f->center[k] - (double)f->apex[k];
        d2 += w[k] * w[k];
    }
    f->radius = light->radius;
    f->dist = sqrt(d2);
    if (!(f->dist > f->radius) || !isfinite(f->dist))
        return KDR_EINVAL;
    for (int k = 0; k < 3; k++) {
        f->axis[k] = w[k] / f->dist;
        f->oc[k] = w[k];
    }
    f->near_c = (f->dist - f->radius) * (f->dist + f->radius);
    basis_around(f->axis, f->b1, f->b2);
    f->sin_a = f->radius / f->dist;
    const double cos_a = sqrt((1.0 - f->sin_a) * (1.0 + f->sin_a));
    f->one_minus_cos = f->sin_a * f->sin_a / (1.0 + cos_a);
    f->key = mix64(mix64(mix64(q->seed) ^ (i * SAMPLE_KEY_POINT)) ^
                   (l * SAMPLE_KEY_LIGHT));
    f->phi_shift = unit_double(mix64(f->key ^ SAMPLE_KEY_PHI));
    pthread_once(&g_lattice_once, lattice_fill);
    f->cos_shift = cos(TWO_PI * f->phi_shift);
    f->sin_shift = sin(TWO_PI * f->phi_shift);
    return KDR_OK;
}

/* Distance along dir (|dir| ~ 1) from the apex to the sphere's near side.
 * The discriminant uses |oc x dir|^2 (Lagrange) so grazing samples at the
 * cone's rim do not cancel catastrophically. */
static double near_surface(const kd_shadow_frame *f, const float dir[3]) {
    const double *oc = f->oc;
    double dd[3];
    for (int k = 0; k < 3; k++)
        dd[k] = dir[k];
    const double qq = dd[0] * dd[0] + dd[1] * dd[1] + dd[2] * dd[2];
    const double b = oc[0] * dd[0] + oc[1] * dd[1] + oc[2] * dd[2];
    const double cx = oc[1] * dd[2] - oc[2] * dd[1];
    const double cy = oc[2] * dd[0] - oc[0] * dd[2];
    const double cz = oc[0] * dd[1] - oc[1] * dd[0];
    double disc = qq * f->radius * f->radius - (cx * cx + cy * cy + cz * cz);
    if (disc < 0.0) /* a rim sample rounded just outside: tangent point */
        disc = 0.0;
    return f->near_c / (b + sqrt(disc));
}

double kd_shadow_frame_phase(const kd_shadow_frame *f, uint32_t s) {
    const double phi = (double)s * GOLDEN_FRACTION + f->phi_shift;
    /* phi is in [0, 4097): truncation is floor, without libm's call */
    return phi - (double)(int64_t)phi;
}

void kd_shadow_frame_ray(const kd_shadow_frame *f, uint32_t s,
                         uint32_t nsamples, kdr_ray *out) {
    const uint64_t h = mix64(f->key ^ ((uint64_t)s * SAMPLE_KEY_SAMPLE));
    const double u = ((double)s + unit_double(h)) / (double)nsamples;
    const double one_minus_ct = u * f->one_minus_cos;
    const double ct = 1.0 - one_minus_ct;
    const double st = sqrt(one_minus_ct * (2.0 - one_minus_ct));
    /* the azimuth 2 pi (frac(s g) + phi_shift), which is 2 pi times
     * kd_shadow_frame_phase up to a whole turn, by the angle sum: within a
     * few 1e-16 rad of it, far inside the 1e-6 rad that sub-cones allow
     * for the rounding of directions */
    const double cphi = g_cos[s] * f->cos_shift - g_sin[s] * f->sin_shift;
    const double sphi = g_sin[s] * f->cos_shift + g_cos[s] * f->sin_shift;
    const double cp = cphi * st, sp = sphi * st;
    /* axis, b1, b2 are orthonormal and ct^2 + st^2 = 1: d is a unit
     * vector up to double rounding, far below the float rounding of dir */
    for (int k = 0; k < 3; k++)
        out->dir[k] = (float)(ct * f->axis[k] + cp * f->b1[k] + sp * f->b2[k]);
    const double reach = near_surface(f, out->dir) - (double)f->along;
    for (int k = 0; k < 3; k++)
        out->org[k] = f->apex[k] + f->along * out->dir[k];
    out->tmin = 0.0f;
    out->tmax = reach > 0.0 ? (float)reach : 0.0f;
}

/* Four samples s[0..4) of kd_shadow_frame_ray at once: every lane
 * performs the scalar function's double operations in its order (no FMA
 * in the build; sqrt, division and the float conversions round as the
 * scalar ones; max(0, disc) keeps a NaN as the scalar test does), so the
 * rays are the scalar ones bit for bit. The hash stays scalar (64-bit
 * products). */
KD_AVX2 static void frame_rays4(const kd_shadow_frame *f, const uint32_t s[4],
                                uint32_t nsamples, kdr_ray *out) {
    _Alignas(32) double sd[4], jit[4], lc[4], ls[4];
    f4 lo[4], hi[4]; /* org x, y, z, dir x; dir y, z, tmin, tmax */
    for (int j = 0; j < 4; j++) {
        sd[j] = (double)s[j];
        jit[j] = unit_double(mix64(f->key ^ ((uint64_t)s[j] * SAMPLE_KEY_SAMPLE)));
        lc[j] = g_cos[s[j]];
        ls[j] = g_sin[s[j]];
    }
    const d4 zero = d4_zero();
    const d4 u = d4_div(d4_add(d4_load(sd), d4_load(jit)), d4_set1((double)nsamples));
    const d4 omc = d4_mul(u, d4_set1(f->one_minus_cos));
    const d4 ct = d4_sub(d4_set1(1.0), omc);
    const d4 st = d4_sqrt(d4_mul(omc, d4_sub(d4_set1(2.0), omc)));
    const d4 cs = d4_set1(f->cos_shift), sn = d4_set1(f->sin_shift);
    const d4 lcv = d4_load(lc), lsv = d4_load(ls);
    const d4 cphi = d4_sub(d4_mul(lcv, cs), d4_mul(lsv, sn));
    const d4 sphi = d4_add(d4_mul(lsv, cs), d4_mul(lcv, sn));
    const d4 cp = d4_mul(cphi, st), sp = d4_mul(sphi, st);
    d4 dd[3];
    for (int k = 0; k < 3; k++) {
        const d4 d = d4_add(d4_add(d4_mul(ct, d4_set1(f->axis[k])), d4_mul(cp, d4_set1(f->b1[k]))),
                            d4_mul(sp, d4_set1(f->b2[k])));
        const f4 df = d4_to_f4(d);
        if (k == 0)
            lo[3] = df;
        else
            hi[k - 1] = df;
        dd[k] = d4_from_f4(df);
        lo[k] = f4_add(f4_set1(f->apex[k]), f4_mul(f4_set1(f->along), df));
    }
    /* near_surface */
    const d4 oc0 = d4_set1(f->oc[0]), oc1 = d4_set1(f->oc[1]), oc2 = d4_set1(f->oc[2]);
    const d4 qq = d4_add(d4_add(d4_mul(dd[0], dd[0]), d4_mul(dd[1], dd[1])), d4_mul(dd[2], dd[2]));
    const d4 b = d4_add(d4_add(d4_mul(oc0, dd[0]), d4_mul(oc1, dd[1])), d4_mul(oc2, dd[2]));
    const d4 cx = d4_sub(d4_mul(oc1, dd[2]), d4_mul(oc2, dd[1]));
    const d4 cy = d4_sub(d4_mul(oc2, dd[0]), d4_mul(oc0, dd[2]));
    const d4 cz = d4_sub(d4_mul(oc0, dd[1]), d4_mul(oc1, dd[0]));
    const d4 rr = d4_set1(f->radius);
    d4 disc = d4_sub(d4_mul(d4_mul(qq, rr), rr),
                     d4_add(d4_add(d4_mul(cx, cx), d4_mul(cy, cy)), d4_mul(cz, cz)));
    disc = d4_max(zero, disc);
    const d4 reach = d4_sub(d4_div(d4_set1(f->near_c), d4_add(b, d4_sqrt(disc))),
                            d4_set1((double)f->along));
    hi[2] = f4_set1(0.0f);
    hi[3] = d4_to_f4(d4_and(d4_gt(reach, zero), reach));
    /* kdr_ray is eight floats: org, dir, tmin, tmax */
    _Static_assert(sizeof(kdr_ray) == 8 * sizeof(float), "kdr_ray layout");
    float *const rows[4] = {(float *)(void *)&out[0], (float *)(void *)&out[1],
                            (float *)(void *)&out[2], (float *)(void *)&out[3]};
    f4_to_rows4(lo, rows, 0);
    f4_to_rows4(hi, rows, 4);
}

void kd_shadow_frame_rays(const kd_shadow_frame *f, const uint32_t *idx, uint32_t s0,
                          uint32_t count, uint32_t nsamples, kdr_ray *out) {
    uint32_t i = 0;
    if (__builtin_cpu_supports("avx2"))
        for (; i + 4 <= count; i += 4) {
            uint32_t s[4];
            for (int j = 0; j < 4; j++)
                s[j] = idx ? idx[i + (uint32_t)j] : s0 + i + (uint32_t)j;
            frame_rays4(f, s, nsamples, out + i);
        }
    for (; i < count; i++)
        kd_shadow_frame_ray(f, idx ? idx[i] : s0 + i, nsamples, out + i);
}

/* Spreads the low 16 bits of x to the even bits. */
static uint32_t spread16(uint32_t x) {
    x &= 0xffffu;
    x = (x | x << 8) & 0x00ff00ffu;
    x = (x | x << 4) & 0x0f0f0f0fu;
    x = (x | x << 2) & 0x33333333u;
    return (x | x << 1) & 0x55555555u;
}

static int by_key(const void *a, const void *b) {
    const uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

int kd_shadow_disc_order(uint32_t n, uint32_t *order) {
    uint64_t *key = malloc(n * sizeof *key);
    if (!key)
        return KDR_ENOMEM;
    pthread_once(&g_lattice_once, lattice_fill);
    for (uint32_t s = 0; s < n; s++) {
        const double r = sqrt(((double)s + 0.5) / (double)n);
        const uint32_t x = (uint32_t)((r * g_cos[s] + 1.0) * 32767.0);
        const uint32_t y = (uint32_t)((r * g_sin[s] + 1.0) * 32767.0);
        key[s] = (uint64_t)(spread16(x) | spread16(y) << 1) << 32 | s;
    }
    qsort(key, n, sizeof *key, by_key);
    for (uint32_t s = 0; s < n; s++)
        order[s] = (uint32_t)key[s];
    free(key);
    return KDR_OK;
}

int kdr_shadow_ray(const kdr_scene *scene, const kdr_shadow_query *q, size_t i,
                   size_t l, uint32_t s, kdr_ray *out) {
    if (!scene || !q || !out || !q->points || !q->lights || i >= q->n ||
        l >= q->nlights || q->samples < 1 || q->samples > KD_SHADOW_MAX_SAMPLES ||
        s >= q->samples)
        return KDR_EINVAL;
    kd_shadow_frame f;
    int rc = kd_shadow_frame_init(scene, q, i, l, &f);
    if (rc != KDR_OK)
        return rc;
    kd_shadow_frame_ray(&f, s, q->samples, out);
    return KDR_OK;
}
