/*
 * kd_cone.h — internal interface between the shadow-ray sampler
 * (kd_cone_sample.c, which defines kdr_shadow_ray) and the cone-shadow query
 * (kd_cone.c: one point and light; kd_cone_query.c: the driver). A "frame"
 * is everything about one (point, light) pair that all of its samples
 * share: the cone apex, the axis and its basis, the half-angle and the
 * hash key; building it once per pair keeps the per-sample cost to a few
 * multiplications and makes every mode use identical rays.
 */
#ifndef KD_CONE_H
#define KD_CONE_H

#include <stdint.h>

#include "kd_internal.h"
#include "kdray.h"

/* The contract's largest samples per point and light (kdray.h). */
#define KD_SHADOW_MAX_SAMPLES 4096

typedef struct kd_shadow_frame {
    float apex[3];      /* the point, moved along the normal when given */
    double axis[3];     /* unit vector from apex toward the light centre */
    double b1[3], b2[3];/* completes axis to an orthonormal basis */
    double center[3];
    double radius;
    double dist;        /* apex to light centre, > radius */
    double sin_a;       /* sin of the half-angle: radius / dist */
    double one_minus_cos; /* 1 - cos(half-angle), without cancellation */
    float along;        /* > 0: each ray's origin moves this far along it */
    uint64_t key;       /* hash of (seed, point, light) */
    double phi_shift;   /* per-pair rotation of the azimuth lattice */
    double cos_shift, sin_shift; /* of 2 pi phi_shift */
    double oc[3];       /* center - apex, as each sample's reach uses it */
    double near_c;      /* (dist - radius)(dist + radius), likewise */
} kd_shadow_frame;

/* Sets up the frame of point i and light l; KDR_EINVAL if an input is not
 * finite, the radius is not positive or the apex is inside the light. */
int kd_shadow_frame_init(const kdr_scene *scene, const kdr_shadow_query *q,
                         size_t i, size_t l, kd_shadow_frame *f);

/* Sample s of nsamples of the frame (direction unit length up to
 * rounding, tmin 0).
 * Its direction makes the angle theta with the axis, 1 - cos(theta) =
 * u * one_minus_cos with u in [s, s+1) / nsamples (stratum s), and the
 * azimuth 2 pi kd_shadow_frame_phase(f, s) around it from b1 toward b2. */
void kd_shadow_frame_ray(const kd_shadow_frame *f, uint32_t s,
                         uint32_t nsamples, kdr_ray *out);
/* The samples idx[0..count) of nsamples (idx NULL: s0, s0 + 1, ...) into
 * out[0..count): kd_shadow_frame_ray's rays bit for bit, four at a time
 * in double lanes where AVX2 runs. */
void kd_shadow_frame_rays(const kd_shadow_frame *f, const uint32_t *idx, uint32_t s0,
                          uint32_t count, uint32_t nsamples, kdr_ray *out);
/* order[0..n): the n samples of a pair along a Morton curve of the
 * light's disc as seen without the pair's rotation (the stratum's middle
 * for the radius, the lattice without its shift for the azimuth). A
 * pair's rotation turns the whole disc, so samples consecutive in this
 * order are neighbours on every pair's disc: bundles of them are compact
 * without a sort by direction (kd_cone_query.c's unwalked chunks).
 * KDR_ENOMEM when its scratch cannot be allocated. */
int kd_shadow_disc_order(uint32_t n, uint32_t *order);
/* The azimuth of sample s in turns, in [0, 1): the very value the ray is
 * built from, so a region of (stratum, phase) holds exactly the samples
 * whose parameters lie in it. */
double kd_shadow_frame_phase(const kd_shadow_frame *f, uint32_t s);

/* ---- cone traversal (kd_cone_trav.c) ------------------------------------ */

/*
 * A traversal cone: apex, unit axis and half-angle, containing every sample
 * segment it stands for (the whole light, or one group of samples). The
 * float part drives the kd-tree walk, the double part the per-triangle cull.
 */
typedef struct kd_cone {
    float apex[3];
    float lo[3], hi[3]; /* slopes of the cone's extent along each world axis */
    float inv_lo[3], inv_nhi[3]; /* 1 / lo, -1 / hi */
    float band;         /* positional slack (apex rounding, triangle test) */
    float t_far;        /* axial reach: every segment ends before it */
    float t_near;       /* every segment starts after it (0 but for groups) */
    double dapex[3], axis[3];
    double cos_p, sin_p, tan_p; /* half-angle widened for the cull */
} kd_cone;

