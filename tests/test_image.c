/*
 * test_image.c — tree images (core/kd_image.c). A scene opened from its
 * image must answer every traversal kind bit for bit like the scene it was
 * written from and report the same statistics, and rewriting it must give
 * the same bytes: a field of struct kdr_scene that the image does not carry
 * shows up here. Every damaged image is refused: truncated at every length
 * (each copy in an exact-size allocation, so ASan sees any read past it),
 * one byte changed at every offset, another format version, other build
 * options, a misaligned buffer. Damage with the checksum recomputed (so
 * only the structural checks stand between it and the walks) is either
 * refused or, if accepted, walked by every traversal kind without an
 * out-of-bounds read: run under ASan/UBSan by ./scripts/dev test.
 */
#define _POSIX_C_SOURCE 200809L
#include "test_core_util.h"

#include "kd_internal.h"

/* ---- scenes and answers ---------------------------------------------------- */

static float *random_soup(size_t n, int degenerate_every) {
    float *t = malloc(9 * n * sizeof(float) + 1);
    if (!t) abort();
    for (size_t i = 0; i < n; i++) {
        float c[3] = {rng_f(-1, 1), rng_f(-1, 1), rng_f(-1, 1)};
        for (int j = 0; j < 9; j++)
            t[9 * i + j] = c[j % 3] + rng_f(-0.15f, 0.15f);
        if (degenerate_every && i % (size_t)degenerate_every == 0)
            memcpy(t + 9 * i + 6, t + 9 * i + 3, 3 * sizeof(float)); /* zero area */
    }
    return t;
}

enum { NRAYS = 96, NPOINTS = 24, IMG_W = 19, IMG_H = 13 };

typedef struct answers {
    kdr_hit single[NRAYS];
    int occl[NRAYS];
    float t[3][NRAYS], u[3][NRAYS], v[3][NRAYS];
    int32_t prim[3][NRAYS];
    uint8_t any[3][NRAYS];
    float vis[2][NPOINTS * 2];
    float ft[3][IMG_W * IMG_H], fu[3][IMG_W * IMG_H], fv[3][IMG_W * IMG_H];
    int32_t fprim[3][IMG_W * IMG_H];
    uint8_t fany[3][IMG_W * IMG_H];
    kdr_tree_stats stats;
    kdr_bounds bounds;
    float diagonal;
    size_t ntris;
} answers;

static float g_org[3 * NRAYS], g_dir[3 * NRAYS], g_pts[3 * NPOINTS];

static void make_rays(void) {
    for (int i = 0; i < NRAYS; i++)
        for (int k = 0; k < 3; k++) {
            g_org[3 * i + k] = rng_f(-1.6f, 1.6f);
            g_dir[3 * i + k] = rng_f(-1, 1);
        }
    for (int i = 0; i < 3 * NPOINTS; i++)
        g_pts[i] = rng_f(-1.2f, 1.2f);
}

/* Every traversal kind: single rays, batches in each mode, cone shadows in
 * both modes, frusta in each mode; both query kinds where there are two. */
