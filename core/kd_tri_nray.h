/*
 * kd_tri_nray.h — the watertight ray-triangle test of core/kd_tri.h for N
 * rays against ONE triangle, one ray per lane (bundles, frusta, cone
 * packets). Its twin for one ray against N triangles is kd_tri_ntri.h.
 *
 * This is a template with the convention of simd_width.h: define KD_W,
 * include simd_width.h, then this file (kd_traverse_bundle.h,
 * kd_frustum_trav.h and kd_cone_packet.h do). Names carry the width:
 * kd_nray_test4, kd_nray_test8, ...
 *
 * Bit-identity with kd_tri_intersect is the whole point: each lane performs
 * exactly the scalar float operations in the scalar order. Lanes may shear
 * along different axes (a hemisphere of directions has several dominant
 * axes), so each lane picks its own vertex components with masks; picking
 * is exact, so only the arithmetic that follows has to match (4 lanes:
 * masked selects; 8 and 16 lanes: one permute per component). The rare
 * double-precision fallback (an edge function exactly 0) runs per lane in
 * scalar code, as in kd_tri.h.
 */
#include "kd_tri.h"
#include "simd.h"
#include "kd_tri_t_lanes.h"

/* Per-lane shear of a bundle (kd_ray_pre, transposed). */
typedef struct KD_WN(kd_nray_pre) {
    VF ox, oy, oz;                    /* org[kx], org[ky], org[kz] */
    VF sx, sy, sz;
    VF kx0, kx1, ky0, ky1, kz0, kz1;  /* lane masks: kx == 0, kx == 1, ... */
#if KD_W >= 8
    VF idx[9]; /* int32 indices of A, B, C's x, y, z in tri[0..7] / tri[1..8] */
#endif
    int uniform;                      /* every used lane shears alike */
    int kx, ky, kz;                   /* the shared axes when uniform */
} KD_WN(kd_nray_pre);

/* Transposes the scalar precomputations of the lanes in `used`; unused
 * lanes copy lane `ref` so they compute harmless numbers. */
KD_FN void KD_WN(kd_nray_pre_init)(KD_WN(kd_nray_pre) *p, const kd_ray_pre *pre, int used,
                            int ref) {
    _Alignas(KD_VALIGN) float f[12][KD_W];
    int uniform = 1;
    for (int j = 0; j < KD_W; j++) {
        const kd_ray_pre *r = &pre[(used >> j) & 1 ? j : ref];
        uniform &= r->kz == pre[ref].kz && r->kx == pre[ref].kx;
        f[0][j] = r->org[r->kx];
        f[1][j] = r->org[r->ky];
        f[2][j] = r->org[r->kz];
        f[3][j] = r->sx;
        f[4][j] = r->sy;
        f[5][j] = r->sz;
        for (int a = 0; a < 2; a++) {
            f[6 + a][j] = r->kx == a ? -1.0f : 0.0f;
            f[8 + a][j] = r->ky == a ? -1.0f : 0.0f;
            f[10 + a][j] = r->kz == a ? -1.0f : 0.0f;
        }
    }
    VF *dst[12] = {&p->ox, &p->oy, &p->oz, &p->sx,  &p->sy,  &p->sz,
                   &p->kx0, &p->kx1, &p->ky0, &p->ky1, &p->kz0, &p->kz1};
    for (int k = 0; k < 12; k++)
        *dst[k] = V(load)(f[k]);
    for (int k = 6; k < 12; k++) /* -1.0f has the sign bit: make full masks */
        *dst[k] = V(signmask)(*dst[k]);
#if KD_W >= 8
    _Alignas(KD_VALIGN) int32_t ix[9][KD_W];
    for (int j = 0; j < KD_W; j++) {
        const kd_ray_pre *r = &pre[(used >> j) & 1 ? j : ref];
        const int k[3] = {r->kx, r->ky, r->kz};
        for (int c = 0; c < 3; c++) {
            ix[c][j] = k[c];         /* A: tri[0..7] */
            ix[3 + c][j] = 3 + k[c]; /* B: tri[0..7] */
            ix[6 + c][j] = 5 + k[c]; /* C: tri[1..8] */
        }
    }
    for (int c = 0; c < 9; c++)
        p->idx[c] = V(load)((const float *)ix[c]);
#endif
    p->uniform = uniform;
    p->kx = pre[ref].kx;
    p->ky = pre[ref].ky;
    p->kz = pre[ref].kz;
}

