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
 * before its end event. */
static size_t classify(builder *b, const ev_list *ev, const kd_split *s) {
    if (grow((void **)&b->both, &b->both_cap, ev->ntri + 1, sizeof *b->both))
        return (size_t)-1;
    const kd_event *e = ev->e[s->axis];
    const uint32_t split_key = float_key(s->pos + 0.0f);
    uint8_t *side = b->side;
    size_t nboth = 0;
    for (size_t i = 0; i < ev->n[s->axis]; i++) {
        const uint32_t key = ev_key(e[i]), tri = ev_tri(e[i]);
        switch (ev_type(e[i])) {
        case EV_START:
            side[tri] = key >= split_key ? SIDE_RIGHT : SIDE_BOTH;
            break;
        case EV_END:
            if (key <= split_key)
                side[tri] = SIDE_LEFT;
            else if (side[tri] == SIDE_BOTH)
                b->both[nboth++] = tri;
            break;
        default: /* planar */
            side[tri] = (key < split_key || (key == split_key && s->planar_left))
                            ? SIDE_LEFT
                            : SIDE_RIGHT;
        }
    }
    return nboth;
}

/* Merges sorted add[0..nadd) into dst, whose old sorted events sit at
 * dst[nadd .. nadd+nold); the write index never passes the read index. */
static void merge_tail(kd_event *dst, size_t nadd, size_t nold,
                       const kd_event *add) {
    size_t i = nadd, j = 0, w = 0;
    const size_t end = nadd + nold;
    while (j < nadd) {
        if (i < end && dst[i] <= add[j])
            dst[w++] = dst[i++];
        else
            dst[w++] = add[j++];
    }
}

/* Sorts up to RANK_MAX events by rank: each one's place is the number of
 * smaller keys (keys are unique, so the ranks are a permutation). n * n
 * compares, but without a branch on the data: the lists of straddlers'
 * events are mostly 8-256 long, where a comparison sort's branches
 * mispredict about every other compare. */
#define RANK_MAX 32
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
 * quicksort down to pieces of RANK_MAX, then rank_sort. */
void kd_sort_events(kd_event *a, size_t n) {
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
        kd_sort_events(a, j + 1);
        a += j + 1;
        n -= j + 1;
    }
    rank_sort(a, n);
}

/* Partitions the node's events into the two children (kept in order,
 * branch-free) and merges in the straddlers' new events. The children live
 * in this depth's scratch buffer: a subtree only writes deeper buffers. */
int kd_split_events(builder *b, const ev_list *ev, const kd_split *s,
                    const kdr_bounds *box, const kdr_bounds cbox[2], int depth,
                    ev_list ch[2]) {
    const size_t nboth = classify(b, ev, s);
    if (nboth == (size_t)-1)
        return KDR_ENOMEM;
    const size_t stride = 2 * nboth + 1;
    if (grow((void **)&b->add, &b->add_cap, 6 * stride, sizeof *b->add))
        return KDR_ENOMEM;
    kd_event *add[6];
    size_t nadd[6] = {0, 0, 0, 0, 0, 0}, ntri[2] = {0, 0};
    for (int k = 0; k < 6; k++)
        add[k] = b->add + (size_t)k * stride;
    kd_clip_both(b, nboth, box, s, cbox, add, nadd, ntri);
    size_t need = 0;
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
        for (size_t i = 0; i < ev->n[k]; i++) {
            const kd_event e = ev->e[k][i];
            const uint8_t sd = b->side[ev_tri(e)];
            *w[0] = e;
            *w[1] = e;
            w[0] += sd == SIDE_LEFT;
            w[1] += sd == SIDE_RIGHT;
            if (k == 0 && ev_type(e) != EV_END) {
                ntri[0] += sd == SIDE_LEFT;
                ntri[1] += sd == SIDE_RIGHT;
            }
        }
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
