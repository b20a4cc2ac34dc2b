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
 *   kd_build_sah.c     the split searches: the exact SAH sweep per axis
 *                      over events, and min-max bins for binned nodes;
 *   kd_build_avx512.c  AVX-512 twins of the sweep's two passes and of the
 *                      small sort's last step (same results, bit for bit);
 *   kd_build_bin.c     binned nodes: the root's prims, their partition, and
 *                      the events of a node that turns exact;
 *   kd_build_par.c     tasks on several threads, and the stitch of the
 *                      pieces into the scene's node and reference arrays;
 *   kd_build.c         the recursion and the public kdr_scene_build.
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

#define KD_MAX_TRIS ((size_t)1 << 30)  /* triangle ids fit 30 bits */
#define KD_MAX_NODES ((size_t)1 << 30) /* above-child index fits 30 bits */

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

/* A triangle in a binned node: its bounds inside the node (clipped, for a
 * triangle that straddled a plane above) and its number. */
typedef struct kd_prim {
    float lo[3], hi[3];
    uint32_t tri;
} kd_prim;

/* A binned node's triangles, in triangle-number order, and their bounds. */
typedef struct kd_prims {
    kd_prim *p; /* malloc'ed, owned by whoever builds the node */
    size_t n;
    kdr_bounds tight;
} kd_prims;

/* One piece of the tree, written depth-first by one task. A leaf whose
 * u.first is KD_LINK stands for the whole subtree in fragment kd_count()
 * (kd_build_par.c puts the pieces together). */
typedef struct kd_frag {
    kd_node *nodes;
    size_t nnodes, cap_nodes;
    uint32_t *refs;
    size_t nrefs, cap_refs;
    size_t links;
} kd_frag;

#define KD_LINK UINT32_MAX

/* Fragments and the stitched arrays hold the build's interior format,
 * bits = (above_child << 2) | axis, until kd_layout() (kd_layout.c)
 * rewrites it into the traversal format of kd_internal.h. */
static inline uint32_t kd_build_above(const kd_node *n) { return n->bits >> 2; }

typedef struct kd_pool kd_pool;

/* One worker's view of the build: the shared inputs (read-only), its own
 * scratch buffers, and the fragment it is writing. */
