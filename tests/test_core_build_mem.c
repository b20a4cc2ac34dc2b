/*
 * test_core_build_mem.c — the build's scratch allocator (kd_scratch_alloc, core/kd_mem.c).
 *
 * An array of at least KD_SCRATCH_HUGE_MIN bytes must come 2 MiB-aligned,
 * in a mapping advised for transparent huge pages ('hg' among the VmFlags
 * of its /proc/self/smaps entry), and be writable over all of its bytes;
 * smaller arrays (and 0 bytes) must still be usable memory. Written for
 * Linux (where the build asks for huge pages): on a kernel whose THP mode
 * is `never` madvise still sets the flag, so the test only fails when the
 * allocator does not ask.
 */
#define _DEFAULT_SOURCE
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "kd_build.h"

#define MIB ((size_t)1 << 20)

/* The VmFlags line of the smaps entry holding address a; "" if none. */
static void vm_flags_of(const void *a, char *out, size_t cap) {
    FILE *f = fopen("/proc/self/smaps", "r");
    char line[512];
    int inside = 0;
    out[0] = '\0';
    if (!f)
        return;
    while (fgets(line, sizeof line, f)) {
        unsigned long lo, hi;
        if (sscanf(line, "%lx-%lx ", &lo, &hi) == 2 && strchr(line, '-') < strchr(line, ' ')) {
            inside = (uintptr_t)a >= lo && (uintptr_t)a < hi;
            continue;
        }
        if (inside && strncmp(line, "VmFlags:", 8) == 0) {
            const size_t n = strlen(line + 8);
            const size_t m = n < cap - 1 ? n : cap - 1;
            memcpy(out, line + 8, m);
            out[m] = '\0';
            break;
        }
    }
    fclose(f);
}

static void huge_case(size_t bytes) {
    unsigned char *p = kd_scratch_alloc(bytes);
    CHECK(p != NULL, "%zu bytes", bytes);
    if (!p)
        return;
    CHECK(((uintptr_t)p & (2 * MIB - 1)) == 0, "%zu bytes at %p: not 2 MiB-aligned",
          bytes, (void *)p);
    memset(p, 0xab, bytes);
    CHECK(p[0] == 0xab && p[bytes - 1] == 0xab, "%zu bytes", bytes);
    char flags[512];
    vm_flags_of(p, flags, sizeof flags);
    CHECK(strstr(flags, " hg") != NULL, "%zu bytes: VmFlags '%s' lack hg", bytes, flags);
    free(p);
}

int main(void) {
    huge_case(KD_SCRATCH_HUGE_MIN);
    huge_case(3 * MIB + 8);
    huge_case(9 * MIB);
    static const size_t small[] = {0, 1, 4096, KD_SCRATCH_HUGE_MIN - 1};
    for (size_t i = 0; i < sizeof small / sizeof *small; i++) {
        unsigned char *p = kd_scratch_alloc(small[i]);
        CHECK(p != NULL, "%zu bytes", small[i]);
        if (p && small[i])
            memset(p, 1, small[i]);
        free(p);
    }
    return check_exit("test_core_build_mem");
}
