/*
 * kd_image.c — a built scene as one flat buffer and back (kdray.h, "tree
 * images"). The tree cache (server/tree_cache.c) stores these buffers in
 * files and maps them at the next start instead of building; the core only
 * turns a scene into bytes and validated bytes into a scene, with no I/O.
 *
 * Layout (native little-endian, every section 64-byte aligned):
 *   [0, 64)     head: magic, format, endian mark, length, checksum of
 *               [64, length), node size, depth limit
 *   [64, 256)   body: counts, build options, bounds, tree statistics
 *   [256, ...)  triangles (36 B each), nodes (8 B), leaf lists (4 B)
 * A scene opened from an image points into the caller's buffer, so a
 * memory-mapped image is shared through the page cache by every process
 * that maps it. Opening trusts nothing: after the checksum, every count,
 * index, child link, depth and coordinate a traversal reads is checked,
 * so a corrupt image that happens to match its checksum still cannot make
 * a walk read out of bounds or overflow its stack.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "kd_internal.h"
#include "kd_traverse.h"

/* Every field of struct kdr_scene is carried below: arrays and counts as
 * sections, bounds/diagonal/stats in the body, root_mag and prefetch_leaves
 * re-derived (kd_layout_derive), borrowed set on open. See kd_internal.h. */
_Static_assert(sizeof(struct kdr_scene) == KD_SCENE_STRUCT_SIZE,
               "struct kdr_scene changed: carry the new field in kd_image.c "
               "(write and open), bump KD_IMAGE_FORMAT, then update "
               "KD_SCENE_STRUCT_SIZE in kd_internal.h");

/* Bump whenever the image bytes or the meaning of any node bit changes. */
#define KD_IMAGE_FORMAT 3u
#define KD_IMAGE_ENDIAN 0x01020304u
#define KD_IMAGE_HEAD 64u
#define KD_IMAGE_DATA 256u
#define KD_IMAGE_ALIGN 64u
/* Same limit as kd_build.c's KD_MAX_TRIS: triangle ids fit 30 bits. */
#define KD_IMAGE_MAX_TRIS ((uint64_t)1 << 30)

static const char kd_image_magic[8] = {'K', 'D', 'R', 'A', 'Y', 'T', 'R', 'E'};

typedef struct img_head {
    char magic[8];
    uint32_t format, endian;
    uint64_t length;
    uint64_t checksum; /* kdr_hash64 of bytes [64, length), seed = format */
    uint32_t node_size, max_depth;
    uint8_t pad[24];
} img_head;

typedef struct img_body {
    uint64_t ntris, nnodes, nrefs;
    float isect_cost, trav_cost, empty_bonus;
    int32_t max_depth, leaf_size, exact_max;
    float bounds[6], root[6], diagonal;
    uint64_t st_nodes, st_leaves, st_empty, st_depth, st_refs, st_bytes;
    double st_refs_per_leaf, st_sah, st_build_ms;
} img_body;

_Static_assert(sizeof(img_head) == KD_IMAGE_HEAD, "image head is 64 bytes");
_Static_assert(sizeof(img_body) <= KD_IMAGE_DATA - KD_IMAGE_HEAD, "image body fits");
_Static_assert(sizeof(kd_node) == 8, "nodes are 8 bytes");

/* ---- checksum ------------------------------------------------------------- */

#define H_M1 0x9E3779B97F4A7C15ull
#define H_M2 0xD6E8FEB86659FD93ull
#define H_M3 0xFF51AFD7ED558CCDull

static inline uint64_t rd64(const unsigned char *p) {
    uint64_t v;
    memcpy(&v, p, 8);
    return v;
}

/* Each step is a bijection of the lane for a fixed word and of the word for
 * a fixed lane, so any change to a single word always changes the lane. */
static inline uint64_t lane_step(uint64_t a, uint64_t w) {
    a = (a ^ w) * H_M1;
    return a ^ (a >> 29);
}

static inline uint64_t finish(uint64_t h) {
    h ^= h >> 33;
    h *= H_M3;
    h ^= h >> 29;
    h *= H_M2;
    return h ^ (h >> 32);
}