typedef struct builder {
    const float *tris;
    size_t ntris;
    kdr_build_opts o;
    int max_depth;
    size_t spawn_min; /* a child with at least this many triangles is
                         handed to another worker (pool != NULL) */
    kd_pool *pool;    /* NULL: everything on this thread */
    uint8_t *side; /* per triangle, valid for the node being split */
    kd_event *stack; /* the children's lists of the nodes on the path
                        being built, last split on top (kd_split_events) */
    size_t stack_cap, stack_top; /* in events */
    uint32_t *both; /* straddlers of the node being split */
    size_t both_cap;
    kd_event *add; /* their new events */
    size_t add_cap;
    kd_event *old; /* a split's old events of one axis, before the merge */
    size_t old_cap;
    uint32_t *groups; /* the split search's event groups (kd_groups) */
    size_t groups_cap;
    int avx512; /* the AVX-512 kernels of kd_build_avx512.c may run */
    int huge;   /* scratch of at least KD_SCRATCH_HUGE_MIN bytes in huge
                   pages (kd_scratch_alloc): exact-from-the-root builds */
    kd_frag *frag;
    int err;
    double cpu_ms; /* this worker's thread CPU time in the build */
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

static inline double box_area(const kdr_bounds *b) {
    double dx = (double)b->max[0] - b->min[0];
    double dy = (double)b->max[1] - b->min[1];
    double dz = (double)b->max[2] - b->min[2];
    return 2.0 * (dx * dy + dy * dz + dz * dx);
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

/* ---- kd_mem.c (build scratch) ------------------------------------------------- */

/* Scratch memory of at least KD_SCRATCH_HUGE_MIN bytes in transparent huge
 * pages where the system has them (malloc otherwise); free() it. */
void *kd_scratch_alloc(size_t bytes);

/* ---- kd_build_events.c ----------------------------------------------------- */

/* LSD radix sort of n events by key (tmp holds n events). */
void kd_radix_sort(kd_event *a, kd_event *tmp, size_t n);
/* The same, the sorted keys left in out (n events) and a clobbered. */
void kd_radix_sort_into(kd_event *a, kd_event *out, size_t n);
/* Sorts a few events (keys are unique); avx512: with kd_rank_sort_avx512. */
void kd_sort_events(kd_event *a, size_t n, int avx512);
/* Sorts n <= RANK_MAX events (keys unique): each one's place is the number
 * of smaller keys, counted 8 keys per compare. */
#define RANK_MAX 32
void kd_rank_sort_avx512(kd_event *a, size_t n);
/* kd_sort_events on AVX-512 CPUs: quicksort steps partitioned by compress
 * for lists of at most 1024 events, then kd_rank_sort_avx512. */
void kd_sort_events_avx512(kd_event *a, size_t n);
/* Copies each event of in[0..n) to w[0] and/or w[1] as its triangle's side
 * says, in order, and advances them. Without branches: SIDE_LEFT is bit 0
 * and SIDE_RIGHT bit 1 (with sd == SIDE_LEFT and sd == SIDE_RIGHT gcc 12
 * saw that only one can hold and branched); every event is written to both
 * and each pointer advances by its bit (the slot after a list's last
 * event may be written, but never beyond n slots from where it began).
 * kd_build_events.c's split and the tail of kd_partition_avx512. */
static inline void kd_partition(const kd_event *in, size_t n, const uint8_t *side,
                                kd_event *w[2]) {
    kd_event *w0 = w[0], *w1 = w[1];
    for (size_t i = 0; i < n; i++) {
        const kd_event e = in[i];
        const unsigned sd = side[ev_tri(e)];
        *w0 = e;
        *w1 = e;
        w0 += sd & 1u;
        w1 += sd >> 1;
    }
    w[0] = w0;
    w[1] = w1;
}
/* kd_partition 8 events at a time (AVX-512), the same result. */
void kd_partition_avx512(const kd_event *in, size_t n, const uint8_t *side,
                         kd_event *w[2]);
/* Splits the node's event lists into its children's, ch[0] below and ch[1]
 * above the plane, on top of the worker's stack (b->stack), or in a block
 * of their own (*own, to free) when the stack is full. The caller pops
 * them (b->stack_top back to its value before the call) once both
 * children's subtrees are built. */
int kd_split_events(builder *b, const ev_list *ev, const kd_split *s,
                    const kdr_bounds *box, const kdr_bounds cbox[2], ev_list ch[2],
                    kd_event **own);

/* Scratch of bytes above the top of the worker's stack, valid until the
 * next push (nothing is pushed); NULL when the stack has no such room. */
void *kd_stack_scratch(builder *b, size_t bytes);
/* Makes an empty stack hold at least KD_STACK_SLACK * events (a task's
 * first node, before anything is pushed); on failure it stays as it is. */
void kd_stack_reserve(builder *b, size_t events);

/* ---- kd_build_clip.c ---------------------------------------------------------- */

/* The bounds of the parts of tri inside cbox[0] and cbox[1], the halves of
 * box split at pos on axis; bit s of the result is set when side s keeps
 * something (conservative: never drops a touched side). */
unsigned kd_clip_tri(const float *tri, const kdr_bounds *box, int axis, float pos,
                     const kdr_bounds cbox[2], kdr_bounds bb[2]);
/* kd_clip_tri with a vertex per AVX vector (AVX-512 CPUs only): the same
 * sides and bounds bit for bit (test_core_build_simd compares them). */
unsigned kd_clip_tri_avx512(const float *tri, const kdr_bounds *box, int axis, float pos,
                            const kdr_bounds cbox[2], kdr_bounds bb[2]);

/* Clips the nboth straddlers in b->both to both child boxes; their new
 * events go to add[0..2] (left) and add[3..5] (right), sorted. */
void kd_clip_both(builder *b, size_t nboth, const kdr_bounds *box,
                  const kd_split *s, const kdr_bounds cbox[2], kd_event *add[6],
                  size_t nadd[6], size_t ntri[2]);

/* ---- the split search's kernels (kd_build_sah.c, kd_build_avx512.c) ---- */

/* The SAH terms of the planes of one axis of a node. */
typedef struct sah_ctx {
    float min, max;      /* node extent on the axis */
    float cap, perim;    /* child area = 2 (cap + len * perim) */
    float inv_area;      /* 1 / node area */
    float isect, trav, bonus;
} sah_ctx;

/* One axis' events folded into groups of equal position, as four arrays
 * (room for KD_GROUP_PAD more than the events: the vector kernels store
 * whole vectors): the group's key, the number of end and of planar events
 * up to and including it (cumulative over the list), and the index after
 * its last event. With cumulative counts every group's SAH terms follow
 * from its own and the previous group's entries, so the groups can be
 * evaluated in any order, or 16 at a time. */
#define KD_GROUP_PAD 16
typedef struct kd_groups {
    uint32_t *key, *ends, *planars, *end;
} kd_groups;

/* Folds n sorted events into groups; returns their count. */
size_t kd_group_events(const kd_event *e, size_t n, const kd_groups *g);
size_t kd_group_events_avx512(const kd_event *e, size_t n, const kd_groups *g);
/* Evaluates the SAH at every group strictly inside the node on axis k and
 * keeps the cheapest in *best when it beats best->cost; the first of equal
 * costs wins (the order of a sweep that replaces only on "<"). */
void kd_eval_groups(const sah_ctx *c, int k, const kd_groups *g, size_t ng,
                    size_t ntri, kd_split *best);
void kd_eval_groups_avx512(const sah_ctx *c, int k, const kd_groups *g, size_t ng,
                           size_t ntri, kd_split *best);

/* ---- kd_build_sah.c -------------------------------------------------------------- */

/* The cheapest split of the node over all three axes; 0 if none, or
 * without memory (then b->err is set). */
int kd_find_split(builder *b, const kdr_bounds *box, const ev_list *ev,
                  kd_split *best);

/* The cheapest split of a binned node (n > exact_max): SAH at the
 * boundaries of KD_BINS equal bins over the triangles' tight bounds, from
 * min-max bin counts, plus the planes that cut off the empty space around
 * them; 0 if no plane lies strictly inside the box. */
int kd_bin_split(const builder *b, const kdr_bounds *box, const kd_prims *p,
                 kd_split *best);

/* ---- kd_build_bin.c ------------------------------------------------------------ */

/* The root's prims: every non-degenerate triangle with its bounds. */
int kd_root_prims(const float *tris, size_t ntris, size_t nvalid, kd_prims *out);
/* Splits a binned node's prims into its children's (new arrays, in the same
 * order); straddlers are clipped to each side (kd_clip_tri). */
int kd_bin_partition(const builder *b, const kdr_bounds *box, const kd_split *s,
                     const kdr_bounds cbox[2], const kd_prims *in, kd_prims out[2]);
/* The sorted event lists of a node from its prims, in one malloc'ed block
 * (*block, free it) = where a binned subtree turns exact. */
int kd_prims_to_events(const kd_prims *p, ev_list *ev, kd_event **block, int avx512);

/* ---- kd_build_par.c --------------------------------------------------------------- */

/* A piece of work for one worker: a subtree to build (binned from prims,
 * or exact from event lists it owns), or one axis of the root to sort. */
typedef enum { KD_TASK_BINNED, KD_TASK_EXACT, KD_TASK_SORT } kd_task_kind;

typedef struct kd_task {
    kd_task_kind kind;
    kdr_bounds box;
    int depth, bad;
    kd_prims prims;  /* BINNED */
    ev_list ev;      /* EXACT: lists in block; SORT: e[0], n[0] to sort,
                        e[1] room for n[0] more (the radix sort's) */
    kd_event *block; /* owned, freed when the task is done (may be NULL) */
    int axis;        /* SORT of the root (n_out set): make the events of
                        this axis from the triangles in e[0] first */
    int skip_degenerate; /* ... testing each triangle (some are) */
    size_t *n_out;   /* SORT of the root: receives the count; the sorted
                        events go to e[1] */
    kd_frag *frag;   /* where BINNED and EXACT tasks write */
} kd_task;

/* Builds the tree of root (a BINNED or EXACT task on frags[0]) with the
 * caller and threads-1 helper threads; `proto` holds the shared inputs. A
 * SORT task list (nsort, may be 0) runs first. On success *frags holds
 * the pieces (kd_stitch them, kd_frags_free). cpu_ms[0..1] receive the
 * CPU time of the busiest thread and of all of them (for the log). */
int kd_build_run(const builder *proto, int threads, kd_task *sort, int nsort,
                 kd_task *root, kd_frag ***frags, size_t *nfrags, double cpu_ms[2]);
/* Hands t (copied) to another worker; *frag receives the fragment it will
 * write. Returns KDR_OK, or an error (then the caller builds t itself). */
int kd_spawn(builder *b, const kd_task *t, uint32_t *frag);
/* Nonzero once some worker failed: the others stop early. */
int kd_build_failed(const builder *b);
/* Runs one task on worker b (kd_build.c). */
void kd_run_task(builder *b, kd_task *t);
/* Puts the fragments together depth-first into s->nodes and s->refs and
 * fills the tree statistics; frees nothing. */
int kd_stitch(kd_frag **frags, size_t nfrags, const kdr_build_opts *o,
              kdr_scene *s);
void kd_frags_free(kd_frag **frags, size_t nfrags);

#endif /* KD_BUILD_H */
