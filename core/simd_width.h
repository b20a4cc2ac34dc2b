/*
 * simd_width.h — the one convention of every lane-width template in core/
 * (the N-rays triangle test kd_tri_nray.h, the one-ray N-triangles test
 * kd_tri_ntri_lanes.h, bundles, frusta, cone packets, the interleaved walk
 * kd_traverse_stream_lanes.h). A file that instantiates a template defines
 * KD_W (4, 8 or 16), includes this header, then
 * the template; to instantiate again at another width it redefines KD_W and
 * includes this header once more (no include guard: it first undefines what
 * it defined last time). It defines
 *   VF         the lane vector type (f4 or f8, core/simd.h)
 *   V(op)      the lane helper f4_op / f8_op (f16_op)
 *   VI, IV(op) the int32 lane vector and its helpers (8 and 16 lanes only)
 *   KD_WN(x)   a width-suffixed name: x4 / x8, so that both widths can live
 *              in one translation unit and profiles say which width ran
 *   KD_TARGET  the function attribute of the width (AVX2 for 8 lanes,
 *              KD_AVX512 for 16; the build has no -mavx2, so every 8-wide
 *              function carries it)
 *   KD_FN      the qualifiers of a template's helpers: static inline
 *              KD_TARGET
 *   KD_VALIGN  the alignment of a lane array that V(load) reads (32; 64
 *              for 16 lanes)
 * 8-wide code may only run after kdr_cpu_has_avx2() said yes, 16-wide code
 * after kd_cpu_has_avx512().
 */
#include "simd.h"

#undef VF
#undef V
#undef KD_WN
#undef KD_WN_
#undef KD_WN__
#undef KD_TARGET
#undef KD_FN
#undef KD_VALIGN

#undef VI
#undef IV

#if KD_W == 4
#define VF f4
#define V(op) f4_##op
#define KD_TARGET
#define KD_VALIGN 32
#elif KD_W == 8
#define VF f8
#define V(op) f8_##op
#define VI i8
#define IV(op) i8_##op
#define KD_TARGET KD_AVX2
#define KD_VALIGN 32
#elif KD_W == 16
#define VF f16
#define V(op) f16_##op
#define VI i16
#define IV(op) i16_##op
#define KD_TARGET KD_AVX512
#define KD_VALIGN 64
#else
#error "define KD_W as 4, 8 or 16 before including simd_width.h"
#endif

#define KD_WN__(x, w) x##w
#define KD_WN_(x, w) KD_WN__(x, w)
#define KD_WN(x) KD_WN_(x, KD_W)
#define KD_FN static inline KD_TARGET
