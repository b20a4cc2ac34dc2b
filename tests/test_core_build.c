/*
 * test_core_build.c — the binned and parallel build (core/kd_build*.c).
 *
 * 1. The tree does not depend on the thread count: scenes large enough to
 *    be cut into many tasks are built with 1, 2, 3, 8 and INT_MAX (capped
 *    by the build) threads, with the exact sweep everywhere and with
 *    binned tops over exact subtrees; node and reference arrays must be
 *    byte-identical and the statistics equal, and a build with threads
 *    must really have run in pieces (the build's log says how many).
 * 2. Binned trees answer like brute force (a sample of rays per mode; the
 *    adversarial scenes of test_core run on binned trees too).
 * 3. The trees are the ones the build made before its speed work of issue
 *    11 round 3 (digests of the node and reference arrays recorded at
 *    3d56534; the node digests re-recorded when leaf bits gained the flat
 *    field, count << 4 instead of << 2, with every split, child, count and
 *    reference unchanged: on five ladder scenes the new nodes, put back into
 *    the old leaf encoding, hash to the old build's digests): a change
 *    meant to make the build faster must not change a tree. A change that
 *    means to change trees updates these on purpose.
 * It is also the program the ThreadSanitizer test runs (tests/core.cmake).
 */
#define _POSIX_C_SOURCE 200809L
#include <limits.h>

#include "test_core_util.h"
#include "tree_hash.h"

typedef struct scene {
    const char *name;
    float *t;
    size_t n;
} scene;

/* Room for triangle n; capacity doubles at powers of two (a realloc per
 * triangle costs millions of page faults under ThreadSanitizer). */
static float *grow_tris(float *t, size_t n) {
    if (t && (n & (n - 1)) != 0)
        return t;
    float *r = realloc(t, (n ? 2 * n : 1) * 9 * sizeof *r);
    if (!r)
        abort();
    return r;
}

/* Clusters of small triangles of varied density, some quantised so that
 * many of them share planes: an uneven tree with real straddlers. */
static scene make_clusters(size_t n) {
    scene s = {"clusters", NULL, 0};
    s.t = grow_tris(NULL, n);
    for (size_t i = 0; i < n; i++) {
        const size_t c = i / 4096;
        const float cx = (float)(c % 5), cy = (float)(c / 5 % 3), cz = (float)(c / 15);
        const float size = 0.004f + 0.012f * (float)(c % 3), spread = 0.3f + 0.2f * (float)(c % 4);
        const float q = c % 2 ? 0.00390625f : 0.0f;
        for (int v = 0; v < 3; v++) {
            const float base[3] = {cx + rng_f(-spread, spread), cy + rng_f(-spread, spread),
                                   cz + rng_f(-spread, spread)};
            for (int k = 0; k < 3; k++) {
                float x = (v == 0 ? base[k] : s.t[9 * i + k]) + (v ? rng_f(-size, size) : 0);
                if (q > 0)
                    x = roundf(x / q) * q;
                s.t[9 * i + 3 * v + k] = x;
            }
        }
    }
    s.n = n;
    return s;
}

/* Unit cubes on a grid (faces in candidate planes, coincident faces) and a
 * sheet of small triangles lying in z = 0 (planar on the split axis). (A
 * sheet of thousands of huge overlapping triangles makes the tree explode
 * to millions of references in every mode: too slow for a unit test.) */