uint64_t kdr_hash64(const void *data, size_t len, uint64_t seed) {
    const unsigned char *p = data;
    /* four independent lanes keep four multiplies in flight */
    uint64_t a = seed ^ H_M2, b = seed + H_M1, c = ~seed, d = seed * H_M3 + 1;
    size_t i = 0;
    for (; i + 32 <= len; i += 32) {
        a = lane_step(a, rd64(p + i));
        b = lane_step(b, rd64(p + i + 8));
        c = lane_step(c, rd64(p + i + 16));
        d = lane_step(d, rd64(p + i + 24));
    }
    for (; i + 8 <= len; i += 8)
        a = lane_step(a, rd64(p + i));
    uint64_t tail = 0;
    for (size_t k = 0; i + k < len; k++)
        tail |= (uint64_t)p[i + k] << (8 * k);
    b = lane_step(b, tail);
    uint64_t h = lane_step((uint64_t)len, a);
    h = lane_step(h, b);
    h = lane_step(h, c);
    h = lane_step(h, d);
    return finish(h);
}

/* ---- sizes ------------------------------------------------------------------ */

static uint64_t align_up(uint64_t x) {
    return (x + KD_IMAGE_ALIGN - 1) & ~(uint64_t)(KD_IMAGE_ALIGN - 1);
}

typedef struct img_layout {
    uint64_t tris, nodes, refs, length;
} img_layout;

/* Counts are bounded by the caller first, so nothing here overflows. */
static img_layout layout_of(uint64_t ntris, uint64_t nnodes, uint64_t nrefs) {
    img_layout l;
    l.tris = KD_IMAGE_DATA;
    l.nodes = align_up(l.tris + 36 * ntris);
    l.refs = align_up(l.nodes + 8 * nnodes);
    l.length = align_up(l.refs + 4 * nrefs);
    return l;
}

size_t kdr_scene_image_size(const kdr_scene *s) {
    if (!s) return 0;
    return (size_t)layout_of(s->ntris, s->nnodes, s->nrefs).length;
}

static void opts_or_default(const kdr_build_opts *in, kdr_build_opts *out) {
    if (in)
        *out = *in;
    else
        kdr_build_opts_default(out);
}

/* ---- write -------------------------------------------------------------------- */

int kdr_scene_image_write(const kdr_scene *s, const kdr_build_opts *opts, void *buf,
                          size_t len) {
    if (!s || !buf) return KDR_EINVAL;
    const img_layout l = layout_of(s->ntris, s->nnodes, s->nrefs);
    if (len < l.length) return KDR_EINVAL;
    kdr_build_opts o;
    opts_or_default(opts, &o);
    unsigned char *p = buf;
    memset(p, 0, (size_t)l.length);
    img_body b = {
        .ntris = s->ntris,
        .nnodes = s->nnodes,
        .nrefs = s->nrefs,
        .isect_cost = o.isect_cost,
        .trav_cost = o.trav_cost,
        .empty_bonus = o.empty_bonus,
        .max_depth = o.max_depth,
        .leaf_size = o.leaf_size,
        .exact_max = o.exact_max,
        .diagonal = s->diagonal,
        .st_nodes = s->stats.nodes,
        .st_leaves = s->stats.leaves,
        .st_empty = s->stats.empty_leaves,
        .st_depth = s->stats.max_depth,
        .st_refs = s->stats.refs,
        .st_bytes = s->stats.bytes,
        .st_refs_per_leaf = s->stats.refs_per_leaf,
        .st_sah = s->stats.sah_cost,
        .st_build_ms = s->stats.build_ms,
    };
    memcpy(b.bounds, s->bounds.min, 12);
    memcpy(b.bounds + 3, s->bounds.max, 12);
    memcpy(b.root, s->root.min, 12);
    memcpy(b.root + 3, s->root.max, 12);
    memcpy(p + KD_IMAGE_HEAD, &b, sizeof b);
    if (s->ntris) memcpy(p + l.tris, s->tris, 36 * s->ntris);
    if (s->nnodes) memcpy(p + l.nodes, s->nodes, 8 * s->nnodes);
    if (s->nrefs) memcpy(p + l.refs, s->refs, 4 * s->nrefs);
    img_head h = {.format = KD_IMAGE_FORMAT,
                  .endian = KD_IMAGE_ENDIAN,
                  .length = l.length,
                  .node_size = sizeof(kd_node),
                  .max_depth = KD_MAX_DEPTH};
    memcpy(h.magic, kd_image_magic, sizeof h.magic);
    h.checksum = kdr_hash64(p + KD_IMAGE_HEAD, (size_t)(l.length - KD_IMAGE_HEAD),
                            KD_IMAGE_FORMAT);
    memcpy(p, &h, sizeof h);
    return KDR_OK;
}

/* ---- open ---------------------------------------------------------------------- */

static int all_finite(const float *f, size_t n) {
    for (size_t i = 0; i < n; i++)
        if (!isfinite(f[i])) return 0;
    return 1;
}

