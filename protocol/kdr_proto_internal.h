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

/* Grows b's capacity to exactly len + extra if it is smaller (no doubling):
 * for an answer whose size is bounded beforehand. 0 or KDR_ENOMEM. */
int kdr_buf_reserve_exact(kdr_buf *b, size_t extra);

/* Appends s as a quoted JSON string (control characters escaped; bytes
 * >= 0x80 copied, so UTF-8 stays UTF-8). */
int kdr_buf_json_string(kdr_buf *b, const char *s);

/* ---- metered allocation (kdr_meter.c) ----------------------------------------- */

/* malloc / realloc / free for everything a parse allocates (cJSON's hooks
 * are these too): counted on the thread's meter (kdr_proto_meter_set)
 * before the block exists, counted back when freed; NULL when the meter
 * refuses or malloc fails (both counted as failures). */
void *kdr_pf_malloc(size_t n);
void *kdr_pf_realloc(void *p, size_t n);
void kdr_pf_free(void *p);
/* Allocations that failed on this thread so far: a parser that gets NULL
 * from cJSON compares it with the value before the call (NULL with no new
 * failure is malformed input). */
unsigned long kdr_pf_alloc_failures(void);

/* ---- CBOR writing (kdr_cbor_write.c) ---------------------------------------- */

/* RFC 8746 typed-array tags used here (little-endian element order). */
#define KDR_CBOR_TAG_U8 64
#define KDR_CBOR_TAG_I32LE 78
#define KDR_CBOR_TAG_F32LE 85

/* Heads in preferred serialization; each returns 0 or KDR_ENOMEM. */
int kdr_cbor_map(kdr_buf *b, size_t entries);
int kdr_cbor_text(kdr_buf *b, const char *s);
int kdr_cbor_uint(kdr_buf *b, uint64_t v);
/* Tag + byte-string head of nbytes, with room reserved for the nbytes the
 * caller appends next (kdr_buf_put or direct writes). */
int kdr_cbor_typed_head(kdr_buf *b, uint64_t tag, size_t nbytes);
/* The same heads with no room reserved for the payload, which is sent
 * from elsewhere (kdr_proto_hits_pieces). */
int kdr_cbor_typed_head_only(kdr_buf *b, uint64_t tag, size_t nbytes);

/* ---- field readers (kdr_fields.c, kdr_json_fast.c) ---------------------- */

/* Doubles at or beyond the midpoint between FLT_MAX and 2^128 round to
 * infinity as float32; below it they round to a finite float. Checking
 * first keeps the double->float conversion defined (C11 6.3.1.5). */
#define KDR_FLOAT_OVERFLOW 0x1.ffffffp127

/* A top-level float-array field read without a cJSON node per number, in
 * one of three forms:
 *  - v: numbers already converted to float32 (a flat JSON array of numbers,
 *    or a CBOR array), saturated; first_inf / first_big / first_nan: the
 *    first element that was infinite as a double (1e999) / finite but
 *    beyond float32 / NaN or not a number at all (CBOR), SIZE_MAX if none;
 *  - b64: {"f32": "..."}, the base64 text inside the body (decoded only
 *    once counted);
 *  - raw: a CBOR float32 typed array (RFC 8746 tag 85), n little-endian
 *    floats inside the body, read in place when aligned. */
typedef struct kdr_numarray {
    char key[32];
    float *v;
    size_t n, first_inf, first_big, first_nan;
    const char *b64;
    size_t b64_len;
    const unsigned char *raw;
} kdr_numarray;

#define KDR_PF_MAX_FAST 8
/* A parsed body: numeric arrays apart, every other member in root. */
typedef struct kdr_pf_doc {
    cJSON *root;
    kdr_numarray fast[KDR_PF_MAX_FAST];
    int nfast;
    kdr_media media;
} kdr_pf_doc;

/* One field value: a cJSON item, or a numeric array, or neither (absent);
 * cbor: the body was CBOR (error messages name its forms). */
typedef struct kdr_pf_field {
    const cJSON *item;
    const kdr_numarray *arr;
    int cbor;
} kdr_pf_field;

static inline kdr_pf_field kdr_pf_wrap(const cJSON *item) {
    kdr_pf_field f = {item, NULL, 0};
    return f;
}
static inline int kdr_pf_present(kdr_pf_field f) { return f.item || f.arr; }

/* Parses the body (JSON or CBOR) into an object; 0 or the error status. */
int kdr_pf_parse_body(kdr_media media, const char *body, size_t len, kdr_pf_doc *doc,
                      kdr_proto_error *err);
void kdr_pf_doc_free(kdr_pf_doc *doc);
/* The fast walk: 0 done, 1 "parse it all with cJSON", or an error status. */
int kdr_pf_fast_doc(const char *body, size_t len, kdr_pf_doc *doc,
                    kdr_proto_error *err);
/* The CBOR reader (kdr_cbor_read.c): 0 or an error status. */
int kdr_pf_cbor_doc(const char *body, size_t len, kdr_pf_doc *doc, kdr_proto_error *err);
/* A top-level member. */
kdr_pf_field kdr_pf_get(const kdr_pf_doc *doc, const char *name);
/* The contract's float-array members (the fast paths read only these). */
int kdr_pf_float_array_field(const char *key);

/* Float arrays in both forms. kdr_pf_count validates the form and gives the
 * number of floats without decoding; kdr_pf_read then fills dst[count]. */
#define KDR_PF_SATURATE 1u /* tmin/tmax: +-inf allowed, huge -> +-inf */
int kdr_pf_count(kdr_pf_field f, const char *name, size_t *count,
                 kdr_proto_error *err);
int kdr_pf_read(kdr_pf_field f, const char *name, float *dst, size_t count,
                unsigned flags, kdr_proto_error *err);
/* kdr_pf_read without the copy where possible: *view gets the count floats
 * in place (a CBOR typed array at a 4-byte aligned address; *storage =
 * NULL) or in *storage (malloc'd, the caller frees it; also on failure). */
int kdr_pf_view(kdr_pf_field f, const char *name, size_t count, unsigned flags,
                float **storage, const float **view, kdr_proto_error *err);
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
/* The bundle's "query": closest, any, all or count. */
int kdr_pf_bundle_query(const cJSON *root, kdr_query *out, kdr_proto_error *err);
int kdr_pf_encoding(const cJSON *root, kdr_encoding *out, kdr_proto_error *err);
/* "fields" for a bundle / frustum query: KDR_FIELD_* bits, the query's
 * defaults when absent. */
int kdr_pf_fields(const cJSON *root, kdr_query query, unsigned *out, kdr_proto_error *err);

/* The answer fields in answer order (kdr_fields.c). closest_only: not
 * available to an any query. */
typedef struct kdr_field_info {
    const char *name;
    unsigned bit;
    int closest_only;
    unsigned width; /* values per ray / hit */
} kdr_field_info;
#define KDR_FIELD_COUNT 7
extern const kdr_field_info kdr_field_table[KDR_FIELD_COUNT];
/* "deadline_ms": absent gives 0, else a number in (0, KDR_PROTO_MAX_DEADLINE_MS]. */
int kdr_pf_deadline(const cJSON *root, double *out, kdr_proto_error *err);

int kdr_pf_too_many(kdr_proto_error *err, uint64_t rays, size_t max_rays,
                    const char *what);

#endif /* KDR_PROTO_INTERNAL_H */
