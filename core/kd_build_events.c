/*
 * kd_build_events.c — the event lists of the SAH build (kd_build.h): the
 * root's lists are sorted once (LSD radix sort on the key); a split then
 * partitions each list into the children's in order, and only the
 * triangles that straddle the plane get new events, which are clipped
 * (kd_build_clip.c), sorted and merged in. This is what makes the build
 * O(N log N) (Wald and Havran 2006). The children's lists go on a stack
 * per worker: the build is depth-first, so a subtree only ever writes
 * above its own lists, and pops what it pushed. A side that gets new events has its
 * old ones partitioned into a buffer of their own first and merged into
 * place from there (from both ends at once).
 */
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "kd_build.h"

/* LSD radix sort on bits 30..63 (position and type); stable, so events
 * generated in triangle order end up in full key order. The three digits'
 * counts come from one pass over the input, and the three scatter passes
 * go a -> out -> a -> out, so the sorted keys land in out without a copy
 * (the version before read the input once per digit for its counts and
 * copied tmp back after every pass). */
void kd_radix_sort_into(kd_event *a, kd_event *out, size_t n) {
    static const int shift[3] = {30, 41, 52};
    static const size_t nb[3] = {(size_t)1 << 11, (size_t)1 << 11, (size_t)1 << 12};
    size_t count0[1u << 11], count1[1u << 11], count2[1u << 12];
    size_t *count[3] = {count0, count1, count2};
    memset(count0, 0, sizeof count0);
    memset(count1, 0, sizeof count1);
    memset(count2, 0, sizeof count2);
    for (size_t i = 0; i < n; i++) {
        const kd_event e = a[i];
        count0[(e >> 30) & 0x7ff]++;
        count1[(e >> 41) & 0x7ff]++;
        count2[(e >> 52) & 0xfff]++;
    }
    kd_event *src = a, *dst = out;
    for (int pass = 0; pass < 3; pass++) {
        size_t *c = count[pass], sum = 0;
        const uint64_t mask = nb[pass] - 1;
        for (size_t b = 0; b < nb[pass]; b++) {
            const size_t k = c[b];
            c[b] = sum;
            sum += k;
        }
        for (size_t i = 0; i < n; i++)
            dst[c[(src[i] >> shift[pass]) & mask]++] = src[i];
        kd_event *t = src;
        src = dst;
        dst = t;
    }
}

void kd_radix_sort(kd_event *a, kd_event *tmp, size_t n) {
    kd_radix_sort_into(a, tmp, n);
    memcpy(a, tmp, n * sizeof *a);
}

/* ---- splitting the event lists ------------------------------------------------ */

/* Makes *p hold at least need elements; the old contents are dead. In
 * huge pages where the builder says so (kd_scratch_alloc in kd_mem.c, builder.huge). */
static int grow(const builder *b, void **p, size_t *cap, size_t need, size_t elem) {
    if (need <= *cap)
        return KDR_OK;
    size_t c = *cap ? *cap : 4096;
    while (c < need)
        c *= 2;
    free(*p);
    *p = b->huge ? kd_scratch_alloc(c * elem) : malloc(c * elem);
    *cap = *p ? c : 0;
    return *p ? KDR_OK : KDR_ENOMEM;
}

static size_t count_below(const kd_event *a, size_t n, kd_event x);

/* Marks each triangle of the node LEFT, RIGHT or BOTH and gathers the BOTH
 * ones in b->both; returns their count, or (size_t)-1 without memory.
 * One pass over the split axis suffices: a triangle's start event comes
 * before its end event. The list is sorted by key, so it is three runs:
 * below the plane (a start marks BOTH, an end or planar event LEFT), in
 * it (start RIGHT, end LEFT, planar by planar_left) and above it (start
 * and planar RIGHT; an end leaves the mark and its triangle is a
 * straddler when the mark is still BOTH). Each run has its own loop, and
 * inside a run no branch on the event: start, end and planar events
 * interleave at random (a switch on the type mispredicted about once an
 * event). The marks, the straddlers' order and the counts are those of
 * one loop that computes all three outcomes per event (until this
 * round). */