/* The cone of the frame's whole light (axis NULL) or the cone around axis
 * with half-angle asin(sin_a) from the frame's apex. */
void kd_cone_init(kd_cone *c, const kdr_scene *scene, const kd_shadow_frame *f,
                  const double *axis, double sin_a);

/* The cone of a group of points toward one light (kd_cone_group.c): it
 * holds every sample segment of the n frames fs (same light, fixed apexes)
 * and a margin over each point's own walk and cull. 0 (no group) if a
 * frame has no fixed apex, or the ball around the apexes is wider than
 * max_spread times the light's ball (or the cone would be wide). */
int kd_group_cone(const kdr_scene *scene, const kd_shadow_frame *const *fs, size_t n,
                  double max_spread, kd_cone *c);
/* How far from the light's centre the frame's cone, widened by twice the
 * cull's angular slack, reaches at its t_far (the rim of its last disc). */
double kd_frame_reach(const kd_shadow_frame *f);

/* Leaf by leaf, front to back (kd_cone_walk_next returns NULL at the end). */
typedef struct kd_cone_item {
    uint32_t node;
    float tn, tf;
} kd_cone_item;

typedef struct kd_cone_walk {
    const kdr_scene *scene;
    const kd_cone *cone;
    kd_cone_item stack[KD_MAX_DEPTH + 2]; /* one push per level at most */
    int top;
    uint64_t visited; /* nodes entered so far */
} kd_cone_walk;

void kd_cone_walk_init(kd_cone_walk *w, const kdr_scene *scene, const kd_cone *c);
const struct kd_node *kd_cone_walk_next(kd_cone_walk *w);

typedef struct kd_cand_list {
    uint32_t *v;
    size_t n, cap;
} kd_cand_list;

#define KD_CONE_OVER 1 /* kd_cone_collect gave up: over its budget */

/* The distinct triangles (in walk order) of the leaves the cone reaches
 * that may touch a segment inside it (prism: the cull's prism-side test
 * too; without it the list keeps more, never less). Returns KDR_OK,
 * KDR_ENOMEM, or KD_CONE_OVER once more than max_cands candidates or
 * max_nodes nodes are reached (the list is then incomplete). Adds the
 * nodes visited to *nodes. */
int kd_cone_collect(const kdr_scene *scene, const kd_cone *c, kd_cand_list *cl,
                    size_t max_cands, uint64_t max_nodes, int prism, uint64_t *nodes);

/* A triangle's cull data, made once for the many cones of a group
 * (kd_cone_trav.c): unit normal and offset of its plane, its bounding
 * sphere, and the outward unit normals and offsets of its prism's sides. */
typedef struct kd_tri_pre {
    double n[3], n_off;
    double c[3], r;
    double e[3][3], e_off[3];
    int flat;     /* plane and prism usable (not degenerate) */
    int clear;    /* kd_group_clear: no point of the group needs it */
    uint32_t prim;
} kd_tri_pre;

/* The cull's relative distance slack (kd_cone_trav.c, kd_cone_cull4.c). */
#define KD_CULL_REL_SLACK 1e-6

/* A group list's cull data by field, four triangles to a block (made once
 * per group, read by every point of it: kd_cone_cull4.c). Lanes past n
 * are padding that no cull keeps. */
typedef struct kd_tri_soa {
    double *f;      /* KD_SOA_FIELDS arrays of cap doubles */
    uint32_t *prim;
    size_t n, cap;
} kd_tri_soa;
#define KD_SOA_FIELDS 22 /* n[3], n_off, c[3], r, e[3][3], e_off[3], flat, used */

/* Copies pre[0..n) into s (s->cap >= n rounded up to 4). */
void kd_tri_soa_fill(kd_tri_soa *s, const kd_tri_pre *pre, size_t n);
/* kd_cone_pre_may_block of the four triangles s[j..j+4) (j a multiple of
 * 4) at once, bit i for triangle j + i: the same float operations in the
 * same order, so the same answer for every triangle. AVX2 only (after
 * kdr_cpu_has_avx2()); c->cos_p != 0 (the caller keeps all otherwise). */
