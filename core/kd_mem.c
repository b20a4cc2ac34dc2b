/*
 * kd_mem.c — where a scene's large read-mostly arrays come from (triangles,
 * nodes, leaf references: what every walk reads). On large scenes the walks
 * wait on memory, and a good part of that wait is TLB misses: random rays
 * over the 1.09M scene touch ~60 MB spread over 15 000 4 KiB pages, far
 * more than the TLB holds. Embree madvises its BVH memory for transparent
 * huge pages; on a machine whose THP mode is `madvise` (Debian's default)
 * memory that is not advised never gets them. So an array of at least
 * KD_HUGE_MIN_BYTES is allocated 2 MiB-aligned, its size rounded up to
 * whole 2 MiB pages, and advised with MADV_HUGEPAGE before anything touches
 * it, so its first-touch faults can map 2 MiB pages directly.
 *
 * The array gets a mapping of its own (mmap), not heap memory: memory a
 * build just freed back to malloc is already backed by 4 KiB pages, and
 * advice does not convert pages that exist (test_core_mem's test_fresh:
 * with posix_memalign, an 8 MiB array asked for after a 12 MiB heap block
 * was freed came back with all 8 MiB already resident). A small header
 * just below the array says how it was allocated, so kd_mem_free needs no
 * size.
 *
 * The builder's large scratch arrays (kd_scratch_alloc, at the end) are
 * written once each into fresh memory, so on small scenes their first-touch
 * faults were a cost of their own: on haus (36K triangles) a one-thread
 * build touched ~13.6 MB in 3400 4 KiB faults, and the kernel took ~19 % of
 * its samples (perf -e cpu-clock). They take huge pages too, but from the
 * heap (posix_memalign, freed with free): they live only as long as a
 * build step, and a mapping per array cost more at 2 threads than it saved
 * (docs/BUILD.md, round 4).
 *
 * These are the core's only OS calls, kept here behind __linux__:
 * elsewhere, for small arrays, or when the mapping fails, it is plain
 * malloc. A failed madvise (a kernel without THP) leaves ordinary pages,
 * only slower.
 */
#if defined(__linux__)
#define _DEFAULT_SOURCE /* mmap, MAP_ANONYMOUS, madvise, MADV_HUGEPAGE, posix_memalign */
#include <sys/mman.h>
#include <unistd.h>
#endif
#include <stdint.h>
#include <stdlib.h>

#include "kd_build.h"
#include "kd_internal.h"

#if defined(__SANITIZE_ADDRESS__)
#define KD_MEM_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define KD_MEM_ASAN 1
#endif
#endif
#ifdef KD_MEM_ASAN
#include <sanitizer/asan_interface.h>
#endif

#define KD_HUGE_PAGE ((size_t)2 << 20)

/* Just below every array: where its memory starts and how long it is;
 * base NULL for malloc'd memory (the header is then malloc's block). */
typedef struct kd_mem_head {
    void *base;
    size_t len;
} kd_mem_head;
_Static_assert(sizeof(kd_mem_head) == 16, "keeps malloc's 16-byte alignment");

#if defined(__linux__)
/* bytes in a 2 MiB-aligned range of whole 2 MiB pages, the header in the
 * 4 KiB page below it; NULL if the mapping fails */
static void *huge_alloc(size_t bytes) {
    const size_t page = (size_t)sysconf(_SC_PAGESIZE);
    const size_t whole = (bytes + KD_HUGE_PAGE - 1) & ~(KD_HUGE_PAGE - 1);
    const size_t reserve = whole + KD_HUGE_PAGE + page;
    char *raw = mmap(NULL, reserve, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (raw == MAP_FAILED)
        return NULL;
    char *p = (char *)(((uintptr_t)raw + page + KD_HUGE_PAGE - 1) & ~(uintptr_t)(KD_HUGE_PAGE - 1));
    char *base = p - page;
    /* keep [base, p + whole) of [raw, raw + reserve) */
    if (base > raw)
        munmap(raw, (size_t)(base - raw));
    if (raw + reserve > p + whole)
        munmap(p + whole, (size_t)(raw + reserve - (p + whole)));
    (void)madvise(p, whole, MADV_HUGEPAGE); /* a hint: failure is fine */
    kd_mem_head *h = (kd_mem_head *)p - 1;
    h->base = base;
    h->len = (size_t)(p + whole - base);
#ifdef KD_MEM_ASAN
    /* the rounding is not the caller's: reading it is still a bug */
    ASAN_POISON_MEMORY_REGION(p + bytes, whole - bytes);
#endif
    return p;
}
#endif

void *kd_mem_alloc(size_t bytes) {
#if defined(__linux__)
    if (bytes >= KD_HUGE_MIN_BYTES && bytes <= SIZE_MAX / 2) {
        void *p = huge_alloc(bytes);
        if (p)
            return p;
    }
#endif
    if (bytes > SIZE_MAX - sizeof(kd_mem_head))
        return NULL;
    kd_mem_head *h = malloc(sizeof *h + bytes);
    if (!h)
        return NULL;
    h->base = NULL;
    h->len = 0;
    return h + 1;
}

void kd_mem_free(void *p) {
    if (!p)
        return;
    kd_mem_head *h = (kd_mem_head *)p - 1;
    if (!h->base) {
        free(h);
        return;
    }
#if defined(__linux__)
#ifdef KD_MEM_ASAN
    /* a later mapping at this address must not inherit the poison */
    ASAN_UNPOISON_MEMORY_REGION(p, (size_t)((char *)h->base + h->len - (char *)p));
#endif
    munmap(h->base, h->len);
#endif
}

void *kd_scratch_alloc(size_t bytes) {
#if defined(__linux__)
    if (bytes >= KD_SCRATCH_HUGE_MIN && bytes <= SIZE_MAX - KD_HUGE_PAGE) {
        const size_t rounded = (bytes + KD_HUGE_PAGE - 1) & ~(KD_HUGE_PAGE - 1);
        void *p = NULL;
        if (posix_memalign(&p, KD_HUGE_PAGE, rounded) == 0) {
            (void)madvise(p, rounded, MADV_HUGEPAGE);
#ifdef KD_MEM_ASAN
            /* the rounding is not the caller's to use */
            ASAN_POISON_MEMORY_REGION((char *)p + bytes, rounded - bytes);
#endif
            return p;
        }
    }
#endif
    return malloc(bytes ? bytes : 1);
}