static void answer(const kdr_scene *s, answers *a) {
    memset(a, 0, sizeof *a);
    for (int i = 0; i < NRAYS; i++) {
        kdr_ray r = {{g_org[3 * i], g_org[3 * i + 1], g_org[3 * i + 2]},
                     {g_dir[3 * i], g_dir[3 * i + 1], g_dir[3 * i + 2]},
                     0.0f,
                     INFINITY};
        kdr_intersect1(s, &r, &a->single[i], NULL);
        a->occl[i] = kdr_occluded1(s, &r, NULL);
    }
    float tmin = 0.0f, tmax = INFINITY;
    kdr_ray_batch b = {NRAYS, g_org, 3, g_dir, &tmin, 0, &tmax, 0};
    const kdr_trav_mode modes[3] = {KDR_TRAV_SINGLE, KDR_TRAV_BUNDLE4, KDR_TRAV_BUNDLE8};
    for (int m = 0; m < 3; m++) {
        kdr_hits h = {a->t[m], a->prim[m], a->u[m], a->v[m], NULL};
        EXPECT(kdr_trace_batch(s, &b, 0, NRAYS, KDR_CLOSEST, modes[m], &h, NULL) ==
              KDR_OK);
        kdr_hits o = {NULL, NULL, NULL, NULL, a->any[m]};
        EXPECT(kdr_trace_batch(s, &b, 0, NRAYS, KDR_ANY, modes[m], &o, NULL) == KDR_OK);
    }
    kdr_sphere_light lights[2] = {{{0.3f, 3.0f, 0.2f}, 0.4f},
                                  {{-3.0f, 0.5f, 1.0f}, 0.2f}};
    kdr_shadow_query q = {NPOINTS, g_pts, NULL, lights, 2, 16, 7, KDR_OFFSET_DIAGONAL, 1e-4f};
    EXPECT(kdr_shadow_trace(s, &q, 0, NPOINTS, KDR_SHADOW_CONE, a->vis[0], NULL) ==
          KDR_OK);
    EXPECT(kdr_shadow_trace(s, &q, 0, NPOINTS, KDR_SHADOW_RAYS, a->vis[1], NULL) ==
          KDR_OK);
    kdr_camera cam = {{0.2f, 0.4f, 3.5f}, {0, 0, 0}, {0, 1, 0}, 50.0f, IMG_W, IMG_H};
    const kdr_frustum_mode fm[3] = {KDR_FRUSTUM_MULTI4, KDR_FRUSTUM_SINGLE,
                                    KDR_FRUSTUM_RAYS};
    for (int m = 0; m < 3; m++) {
        size_t tiles = kdr_frustum_tile_count(&cam, 4);
        kdr_hits h = {a->ft[m], a->fprim[m], a->fu[m], a->fv[m], NULL};
        EXPECT(kdr_frustum_trace(s, &cam, 4, 0, tiles, KDR_CLOSEST, fm[m], &h, NULL) ==
              KDR_OK);
        kdr_hits o = {NULL, NULL, NULL, NULL, a->fany[m]};
        EXPECT(kdr_frustum_trace(s, &cam, 4, 0, tiles, KDR_ANY, fm[m], &o, NULL) ==
              KDR_OK);
    }
    kdr_scene_tree_stats(s, &a->stats);
    kdr_scene_bounds(s, &a->bounds);
    a->diagonal = kdr_scene_diagonal(s);
    a->ntris = kdr_scene_triangle_count(s);
}

/* An exact-size, 64-byte aligned copy: ASan flags any read past len. */
static unsigned char *copy_exact(const unsigned char *src, size_t len) {
    void *p = NULL;
    if (posix_memalign(&p, 64, len ? len : 1) != 0) abort();
    if (len) memcpy(p, src, len);
    return p;
}

static unsigned char *image_of(const kdr_scene *s, const kdr_build_opts *o, size_t *len) {
    *len = kdr_scene_image_size(s);
    unsigned char *buf = NULL;
    if (posix_memalign((void **)&buf, 64, *len) != 0) abort();
    EXPECT(kdr_scene_image_write(s, o, buf, *len) == KDR_OK);
    return buf;
}

/* ---- round trip --------------------------------------------------------------- */

static void round_trip(const char *what, const float *tris, size_t n,
                       const kdr_build_opts *o) {
    kdr_scene *s = NULL, *m = NULL;
    EXPECT(kdr_scene_build(tris, n, o, NULL, NULL, &s) == KDR_OK);
    if (!s) return;
    size_t len;
    unsigned char *img = image_of(s, o, &len);
    const char *why = NULL;
    int rc = kdr_scene_image_open(img, len, o, &m, &why);
    if (rc != KDR_OK) {
        fprintf(stderr, "%s: image refused: %s\n", what, why ? why : "?");
        EXPECT(rc == KDR_OK);
        kdr_scene_free(s);
        free(img);
        return;
    }
    static answers a, b;
    answer(s, &a);
    answer(m, &b);
    if (memcmp(&a, &b, sizeof a) != 0) {
        fprintf(stderr, "%s: answers differ after the round trip\n", what);
        EXPECT(0);
    }
    /* the scene from the image writes the very same bytes */
    size_t len2;
    unsigned char *img2 = image_of(m, o, &len2);
    EXPECT(len2 == len && memcmp(img, img2, len) == 0);
    EXPECT(m->root_mag == s->root_mag && m->prefetch_leaves == s->prefetch_leaves);
    kdr_scene_free(m); /* borrowed arrays: frees only the record */
    kdr_scene_free(s);
    free(img);
    free(img2);
}

/* ---- damage --------------------------------------------------------------------- */

static int refused(const unsigned char *img, size_t len, const kdr_build_opts *o) {
    unsigned char *c = copy_exact(img, len);
    kdr_scene *m = NULL;
    const char *why = NULL;
    int rc = kdr_scene_image_open(c, len, o, &m, &why);
    int ok = rc == KDR_EIMAGE && m == NULL && why != NULL;
    if (rc == KDR_OK) kdr_scene_free(m);
    free(c);
    return ok;
}

