/*
 * test_core_build_simd.c — the split search's kernels (core/kd_build_sah.c,
 * core/kd_build_avx512.c) against a plain sweep.
 *
 * Random sorted event lists (positions drawn from a few values so that many
 * events share one, start/end pairs and planar triangles, lengths 0 to a
 * few thousand, every tail length of the 16-lane loops) go through
 *   - a reference: the one-pass sweep the build used before the kernels
 *     (a group's counts reset at its end, sah_try per group in order);
 *   - kd_group_events + kd_eval_groups (scalar);
 *   - kd_group_events_avx512 + kd_eval_groups_avx512, where the CPU has
 *     AVX-512 (the program says which; the build uses them there).
 * The chosen split (axis, position, side of planar triangles, cost) must
 * be the same bits, and both group passes must write the same groups.
 * The straddlers' small sort (kd_sort_events, scalar and AVX-512 rank
 * sort) must give qsort's order on random unique keys of every length
 * up to 300.
 */
#include "test_core_util.h"
#include "kd_build.h"
#include "kd_stream.h"

#define MAXN 6000

/* The sweep as it was: counts per group, reset at the group's end. */
static void reference(const sah_ctx *c, int k, const kd_event *e, size_t n,
                      size_t ntri, kd_split *best) {
    size_t nl = 0, nr = ntri, i = 0;
    while (i < n) {
        const uint32_t key = ev_key(e[i]);
        size_t pe = 0, pp = 0, ps = 0;
        for (; i < n && ev_key(e[i]) == key; i++) {
            pe += ev_type(e[i]) == EV_END;
            pp += ev_type(e[i]) == EV_PLANAR;
            ps += ev_type(e[i]) == EV_START;
        }
        const float p = key_float(key);
        nr -= pp + pe;
        if (p > c->min && p < c->max) {
            /* sah_try, spelled out */
            const float pl = 2.0f * (c->cap + (p - c->min) * c->perim) * c->inv_area;
            const float pr = 2.0f * (c->cap + (c->max - p) * c->perim) * c->inv_area;
            float cost2[2];
            for (int s = 0; s < 2; s++) {
                const size_t a = s ? nl : nl + pp, b = s ? nr + pp : nr;
                const float eb = (a == 0 || b == 0) ? 1.0f - c->bonus : 1.0f;
                cost2[s] = c->trav + c->isect * eb *
                                         (pl * (float)(int64_t)a + pr * (float)(int64_t)b);
            }
            const float cost = cost2[0] <= cost2[1] ? cost2[0] : cost2[1];
            if (cost < best->cost) {
                best->cost = cost;
                best->axis = k;
                best->pos = p;
                best->planar_left = cost2[0] <= cost2[1];
            }
        }
        nl += ps + pp;
    }
}

static int cmp_ev(const void *a, const void *b) {
    const kd_event x = *(const kd_event *)a, y = *(const kd_event *)b;
    return x < y ? -1 : x > y;
}

/* ntri triangles at positions from `spread` values in [0, 8); returns the
 * event count. */
static size_t make_events(kd_event *e, size_t ntri, int spread, float *lo, float *hi) {
    size_t n = 0;
    *lo = INFINITY;
    *hi = -INFINITY;
    for (size_t t = 0; t < ntri; t++) {
        float a = (float)(rng_u32() % (uint32_t)spread) * (8.0f / (float)spread);
        float b = (float)(rng_u32() % (uint32_t)spread) * (8.0f / (float)spread);
        if (rng_u32() % 4 == 0)
            b = a;
        if (b < a) {
            const float x = a;
            a = b;
            b = x;
        }
        if (rng_u32() % 8 == 0) { /* some negative positions */
            a -= 4.0f;
            b -= 4.0f;
        }
        if (a == b) {
            e[n++] = ev_make(a, EV_PLANAR, (uint32_t)t);
        } else {
            e[n++] = ev_make(a, EV_START, (uint32_t)t);
            e[n++] = ev_make(b, EV_END, (uint32_t)t);
        }
        *lo = a < *lo ? a : *lo;
        *hi = b > *hi ? b : *hi;
    }
    qsort(e, n, sizeof *e, cmp_ev);
    return n;
}

static int same_split(const kd_split *a, const kd_split *b) {
    return a->axis == b->axis && memcmp(&a->pos, &b->pos, sizeof a->pos) == 0 &&
           a->planar_left == b->planar_left && memcmp(&a->cost, &b->cost, sizeof a->cost) == 0;
}

