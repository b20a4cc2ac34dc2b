/*
 * kd_tri_ntri_lanes.h — the one-ray-against-KD_W-triangles watertight test,
 * written once for any lane count (template of kd_tri_ntri.h, which
 * instantiates it per width with the convention of simd_width.h, after
 * defining KD_WN(kd_ntri_load)(r, A, B, C): the transpose of rows
 * r[0..KD_W-1] into the vertices' x, y, z vectors). No include guard.
 *
 * Every lane performs exactly the float operations of kd_tri_intersect
 * (core/kd_tri.h) in the same order, so keep both in step.
 */
#include "kd_tri_t_lanes.h"

/* A ray's shear broadcast to KD_W lanes (built once per ray). */
typedef struct KD_WN(kd_ntri_pre) {
    VF ox, oy, oz, sx, sy, sz;
    int kx, ky, kz;
} KD_WN(kd_ntri_pre);

KD_FN void KD_WN(kd_ntri_pre_init)(const kd_ray_pre *p, KD_WN(kd_ntri_pre) *q) {
    q->ox = V(set1)(p->org[p->kx]);
    q->oy = V(set1)(p->org[p->ky]);
    q->oz = V(set1)(p->org[p->kz]);
    q->sx = V(set1)(p->sx);
    q->sy = V(set1)(p->sy);
    q->sz = V(set1)(p->sz);
    q->kx = p->kx;
    q->ky = p->ky;
    q->kz = p->kz;
}

/* The scalar double-precision recomputation for the lanes in `lanes`. */
KD_FN void KD_WN(kd_ntri_exact)(int lanes, VF ax, VF ay, VF bx, VF by, VF cx, VF cy,
                     VF *Ue, VF *Ve, VF *We) {
    _Alignas(sizeof(VF)) float s[9][KD_W];
    const VF in[9] = {ax, ay, bx, by, cx, cy, *Ue, *Ve, *We};
    for (int k = 0; k < 9; k++)
        V(store)(s[k], in[k]);
    for (int j = 0; j < KD_W; j++) {
        if (!((lanes >> j) & 1))
            continue;
        kd_tri_edges_exact(s[0][j], s[1][j], s[2][j], s[3][j], s[4][j], s[5][j],
                           &s[6][j], &s[7][j], &s[8][j]);
    }
    *Ue = V(load)(s[6]);
    *Ve = V(load)(s[7]);
    *We = V(load)(s[8]);
}

/*
 * Tests the triangles whose rows are r[0..KD_W-1] (rows may repeat);
 * returns the lane mask of hits with tmin <= t <= tmax and their t, scaled
 * edge functions Ve, We (kd_tri.h's V, W) and det (u = Ve / det,
 * v = We / det, as kd_tri_intersect computes
 * them). When no lane passes the edge tests, the outputs are zero and t is
 * never computed.
 */
KD_FN int KD_WN(kd_ntri_test)(const KD_WN(kd_ntri_pre) *p, const float *const r[KD_W],
                        VF tmin, VF tmax, VF *t_out, VF *V_out, VF *W_out,
                        VF *det_out) {
    VF A[3], B[3], C[3];
    KD_WN(kd_ntri_load)(r, A, B, C);
    /* vertices relative to the origin */
    const VF Ax = V(sub)(A[p->kx], p->ox), Ay = V(sub)(A[p->ky], p->oy),
             Az0 = V(sub)(A[p->kz], p->oz);
    const VF Bx = V(sub)(B[p->kx], p->ox), By = V(sub)(B[p->ky], p->oy),
             Bz0 = V(sub)(B[p->kz], p->oz);
    const VF Cx = V(sub)(C[p->kx], p->ox), Cy = V(sub)(C[p->ky], p->oy),
             Cz0 = V(sub)(C[p->kz], p->oz);
    /* shear into ray space */
    const VF ax = V(sub)(Ax, V(mul)(p->sx, Az0)),
             ay = V(sub)(Ay, V(mul)(p->sy, Az0));
    const VF bx = V(sub)(Bx, V(mul)(p->sx, Bz0)),
             by = V(sub)(By, V(mul)(p->sy, Bz0));
    const VF cx = V(sub)(Cx, V(mul)(p->sx, Cz0)),
             cy = V(sub)(Cy, V(mul)(p->sy, Cz0));
    /* scaled barycentrics */
    VF Ue = V(sub)(V(mul)(cx, by), V(mul)(cy, bx));
    VF Ve = V(sub)(V(mul)(ax, cy), V(mul)(ay, cx));
    VF We = V(sub)(V(mul)(bx, ay), V(mul)(by, ax));
    const VF zero = V(set1)(0.0f);
    const int zl = V(bits)(
        V(or)(V(or)(V(eq)(Ue, zero), V(eq)(Ve, zero)), V(eq)(We, zero)));
    if (zl)
        KD_WN(kd_ntri_exact)(zl, ax, ay, bx, by, cx, cy, &Ue, &Ve, &We);
    const VF neg =
        V(or)(V(or)(V(lt)(Ue, zero), V(lt)(Ve, zero)), V(lt)(We, zero));
    const VF pos =
        V(or)(V(or)(V(gt)(Ue, zero), V(gt)(Ve, zero)), V(gt)(We, zero));
    const VF det = V(add)(V(add)(Ue, Ve), We);
    const VF ok = V(andnot)(V(or)(V(and)(neg, pos), V(eq)(det, zero)),
                            V(seti)(-1));
    if (!V(bits)(ok)) {
        *t_out = *V_out = *W_out = *det_out = zero;
        return 0;
    }
    const VF az = V(mul)(p->sz, Az0), bz = V(mul)(p->sz, Bz0),
             cz = V(mul)(p->sz, Cz0);
    const VF T =
        V(add)(V(add)(V(mul)(Ue, az), V(mul)(Ve, bz)), V(mul)(We, cz));
    const VF t = KD_WN(kd_lanes_t)(ok, T, det, Ue, Ve, We, Az0, Bz0, Cz0, p->sz);
    *t_out = t;
    *V_out = Ve;
    *W_out = We;
    *det_out = det;
    return V(bits)(V(and)(ok, V(and)(V(le)(tmin, t), V(le)(t, tmax))));
}
