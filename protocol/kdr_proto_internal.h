/*
 * kdr_proto_internal.h — helpers shared by the protocol files (not part of
 * the API): raw appends into a kdr_buf that the caller has reserved, JSON
 * string escaping, and the field readers the request parsers are built from.
 */
#ifndef KDR_PROTO_INTERNAL_H
#define KDR_PROTO_INTERNAL_H

#include <string.h>

#include <cjson/cJSON.h>

#include "kdr_protocol.h"

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "protocol/ copies float32/int32 arrays as little-endian bytes"
#endif

/* Appends n bytes that kdr_buf_reserve has already made room for. */
static inline void kdr_buf_put(kdr_buf *b, const void *bytes, size_t n) {
    memcpy(b->data + b->len, bytes, n);
    b->len += n;
}

/* lit must be a string literal (sizeof of a pointer would be wrong). */
#define KDR_BUF_LIT(b, lit) kdr_buf_append((b), "" lit, sizeof(lit) - 1)

/* Appends s as a quoted JSON string (control characters escaped; bytes
 * >= 0x80 copied, so UTF-8 stays UTF-8). */
int kdr_buf_json_string(kdr_buf *b, const char *s);

/* ---- field readers (kdr_fields.c) -------------------------------------- */

/* Parses the body into an object; 0 or the error status. */
int kdr_pf_parse_body(const char *body, size_t len, cJSON **root,
                      kdr_proto_error *err);

/* Float arrays in both forms. kdr_pf_count validates the form and gives the
 * number of floats without decoding; kdr_pf_read then fills dst[count]. */
#define KDR_PF_SATURATE 1u /* tmin/tmax: +-inf allowed, huge -> +-inf */
int kdr_pf_count(const cJSON *item, const char *name, size_t *count,
                 kdr_proto_error *err);
int kdr_pf_read(const cJSON *item, const char *name, float *dst, size_t count,
                unsigned flags, kdr_proto_error *err);
/* A field of exactly 3 floats (e.g. "camera.eye"). */
int kdr_pf_vec3(const cJSON *item, const char *name, float out[3],
                kdr_proto_error *err);

/* A float number field (JSON number only); status or 0. */
int kdr_pf_float(const cJSON *item, const char *name, float *out,
                 kdr_proto_error *err);
/* An integer in [lo, hi] (JSON number with no fraction); the message on
 * failure is "<name>: must be an integer in <range_text>". */
int kdr_pf_int(const cJSON *item, const char *name, double lo, double hi,
               const char *range_text, uint64_t *out, kdr_proto_error *err);
int kdr_pf_query(const cJSON *root, kdr_query *out, kdr_proto_error *err);
int kdr_pf_encoding(const cJSON *root, kdr_encoding *out, kdr_proto_error *err);

int kdr_pf_too_many(kdr_proto_error *err, uint64_t rays, size_t max_rays,
                    const char *what);

#endif /* KDR_PROTO_INTERNAL_H */
