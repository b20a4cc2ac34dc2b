/*
 * thp_smaps.h — is memory huge-page eligible? Reads the entry of
 * /proc/self/smaps that holds an address (its VmFlags "hg": the mapping
 * was advised with MADV_HUGEPAGE; THPeligible: the kernel would back it
 * with transparent huge pages), any one field of it, and the machine's THP
 * mode. Linux only; header-only for test_core_mem.c, test_tree_cache_mem.c
 * and the two memory benchmarks (bench_cache_mem.c, bench_rival_mem.c).
 */
#ifndef KDRAY_TESTS_THP_SMAPS_H
#define KDRAY_TESTS_THP_SMAPS_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define THP_HUGE_PAGE ((uintptr_t)2 << 20)

typedef struct thp_vma {
    int found;
    int eligible;   /* THPeligible value, -1 when the kernel does not print it */
    int advised;    /* "hg" in VmFlags */
    char perms[5];  /* "r--p" and so on */
    long rss_kb;    /* resident kB of the whole mapping */
} thp_vma;

/* The smaps entry of the mapping holding addr. */
static inline thp_vma thp_vma_of(const void *addr) {
    thp_vma v = {0, -1, 0, "", -1};
    FILE *f = fopen("/proc/self/smaps", "r");
    if (!f)
        return v;
    const uintptr_t a = (uintptr_t)addr;
    char line[512];
    int inside = 0;
    while (fgets(line, sizeof line, f)) {
        unsigned long lo, hi;
        char dash, perms[5];
        if (sscanf(line, "%lx%c%lx %4s ", &lo, &dash, &hi, perms) == 4 && dash == '-') {
            if (inside)
                break; /* the next mapping: ours is complete */
            inside = a >= lo && a < hi;
            if (inside) {
                v.found = 1;
                memcpy(v.perms, perms, sizeof v.perms);
            }
            continue;
        }
        if (!inside)
            continue;
        int e;
        long kb;
        if (sscanf(line, "THPeligible: %d", &e) == 1)
            v.eligible = e;
        else if (sscanf(line, "Rss: %ld kB", &kb) == 1)
            v.rss_kb = kb;
        else if (strncmp(line, "VmFlags:", 8) == 0)
            v.advised = strstr(line, " hg") != NULL;
    }
    fclose(f);
    return v;
}

/* kB of one field ("Rss", "AnonHugePages", "FilePmdMapped", ...) of the
 * smaps entry holding addr, or of the whole process (smaps_rollup) when
 * addr is NULL; -1 when the file or the field is missing. */
static inline long thp_smaps_kb(const void *addr, const char *field) {
    FILE *f = fopen(addr ? "/proc/self/smaps" : "/proc/self/smaps_rollup", "r");
    if (!f)
        return -1;
    char line[512];
    int inside = addr == NULL;
    long kb = -1;
    const size_t n = strlen(field);
    while (fgets(line, sizeof line, f)) {
        unsigned long lo, hi;
        char dash;
        if (addr && sscanf(line, "%lx%c%lx ", &lo, &dash, &hi) == 3 && dash == '-') {
            if (inside)
                break;
            inside = (uintptr_t)addr >= lo && (uintptr_t)addr < hi;
            continue;
        }
        if (inside && strncmp(line, field, n) == 0 && line[n] == ':')
            kb = strtol(line + n + 1, NULL, 10);
    }
    fclose(f);
    return kb;
}

/* 0 when THP is off (mode never) or unknown; the mode line into mode[]. */
static inline int thp_possible(char *mode, size_t len) {
    snprintf(mode, len, "(unreadable)");
    FILE *f = fopen("/sys/kernel/mm/transparent_hugepage/enabled", "r");
    if (!f)
        return 0;
    if (!fgets(mode, (int)len, f))
        snprintf(mode, len, "(empty)");
    fclose(f);
    mode[strcspn(mode, "\n")] = '\0';
    return strstr(mode, "[never]") == NULL;
}

#define THP_OFF_MESSAGE                                                                  \
    "transparent huge pages are off on this machine "                                  \
    "(/sys/kernel/mm/transparent_hugepage/enabled: %s): a scene's arrays cannot be "   \
    "huge pages; set the mode to madvise or always (docs/OPERATIONS.md)\n"

#endif