static int same_bits(const void *a, const void *b, size_t n) { return !memcmp(a, b, n); }

static int opts_match(const img_body *b, const kdr_build_opts *o) {
    return same_bits(&b->isect_cost, &o->isect_cost, 4) &&
           same_bits(&b->trav_cost, &o->trav_cost, 4) &&
           same_bits(&b->empty_bonus, &o->empty_bonus, 4) &&
           b->max_depth == o->max_depth && b->leaf_size == o->leaf_size &&
           b->exact_max == o->exact_max; /* not threads: same tree on any count */
}

typedef struct walk_item {
    uint32_t node;
    uint32_t depth;
    kdr_bounds box;
} walk_item;

/* The tree must be exactly what kd_build + kd_layout produce: nodes in
 * depth-first order (the below child is the next node, the above child
 * follows the below subtree), every node reached once, depth within the
 * walks' stacks, splits strictly inside their node's box, empty flags that
 * match the children, leaf lists in range and naming only non-degenerate
 * triangles, statistics that agree. A walk in preorder checks all of it
 * with a stack of KD_MAX_DEPTH + 2 entries and no allocation. */
static const char *check_tree(const kdr_scene *s) {
    walk_item st[KD_MAX_DEPTH + 2];
    size_t sp = 0, next = 0;
    uint64_t leaves = 0, empty = 0, depth_seen = 0, refs_seen = 0;
    st[sp++] = (walk_item){0, 0, s->bounds};
    while (sp > 0) {
        const walk_item it = st[--sp];
        if (it.node != next || next >= s->nnodes)
            return "tree nodes out of depth-first order";
        next++;
        const kd_node *n = &s->nodes[it.node];
        if (it.depth > depth_seen) depth_seen = it.depth;
        if (kd_is_leaf(n)) {
            const uint64_t first = n->u.first, count = kd_count(n);
            if (first + count > s->nrefs) return "leaf list out of range";
            for (uint64_t r = 0; r < count; r++) {
                const uint32_t prim = s->refs[first + r];
                if (prim >= s->ntris) return "leaf names a triangle out of range";
                if (kd_tri_degenerate(s->tris + 9 * (size_t)prim))
                    return "leaf names a zero-area triangle";
            }
            /* a wrong flat flag would let walks skip triangles they must test */
            if (kd_leaf_flat(n) != kd_layout_flat(s, n))
                return "flat-leaf flag disagrees with the leaf's triangles";
            leaves++;
            empty += count == 0;
            refs_seen += count;
            continue;
        }
        if (it.depth >= KD_MAX_DEPTH) return "tree deeper than the traversal stacks";
        const int k = kd_axis(n);
        const uint32_t above = kd_above(n);
        const float split = n->u.split;
        if (!(split > it.box.min[k] && split < it.box.max[k]))
            return "split outside its node";
        if ((size_t)it.node + 1 >= s->nnodes || above <= it.node + 1 ||
            above >= s->nnodes)
            return "child index out of range";
        const kd_node *below_n = &s->nodes[it.node + 1], *above_n = &s->nodes[above];
        const int eb = kd_is_leaf(below_n) && kd_count(below_n) == 0;
        const int ea = kd_is_leaf(above_n) && kd_count(above_n) == 0;
        if (kd_below_empty(n) != eb || kd_above_empty(n) != ea)
            return "empty-child flags disagree with the children";
        walk_item a = {above, it.depth + 1, it.box},
                  b = {it.node + 1, it.depth + 1, it.box};
        a.box.min[k] = split;
        b.box.max[k] = split;
        st[sp++] = a; /* popped after the whole below subtree */
        st[sp++] = b;
    }
    if (next != s->nnodes) return "tree nodes not all reachable";
    if (s->stats.nodes != s->nnodes || s->stats.leaves != leaves ||
        s->stats.empty_leaves != empty || s->stats.max_depth != depth_seen ||
        s->stats.refs != s->nrefs || refs_seen != s->nrefs)
        return "tree statistics disagree with the tree";
    return NULL;
}