static size_t classify(builder *b, const ev_list *ev, const kd_split *s,
                       size_t *nleft) {
    if (grow(b, (void **)&b->both, &b->both_cap, ev->ntri + 1, sizeof *b->both))
        return (size_t)-1;
    const kd_event *const e = ev->e[s->axis];
    const size_t n = ev->n[s->axis];
    const uint32_t split_key = float_key(s->pos + 0.0f);
    const size_t in_from = count_below(e, n, (kd_event)split_key << 32);
    const size_t above_from =
        split_key == UINT32_MAX ? n : count_below(e, n, (kd_event)(split_key + 1u) << 32);
    const uint8_t planar_side = s->planar_left ? SIDE_LEFT : SIDE_RIGHT;
    uint8_t *const side = b->side;
    uint32_t *const both = b->both;
    size_t nboth = 0, nl = 0;
    for (size_t i = 0; i < in_from; i++) {
        const unsigned notstart = ev_type(e[i]) != EV_START;
        side[ev_tri(e[i])] = (uint8_t)(SIDE_LEFT & -notstart);
        nl += notstart;
    }
    for (size_t i = in_from; i < above_from; i++) {
        const unsigned type = ev_type(e[i]);
        const uint8_t m_start = (uint8_t)-(type == EV_START);
        const uint8_t m_end = (uint8_t)-(type == EV_END);
        const uint8_t v = (uint8_t)((SIDE_RIGHT & m_start) | (SIDE_LEFT & m_end) |
                                    (planar_side & (uint8_t)~(m_start | m_end)));
        side[ev_tri(e[i])] = v;
        nl += v == SIDE_LEFT;
    }
    for (size_t i = above_from; i < n; i++) {
        const uint32_t tri = ev_tri(e[i]);
        const uint8_t old = side[tri];
        const unsigned end = ev_type(e[i]) == EV_END;
        side[tri] = (uint8_t)((old & -end) | (SIDE_RIGHT & (uint8_t)~-end));
        both[nboth] = tri;
        nboth += end & (old == SIDE_BOTH);
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
 * count_below and the old run before it is copied in one memcpy (a merge
 * pays a dependent load and compare for every event). */
#define GALLOP_RATIO 16

/* Merges the sorted old[0..no) and add[0..na) into out (keys are unique:
 * a straddler's old events were dropped). Both inputs have sentinels:
 * old[-1] = add[-1] = 0 below every key, old[no] = add[na] = UINT64_MAX
 * above (no key is either: key 0 would be a NaN position, UINT64_MAX a
 * type 3). Without branches on the data (their order is random), from
 * both ends at once: the front half and the back half are two independent
 * chains of load, compare and select, which the core overlaps (one chain
 * waited ~7 cycles per event on its own loads). */
static void merge_out(kd_event *out, const kd_event *old, size_t no,
                      const kd_event *add, size_t na) {
    if (na * GALLOP_RATIO <= no) {
        size_t i = 0, w = 0;
        for (size_t j = 0; j < na; j++) {
            const size_t r = i + count_below(old + i, no - i, add[j]);
            memcpy(out + w, old + i, (r - i) * sizeof *out);
            w += r - i;
            i = r;
            out[w++] = add[j];
        }
        memcpy(out + w, old + i, (no - i) * sizeof *out);
        return;
    }
    const size_t total = no + na, back = total / 2;
    size_t i = 0, j = 0, w = 0;
    ptrdiff_t ib = (ptrdiff_t)no - 1, jb = (ptrdiff_t)na - 1, wb = (ptrdiff_t)total - 1;
    for (size_t step = 0; step < back; step++) {
        const kd_event x = old[i], y = add[j];
        const size_t tf = x < y;
        const kd_event mf = (kd_event)0 - (kd_event)tf; /* mask: ?: made a branch */
        out[w++] = (x & mf) | (y & ~mf);
        i += tf;
        j += tf ^ 1u;
        const kd_event xb = old[ib], yb = add[jb];
        const ptrdiff_t tb = xb > yb;
        const kd_event mb = (kd_event)0 - (kd_event)tb;
        out[wb--] = (xb & mb) | (yb & ~mb);
        ib -= tb;
        jb -= tb ^ 1;
    }
    if (total - back > back) {
        const kd_event x = old[i], y = add[j];
        out[w] = x < y ? x : y;
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
        if (avx512 && n <= 1024) {
            kd_sort_events_avx512(a, n);
            return;
        }
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

/* Room for need events on top of the worker's stack. The stack is one
 * block per worker, reused by every node and task it builds: the lists of
 * the nodes on the current path are all it holds (a subtree only writes
 * above its own lists), so its size is about the sum of the list sizes
 * down one path. When need does not fit, an empty stack is reallocated
 * (KD_STACK_SLACK times need: room for the path below); a non-empty one
 * cannot move, so the node gets a block of its own (*own). (Until this,
 * every depth had a buffer of its own, grown when a later node of that
 * depth was bigger: haus' one-thread build made 15 allocations of at least
 * 1 MiB, 36 MB in huge pages that the kernel zeroed, for about 8 MB of
 * lists.) */
static kd_event *stack_push(builder *b, size_t need, kd_event **own) {
    *own = NULL;
    if (b->stack_cap - b->stack_top >= need) {
        kd_event *p = b->stack + b->stack_top;
        b->stack_top += need;
        return p;
    }
    if (b->stack_top == 0) {
        free(b->stack);
        b->stack_cap = 0;
        const size_t cap = KD_STACK_SLACK * need;
        b->stack = b->huge ? kd_scratch_alloc(cap * sizeof *b->stack)
                           : malloc(cap * sizeof *b->stack);
        if (!b->stack)
            return NULL;
        b->stack_cap = cap;
        b->stack_top = need;
        return b->stack;
    }
    *own = b->huge ? kd_scratch_alloc(need * sizeof **own)
                   : malloc(need * sizeof **own);
    return *own;
}

void *kd_stack_scratch(builder *b, size_t bytes) {
    const size_t events = (bytes + sizeof(kd_event) - 1) / sizeof(kd_event);
    return b->stack && b->stack_cap - b->stack_top >= events ? b->stack + b->stack_top
                                                             : NULL;
}

void kd_stack_reserve(builder *b, size_t events) {
    if (b->stack_top != 0 || b->stack_cap >= events)
        return;
    free(b->stack);
    const size_t cap = KD_STACK_SLACK * events;
    b->stack = b->huge ? kd_scratch_alloc(cap * sizeof *b->stack)
                       : malloc(cap * sizeof *b->stack);
    b->stack_cap = b->stack ? cap : 0;
}

/* Partitions the node's events into the two children (kept in order,
 * branch-free) and merges in the straddlers' new events. The children go
 * on top of the worker's stack (stack_push); the caller pops them. */
int kd_split_events(builder *b, const ev_list *ev, const kd_split *s,
                    const kdr_bounds *box, const kdr_bounds cbox[2], ev_list ch[2],
                    kd_event **own) {
    size_t nleft;
    const size_t nboth = classify(b, ev, s, &nleft);
    if (nboth == (size_t)-1)
        return KDR_ENOMEM;
    /* each list of new events has a sentinel slot before and after it */
    const size_t stride = 2 * nboth + 2;
    if (grow(b, (void **)&b->add, &b->add_cap, 6 * stride, sizeof *b->add))
        return KDR_ENOMEM;
    kd_event *add[6];
    /* the straddlers kept on each side are added by kd_clip_both */
    size_t nadd[6] = {0, 0, 0, 0, 0, 0}, ntri[2] = {nleft, ev->ntri - nleft - nboth};
    for (int k = 0; k < 6; k++)
        add[k] = b->add + (size_t)k * stride + 1;
    kd_clip_both(b, nboth, box, s, cbox, add, nadd, ntri);
    size_t need = 0, most = 0;
    for (int k = 0; k < 3; k++) {
        add[k][-1] = add[3 + k][-1] = 0;
        add[k][nadd[k]] = add[3 + k][nadd[3 + k]] = UINT64_MAX;
        need += 2 * ev->n[k] + nadd[k] + nadd[3 + k];
        most = ev->n[k] > most ? ev->n[k] : most;
    }
    const size_t mark = b->stack_top;
    kd_event *const start = stack_push(b, need, own);
    if (!start)
        return KDR_ENOMEM;
    kd_event *base = start;
    /* the old events wait above the children's lists while there is room
     * (memory the path below touches anyway), else in a buffer of their own */
    kd_event *oldbuf = kd_stack_scratch(b, 2 * (most + 2) * sizeof(kd_event));
    if (!oldbuf) {
        if (grow(b, (void **)&b->old, &b->old_cap, 2 * (most + 2), sizeof(kd_event))) {
            b->stack_top = mark;
            free(*own);
            *own = NULL;
            return KDR_ENOMEM;
        }
        oldbuf = b->old;
    }
    for (int k = 0; k < 3; k++) {
        /* a side without new events gets its old ones in place; the others
         * in b->old (with sentinel slots), to be merged from there */
        kd_event *w[2], *old[2];
        for (int side = 0; side < 2; side++) {
            ch[side].e[k] = base;
            base += ev->n[k] + nadd[3 * side + k];
            old[side] = nadd[3 * side + k] ? oldbuf + (size_t)side * (most + 2) + 1
                                            : ch[side].e[k];
            w[side] = old[side];
        }
        if (b->avx512)
            kd_partition_avx512(ev->e[k], ev->n[k], b->side, w);
        else
            kd_partition(ev->e[k], ev->n[k], b->side, w);
        for (int side = 0; side < 2; side++) {
            const size_t na = nadd[3 * side + k];
            const size_t no = (size_t)(w[side] - old[side]);
            if (na) {
                old[side][-1] = 0;
                old[side][no] = UINT64_MAX;
                merge_out(ch[side].e[k], old[side], no, add[3 * side + k], na);
            }
            ch[side].n[k] = na + no;
        }
    }
    ch[0].ntri = ntri[0];
    ch[1].ntri = ntri[1];
    /* the stack keeps what the lists use (the last list's room beyond its
     * events is free again) */
    if (!*own)
        b->stack_top = mark + (size_t)(ch[1].e[2] + ch[1].n[2] - start);
    return KDR_OK;
}
