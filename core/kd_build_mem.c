/*
 * kd_build_mem.c — where the SAH build's large scratch arrays come from
 * (kd_build.h): the root's event lists and their sort buffers, the
 * per-depth child lists, the straddlers' new events, the split search's
 * groups. A build writes each of them once into fresh memory, so on small
 * scenes the first-touch page faults were a fixed cost of their own: on
 * haus (36K triangles) a one-thread build touched about 13.6 MB, 3400 4 KiB
 * faults, and the kernel took ~19 % of the build's samples (perf -e
 * cpu-clock), page faults and the unmapping of freed buffers.
 *
 * An array of at least KD_SCRATCH_HUGE_MIN bytes is therefore allocated
 * 2 MiB-aligned, rounded up to whole 2 MiB pages and advised
 * MADV_HUGEPAGE before it is touched, so that (THP mode `madvise`, as on
 * Debian) one fault maps 2 MiB. Smaller ones, other systems, or a failed
 * aligned allocation get plain malloc; a failed madvise only leaves small
 * pages. Everything from here is freed with free().
 *
 * core/kd_mem.c (the scene's final arrays) does the same for memory that
 * outlives the build; the two could become one helper.
 */
#if defined(__linux__)
#define _DEFAULT_SOURCE /* madvise, posix_memalign */
#include <sys/mman.h>
#endif
#include <stdint.h>
#include <stdlib.h>

#include "kd_build.h"

#if defined(__SANITIZE_ADDRESS__)
#define KD_SCRATCH_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define KD_SCRATCH_ASAN 1
#endif
#endif
#ifdef KD_SCRATCH_ASAN
#include <sanitizer/asan_interface.h>
#endif

#define HUGE_PAGE ((size_t)2 << 20)

void *kd_scratch_alloc(size_t bytes) {
#if defined(__linux__)
    if (bytes >= KD_SCRATCH_HUGE_MIN && bytes <= SIZE_MAX - HUGE_PAGE) {
        const size_t rounded = (bytes + HUGE_PAGE - 1) & ~(HUGE_PAGE - 1);
        void *p = NULL;
        if (posix_memalign(&p, HUGE_PAGE, rounded) == 0) {
            (void)madvise(p, rounded, MADV_HUGEPAGE);
#ifdef KD_SCRATCH_ASAN
            /* the rounding is not the caller's to use */
            ASAN_POISON_MEMORY_REGION((char *)p + bytes, rounded - bytes);
#endif
            return p;
        }
    }
#endif
    return malloc(bytes ? bytes : 1);
}