int kd_cone_pre_may_block4(const kd_cone *c, const kd_tri_soa *s, size_t j);
/* The first test of kd_cone_tri_may_block (kd_cone_trav.c): 0 if the
 * triangle's bounding sphere lies beyond the segments' axial reach or
 * beside the cone (c->cos_p != 0). */
int kd_cone_tri_sphere_may(const kd_cone *c, const float *tri);
/* The rest of kd_cone_tri_may_block after the sphere (plane, prism):
 * kd_cone_tri_may_block = kd_cone_tri_sphere_may && kd_cone_tri_rest_may
 * wherever c->cos_p != 0. */
int kd_cone_tri_rest_may(const kd_cone *c, const float *tri);
/* kd_cone_tri_sphere_may of tris[0..n) (n <= 4) at once, bit i for
 * tris[i], each the scalar answer. AVX2 only; c->cos_p != 0. */
int kd_cone_tri_sphere4(const kd_cone *c, const float *const *tris, int n);

void kd_tri_pre_init(kd_tri_pre *p, const float *tri, uint32_t prim);
/* kd_tri_pre_init in two parts: the plane and the bounding sphere (all
 * kd_group_clear needs), then the prism's sides. */
void kd_tri_pre_plane(kd_tri_pre *p, const float *tri, uint32_t prim);
void kd_tri_pre_sides(kd_tri_pre *p, const float *tri);
/* kd_cone_tri_may_block from the precomputed data, with margins at least
 * as wide: 0 only if the triangle provably misses every segment of c. */
int kd_cone_pre_may_block(const kd_cone *c, const kd_tri_pre *p);
/* Sets pre[j].clear for the group triangles whose plane has every apex of
 * the n frames (fixed apexes, one light) and the ball of radius
 * max kd_frame_reach around the light's centre strictly on one side, by
 * more than any point's cull slack (band: the largest of the points'):
 * every point's kd_cone_pre_may_block would drop it at its plane test, and
 * no segment of the group crosses that plane. */
void kd_group_clear(const kd_shadow_frame *const *fs, size_t n, float band,
                    kd_tri_pre *pre, size_t npre);

/* ---- proofs about one triangle (kd_cone_proof.c) -------------------------- */

/* What one triangle does to every sample segment of a cone. */
typedef enum kd_verdict {
    KD_TRI_UNKNOWN = 0, /* some may hit it, some may not: trace them */
    KD_TRI_MISSES = 1,  /* the triangle test rejects every one */
    KD_TRI_COVERS = 2,  /* the triangle test accepts every one */
} kd_verdict;

/* A triangle as seen from a fixed apex (every ray starts exactly there),
 * with the margins the float triangle test needs (kd_cone_proof.c). */
typedef struct kd_tri_view {
    double edge[3][3];            /* unit normals of the planes (apex, edge) */
    double edge_sin[3], edge_cos[3]; /* margin angle of each edge sign */
    double plane[3];              /* unit normal, from the plane to the apex */
    double plane_sin, plane_cos;  /* grazing margin of the plane */
    double lo[3], hi[3];          /* range of the vertices minus the apex */
    uint32_t prim;
    int det_sign;                 /* side of the apex (sign of det(A)) */
    int det_ok;                   /* the computed t has the sign of the exact one */
} kd_tri_view;

/* A cone of directions: unit axis, half-angle b (covering the float
 * rounding of every direction it stands for), the range of each world
 * component of its directions, and the least tmax of its rays. */
typedef struct kd_dir_cone {
    double axis[3];
    double cos_b, sin_b;
    double dmin[3], dmax[3];
    double tmax_lo;
} kd_dir_cone;

void kd_tri_view_init(kd_tri_view *v, const float *tri, uint32_t prim,
                      const float apex[3]);
void kd_dir_cone_set(kd_dir_cone *c, const double axis[3], double cos_b, double sin_b,
                     double tmax_lo);
kd_verdict kd_tri_view_classify(const kd_tri_view *v, const kd_dir_cone *c);
/* 1 only if kd_tri_view_classify would find the triangle MISSES by two
 * robust edges of opposite signs, with wider margins and no view made. */
int kd_tri_edges_miss(const float *tri, const float apex[3], const kd_dir_cone *c);
/* kd_tri_edges_miss of tris[0..n) (n <= 4) at once (kd_cone_cull4.c), bit
 * i for tris[i], each the scalar answer. AVX2 only. */