static uint32_t *arrays[2];

static kd_groups groups_in(uint32_t *a) {
    const size_t stride = 2 * MAXN + KD_GROUP_PAD;
    return (kd_groups){a, a + stride, a + 2 * stride, a + 3 * stride};
}

static void one_case(size_t ntri, int spread, int avx512) {
    static kd_event e[2 * MAXN];
    float lo, hi;
    const size_t n = make_events(e, ntri, spread, &lo, &hi);
    sah_ctx c;
    /* the node's extent: the events' range, widened or cut a little so
     * that some positions fall on or outside its faces */
    c.min = lo - (rng_u32() % 2 ? 0.0f : 0.5f);
    c.max = hi + (rng_u32() % 2 ? 0.0f : 0.5f);
    if (rng_u32() % 3 == 0)
        c.min += 1.0f;
    c.cap = rng_f(0.1f, 30.0f);
    c.perim = rng_f(0.1f, 10.0f);
    c.inv_area = 1.0f / (2.0f * (c.cap + (c.max - c.min) * c.perim));
    c.isect = 80.0f;
    c.trav = 1.0f;
    c.bonus = 0.5f;
    kd_split r = {-1, 0.0f, 1, INFINITY}, s = r, v = r;
    if (rng_u32() % 4 == 0) /* a better split from another axis already */
        r.cost = s.cost = v.cost = rng_f(10.0f, 80.0f * (float)ntri);
    const int k = (int)(rng_u32() % 3);
    reference(&c, k, e, n, ntri, &r);
    const kd_groups gs = groups_in(arrays[0]), gv = groups_in(arrays[1]);
    const size_t ng = kd_group_events(e, n, &gs);
    kd_eval_groups(&c, k, &gs, ng, ntri, &s);
    EXPECT(same_split(&r, &s));
    if (!avx512)
        return;
    const size_t ngv = kd_group_events_avx512(e, n, &gv);
    EXPECT(ngv == ng);
    if (ngv == ng) {
        EXPECT(memcmp(gs.key, gv.key, ng * 4) == 0);
        EXPECT(memcmp(gs.ends, gv.ends, ng * 4) == 0);
        EXPECT(memcmp(gs.planars, gv.planars, ng * 4) == 0);
        EXPECT(memcmp(gs.end, gv.end, ng * 4) == 0);
    }
    kd_eval_groups_avx512(&c, k, &gs, ng, ntri, &v);
    if (!same_split(&r, &v))
        fprintf(stderr, "ntri %zu spread %d: ref axis %d pos %a left %d cost %a, avx512 axis %d pos %a left %d cost %a\n",
                ntri, spread, r.axis, r.pos, r.planar_left, r.cost, v.axis, v.pos,
                v.planar_left, v.cost);
    EXPECT(same_split(&r, &v));
}

static void sort_cases(int avx512) {
    static kd_event a[3000], b[3000], c[3000];
    for (size_t n = 0; n <= 3000; n += n < 300 ? 1 : 97) {
        for (size_t i = 0; i < n; i++) /* unique: the index in the low bits */
            a[i] = ev_make(rng_f(-2.0f, 2.0f) * (float)(rng_u32() % 3), rng_u32() % 3,
                           (uint32_t)i);
        memcpy(b, a, n * sizeof *a);
        memcpy(c, a, n * sizeof *a);
        qsort(a, n, sizeof *a, cmp_ev);
        kd_sort_events(b, n, 0);
        EXPECT(memcmp(a, b, n * sizeof *a) == 0);
        if (avx512) {
            kd_sort_events(c, n, 1);
            EXPECT(memcmp(a, c, n * sizeof *a) == 0);
        }
    }
}

/* kd_partition_avx512 against the rule: each event to the left list when
 * its triangle's side has SIDE_LEFT, to the right one when SIDE_RIGHT, in
 * order; nothing written beyond n slots from either list's start. */
