/*
 * kd_tri_t_lanes.h — the hit distance t = T / det of the lane-wise triangle
 * tests (kd_tri_nray.h: N rays against one triangle, the frustum's eye test
 * in kd_frustum_trav.h; kd_tri_ntri_lanes.h: one ray against N triangles),
 * with kd_tri_intersect's recomputation of a t whose T may have underflowed
 * (kd_tri_t_exact, core/kd_tri.h), so every lane keeps the scalar t bit for
 * bit.
 *
 * A width template (simd_width.h's convention) that two other templates
 * include, possibly in one translation unit at one width: it is guarded per
 * width, so each width is defined once.
 */
#include "kd_tri.h"

#if (KD_W == 4 && !defined(KD_TRI_T_LANES_4)) || \
    (KD_W == 8 && !defined(KD_TRI_T_LANES_8)) || \
    (KD_W == 16 && !defined(KD_TRI_T_LANES_16))
#if KD_W == 4
#define KD_TRI_T_LANES_4
#elif KD_W == 8
#define KD_TRI_T_LANES_8
#else
#define KD_TRI_T_LANES_16
#endif

/* kd_tri_t_exact for the lanes in `lanes`: returns t with those lanes
 * replaced. Rare (a product of T below FLT_MIN), so one lane at a time. */
KD_FN VF KD_WN(kd_lanes_t_exact)(int lanes, VF U, VF Vv, VF W, VF Az0, VF Bz0, VF Cz0,
                                 VF sz, VF det, VF t) {
    _Alignas(sizeof(VF)) float s[9][KD_W]; /* V(load) needs the vector's own alignment */
    const VF in[9] = {U, Vv, W, Az0, Bz0, Cz0, sz, det, t};
    for (int k = 0; k < 9; k++)
        V(store)(s[k], in[k]);
    for (int j = 0; j < KD_W; j++)
        if ((lanes >> j) & 1)
            s[8][j] = kd_tri_t_exact(s[0][j], s[1][j], s[2][j], s[3][j], s[4][j],
                                     s[5][j], s[6][j], s[7][j], s[8][j]);
    return V(load)(s[8]);
}

/* t = T / det on every lane; the lanes of `ok` (those that passed the edge
 * tests) whose |T| is under KD_TRI_T_EXACT_BELOW get kd_tri_intersect's
 * recomputation. */
KD_FN VF KD_WN(kd_lanes_t)(VF ok, VF T, VF det, VF U, VF Vv, VF W, VF Az0, VF Bz0,
                           VF Cz0, VF sz) {
    const VF t = V(div)(T, det);
    const VF tiny = V(lt)(V(andnot)(V(set1)(-0.0f), T), V(set1)(KD_TRI_T_EXACT_BELOW));
    const int tl = V(bits)(V(and)(ok, tiny));
    return tl ? KD_WN(kd_lanes_t_exact)(tl, U, Vv, W, Az0, Bz0, Cz0, sz, det, t) : t;
}

#endif