int kd_tri_edges_miss4(const float *const *tris, int n, const float apex[3],
                       const kd_dir_cone *c);

/* ---- adaptive sub-cones (kd_cone_cells.c) --------------------------------- */

#define KD_CELL_MAX_DEPTH 8  /* levels of 4-way splits below the whole light */
#define KD_CELL_MAX_LEVEL 40 /* halvings of the phase */
#define KD_SEEN_BITS 9       /* one walk remembers up to 2^8 triangles judged */

/* One (point, light) being decided: set by kd_cone.c, read and updated by
 * kd_cells_lit. */
typedef struct kd_cone_pair {
    const kdr_scene *scene;
    const kd_shadow_frame *f;
    uint32_t n;          /* samples */
    int wide;            /* 8-wide (AVX2) packets */
    int wide16;          /* 16-wide (AVX-512) packets for lists */
    int proofs;          /* fixed origin (normals given): kd_cone_proof applies */
    double tmax_lo;      /* least tmax of any sample */
    size_t max_cands;    /* a walk with more candidates is over budget
                            (<= CONE_MAX_CANDS) */
    uint32_t last;       /* last blocker (in and out) */
    const kd_tri_pre *group; /* non-NULL: the group's list (kd_group_cone's
                                walk, every triangle any of the pair's
                                segments can touch, less those
                                kd_group_clear showed harmless) replaces
                                the pair's walk */
    size_t ngroup;
    const kd_tri_soa *gsoa; /* non-NULL: the group's list by field, culled
                               four at a time (AVX2) */
    kdr_shadow_stats st; /* added to */
    int rc;
} kd_cone_pair;

/* Workspace, reused across pairs (zero-initialise; kd_cells_free). */
typedef struct kd_cells {
    uint32_t *idx;       /* samples, partitioned cell by cell */
    double *phase;       /* kd_shadow_frame_phase of every sample */
    uint32_t cap_samples;
    kd_tri_view *views;
    size_t nviews, cap_views;
    uint32_t *lists;     /* KD_CELL_MAX_DEPTH lists of CONE_MAX_CANDS */
    kd_cand_list cl;
    kdr_ray rays[16];
    double hw_cos[KD_CELL_MAX_LEVEL], hw_sin[KD_CELL_MAX_LEVEL];
    double slack_cos, slack_sin;
    int hw_ready;
    uint32_t seen_prim[1 << KD_SEEN_BITS], seen_stamp[1 << KD_SEEN_BITS];
    uint32_t stamp;      /* of the current walk */
    uint32_t nseen;      /* entries marked by it */
} kd_cells;

int kd_cells_reserve(kd_cells *c, uint32_t nsamples);
void kd_cells_free(kd_cells *c);
/* The pair's lit samples, found by the whole light's cone and its
 * sub-cones (kd_cone_cells.c). KDR_OK, KDR_ENOMEM, or KD_CONE_OVER when
 * the whole light's walk went over budget (nothing decided). */
int kd_cells_lit(kd_cells *c, kd_cone_pair *pr, uint32_t *lit);

/* The cull of kd_cone_collect for one triangle (kd_cone_trav.c): 0 only if
 * it provably misses every segment of the cone. */
int kd_cone_tri_may_block(const kd_cone *c, const float *tri);

/* ---- packets (kd_cone_packet.c) ------------------------------------------ */

/* Tests the n <= 16 rays lanes[0..n) against the candidates (any hit in
 * each ray's [tmin, tmax]); returns the mask of blocked lanes and sets
 * *blocker to the last triangle that blocked one. width: 16 (AVX-512, only
 * when kd_cpu_has_avx512(); n <= 16), 8 (AVX2, only when
 * kdr_cpu_has_avx2(); n <= 8) or 4 (two packets of 4; n <= 8). */
int kd_cone_packet_blocked(const kdr_scene *scene, const kdr_ray *const *lanes,
                           int n, const uint32_t *cands, size_t ncand,
                           uint32_t *blocker, int width);

/* The n rays (n <= 8 with wide, <= 4 without) walk cone c together, testing
 * each leaf's triangles on the way; returns the mask of blocked lanes. When
 * more than max_nodes nodes would be needed the lanes still undecided are
 * returned in *open (they must be traced otherwise). */