/* Lanes' value of axis k where m0 / m1 flag k == 0 / k == 1 (else 2). */
KD_FN VF KD_WN(kd_nray_axis)(VF m0, VF m1, VF x, VF y, VF z) {
    return V(sel)(m0, x, V(sel)(m1, y, z));
}

/*
 * kd_ray_precompute for all lanes at once, from SoA origins and directions
 * (divisions and selects only, so every lane gets the scalar bits). `used`
 * lanes decide `uniform`; the others must hold finite, non-zero directions.
 */
KD_FN void KD_WN(kd_nray_setup)(KD_WN(kd_nray_pre) *p, const VF org[3], const VF dir[3],
                             int used) {
    const VF absm = V(seti)(0x7fffffff);
    const VF ax = V(and)(dir[0], absm), ay = V(and)(dir[1], absm),
             az = V(and)(dir[2], absm);
    /* the dominant axis, first one on ties (kd_ray_precompute's order) */
    const VF ge_xy = V(le)(ay, ax);
    const VF z0 = V(and)(ge_xy, V(le)(az, ax));
    const VF z1 = V(andnot)(ge_xy, V(le)(az, ay));
    const VF z2 = V(andnot)(V(or)(z0, z1), V(seti)(-1));
    const VF dkz = KD_WN(kd_nray_axis)(z0, z1, dir[0], dir[1], dir[2]);
    const VF swap = V(lt)(dkz, V(set1)(0.0f));
    /* kx = kz + 1, ky = kz + 2 (mod 3), exchanged when dir[kz] < 0 */
    p->kx0 = V(sel)(swap, z1, z2), p->kx1 = V(sel)(swap, z2, z0);
    p->ky0 = V(sel)(swap, z2, z1), p->ky1 = V(sel)(swap, z0, z2);
    p->kz0 = z0, p->kz1 = z1;
    p->ox = KD_WN(kd_nray_axis)(p->kx0, p->kx1, org[0], org[1], org[2]);
    p->oy = KD_WN(kd_nray_axis)(p->ky0, p->ky1, org[0], org[1], org[2]);
    p->oz = KD_WN(kd_nray_axis)(z0, z1, org[0], org[1], org[2]);
    p->sx = V(div)(KD_WN(kd_nray_axis)(p->kx0, p->kx1, dir[0], dir[1], dir[2]), dkz);
    p->sy = V(div)(KD_WN(kd_nray_axis)(p->ky0, p->ky1, dir[0], dir[1], dir[2]), dkz);
    p->sz = V(div)(V(set1)(1.0f), dkz);
#if KD_W >= 8
    for (int c = 0; c < 3; c++) {
        const VF m0 = c == 0 ? p->kx0 : c == 1 ? p->ky0 : z0;
        const VF m1 = c == 0 ? p->kx1 : c == 1 ? p->ky1 : z1;
        p->idx[c] = KD_WN(kd_nray_axis)(m0, m1, V(seti)(0), V(seti)(1), V(seti)(2));
        p->idx[3 + c] = KD_WN(kd_nray_axis)(m0, m1, V(seti)(3), V(seti)(4), V(seti)(5));
        p->idx[6 + c] = KD_WN(kd_nray_axis)(m0, m1, V(seti)(5), V(seti)(6), V(seti)(7));
    }
#endif
    /* uniform: every used lane has the same kz and the same swap */
    const int b0 = V(bits)(z0) & used, b1 = V(bits)(z1) & used,
              bs = V(bits)(swap) & used;
    p->uniform = (b0 == 0 || b0 == used) && (b1 == 0 || b1 == used) &&
                 (bs == 0 || bs == used);
    const int kz = b0 ? 0 : b1 ? 1 : 2, sw = bs != 0;
    p->kz = kz;
    p->kx = sw ? (kz + 2) % 3 : (kz + 1) % 3;
    p->ky = sw ? (kz + 1) % 3 : (kz + 2) % 3;
}