static const char *check_body(const img_body *b, uint64_t len, const kdr_build_opts *o) {
    if (b->ntris > KD_IMAGE_MAX_TRIS || b->nnodes >= KD_LAYOUT_MAX_NODES ||
        b->nrefs > UINT32_MAX)
        return "counts over the core's limits";
    if (layout_of(b->ntris, b->nnodes, b->nrefs).length != len)
        return "sections do not match the image size";
    if (!opts_match(b, o)) return "built with other build options";
    if (!all_finite(b->bounds, 6) || !all_finite(b->root, 6) || !isfinite(b->diagonal) ||
        b->diagonal < 0.0f)
        return "non-finite bounds";
    for (int k = 0; k < 3; k++)
        if (!(b->root[k] <= b->bounds[k] && b->bounds[k] <= b->bounds[3 + k] &&
              b->bounds[3 + k] <= b->root[3 + k]))
            return "bounds out of order";
    if (b->nnodes == 0 && b->nrefs != 0) return "leaf lists without a tree";
    const uint64_t bytes = b->nnodes * sizeof(kd_node) + b->nrefs * 4 + 36 * b->ntris;
    if (b->st_bytes != bytes) return "tree statistics disagree with the sizes";
    return NULL;
}

int kdr_scene_image_open(const void *buf, size_t len, const kdr_build_opts *opts,
                         kdr_scene **out, const char **why) {
    const char *bad = NULL;
    const char *dummy;
    if (!why) why = &dummy;
    *why = NULL;
    if (!out || !buf) {
        *why = "no buffer";
        return KDR_EINVAL;
    }
    *out = NULL;
    if ((uintptr_t)buf % KD_IMAGE_ALIGN != 0) {
        *why = "buffer not 64-byte aligned";
        return KDR_EINVAL;
    }
    kdr_build_opts o;
    opts_or_default(opts, &o);
    const unsigned char *p = buf;
    img_head h;
    img_body b;
    if (len < KD_IMAGE_DATA) {
        *why = "truncated header";
        return KDR_EIMAGE;
    }
    memcpy(&h, p, sizeof h);
    memcpy(&b, p + KD_IMAGE_HEAD, sizeof b);
    if (memcmp(h.magic, kd_image_magic, sizeof h.magic) != 0)
        bad = "not a kdray tree image (magic)";
    else if (h.endian != KD_IMAGE_ENDIAN)
        bad = "other byte order";
    else if (h.format != KD_IMAGE_FORMAT || h.node_size != sizeof(kd_node) ||
             h.max_depth != KD_MAX_DEPTH)
        bad = "other image format version";
    else if (memcmp(h.pad, (const uint8_t[sizeof h.pad]){0}, sizeof h.pad) != 0)
        bad = "unknown header bytes";
    else if (h.length != len)
        bad = "image size differs from its header (truncated?)";
    else if (kdr_hash64(p + KD_IMAGE_HEAD, len - KD_IMAGE_HEAD, KD_IMAGE_FORMAT) !=
             h.checksum)
        bad = "checksum mismatch";
    else
        bad = check_body(&b, len, &o);
    if (bad) {
        *why = bad;
        return KDR_EIMAGE;
    }
    const img_layout l = layout_of(b.ntris, b.nnodes, b.nrefs);
    kdr_scene *s = calloc(1, sizeof *s);
    if (!s) {
        *why = "out of memory";
        return KDR_ENOMEM;
    }
    /* the scene never writes through these: the cast only fits the struct */
    s->borrowed = 1;
    s->ntris = (size_t)b.ntris;
    s->tris = (float *)(uintptr_t)(p + l.tris);
    s->nnodes = (size_t)b.nnodes;
    s->nodes = b.nnodes ? (kd_node *)(uintptr_t)(p + l.nodes) : NULL;
    s->nrefs = (size_t)b.nrefs;
    s->refs = (uint32_t *)(uintptr_t)(p + l.refs);
    memcpy(s->bounds.min, b.bounds, 12);
    memcpy(s->bounds.max, b.bounds + 3, 12);
    memcpy(s->root.min, b.root, 12);
    memcpy(s->root.max, b.root + 3, 12);
    s->diagonal = b.diagonal;
    s->stats = (kdr_tree_stats){
        .nodes = b.st_nodes,
        .leaves = b.st_leaves,
        .empty_leaves = b.st_empty,
        .max_depth = b.st_depth,
        .refs = b.st_refs,
        .refs_per_leaf = b.st_refs_per_leaf,
        .sah_cost = b.st_sah,
        .build_ms = b.st_build_ms,
        .bytes = b.st_bytes,
    };
    if (!all_finite(s->tris, 9 * s->ntris))
        bad = "non-finite triangle coordinate";
    else if (s->nnodes)
        bad = check_tree(s);
    else if (s->stats.nodes || s->stats.leaves || s->stats.refs)
        bad = "tree statistics disagree with the tree";
    if (bad) {
        free(s);
        *why = bad;
        return KDR_EIMAGE;
    }
    if (s->nodes) kd_layout_derive(s); /* as kd_layout() does: only for a tree */
    *out = s;
    return KDR_OK;
}
