/*
 * float_exhaustive.c — all 2^32 float32 bit patterns through
 * kdr_format_float: every finite one must read back bit for bit through
 * strtof and through strtod-then-float (the double path of most JSON
 * readers) and be no longer than the pre-Dragonbox printer's text
 * (tests/support/old_codecs.c); NaN and infinities must print null. Not a
 * ctest (minutes of CPU): run by hand after touching kdr_float.c,
 *   build/tests/float_exhaustive [threads]
 * Prints the counts and exits 1 on any failure.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_protocol.h"
#include "old_codecs.h"

typedef struct part {
    uint64_t first, last; /* [first, last) */
    uint64_t bad, longer, shorter, differ;
} part;

static void *run(void *arg) {
    part *p = arg;
    char a[KDR_FLOAT_CHARS + 1], b[KDR_FLOAT_CHARS + 1];
    for (uint64_t k = p->first; k < p->last; k++) {
        const uint32_t bits = (uint32_t)k;
        float f;
        memcpy(&f, &bits, 4);
        const size_t la = kdr_format_float(f, a);
        a[la] = '\0';
        if (!isfinite(f)) {
            p->bad += strcmp(a, "null") != 0;
            continue;
        }
        const float back = strtof(a, NULL), via_double = (float)strtod(a, NULL);
        if (memcmp(&back, &f, 4) || memcmp(&via_double, &f, 4)) {
            if (p->bad++ < 5)
                fprintf(stderr, "%08x: %s reads back as %a (through a double: %a)\n",
                        (unsigned)bits, a, (double)back, (double)via_double);
        }
        const size_t lb = old_format_float(f, b);
        b[lb] = '\0';
        p->longer += la > lb;
        p->shorter += la < lb;
        p->differ += la == lb && strcmp(a, b) != 0;
    }
    return NULL;
}

int main(int argc, char **argv) {
    int nt = argc > 1 ? atoi(argv[1]) : 2;
    if (nt < 1 || nt > 64)
        nt = 2;
    part parts[64];
    pthread_t th[64];
    const uint64_t total = 1ull << 32;
    for (int i = 0; i < nt; i++) {
        parts[i] = (part){total * i / nt, total * (i + 1) / nt, 0, 0, 0, 0};
        pthread_create(&th[i], NULL, run, &parts[i]);
    }
    uint64_t bad = 0, longer = 0, shorter = 0, differ = 0;
    for (int i = 0; i < nt; i++) {
        pthread_join(th[i], NULL);
        bad += parts[i].bad, longer += parts[i].longer;
        shorter += parts[i].shorter, differ += parts[i].differ;
    }
    printf("float_exhaustive: %llu patterns: %llu failed round trips or null, %llu "
           "longer than the old printer, %llu shorter, %llu same length other digits\n",
           (unsigned long long)total, (unsigned long long)bad, (unsigned long long)longer,
           (unsigned long long)shorter, (unsigned long long)differ);
    return bad || longer ? 1 : 0;
}