/* Component k of vertex v, per lane, where m0/m1 flag k == 0 / k == 1. */
KD_FN VF KD_WN(kd_nray_pick)(VF m0, VF m1, const float *v) {
    return V(sel)(m0, V(set1)(v[0]), V(sel)(m1, V(set1)(v[1]), V(set1)(v[2])));
}

/* The scalar double-precision recomputation, for the lanes in `lanes`. */
KD_FN void KD_WN(kd_nray_exact)(int lanes, VF ax, VF ay, VF bx, VF by, VF cx, VF cy,
                         VF *U, VF *Vv, VF *W) {
    _Alignas(KD_VALIGN) float s[9][KD_W];
    const VF in[9] = {ax, ay, bx, by, cx, cy, *U, *Vv, *W};
    for (int k = 0; k < 9; k++)
        V(store)(s[k], in[k]);
    for (int j = 0; j < KD_W; j++) {
        if (!((lanes >> j) & 1))
            continue;
        kd_tri_edges_exact(s[0][j], s[1][j], s[2][j], s[3][j], s[4][j], s[5][j],
                           &s[6][j], &s[7][j], &s[8][j]);
    }
    *U = V(load)(s[6]);
    *Vv = V(load)(s[7]);
    *W = V(load)(s[8]);
}

/*
 * Tests triangle tri against the lanes in mask act; returns the mask of
 * lanes that hit with tmin <= t <= tmax, their t, and the scaled V, W and
 * det (u = V / det, v = W / det: callers divide only for the lanes whose
 * best hit changes, as the scalar test divides only on a hit).
 */
