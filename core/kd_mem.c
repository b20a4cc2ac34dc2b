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
 * This is the core's only OS call, kept here behind __linux__: elsewhere,
 * for small arrays, or when the aligned allocation fails, it is plain
 * malloc. A failed madvise (a kernel without THP) leaves ordinary pages,
 * which is only slower. Every array from here is freed with free().
 */
#if defined(__linux__)
#define _DEFAULT_SOURCE /* madvise, MADV_HUGEPAGE, posix_memalign */
#include <sys/mman.h>
#endif
#include <stdint.h>
#include <stdlib.h>

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

void *kd_mem_alloc(size_t bytes) {
#if defined(__linux__)
    if (bytes >= KD_HUGE_MIN_BYTES && bytes <= SIZE_MAX - KD_HUGE_PAGE) {
        const size_t whole = (bytes + KD_HUGE_PAGE - 1) & ~(KD_HUGE_PAGE - 1);
        void *p = NULL;
        if (posix_memalign(&p, KD_HUGE_PAGE, whole) == 0) {
            (void)madvise(p, whole, MADV_HUGEPAGE); /* a hint: failure is fine */
#ifdef KD_MEM_ASAN
            /* the rounding is not the caller's: reading it is still a bug */
            ASAN_POISON_MEMORY_REGION((char *)p + bytes, whole - bytes);
#endif
            return p;
        }
    }
#endif
    return malloc(bytes ? bytes : 1);
}
