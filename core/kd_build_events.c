/*
 * kd_build_events.c — the event lists of the SAH build (kd_build.h): the
 * root's lists are sorted once (LSD radix sort on the key); a split then
 * partitions each list into the children's in order, and only the
 * triangles that straddle the plane get new events, which are clipped
 * (kd_build_clip.c), sorted and merged in. This is what makes the build
 * O(N log N) (Wald and Havran 2006). The children's lists live in a
 * scratch buffer per depth: the build is depth-first, so a subtree only
 * ever writes the buffers below it.
 */
#include <stdlib.h>
#include <string.h>

#include "kd_build.h"

void kd_ev_free(ev_list *l) {
    for (int k = 0; k < 3; k++) {
        free(l->e[k]);
        l->e[k] = NULL;
    }
}

/* LSD radix sort on bits 30..63 (position and type); stable, so events
 * generated in triangle order end up in full key order. */
void kd_radix_sort(kd_event *a, kd_event *tmp, size_t n) {
    static const int shift[3] = {30, 41, 52};
    static const int bits[3] = {11, 11, 12};
    size_t count[1u << 12];
    for (int pass = 0; pass < 3; pass++) {
        const size_t nb = (size_t)1 << bits[pass];
        const uint64_t mask = nb - 1;
        memset(count, 0, nb * sizeof *count);
        for (size_t i = 0; i < n; i++)
            count[(a[i] >> shift[pass]) & mask]++;
        size_t sum = 0;
        for (size_t b = 0; b < nb; b++) {
            size_t c = count[b];
            count[b] = sum;
            sum += c;
        }
        for (size_t i = 0; i < n; i++)
            tmp[count[(a[i] >> shift[pass]) & mask]++] = a[i];
        memcpy(a, tmp, n * sizeof *a);
    }
}

/* ---- splitting the event lists ------------------------------------------------ */

/* Makes *p hold at least need elements; the old contents are dead. */
static int grow(void **p, size_t *cap, size_t need, size_t elem) {
    if (need <= *cap)
        return KDR_OK;
    size_t c = *cap ? *cap : 4096;
    while (c < need)
        c *= 2;
    free(*p);
    *p = malloc(c * elem);
    *cap = *p ? c : 0;
    return *p ? KDR_OK : KDR_ENOMEM;
}

/* Marks each triangle of the node LEFT, RIGHT or BOTH and gathers the BOTH
 * ones in b->both; returns their count, or (size_t)-1 without memory.
 * One pass over the split axis suffices: a triangle's start event comes
 * before its end event. Without branches on the event: start, end and
 * planar events interleave at random, so a switch on the type mispredicted
 * about once an event; each event computes all three outcomes and keeps
 * one (b->side is zeroed once, so the value read for a start event is
 * defined even though it is not used). */
static size_t classify(builder *b, const ev_list *ev, const kd_split *s,
                       size_t *nleft) {
    if (grow((void **)&b->both, &b->both_cap, ev->ntri + 1, sizeof *b->both))
        return (size_t)-1;
    const kd_event *e = ev->e[s->axis];
    const uint32_t split_key = float_key(s->pos + 0.0f);
    const int planar_left = s->planar_left != 0;
    uint8_t *side = b->side;
    uint32_t *both = b->both;
    size_t nboth = 0, nl = 0;
    for (size_t i = 0; i < ev->n[s->axis]; i++) {
        const uint32_t key = ev_key(e[i]), tri = ev_tri(e[i]);
        const unsigned type = ev_type(e[i]);
        const uint8_t old = side[tri];
        const int le = key <= split_key;
        const uint8_t v_start = key >= split_key ? SIDE_RIGHT : SIDE_BOTH;
        const uint8_t v_end = le ? SIDE_LEFT : old;
        const uint8_t v_planar =
            (key < split_key || (key == split_key && planar_left)) ? SIDE_LEFT
                                                                   : SIDE_RIGHT;
        /* masks, not ?: -- the compiler turned the select into branches */
        const uint8_t m_start = (uint8_t)-(type == EV_START);
        const uint8_t m_end = (uint8_t)-(type == EV_END);
        side[tri] = (uint8_t)((v_start & m_start) | (v_end & m_end) |
                              (v_planar & (uint8_t)~(m_start | m_end)));
        both[nboth] = tri;
        nboth += (type == EV_END) & !le & (old == SIDE_BOTH);
        /* a triangle's side is final at its end or planar event */
        nl += ((type == EV_END) & le) | ((type == EV_PLANAR) & (v_planar == SIDE_LEFT));
    }
    *nleft = nl;
    return nboth;
}

/* The number of events of a[0..n) smaller than x (a sorted), without a
 * branch on the data: each step keeps the half that holds the answer. */
static size_t count_below(const kd_event *a, size_t n, kd_event x) {
    if (n == 0)
        return 0;
    const kd_event *base = a;
    while (n > 1) {
        const size_t half = n / 2;
        base += half & ((size_t)0 - (size_t)(base[half - 1] < x));
        n -= half;
    }
    return (size_t)(base - a) + (*base < x);
}

/* Few new events among many old ones: each new event's place is found by
 * count_below and the old run before it moves down in one memmove (the
 * merge loop below pays a dependent load and compare for every old event
 * up to the last new one, ~7 cycles each). */
#define GALLOP_RATIO 16

/* Merges sorted add[0..nadd) into dst, whose old sorted events sit at
 * dst[nadd .. nadd+nold); the write index never passes the read index
 * (old events move down, never over one not yet read). The old events
 * before the first new one only move down (memmove); old events after the
 * last new one are already in place. */
