/*
 * textbuf.c — printf-style appends into a doubling buffer.
 */
#include "textbuf.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

enum { TB_MIN_CAP = 4096 };

static int tb_reserve(kdr_tb *tb, size_t extra) {
    if (tb->failed) return 0;
    if (tb->len + extra + 1 <= tb->cap) return 1;
    size_t cap = tb->cap ? tb->cap : TB_MIN_CAP;
    while (cap < tb->len + extra + 1)
        cap *= 2;
    char *p = realloc(tb->p, cap);
    if (!p) {
        tb->failed = 1;
        return 0;
    }
    tb->p = p;
    tb->cap = cap;
    return 1;
}

void kdr_tb_printf(kdr_tb *tb, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n < 0 || !tb_reserve(tb, (size_t)n)) return;
    va_start(ap, fmt);
    vsnprintf(tb->p + tb->len, tb->cap - tb->len, fmt, ap);
    va_end(ap);
    tb->len += (size_t)n;
}

char *kdr_tb_take(kdr_tb *tb, size_t *len) {
    if (!tb_reserve(tb, 0)) {
        free(tb->p);
        *tb = (kdr_tb){0};
        return NULL;
    }
    tb->p[tb->len] = '\0';
    char *p = tb->p;
    *len = tb->len;
    *tb = (kdr_tb){0};
    return p;
}
