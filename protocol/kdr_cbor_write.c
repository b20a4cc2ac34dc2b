/*
 * kdr_cbor_write.c — the pieces of CBOR (RFC 8949) an answer is made of:
 * map and item heads in preferred (shortest) serialization, written by
 * libcbor's encoders (Debian libcbor-dev) straight into a kdr_buf, and the
 * head of an RFC 8746 typed array (tag + byte-string head) whose payload
 * the caller then writes in place, a chunk at a time if it likes. No tree
 * is built: an answer of millions of rays is a few heads and raw arrays.
 */
#include <cbor.h>
#include <stdint.h>

#include "kdr_proto_internal.h"

/* A head is at most 9 bytes (initial byte + 8-byte argument). */
#define KDR_CBOR_HEAD_MAX 9

typedef size_t (*head_fn)(size_t, unsigned char *, size_t);

static int put_head(kdr_buf *b, head_fn fn, size_t v) {
    if (kdr_buf_reserve(b, KDR_CBOR_HEAD_MAX))
        return KDR_ENOMEM;
    b->len += fn(v, (unsigned char *)b->data + b->len, KDR_CBOR_HEAD_MAX);
    return 0;
}

int kdr_cbor_map(kdr_buf *b, size_t entries) {
    return put_head(b, cbor_encode_map_start, entries);
}

int kdr_cbor_text(kdr_buf *b, const char *s) {
    const size_t n = strlen(s);
    return put_head(b, cbor_encode_string_start, n) || kdr_buf_append(b, s, n);
}

int kdr_cbor_uint(kdr_buf *b, uint64_t v) {
    if (kdr_buf_reserve(b, KDR_CBOR_HEAD_MAX))
        return KDR_ENOMEM;
    b->len += cbor_encode_uint(v, (unsigned char *)b->data + b->len, KDR_CBOR_HEAD_MAX);
    return 0;
}

int kdr_cbor_typed_head(kdr_buf *b, uint64_t tag, size_t nbytes) {
    if (nbytes > SIZE_MAX - 2 * KDR_CBOR_HEAD_MAX ||
        kdr_buf_reserve(b, 2 * KDR_CBOR_HEAD_MAX + nbytes))
        return KDR_ENOMEM;
    return kdr_cbor_typed_head_only(b, tag, nbytes);
}

int kdr_cbor_typed_head_only(kdr_buf *b, uint64_t tag, size_t nbytes) {
    if (kdr_buf_reserve(b, 2 * KDR_CBOR_HEAD_MAX))
        return KDR_ENOMEM;
    unsigned char *p = (unsigned char *)b->data + b->len;
    size_t k = cbor_encode_tag(tag, p, KDR_CBOR_HEAD_MAX);
    k += cbor_encode_bytestring_start(nbytes, p + k, KDR_CBOR_HEAD_MAX);
    b->len += k;
    return 0;
}
