/*
 * kd_build.h — what the files of the SAH build share, and nothing else
 * includes: the event key, a node's event lists, a chosen split, the
 * builder's state, and the entry point of each stage.
 *
 * The build is split by concern:
 *   kd_build_events.c  event lists: the root's radix sort, the partition of
 *                      a node's lists into its children, the small sort and
 *                      merge of the straddlers' new events;
 *   kd_build_clip.c    clipping straddling triangles to the child boxes
 *                      ("perfect splits"), conservative in float;
 *   kd_build_sah.c     the split search: one SAH sweep per axis;
 *   kd_build.c         the recursion, the node and reference arrays, and the
 *                      public kdr_scene_build.
 *
 * An event is one 64-bit key: the order-preserving bits of its position
 * (high 32), its type (end < planar < start, bits 30-31) and its triangle
 * (low 30 bits), so that sorting keys sorts events by (position, type,
 * triangle).
 */
#ifndef KD_BUILD_H
#define KD_BUILD_H

#include <stdint.h>
#include <string.h>

#include "kd_internal.h"

#define KD_MAX_TRIS ((size_t)1 << 30) /* triangle ids fit 30 bits */

enum { EV_END = 0, EV_PLANAR = 1, EV_START = 2 };
enum { SIDE_BOTH = 0, SIDE_LEFT = 1, SIDE_RIGHT = 2 };

typedef uint64_t kd_event;

typedef struct ev_list {
    kd_event *e[3];
    size_t n[3];
    size_t ntri;
} ev_list;

typedef struct kd_split {
    int axis;
    float pos;
    int planar_left;
    float cost;
} kd_split;

typedef struct builder {
    const float *tris;
    kdr_build_opts o;
    int max_depth;
    uint8_t *side; /* per triangle, valid for the node being split */
    kd_event *lvl[KD_MAX_DEPTH + 1]; /* children of a node at depth d */
    size_t lvl_cap[KD_MAX_DEPTH + 1];
    uint32_t *both; /* straddlers of the node being split */
    size_t both_cap;
    kd_event *add; /* their new events */
    size_t add_cap;
    kd_node *nodes;
    size_t nnodes, cap_nodes;
    uint32_t *refs;
    size_t nrefs, cap_refs;
    uint64_t leaves, empty_leaves, depth_seen;
    double sah, inv_root_area;
    int err;
} builder;

/* ---- event keys ---------------------------------------------------------- */

static inline uint32_t float_key(float f) {
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

static inline float key_float(uint32_t k) {
    uint32_t u = (k & 0x80000000u) ? (k & 0x7fffffffu) : ~k;
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* pos + 0.0f turns -0.0 into +0.0 so equal positions share one key. */
static inline kd_event ev_make(float pos, unsigned type, uint32_t tri) {
    return ((uint64_t)float_key(pos + 0.0f) << 32) | ((uint64_t)type << 30) | tri;
}
static inline uint32_t ev_tri(kd_event e) { return (uint32_t)e & 0x3fffffffu; }
static inline unsigned ev_type(kd_event e) { return (unsigned)(e >> 30) & 3u; }
static inline uint32_t ev_key(kd_event e) { return (uint32_t)(e >> 32); }

/* Inputs are finite, so plain compares do; fminf/fmaxf are library calls
 * without -ffast-math. */
static inline float min3(float a, float b, float c) {
    float m = a < b ? a : b;
    return m < c ? m : c;
}
static inline float max3(float a, float b, float c) {
    float m = a > b ? a : b;
    return m > c ? m : c;
}

/* Appends the events of a triangle with bounds bb to dst[k] + n[k]. */
static inline void ev_add(kd_event *dst[3], size_t n[3], const kdr_bounds *bb,
                          uint32_t tri) {
    for (int k = 0; k < 3; k++) {
        if (bb->min[k] == bb->max[k]) {
            dst[k][n[k]++] = ev_make(bb->min[k], EV_PLANAR, tri);
        } else {
            dst[k][n[k]++] = ev_make(bb->min[k], EV_START, tri);
            dst[k][n[k]++] = ev_make(bb->max[k], EV_END, tri);
        }
    }
}

/* ---- kd_build_events.c ----------------------------------------------------- */

void kd_ev_free(ev_list *l);
/* LSD radix sort of n events by key (tmp holds n events). */
void kd_radix_sort(kd_event *a, kd_event *tmp, size_t n);
/* Sorts a few events (keys are unique). */
void kd_sort_events(kd_event *a, size_t n);
/* Splits the node's event lists into its children's, ch[0] below and ch[1]
 * above the plane, in the scratch buffer of this depth. */
int kd_split_events(builder *b, const ev_list *ev, const kd_split *s,
                    const kdr_bounds *box, const kdr_bounds cbox[2], int depth,
                    ev_list ch[2]);

/* ---- kd_build_clip.c ---------------------------------------------------------- */

/* Clips the nboth straddlers in b->both to both child boxes; their new
 * events go to add[0..2] (left) and add[3..5] (right), sorted. */
void kd_clip_both(builder *b, size_t nboth, const kdr_bounds *box,
                  const kd_split *s, const kdr_bounds cbox[2], kd_event *add[6],
                  size_t nadd[6], size_t ntri[2]);

/* ---- kd_build_sah.c -------------------------------------------------------------- */

/* The cheapest split of the node over all three axes; 0 if none. */
int kd_find_split(const builder *b, const kdr_bounds *box, const ev_list *ev,
                  kd_split *best);

#endif /* KD_BUILD_H */
