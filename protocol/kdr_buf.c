/*
 * kdr_buf.c — the growing output buffer every encoder writes into, the
 * large blocks a request body or an answer lives in (kdr_block_alloc), the
 * protocol error struct, and the RFC 7807 problem+json body. Buffers grow
 * geometrically so that multi-megabyte responses cost amortised O(1) per
 * byte and can be handed to libmicrohttpd as one malloc'd block.
 *
 * A 1M-ray answer or body is 16-24 MiB written once into fresh memory and
 * freed after one request. In 4 KiB pages that is 4000-6000 first-touch
 * faults on the way in and as many pages unmapped on the way out: issue
 * 16's svc8 round found them behind most of a frustum answer's "encode"
 * time (perf record -e page-faults on kdrayd: 79 % in the encoder's
 * memcpy, the rest in the trace writing its result arrays) and 2.4 ms per
 * munmap (strace -c). So a block of at least KDR_BLOCK_HUGE_MIN comes
 * 2 MiB-aligned in whole 2 MiB pages, advised MADV_HUGEPAGE before it is
 * touched (as core/kd_mem.c does for the scene arrays): with THP in
 * `madvise` mode (Debian's default) it faults 2 MiB at a time. It is still
 * malloc's memory (posix_memalign), so free() and realloc() take it and no
 * owner of a body or an answer needs to know how it was allocated.
 *
 * Only up to KDR_BLOCK_HUGE_MAX: with the 2 MiB of alignment slack such a
 * block stays within kdrayd's 32 MiB mmap threshold (server/main.c), so it
 * is kept in the heap and reused warm. A larger one is mapped fresh for
 * every request, and on this machine a cold 2 MiB page sometimes costs far
 * more than its 4 KiB pages: a 1M-ray closest answer in JSON numbers
 * (31 MB written into a ~70 MB bound) encoded in 213-532 ms as a huge block
 * against 185-213 ms in malloc's pages (three requests each, alternated).
 */
#define _DEFAULT_SOURCE /* madvise, MADV_HUGEPAGE, posix_memalign */
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_proto_internal.h"

#if defined(__linux__)
#include <sys/mman.h>
#endif

/* First allocation; later ones double. */
#define KDR_BUF_MIN_CAP 256
#define KDR_HUGE_PAGE ((size_t)2 << 20)

/* Whole huge pages only where kdr_block_alloc takes them. */
static int block_is_huge(size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    return bytes >= KDR_BLOCK_HUGE_MIN && bytes <= KDR_BLOCK_HUGE_MAX;
#else
    return 0;
#endif
}

size_t kdr_block_size(size_t bytes) {
    return block_is_huge(bytes) ? (bytes + KDR_HUGE_PAGE - 1) & ~(KDR_HUGE_PAGE - 1)
                                : bytes;
}

void *kdr_block_alloc(size_t bytes, size_t *usable) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (block_is_huge(bytes)) {
        const size_t whole = kdr_block_size(bytes);
        void *p = NULL;
        if (posix_memalign(&p, KDR_HUGE_PAGE, whole) == 0) {
            (void)madvise(p, whole, MADV_HUGEPAGE); /* a hint: else 4 KiB pages */
            if (usable) *usable = whole;
            return p;
        }
    }
#endif
    void *p = malloc(bytes ? bytes : 1);
    if (usable) *usable = p ? bytes : 0;
    return p;
}

/* b's data moved to a block of at least cap bytes: realloc below
 * KDR_BLOCK_HUGE_MIN, a fresh block (and a copy) from it on. */
static int buf_resize(kdr_buf *b, size_t cap) {
    if (cap < KDR_BLOCK_HUGE_MIN) {
        char *data = realloc(b->data, cap);
        if (!data)
            return KDR_ENOMEM;
        b->data = data;
        b->cap = cap;
        return 0;
    }
    size_t usable;
    char *data = kdr_block_alloc(cap, &usable);
    if (!data)
        return KDR_ENOMEM;
    if (b->len)
        memcpy(data, b->data, b->len);
    free(b->data);
    b->data = data;
    b->cap = usable;
    return 0;
}