/* The checksum's seed is the image's format number (head bytes 8..11). */
static void reseal(unsigned char *img, size_t len) {
    uint32_t format;
    memcpy(&format, img + 8, 4);
    uint64_t h = kdr_hash64(img + 64, len - 64, format);
    memcpy(img + 24, &h, 8); /* head: magic 8, format 4, endian 4, length 8 */
}

static void damage(const float *tris, size_t n, const kdr_build_opts *o) {
    kdr_scene *s = NULL;
    EXPECT(kdr_scene_build(tris, n, o, NULL, NULL, &s) == KDR_OK);
    size_t len;
    unsigned char *img = image_of(s, o, &len);
    unsigned char *c = copy_exact(img, len);
    size_t bad_trunc = 0, bad_flip = 0, forged_ok = 0, forged_no = 0;
    /* truncated at every length */
    for (size_t l = 0; l < len; l++)
        bad_trunc += !refused(img, l, o);
    /* one byte changed at every offset (head, body and every section) */
    for (size_t off = 0; off < len; off++) {
        c[off] ^= (unsigned char)(1u << (off % 8));
        bad_flip += !refused(c, len, o);
        c[off] = img[off];
    }
    /* forged: changed bytes with a valid checksum, from offset 64 on */
    for (size_t off = 64; off < len; off += 3) {
        c[off] ^= (unsigned char)(0x11u << (off % 4));
        reseal(c, len);
        kdr_scene *m = NULL;
        if (kdr_scene_image_open(c, len, o, &m, NULL) == KDR_OK) {
            static answers a;
            answer(m, &a); /* must stay in bounds: ASan aborts otherwise */
            kdr_scene_free(m);
            forged_ok++;
        } else {
            forged_no++;
        }
        c[off] = img[off];
    }
    memcpy(c, img, len);
    EXPECT(bad_trunc == 0);
    EXPECT(bad_flip == 0);
    fprintf(stderr,
            "damage (%zu triangles, %zu-byte image): %zu truncations and %zu one-byte "
            "changes refused; forged: %zu refused, %zu accepted and walked safely\n",
            n, len, len - bad_trunc, len - bad_flip, forged_no, forged_ok);
    EXPECT(forged_no > 0);
    /* another format version (the head is outside the checksum) */
    c[8] ^= 1;
    EXPECT(refused(c, len, o));
    c[8] = img[8];
    /* other build options */
    kdr_build_opts other = *o;
    other.leaf_size += 1;
    EXPECT(refused(img, len, &other));
    other = *o;
    other.empty_bonus = nextafterf(other.empty_bonus, 1.0f);
    EXPECT(refused(img, len, &other));
    other = *o; /* binned and exact builds give different trees */
    other.exact_max = o->exact_max == 0 ? 1 : 0;
    EXPECT(refused(img, len, &other));
    other = *o; /* the tree is the same on any thread count */
    other.threads = o->threads + 3;
    EXPECT(!refused(img, len, &other));
    /* trailing bytes are not part of the image; a misaligned buffer */
    unsigned char *big = NULL;
    if (posix_memalign((void **)&big, 64, len + 64) != 0) abort();
    memcpy(big, img, len);
    memset(big + len, 0, 64);
    kdr_scene *m = NULL;
    EXPECT(kdr_scene_image_open(big, len + 64, o, &m, NULL) == KDR_EIMAGE && !m);
    memmove(big + 8, big, len);
    EXPECT(kdr_scene_image_open(big + 8, len, o, &m, NULL) == KDR_EINVAL && !m);
    free(big);
    free(c);
    free(img);
    kdr_scene_free(s);
}

