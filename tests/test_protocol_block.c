/*
 * test_protocol_block.c — the blocks a large request body or answer lives
 * in (kdr_block_alloc, protocol/kdr_buf.c; issue 16, svc8 round): from
 * KDR_BLOCK_HUGE_MIN bytes on a block starts on a 2 MiB boundary, spans
 * whole 2 MiB pages and lies in memory advised for transparent huge pages
 * ("hg" in /proc/self/smaps' VmFlags), so a 16-24 MiB answer or body
 * faults in 2 MiB at a time instead of 4000-6000 4 KiB pages. Smaller
 * blocks are plain malloc. Every block is freed with free() and resized
 * with realloc, as the server and the executor do with answers and bodies.
 * kdr_buf's growth and an encoder's one-shot answer buffer take the same
 * blocks, and the bytes written are unchanged.
 *
 * Linux only, and it needs THP: on a machine whose THP mode is `never` the
 * advice is refused (madvise fails) and this test FAILS on the missing "hg"
 * flag instead of passing on a machine where the feature is off.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "kdr_protocol.h"
#include "thp_smaps.h"

/* p .. p + bytes - 1 is 2 MiB-aligned and in advised memory. */
static void check_huge(const char *what, const void *p, size_t bytes) {
    CHECK(p != NULL, "%s: NULL", what);
    if (!p) return;
    CHECK(((uintptr_t)p & (THP_HUGE_PAGE - 1)) == 0,
          "%s (%zu bytes) at %p: not 2 MiB-aligned", what, bytes, p);
    const void *ends[2] = {p, (const char *)p + bytes - 1};
    for (int i = 0; i < 2; i++) {
        const thp_vma v = thp_vma_of(ends[i]);
        CHECK(v.found, "%s: %p not in /proc/self/smaps", what, ends[i]);
        CHECK(v.advised,
              "%s (%zu bytes): %p's mapping lacks the 'hg' VmFlag (no "
              "MADV_HUGEPAGE)",
              what, bytes, ends[i]);
    }
}

static void test_block(void) {
    size_t usable = 0;
    const size_t three = (size_t)3 << 20;
    unsigned char *p = kdr_block_alloc(three, &usable);
    check_huge("3 MiB block", p, three);
    CHECK(usable == (size_t)4 << 20,
          "3 MiB block: usable %zu, want whole 2 MiB pages (4 MiB)", usable);
    /* what the executor charges for a block (svc9) is what it holds */
    CHECK(kdr_block_size(three) == usable && kdr_block_size(100) == 100 &&
              kdr_block_size(KDR_BLOCK_HUGE_MIN) == KDR_BLOCK_HUGE_MIN &&
              kdr_block_size(KDR_BLOCK_HUGE_MAX + 1) == KDR_BLOCK_HUGE_MAX + 1,
          "kdr_block_size(3 MiB) %zu, usable %zu", kdr_block_size(three), usable);
    if (p) {
        memset(p, 0xab, usable);             /* all of it is the caller's */
        unsigned char *q = realloc(p, 1000); /* the executor shrinks answers */
        CHECK(q && q[0] == 0xab && q[999] == 0xab, "realloc of a block lost its bytes");
        free(q ? q : p);
    }
    size_t small_usable = 1;
    void *s = kdr_block_alloc(100, &small_usable);
    CHECK(s && small_usable == 100, "100-byte block: %p, usable %zu", s, small_usable);
    free(s);
    void *z = kdr_block_alloc(0, NULL);
    CHECK(z != NULL, "a 0-byte block is not NULL");
    free(z);
    void *edge = kdr_block_alloc(KDR_BLOCK_HUGE_MIN, &usable);
    check_huge("2 MiB block", edge, KDR_BLOCK_HUGE_MIN);
    CHECK(usable == KDR_BLOCK_HUGE_MIN, "2 MiB block: usable %zu", usable);
    free(edge);
    /* past KDR_BLOCK_HUGE_MAX: malloc's own (mapped fresh, not kept warm) */
    const size_t big = KDR_BLOCK_HUGE_MAX + ((size_t)1 << 20);
    void *over = kdr_block_alloc(big, &usable);
    CHECK(over && usable == big, "block over the maximum: %p, usable %zu (want %zu)",
          over, usable, big);
    free(over);
}

/* A buffer grown by appends past 2 MiB moves into a block, bytes intact. */
static void test_buf_growth(void) {
    kdr_buf b;
    kdr_buf_init(&b);
    uint32_t word[256];
    const size_t total = (size_t)5 << 20;
    uint32_t k = 0;
    int ok = 0;
    while (b.len < total) {
        for (int i = 0; i < 256; i++)
            word[i] = k++;
        if ((ok = kdr_buf_append(&b, word, sizeof word)) != 0) break;
    }
    CHECK(ok == 0, "kdr_buf_append failed at %zu bytes", b.len);
    check_huge("grown kdr_buf", b.data, b.len);
    size_t bad = 0;
    for (size_t i = 0; i < b.len / 4; i++) {
        uint32_t v;
        memcpy(&v, b.data + 4 * i, 4);
        bad += v != (uint32_t)i;
    }
    CHECK(bad == 0, "grown kdr_buf: %zu of %zu words changed in the moves", bad,
          b.len / 4);
    kdr_buf_free(&b);
}

/* A 1M-ray closest answer (16 MiB in CBOR) is written into one block. */
static void test_answer(void) {
    const size_t n = (size_t)1 << 20;
    float *t = malloc(n * sizeof *t), *u = malloc(n * sizeof *u),
          *v = malloc(n * sizeof *v);
    int32_t *prim = malloc(n * sizeof *prim);
    CHECK(t && u && v && prim, "out of memory");
    if (!t || !u || !v || !prim) return;
    for (size_t i = 0; i < n; i++) {
        prim[i] = i % 3 ? (int32_t)i : -1;
        t[i] = (float)i * 0.5f;
        u[i] = 0.25f;
        v[i] = 0.5f;
    }
    kdr_hits h = {.t = t, .prim = prim, .u = u, .v = v};
    kdr_buf out;
    kdr_buf_init(&out);
    const int rc = kdr_proto_encode_hits_fields(&h, n, KDR_CLOSEST, KDR_FIELDS_CLOSEST,
                                                KDR_ENCODING_CBOR, &out);
    CHECK(rc == 0, "encode: %d", rc);
    check_huge("1M-ray CBOR answer", out.data, out.len);
    CHECK(out.len > 16 * n, "answer of %zu bytes, want > %zu", out.len, 16 * n);
    kdr_buf_free(&out);
    free(t), free(u), free(v), free(prim);
}

int main(void) {
    test_block();
    test_buf_growth();
    test_answer();
    return check_exit("test_protocol_block");
}
