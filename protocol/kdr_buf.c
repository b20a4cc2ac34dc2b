/*
 * kdr_buf.c — the growing output buffer every encoder writes into, the
 * protocol error struct, and the RFC 7807 problem+json body. Buffers grow
 * geometrically so that multi-megabyte responses cost amortised O(1) per
 * byte and can be handed to libmicrohttpd as one malloc'd block.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_proto_internal.h"

/* First allocation; later ones double. */
#define KDR_BUF_MIN_CAP 256

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
    char *data = realloc(b->data, cap);
    if (!data)
        return KDR_ENOMEM;
    b->data = data;
    b->cap = cap;
    return 0;
}

int kdr_buf_reserve_exact(kdr_buf *b, size_t extra) {
    if (extra <= b->cap - b->len)
        return 0;
    if (extra > SIZE_MAX - b->len)
        return KDR_ENOMEM;
    char *data = realloc(b->data, b->len + extra);
    if (!data)
        return KDR_ENOMEM;
    b->data = data;
    b->cap = b->len + extra;
    return 0;
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