void kdr_buf_init(kdr_buf *b) { memset(b, 0, sizeof *b); }

void kdr_buf_free(kdr_buf *b) {
    free(b->data);
    memset(b, 0, sizeof *b);
}

int kdr_buf_reserve(kdr_buf *b, size_t extra) {
    if (extra <= b->cap - b->len)
        return 0;
    if (extra > SIZE_MAX / 2 - b->len)
        return KDR_ENOMEM;
    size_t cap = b->cap ? b->cap : KDR_BUF_MIN_CAP;
    while (cap - b->len < extra)
        cap *= 2;
    return buf_resize(b, cap);
}

int kdr_buf_reserve_exact(kdr_buf *b, size_t extra) {
    if (extra <= b->cap - b->len)
        return 0;
    if (extra > SIZE_MAX - b->len)
        return KDR_ENOMEM;
    return buf_resize(b, b->len + extra);
}

int kdr_buf_append(kdr_buf *b, const void *bytes, size_t n) {
    if (kdr_buf_reserve(b, n))
        return KDR_ENOMEM;
    if (n)
        kdr_buf_put(b, bytes, n);
    return 0;
}

const char *kdr_buf_cstr(kdr_buf *b) {
    if (kdr_buf_reserve(b, 1))
        return NULL;
    b->data[b->len] = '\0';
    return b->data;
}

int kdr_buf_json_string(kdr_buf *b, const char *s) {
    static const char hex[] = "0123456789abcdef";
    size_t n = strlen(s);
    /* worst case: every byte becomes \u00XX */
    if (n > (SIZE_MAX - 2) / 6 || kdr_buf_reserve(b, 6 * n + 2))
        return KDR_ENOMEM;
    char *p = b->data + b->len;
    *p++ = '"';
    for (; *s; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\') {
            *p++ = '\\';
            *p++ = (char)c;
        } else if (c < 0x20) {
            memcpy(p, "\\u00", 4);
            p[4] = hex[c >> 4];
            p[5] = hex[c & 15];
            p += 6;
        } else {
            *p++ = (char)c;
        }
    }
    *p++ = '"';
    b->len = (size_t)(p - b->data);
    return 0;
}

/* ---- errors ---------------------------------------------------------------- */

int kdr_proto_error_set(kdr_proto_error *err, int status, const char *fmt, ...) {
    va_list ap;
    err->status = status;
    va_start(ap, fmt);
    vsnprintf(err->detail, sizeof err->detail, fmt, ap);
    va_end(ap);
    return status;
}

const char *kdr_proto_status_title(int status) {
    switch (status) {
    case 400: return "Bad Request";
    case 404: return "Not Found";
    case 405: return "Method Not Allowed";
    case 406: return "Not Acceptable";
    case 413: return "Content Too Large";
    case 415: return "Unsupported Media Type";
    case 500: return "Internal Server Error";
    case 503: return "Service Unavailable";
    default: return "Error";
    }
}

int kdr_proto_encode_error(const kdr_proto_error *err, kdr_buf *out) {
    char head[96];
    /* detail is a fixed array: make sure it is terminated before escaping */
    char detail[sizeof err->detail];
    memcpy(detail, err->detail, sizeof detail);
    detail[sizeof detail - 1] = '\0';
    int n = snprintf(head, sizeof head, "{\"type\":\"about:blank\",\"title\":");
    if (kdr_buf_append(out, head, (size_t)n) ||
        kdr_buf_json_string(out, kdr_proto_status_title(err->status)))
        return KDR_ENOMEM;
    n = snprintf(head, sizeof head, ",\"status\":%d,\"detail\":", err->status);
    if (kdr_buf_append(out, head, (size_t)n) || kdr_buf_json_string(out, detail) ||
        kdr_buf_append(out, "}", 1))
        return KDR_ENOMEM;
    return 0;
}
