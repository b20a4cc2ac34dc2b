/*
 * textbuf.h — a growable text buffer for the few bodies the server writes
 * itself (metrics, problem+json fallbacks). Allocation failure is sticky:
 * once set, appends are ignored and kdr_tb_take returns NULL.
 */
#ifndef KDR_SRV_TEXTBUF_H
#define KDR_SRV_TEXTBUF_H

#include <stddef.h>

#include "log.h"

typedef struct kdr_tb {
    char *p;
    size_t len, cap;
    int failed;
} kdr_tb;

void kdr_tb_printf(kdr_tb *tb, const char *fmt, ...) KDR_PRINTF(2, 3);
/* Hands the NUL-terminated text to the caller (free()); NULL on failure. */
char *kdr_tb_take(kdr_tb *tb, size_t *len);

#endif