static scene make_grid(void) {
    scene s = {"grid", NULL, 0};
    for (int x = 0; x < 24; x++)
        for (int y = 0; y < 16; y++)
            for (int z = 0; z < 12; z++) {
                if ((x * 7 + y * 5 + z * 3) % 4 == 0)
                    continue;
                for (int f = 0; f < 12; f++) {
                    s.t = grow_tris(s.t, s.n);
                    float *t = s.t + 9 * s.n++;
                    const int axis = f / 4, hi = (f / 2) % 2, tri = f % 2;
                    static const float q[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
                    const int idx[2][3] = {{0, 1, 2}, {0, 2, 3}};
                    for (int v = 0; v < 3; v++) {
                        const float *c = q[idx[tri][v]];
                        float p[3];
                        p[axis] = (float)hi;
                        p[(axis + 1) % 3] = c[0];
                        p[(axis + 2) % 3] = c[1];
                        t[3 * v] = (float)x + p[0];
                        t[3 * v + 1] = (float)y + p[1];
                        t[3 * v + 2] = (float)z + p[2];
                    }
                }
            }
    for (int i = 0; i < 6000; i++) {
        s.t = grow_tris(s.t, s.n);
        float *t = s.t + 9 * s.n++;
        const float cx = rng_f(-2, 26), cy = rng_f(-2, 18);
        for (int v = 0; v < 3; v++) {
            t[3 * v] = cx + rng_f(-0.3f, 0.3f);
            t[3 * v + 1] = cy + rng_f(-0.3f, 0.3f);
            t[3 * v + 2] = 0.0f;
        }
    }
    return s;
}

static int count_pieces(const char *msg) {
    int pieces;
    return sscanf(msg, "kd build: %d pieces on", &pieces) == 1 ? pieces : 0;
}

static void log_pieces(void *user, const char *msg) {
    const int p = count_pieces(msg);
    if (p)
        *(int *)user = p;
}

static kdr_scene *build(const scene *sc, int exact_max, int threads, int *pieces) {
    kdr_build_opts o;
    kdr_build_opts_default(&o);
    o.exact_max = exact_max;
    o.threads = threads;
    kdr_scene *s = NULL;
    *pieces = 0;
    const int rc = kdr_scene_build(sc->t, sc->n, &o, log_pieces, pieces, &s);
    EXPECT(rc == KDR_OK && s);
    if (rc != KDR_OK) {
        fprintf(stderr, "%s: build failed: %s\n", sc->name, kdr_strerror(rc));
        exit(1);
    }
    return s;
}

static int same_tree(const kdr_scene *a, const kdr_scene *b) {
    kdr_tree_stats sa, sb;
    kdr_scene_tree_stats(a, &sa);
    kdr_scene_tree_stats(b, &sb);
    return a->nnodes == b->nnodes && a->nrefs == b->nrefs &&
           memcmp(a->nodes, b->nodes, a->nnodes * sizeof *a->nodes) == 0 &&
           memcmp(a->refs, b->refs, a->nrefs * sizeof *a->refs) == 0 &&
           sa.nodes == sb.nodes && sa.leaves == sb.leaves &&
           sa.empty_leaves == sb.empty_leaves && sa.max_depth == sb.max_depth &&
           sa.refs == sb.refs && sa.refs_per_leaf == sb.refs_per_leaf &&
           sa.sah_cost == sb.sah_cost && sa.bytes == sb.bytes;
}

/* A sample of rays through the scene's box against brute force. */
static size_t check_rays(const scene *sc, const kdr_scene *s, int nrays) {
    kdr_bounds b;
    kdr_scene_bounds(s, &b);
    size_t bad = 0;
    for (int i = 0; i < nrays; i++) {
        kdr_ray r;
        const float *t = sc->t + 9 * (rng_u32() % sc->n);
        for (int k = 0; k < 3; k++) {
            r.org[k] = rng_f(b.min[k] - 1, b.max[k] + 1);
            /* aim at a vertex or the centre of a random triangle */
            const float target = i % 2 ? t[k] : (t[k] + t[3 + k] + t[6 + k]) / 3;
            r.dir[k] = target - r.org[k];
        }
        if (i % 5 == 0)
            r.dir[i % 3] = 0.0f; /* along split planes */
        if (r.dir[0] == 0 && r.dir[1] == 0 && r.dir[2] == 0)
            r.dir[0] = 1;
        r.tmin = 0;
        r.tmax = INFINITY;
        bad += !compare_ray(s, &r);
    }
    return bad;
}

/* Modes: exact everywhere, a low and a middle switch-over (the default is
 * above these scenes' sizes: exact too). Binning every node is checked on
 * small scenes by test_core; on these it is slow. */
static void test_scene(const scene *sc, const uint64_t want[3][2]) {
    static const int modes[] = {INT_MAX, 500, 8000};
    static const int threads[] = {3, 2, 8, INT_MAX}; /* INT_MAX: capped by the build */
    for (size_t m = 0; m < sizeof modes / sizeof *modes; m++) {
        const int exact_max = modes[m];
        int pieces;
        kdr_scene *ref = build(sc, exact_max, 1, &pieces);
        uint64_t dig[2];
        th_tree_digest(ref, dig);
        if (dig[0] != want[m][0] || dig[1] != want[m][1])
            fprintf(stderr, "%s, exact_max %d: digests %016llx %016llx, want %016llx %016llx\n",
                    sc->name, exact_max, (unsigned long long)dig[0],
                    (unsigned long long)dig[1], (unsigned long long)want[m][0],
                    (unsigned long long)want[m][1]);
        EXPECT(dig[0] == want[m][0] && dig[1] == want[m][1]);
        for (size_t t = 0; t < sizeof threads / sizeof *threads; t++) {
            kdr_scene *s = build(sc, exact_max, threads[t], &pieces);
            const int same = same_tree(ref, s);
            if (!same || pieces < 2)
                fprintf(stderr, "%s, exact_max %d, %d threads: %s, %d pieces\n",
                        sc->name, exact_max, threads[t],
                        same ? "same tree" : "DIFFERENT tree", pieces);
            EXPECT(same);
            EXPECT(pieces >= 2); /* the work really was cut */
            kdr_scene_free(s);
        }
        const size_t bad = check_rays(sc, ref, 100);
        if (bad)
            fprintf(stderr, "%s, exact_max %d: %zu rays differ from brute force\n",
                    sc->name, exact_max, bad);
        EXPECT(bad == 0);
        kdr_scene_free(ref);
    }
}

/* Node and reference digests per scene and mode (exact, 500, 8000). */
static const uint64_t want_digests[2][3][2] = {
    {{0xa2afeb57d35d9870ull, 0x34307f141c35c64bull},
     {0x7da97758bdfce18aull, 0xd5e7be04b1e50297ull},
     {0xecbf5db60f501a88ull, 0x1ffb09e247464561ull}},
    {{0x6bd93a1dee19b138ull, 0x29e8be8246682092ull},
     {0x34e3c568f86594b1ull, 0xdfbc812a4210d5bbull},
     {0x2d8fc584adc6c373ull, 0x839450aabd6d3f65ull}}};

int main(void) {
    scene sc[2] = {make_clusters(40000), make_grid()};
    for (int i = 0; i < 2; i++) {
        test_scene(&sc[i], want_digests[i]);
        free(sc[i].t);
    }
    if (failures)
        fprintf(stderr, "test_core_build: %d failures\n", failures);
    else
        printf("test_core_build: ok\n");
    return failures != 0;
}