int kd_cone_packet_walk(const kdr_scene *scene, const kd_cone *c,
                        const kdr_ray *const *lanes, int n, uint64_t max_nodes,
                        uint32_t *blocker, uint64_t *visited, int *open,
                        int wide);

/* ---- the query's walk policy (kd_cone_query.c) ------------------------------ */

/* Whether a (point, light) walks its whole light's cone before sampling.
 * KD_WALK_AUTO is what kdr_shadow_trace does (a cheap per-point test,
 * kd_tune.h); the forced policies exist so that tests can check that every
 * path gives the same answers. */
typedef enum kd_walk_policy {
    KD_WALK_AUTO = 0,
    KD_WALK_ALWAYS = 1, /* every point walks (at least to its first candidate) */
    KD_WALK_NEVER = 2,  /* no whole-light walk: samples go to the any-hit path */
    KD_WALK_GROUPS = 3, /* every point walks, through its group's list wherever
                           the group's cone exists (kd_group_cone, any spread) */
} kd_walk_policy;

/* kdr_shadow_trace with an explicit walk policy (KDR_SHADOW_CONE only; the
 * policy is ignored by KDR_SHADOW_RAYS). */
int kd_shadow_trace_policy(const kdr_scene *scene, const kdr_shadow_query *q,
                           size_t first, size_t count, kdr_shadow_mode mode,
                           kd_walk_policy policy, float *visibility,
                           kdr_shadow_stats *stats);
/* kdr_shadow_trace_order with an explicit walk policy. */
int kd_shadow_trace_order_policy(const kdr_scene *scene, const kdr_shadow_query *q,
                                 const size_t *order, size_t count, kdr_shadow_mode mode,
                                 kd_walk_policy policy, float *visibility,
                                 kdr_shadow_stats *stats);

/* ---- one (point, light) (kd_cone.c) for the query (kd_cone_query.c) ------ */

#define KD_NO_PRIM UINT32_MAX

/* Per light, carried from point to point (points arrive in image order). */
typedef struct kd_light_state {
    uint32_t last;    /* last blocker: tried first on the next samples */
    uint32_t backoff; /* points to skip after the next failed walk */
    uint32_t skip;    /* points still to skip */
} kd_light_state;

/* One query's workspace (zero-initialise; kd_shadow_ws_free). */
typedef struct kd_shadow_ws {
    kd_cand_list cl;
    kd_cand_list gl; /* a group's list (trace_grouped) */
    kd_tri_pre *gpre; /* its triangles' cull data (GROUP_MAX_CANDS) */
    kd_tri_soa gsoa;  /* the same by field (with AVX2: kd_cone_cull4.c) */
    kdr_ray *rays;  /* the samples of one (point, light) */
    uint32_t *idx;  /* pending (not yet decided) samples */
    uint64_t *keys; /* Morton key << 12 | sample, for grouping */
    kd_light_state *lights;
    float *borg, *bdir, *btmax; /* pending samples as a kdr_ray_batch */
    uint8_t *bhit;
    int wide;       /* AVX2 packets */
    int wide16;     /* AVX-512 packets for a cell's samples (kd_cone_cells.c) */
    kd_walk_policy policy;
    const size_t *order; /* non-NULL: the j-th point traced is order[j] */
    size_t first;        /* else it is first + j */
    kdr_shadow_stats st;
    kd_cells cells;
} kd_shadow_ws;

/* The cheap test: does a point with this many samples toward a light of
 * this angular size (sin_a = r / D) walk its whole light's cone? */
int kd_walk_pays(uint32_t nsamples, double sin_a, kd_walk_policy policy);
/* KDR_SHADOW_CONE's visibility of one (point, light) into *vis; group: the
 * list of its group's shared walk (kd_cone_group.c), or NULL for its own
 * walk. KDR_OK or KDR_ENOMEM. */
int kd_pair_visibility(const kdr_scene *scene, const kd_shadow_frame *f,
                       uint32_t nsamples, kd_shadow_ws *ws, kd_light_state *ls,
                       const kd_cand_list *group, float *vis);
/* KDR_SHADOW_RAYS: every sample traced alone (the reference). */
int kd_pair_visibility_rays(const kdr_scene *scene, const kd_shadow_frame *f,
                            uint32_t nsamples, kd_shadow_ws *ws, float *vis);
void kd_shadow_ws_free(kd_shadow_ws *ws);

#endif /* KD_CONE_H */