static void partition_cases(void) {
    enum { N = 200, GUARD = 16 };
    static kd_event in[N], out[2][N + GUARD], want[2][N];
    static uint8_t side[N];
    const kd_event canary = 0x5a5a5a5a5a5a5a5aull;
    for (size_t n = 0; n <= N; n++) {
        size_t nw[2] = {0, 0};
        for (size_t i = 0; i < n; i++) {
            side[i] = (uint8_t)(rng_u32() % 3); /* SIDE_BOTH, _LEFT, _RIGHT */
            in[i] = ev_make(rng_f(-2.0f, 2.0f), rng_u32() % 3, (uint32_t)(rng_u32() % n));
        }
        for (size_t i = 0; i < n; i++)
            for (int s = 0; s < 2; s++)
                if (side[ev_tri(in[i])] & (1u << s))
                    want[s][nw[s]++] = in[i];
        for (int s = 0; s < 2; s++)
            for (size_t i = 0; i < N + GUARD; i++)
                out[s][i] = canary;
        kd_event *w[2] = {out[0], out[1]};
        kd_partition_avx512(in, n, side, w);
        for (int s = 0; s < 2; s++) {
            EXPECT((size_t)(w[s] - out[s]) == nw[s]);
            EXPECT(memcmp(out[s], want[s], nw[s] * sizeof(kd_event)) == 0);
            for (size_t i = n; i < N + GUARD; i++)
                EXPECT(out[s][i] == canary);
        }
    }
}

/* kd_clip_tri_avx512 against kd_clip_tri: random triangles around random
 * boxes, coordinates often on a coarse grid (vertices in the plane or on
 * the box, equal coordinates, zeros, slivers), every axis. */
static float grid_or_free(float lo, float hi) {
    const float f = rng_f(lo, hi);
    return rng_u32() % 2 ? (float)(int)(f * 4.0f) * 0.25f : f;
}

static void clip_cases(void) {
    for (int c = 0; c < 20000; c++) {
        kdr_bounds box, cbox[2], bb[2][2];
        float tri[9];
        for (int k = 0; k < 3; k++) {
            box.min[k] = grid_or_free(-2.0f, 0.0f);
            box.max[k] = grid_or_free(0.0f, 2.0f);
            if (box.max[k] <= box.min[k])
                box.max[k] = box.min[k] + 0.5f;
        }
        for (int i = 0; i < 9; i++)
            tri[i] = grid_or_free(-3.0f, 3.0f);
        if (c % 7 == 0) /* a sliver */
            for (int k = 0; k < 3; k++)
                tri[6 + k] = tri[k] + rng_f(-1e-6f, 1e-6f);
        const int axis = (int)(rng_u32() % 3);
        float pos = grid_or_free(box.min[axis], box.max[axis]);
        pos = pos < box.min[axis] ? box.min[axis] : pos > box.max[axis] ? box.max[axis] : pos;
        cbox[0] = cbox[1] = box;
        cbox[0].max[axis] = cbox[1].min[axis] = pos;
        const unsigned s0 = kd_clip_tri(tri, &box, axis, pos, cbox, bb[0]);
        const unsigned s1 = kd_clip_tri_avx512(tri, &box, axis, pos, cbox, bb[1]);
        EXPECT(s0 == s1);
        for (int side = 0; side < 2; side++)
            if (s0 == s1 && (s0 >> side) & 1u)
                EXPECT(memcmp(&bb[0][side], &bb[1][side], sizeof(kdr_bounds)) == 0);
    }
}

int main(void) {
    const int avx512 = kd_cpu_has_avx512();
    if (avx512)
        clip_cases();
    sort_cases(avx512);
    if (avx512)
        partition_cases();
    for (int i = 0; i < 2; i++)
        arrays[i] = malloc(4 * (2 * MAXN + KD_GROUP_PAD) * sizeof(uint32_t));
    static const int spreads[] = {1, 3, 16, 200, 100000};
    int cases = 0;
    for (size_t ntri = 0; ntri <= 70; ntri++)
        for (int s = 0; s < 5; s++, cases++)
            one_case(ntri, spreads[s], avx512);
    for (int i = 0; i < 300; i++, cases++)
        one_case(1 + rng_u32() % MAXN, spreads[i % 5], avx512);
    printf("AVX-512: %s\n", avx512 ? "yes (kernels compared)" : "no (scalar kernels only)");
    free(arrays[0]);
    free(arrays[1]);
    if (failures)
        fprintf(stderr, "test_core_build_simd: %d failures in %d cases\n", failures, cases);
    else
        printf("test_core_build_simd: ok (%d cases)\n", cases);
    return failures != 0;
}