KD_FN VF KD_WN(kd_nray_test_raw)(const KD_WN(kd_nray_pre) *p, const float *tri, VF act,
                          VF tmin, VF tmax, VF *t_out, VF *V_out, VF *W_out,
                          VF *det_out) {
    VF Ax, Ay, Az0, Bx, By, Bz0, Cx, Cy, Cz0;
    if (p->uniform) {
        Ax = V(sub)(V(set1)(tri[0 + p->kx]), p->ox);
        Ay = V(sub)(V(set1)(tri[0 + p->ky]), p->oy);
        Az0 = V(sub)(V(set1)(tri[0 + p->kz]), p->oz);
        Bx = V(sub)(V(set1)(tri[3 + p->kx]), p->ox);
        By = V(sub)(V(set1)(tri[3 + p->ky]), p->oy);
        Bz0 = V(sub)(V(set1)(tri[3 + p->kz]), p->oz);
        Cx = V(sub)(V(set1)(tri[6 + p->kx]), p->ox);
        Cy = V(sub)(V(set1)(tri[6 + p->ky]), p->oy);
        Cz0 = V(sub)(V(set1)(tri[6 + p->kz]), p->oz);
    } else {
#if KD_W >= 8
#if KD_W == 8
        const VF lo = f8_loadu(tri), hi = f8_loadu(tri + 1);
#else /* the same 8 floats in the low lanes; indices stay below 8 */
        const VF lo = f16_load8u(tri), hi = f16_load8u(tri + 1);
#endif
        Ax = V(sub)(V(permute)(lo, p->idx[0]), p->ox);
        Ay = V(sub)(V(permute)(lo, p->idx[1]), p->oy);
        Az0 = V(sub)(V(permute)(lo, p->idx[2]), p->oz);
        Bx = V(sub)(V(permute)(lo, p->idx[3]), p->ox);
        By = V(sub)(V(permute)(lo, p->idx[4]), p->oy);
        Bz0 = V(sub)(V(permute)(lo, p->idx[5]), p->oz);
        Cx = V(sub)(V(permute)(hi, p->idx[6]), p->ox);
        Cy = V(sub)(V(permute)(hi, p->idx[7]), p->oy);
        Cz0 = V(sub)(V(permute)(hi, p->idx[8]), p->oz);
#else
        Ax = V(sub)(KD_WN(kd_nray_pick)(p->kx0, p->kx1, tri + 0), p->ox);
        Ay = V(sub)(KD_WN(kd_nray_pick)(p->ky0, p->ky1, tri + 0), p->oy);
        Az0 = V(sub)(KD_WN(kd_nray_pick)(p->kz0, p->kz1, tri + 0), p->oz);
        Bx = V(sub)(KD_WN(kd_nray_pick)(p->kx0, p->kx1, tri + 3), p->ox);
        By = V(sub)(KD_WN(kd_nray_pick)(p->ky0, p->ky1, tri + 3), p->oy);
        Bz0 = V(sub)(KD_WN(kd_nray_pick)(p->kz0, p->kz1, tri + 3), p->oz);
        Cx = V(sub)(KD_WN(kd_nray_pick)(p->kx0, p->kx1, tri + 6), p->ox);
        Cy = V(sub)(KD_WN(kd_nray_pick)(p->ky0, p->ky1, tri + 6), p->oy);
        Cz0 = V(sub)(KD_WN(kd_nray_pick)(p->kz0, p->kz1, tri + 6), p->oz);
#endif
    }
    /* shear into ray space */
    const VF ax = V(sub)(Ax, V(mul)(p->sx, Az0)), ay = V(sub)(Ay, V(mul)(p->sy, Az0));
    const VF bx = V(sub)(Bx, V(mul)(p->sx, Bz0)), by = V(sub)(By, V(mul)(p->sy, Bz0));
    const VF cx = V(sub)(Cx, V(mul)(p->sx, Cz0)), cy = V(sub)(Cy, V(mul)(p->sy, Cz0));
    /* scaled barycentrics */
    VF U = V(sub)(V(mul)(cx, by), V(mul)(cy, bx));
    VF Vv = V(sub)(V(mul)(ax, cy), V(mul)(ay, cx));
    VF W = V(sub)(V(mul)(bx, ay), V(mul)(by, ax));
    const VF zero = V(set1)(0.0f);
    VF z = V(or)(V(or)(V(eq)(U, zero), V(eq)(Vv, zero)), V(eq)(W, zero));
    int zl = V(bits)(V(and)(z, act));
    if (zl)
        KD_WN(kd_nray_exact)(zl, ax, ay, bx, by, cx, cy, &U, &Vv, &W);
    VF neg = V(or)(V(or)(V(lt)(U, zero), V(lt)(Vv, zero)), V(lt)(W, zero));
    VF pos = V(or)(V(or)(V(gt)(U, zero), V(gt)(Vv, zero)), V(gt)(W, zero));
    VF ok = V(andnot)(V(and)(neg, pos), act);
    const VF det = V(add)(V(add)(U, Vv), W);
    ok = V(andnot)(V(eq)(det, zero), ok);
    if (!V(bits)(ok)) {
        *t_out = *V_out = *W_out = *det_out = zero;
        return ok;
    }
    const VF az = V(mul)(p->sz, Az0), bz = V(mul)(p->sz, Bz0), cz = V(mul)(p->sz, Cz0);
    const VF T = V(add)(V(add)(V(mul)(U, az), V(mul)(Vv, bz)), V(mul)(W, cz));
    const VF t = KD_WN(kd_lanes_t)(ok, T, det, U, Vv, W, Az0, Bz0, Cz0, p->sz);
    ok = V(and)(ok, V(and)(V(le)(tmin, t), V(le)(t, tmax)));
    *t_out = t;
    *V_out = Vv;
    *W_out = W;
    *det_out = det;
    return ok;
}

/* The same with u, v computed for every hit lane. */
KD_FN VF KD_WN(kd_nray_test)(const KD_WN(kd_nray_pre) *p, const float *tri, VF act,
                             VF tmin, VF tmax, VF *t_out, VF *u_out, VF *v_out) {
    VF Vv, W, det;
    VF ok = KD_WN(kd_nray_test_raw)(p, tri, act, tmin, tmax, t_out, &Vv, &W, &det);
    *u_out = *v_out = V(set1)(0.0f);
    if (V(bits)(ok)) {
        *u_out = V(div)(Vv, det);
        *v_out = V(div)(W, det);
    }
    return ok;
}