/* Targeted forgeries, each must be refused for its own reason. */
static void forged_structure(const float *tris, size_t n, const kdr_build_opts *o) {
    kdr_scene *s = NULL;
    EXPECT(kdr_scene_build(tris, n, o, NULL, NULL, &s) == KDR_OK);
    size_t len;
    unsigned char *img = image_of(s, o, &len);
    const size_t tris_off = 256;
    const size_t nodes_off = (tris_off + 36 * s->ntris + 63) / 64 * 64;
    const size_t refs_off = (nodes_off + 8 * s->nnodes + 63) / 64 * 64;
    size_t leaf = 0, interior = 0;
    for (size_t i = 0; i < s->nnodes; i++)
        if (kd_is_leaf(&s->nodes[i]) && kd_count(&s->nodes[i]) > 0)
            leaf = i;
        else if (!kd_is_leaf(&s->nodes[i]) && !interior)
            interior = i + 1; /* +1: 0 means none */
    EXPECT(interior == 1);     /* the root */
    EXPECT(kd_leaf_flat(&s->nodes[leaf]) == 0);
    struct {
        const char *what;
        size_t off;
        uint32_t value;
    } cases[] = {
        {"above child past the end", nodes_off + 4,
         (uint32_t)s->nnodes << 4 | (s->nodes[0].bits & 15u)},
        {"above child = below child", nodes_off + 4, 1u << 4 | (s->nodes[0].bits & 15u)},
        {"leaf list past the refs", nodes_off + 8 * leaf, (uint32_t)s->nrefs},
        {"ref past the triangles", refs_off, (uint32_t)s->ntris},
        {"NaN coordinate", tris_off, 0x7fc00000u},
        {"leaf count grown", nodes_off + 8 * leaf + 4,
         s->nodes[leaf].bits + (1000u << 4)},
        /* random triangles: no leaf is flat, and a flag would let walks
         * skip the leaf's triangles (kd_leaf_behind) */
        {"flat flag on a leaf that is not flat", nodes_off + 8 * leaf + 4,
         (s->nodes[leaf].bits & ~(3u << 2)) | (2u << 2)},
        {"axis 3 on an interior node turns it into a leaf", nodes_off + 4,
         s->nodes[0].bits | 3u},
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        unsigned char *c = copy_exact(img, len);
        memcpy(c + cases[k].off, &cases[k].value, 4);
        reseal(c, len);
        kdr_scene *m = NULL;
        const char *why = NULL;
        int rc = kdr_scene_image_open(c, len, o, &m, &why);
        if (rc != KDR_EIMAGE) fprintf(stderr, "forged '%s' not refused\n", cases[k].what);
        EXPECT(rc == KDR_EIMAGE && !m);
        free(c);
    }
    /* sanity: the unchanged, resealed image still opens */
    unsigned char *c = copy_exact(img, len);
    reseal(c, len);
    kdr_scene *m = NULL;
    EXPECT(kdr_scene_image_open(c, len, o, &m, NULL) == KDR_OK);
    kdr_scene_free(m);
    free(c);
    free(img);
    kdr_scene_free(s);
}

int main(void) {
    EXPECT(sizeof(struct kdr_scene) == KD_SCENE_STRUCT_SIZE);
    make_rays();
    kdr_build_opts def, tight;
    kdr_build_opts_default(&def);
    tight = def;
    tight.leaf_size = 1;
    tight.max_depth = 12;

    float *big = random_soup(3000, 17);
    round_trip("3000 random triangles", big, 3000, &def);
    round_trip("3000 random triangles, other options", big, 3000, &tight);
    float *one = random_soup(1, 0);
    round_trip("one triangle", one, 1, &def);
    round_trip("no triangle", NULL, 0, &def);
    float *flat = random_soup(20, 1); /* every triangle zero-area: no tree */
    round_trip("only zero-area triangles", flat, 20, &def);
    /* KD_PREFETCH_MIN_BYTES scenes take the prefetching walks */
    float *large = random_soup(120000, 0);
    round_trip("120000 random triangles", large, 120000, &def);

    float *small = random_soup(60, 7);
    damage(small, 60, &def);
    forged_structure(small, 60, &def);
    /* a NULL options pointer means the defaults on both sides */
    {
        kdr_scene *s = NULL, *m = NULL;
        EXPECT(kdr_scene_build(small, 60, NULL, NULL, NULL, &s) == KDR_OK);
        size_t len;
        unsigned char *img = image_of(s, NULL, &len);
        EXPECT(kdr_scene_image_open(img, len, &def, &m, NULL) == KDR_OK);
        kdr_scene_free(m);
        EXPECT(kdr_scene_image_open(img, len, &tight, &m, NULL) == KDR_EIMAGE);
        free(img);
        kdr_scene_free(s);
    }
    EXPECT(kdr_scene_image_open(NULL, 0, NULL, NULL, NULL) == KDR_EINVAL);
    EXPECT(strcmp(kdr_strerror(KDR_EIMAGE), "invalid tree image") == 0);

    free(big);
    free(one);
    free(flat);
    free(large);
    free(small);
    if (failures) {
        fprintf(stderr, "test_image: %d failures\n", failures);
        return 1;
    }
    fprintf(stderr, "test_image: ok\n");
    return 0;
}