static void merge_tail(kd_event *dst, size_t nadd, size_t nold,
                       const kd_event *add) {
    if (nadd == 0)
        return;
    const kd_event *old = dst + nadd;
    if (nadd * GALLOP_RATIO <= nold) {
        size_t i = 0, w = 0;
        for (size_t j = 0; j < nadd; j++) {
            const size_t r = i + count_below(old + i, nold - i, add[j]);
            memmove(dst + w, old + i, (r - i) * sizeof *dst);
            w += r - i;
            i = r;
            dst[w++] = add[j];
        }
        return;
    }
    const size_t p = count_below(old, nold, add[0]);
    memmove(dst, old, p * sizeof *dst);
    /* Branch-free (the order of old and new events is random): dst[end] is
     * read but not used, so the buffer holds one event more than the lists. */
    size_t i = nadd + p, j = 0, w = p;
    const size_t end = nadd + nold;
    while (j < nadd) {
        const kd_event x = dst[i], y = add[j];
        const int o = (i < end) & (x <= y);
        const kd_event m = (kd_event)0 - (kd_event)o; /* mask: ?: made a branch */
        dst[w++] = (x & m) | (y & ~m);
        i += o;
        j += !o;
    }
}

/* Sorts up to RANK_MAX events by rank: each one's place is the number of
 * smaller keys (keys are unique, so the ranks are a permutation). n * n
 * compares, but without a branch on the data: the lists of straddlers'
 * events are mostly 8-256 long, where a comparison sort's branches
 * mispredict about every other compare. (Padding the inner loop to a
 * fixed 8, 16 or 32 keys, so that its exit is predicted, was slower on an
 * engine build's captured lists: 23 against 19 ms.) */
static void rank_sort(kd_event *a, size_t n) {
    kd_event tmp[RANK_MAX];
    memcpy(tmp, a, n * sizeof *a);
    for (size_t i = 0; i < n; i++) {
        const kd_event x = tmp[i];
        size_t r = 0;
        for (size_t j = 0; j < n; j++)
            r += tmp[j] < x;
        a[r] = x;
    }
}

/* Sorts the few new events of straddling triangles (keys are unique):
 * quicksort down to pieces of RANK_MAX, then rank_sort (or its AVX-512
 * twin, which counts the smaller keys 8 per compare). */
void kd_sort_events(kd_event *a, size_t n, int avx512) {
    while (n > RANK_MAX) {
        kd_event x = a[0], y = a[n / 2], z = a[n - 1];
        kd_event p = x < y ? (y < z ? y : (x < z ? z : x)) : (x < z ? x : (y < z ? z : y));
        size_t i = 0, j = n - 1;
        for (;;) {
            while (a[i] < p)
                i++;
            while (a[j] > p)
                j--;
            if (i >= j)
                break;
            kd_event t = a[i];
            a[i++] = a[j];
            a[j--] = t;
        }
        kd_sort_events(a, j + 1, avx512);
        a += j + 1;
        n -= j + 1;
    }
    if (avx512)
        kd_rank_sort_avx512(a, n);
    else
        rank_sort(a, n);
}

/* Partitions the node's events into the two children (kept in order,
 * branch-free) and merges in the straddlers' new events. The children live
 * in this depth's scratch buffer: a subtree only writes deeper buffers. */
int kd_split_events(builder *b, const ev_list *ev, const kd_split *s,
                    const kdr_bounds *box, const kdr_bounds cbox[2], int depth,
                    ev_list ch[2]) {
    size_t nleft;
    const size_t nboth = classify(b, ev, s, &nleft);
    if (nboth == (size_t)-1)
        return KDR_ENOMEM;
    const size_t stride = 2 * nboth + 1;
    if (grow((void **)&b->add, &b->add_cap, 6 * stride, sizeof *b->add))
        return KDR_ENOMEM;
    kd_event *add[6];
    /* the straddlers kept on each side are added by kd_clip_both */
    size_t nadd[6] = {0, 0, 0, 0, 0, 0}, ntri[2] = {nleft, ev->ntri - nleft - nboth};
    for (int k = 0; k < 6; k++)
        add[k] = b->add + (size_t)k * stride;
    kd_clip_both(b, nboth, box, s, cbox, add, nadd, ntri);
    size_t need = 1; /* merge_tail reads one past the last list */
    for (int k = 0; k < 3; k++)
        need += 2 * ev->n[k] + nadd[k] + nadd[3 + k];
    if (grow((void **)&b->lvl[depth], &b->lvl_cap[depth], need, sizeof(kd_event)))
        return KDR_ENOMEM;
    kd_event *base = b->lvl[depth];
    for (int k = 0; k < 3; k++) {
        kd_event *w[2];
        for (int side = 0; side < 2; side++) {
            ch[side].e[k] = base;
            w[side] = base + nadd[3 * side + k];
            base += ev->n[k] + nadd[3 * side + k];
        }
        const kd_event *in = ev->e[k];
        const uint8_t *side = b->side;
        kd_event *w0 = w[0], *w1 = w[1];
        const size_t n = ev->n[k];
        /* SIDE_LEFT is bit 0 and SIDE_RIGHT bit 1: with sd == SIDE_LEFT and
         * sd == SIDE_RIGHT gcc 12 saw that only one can hold and branched */
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
        for (int side = 0; side < 2; side++) {
            const size_t na = nadd[3 * side + k];
            const size_t nold = (size_t)(w[side] - ch[side].e[k]) - na;
            merge_tail(ch[side].e[k], na, nold, add[3 * side + k]);
            ch[side].n[k] = na + nold;
        }
    }
    ch[0].ntri = ntri[0];
    ch[1].ntri = ntri[1];
    return KDR_OK;
}
