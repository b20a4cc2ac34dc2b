/*
 * kdr_response.c — response bodies: hits (bundle, frustum), visibilities
 * (cone-shadow), scene descriptions and health. Large arrays never go
 * through a tree: they are written straight into the output buffer a chunk
 * at a time, as JSON text (kdr_format_float for floats), as base64 of their
 * little-endian bytes, or as CBOR typed arrays (raw little-endian bytes
 * after a tag), each from a small staging block so misses are normalised on
 * the way without a second full-size copy. An answer holds the fields the
 * request chose (kdr_field_table order), "count" first.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "kdr_proto_internal.h"

/* Values per chunk: a multiple of 3 so that each chunk's 4-byte values make
 * whole base64 groups and chunk encodings concatenate. */
#define KDR_CHUNK 3072
#define KDR_INT_CHARS 12 /* "-2147483648" + ',' */

/* Where an array's values come from: floats, int32, bytes (0/1), or 0/1
 * derived from prim >= 0 (hit_of); with misses (prim < 0) replaced by
 * miss_f in float arrays when prim is given, and negative int32 by -1. */
typedef struct array_src {
    const float *f;
    const int32_t *i;
    const uint8_t *u8;
    const int32_t *hit_of;
    const int32_t *prim;
    float miss_f;
    /* f or i already hold the wire's values (the core's convention: a miss
     * is -1 / 0, no other negative int): written as they lie */
    int wire;
} array_src;

static int src_is_bytes(const array_src *s) { return s->u8 || s->hit_of; }

static float src_float(const array_src *s, size_t k) {
    return s->prim && s->prim[k] < 0 ? s->miss_f : s->f[k];
}

static int32_t src_int(const array_src *s, size_t k) {
    if (s->u8) return s->u8[k] ? 1 : 0;
    if (s->hit_of) return s->hit_of[k] >= 0;
    return s->i[k] < 0 ? -1 : s->i[k];
}

static size_t put_int(char *p, int64_t v) {
    char tmp[24];
    size_t n = 0, len = 0;
    uint64_t u = v < 0 ? (uint64_t)0 - (uint64_t)v : (uint64_t)v;
    if (v < 0) p[len++] = '-';
    do {
        tmp[n++] = (char)('0' + u % 10);
        u /= 10;
    } while (u);
    while (n)
        p[len++] = tmp[--n];
    return len;
}

/* The most text one array value takes, with its comma. */
static size_t json_value_max(const array_src *s) {
    return s->f ? KDR_FLOAT_MAX_LEN + 1 : src_is_bytes(s) ? 2 : KDR_INT_CHARS;
}

static int json_array(kdr_buf *b, const array_src *s, size_t n) {
    const size_t per = json_value_max(s);
    if (kdr_buf_append(b, "[", 1)) return KDR_ENOMEM;
    for (size_t k0 = 0; k0 < n; k0 += KDR_CHUNK) {
        const size_t k1 = n - k0 < KDR_CHUNK ? n : k0 + KDR_CHUNK;
        /* kdr_format_float copies KDR_FLOAT_CHARS bytes whatever the length */
        if (kdr_buf_reserve(b, (k1 - k0) * per + KDR_FLOAT_CHARS)) return KDR_ENOMEM;
        char *p = b->data + b->len;
        for (size_t k = k0; k < k1; k++) {
            if (k) *p++ = ',';
            p += s->f ? kdr_format_float(src_float(s, k), p) : put_int(p, src_int(s, k));
        }
        b->len = (size_t)(p - b->data);
    }
    return kdr_buf_append(b, "]", 1);
}

/* Values [k0, k0 + m) as 4-byte little-endian values in stage. */
static void stage_words(const array_src *s, size_t k0, size_t m, void *stage) {
    if (s->f) {
        float *f = stage;
        if (!s->prim) {
            memcpy(f, s->f + k0, m * sizeof *f);
            return;
        }
        /* One integer select per value over hoisted pointers, on the
         * floats' bits: GCC vectorises this loop, not src_float's (a float
         * select under an int32 test, s->prim tested per value). */
        const float *src = s->f + k0;
        const int32_t *prim = s->prim + k0;
        uint32_t *w = (uint32_t *)f, miss;
        memcpy(&miss, &s->miss_f, 4);
        for (size_t k = 0; k < m; k++) {
            uint32_t v;
            memcpy(&v, src + k, 4);
            w[k] = prim[k] < 0 ? miss : v;
        }
    } else if (s->i) {
        const int32_t *src = s->i + k0;
        int32_t *i = stage;
        for (size_t k = 0; k < m; k++)
            i[k] = src[k] < 0 ? -1 : src[k];
    } else if (s->u8) { /* hoisted as above, so that GCC vectorises it */
        const uint8_t *src = s->u8 + k0;
        int32_t *i = stage;
        for (size_t k = 0; k < m; k++)
            i[k] = src[k] != 0;
    } else {
        const int32_t *src = s->hit_of + k0;
        int32_t *i = stage;
        for (size_t k = 0; k < m; k++)
            i[k] = src[k] >= 0;
    }
}

static int base64_array(kdr_buf *b, const array_src *s, size_t n) {
    _Alignas(16) unsigned char stage[4 * KDR_CHUNK];
    if (kdr_buf_append(b, s->f ? "{\"f32\":\"" : "{\"i32\":\"", 8) ||
        kdr_buf_reserve(b, kdr_base64_encoded_len(4 * n) + 2))
        return KDR_ENOMEM;
    if (s->wire && !src_is_bytes(s)) { /* from the array itself, in one pass */
        const void *src = s->f ? (const void *)s->f : (const void *)s->i;
        b->len += kdr_base64_encode(src, 4 * n, b->data + b->len);
        return KDR_BUF_LIT(b, "\"}");
    }
    for (size_t k0 = 0; k0 < n; k0 += KDR_CHUNK) {
        const size_t m = n - k0 < KDR_CHUNK ? n - k0 : KDR_CHUNK;
        stage_words(s, k0, m, stage);
        b->len += kdr_base64_encode(stage, 4 * m, b->data + b->len);
    }
    return KDR_BUF_LIT(b, "\"}");
}

/* An RFC 8746 typed array: uint8 (tag 64) for 0/1 arrays, int32 (78) or
 * float32 (85) little-endian otherwise. */
static int cbor_array(kdr_buf *b, const array_src *s, size_t n) {
    if (src_is_bytes(s)) {
        if (kdr_cbor_typed_head(b, KDR_CBOR_TAG_U8, n)) return KDR_ENOMEM;
        unsigned char *p = (unsigned char *)b->data + b->len;
        if (s->hit_of) /* hoisted as in stage_words */
            for (size_t k = 0; k < n; k++)
                p[k] = s->hit_of[k] >= 0;
        else
            for (size_t k = 0; k < n; k++)
                p[k] = s->u8[k] != 0;
        b->len += n;
        return 0;
    }
    if (kdr_cbor_typed_head(b, s->f ? KDR_CBOR_TAG_F32LE : KDR_CBOR_TAG_I32LE, 4 * n))
        return KDR_ENOMEM;
    if (s->wire) {
        kdr_buf_put(b, s->f ? (const void *)s->f : (const void *)s->i, 4 * n);
        return 0;
    }
    _Alignas(16) unsigned char stage[4 * KDR_CHUNK];
    for (size_t k0 = 0; k0 < n; k0 += KDR_CHUNK) {
        const size_t m = n - k0 < KDR_CHUNK ? n - k0 : KDR_CHUNK;
        stage_words(s, k0, m, stage);
        kdr_buf_put(b, stage, 4 * m);
    }
    return 0;
}

/* ---- answer sizes ------------------------------------------------------------ */

/* Bytes of an answer around its arrays: braces and "count" (JSON <= 30,
 * CBOR <= 16), the cone-shadow "stats" member (JSON <= 123, CBOR < 90),
 * and room for what the encoders reserve beyond what they then write (a
 * float's fixed-size copy of KDR_FLOAT_CHARS). */
#define KDR_ANSWER_FIXED 256
/* Per array member: its name with quotes, colon, comma and brackets, or
 * the {"f32":"..."} wrapper, or CBOR's text, tag and byte-string heads; and
 * the escape room kdr_buf_json_string reserves for a name of <= 8 bytes. */
#define KDR_ANSWER_MEMBER 64

static size_t array_max(const array_src *s, size_t n, kdr_encoding enc) {
    if (enc == KDR_ENCODING_CBOR)
        return KDR_ANSWER_MEMBER + n * (src_is_bytes(s) ? 1 : 4);
    if (enc == KDR_ENCODING_BASE64)
        return KDR_ANSWER_MEMBER + kdr_base64_encoded_len(4 * n);
    return KDR_ANSWER_MEMBER + n * json_value_max(s);
}

/* The kind of values a field's array holds (pointers only mark the kind). */
static array_src field_kind(unsigned bit) {
    static const float f;
    static const int32_t i;
    static const uint8_t u8;
    array_src s = {0};
    if (bit == KDR_FIELD_PRIM || bit == KDR_FIELD_MESH)
        s.i = &i;
    else if (bit == KDR_FIELD_HIT)
        s.u8 = &u8;
    else
        s.f = &f;
    return s;
}

size_t kdr_proto_hits_answer_max(size_t n, kdr_query query, unsigned fields,
                                 kdr_encoding enc) {
    (void)query;
    size_t total = KDR_ANSWER_FIXED;
    for (size_t k = 0; k < KDR_FIELD_COUNT; k++)
        if (fields & kdr_field_table[k].bit) {
            const array_src s = field_kind(kdr_field_table[k].bit);
            total += array_max(&s, n * kdr_field_table[k].width, enc);
        }
    return total;
}

size_t kdr_proto_shadow_answer_max(size_t n, size_t nlights, int stats,
                                   kdr_encoding enc) {
    (void)stats; /* within KDR_ANSWER_FIXED */
    const array_src s = field_kind(KDR_FIELD_T);
    return KDR_ANSWER_FIXED + array_max(&s, n * nlights, enc);
}

/* An empty buffer gets the answer's whole bound at once: one allocation,
 * never a doubling (the caller charged the bound). */
static int presize(kdr_buf *out, size_t bound) {
    return out->cap == 0 ? kdr_buf_reserve_exact(out, bound) : 0;
}

/* One "name": array member (JSON: preceded by a comma). */
static int named_array(kdr_buf *b, const char *name, const array_src *s, size_t n,
                       kdr_encoding enc) {
    if (enc == KDR_ENCODING_CBOR) return kdr_cbor_text(b, name) || cbor_array(b, s, n);
    if (kdr_buf_append(b, ",", 1) || kdr_buf_json_string(b, name) ||
        kdr_buf_append(b, ":", 1))
        return KDR_ENOMEM;
    return enc == KDR_ENCODING_BASE64 ? base64_array(b, s, n) : json_array(b, s, n);
}

/* The answer's head: "count" and room for members more entries. */
static int count_head(kdr_buf *b, size_t n, size_t members, kdr_encoding enc) {
    if (enc == KDR_ENCODING_CBOR)
        return kdr_cbor_map(b, 1 + members) || kdr_cbor_text(b, "count") ||
               kdr_cbor_uint(b, n);
    char head[48];
    int len = snprintf(head, sizeof head, "{\"count\":%zu", n);
    return kdr_buf_append(b, head, (size_t)len);
}

static int close_answer(kdr_buf *b, kdr_encoding enc) {
    return enc == KDR_ENCODING_CBOR ? 0 : kdr_buf_append(b, "}", 1);
}

/* The source of answer field bit for a query; wire: the arrays are in wire
 * form (no miss normalisation, float and int arrays written as they lie). */
static array_src field_src(const kdr_hits *h, const kdr_hit_attrs *a, kdr_query query,
                           unsigned bit, int wire) {
    array_src s = {0};
    switch (bit) {
    case KDR_FIELD_NORMAL:
        s = (array_src){.f = a->normal};
        break;
    case KDR_FIELD_MESH:
        s = (array_src){.i = a->mesh};
        break;
    case KDR_FIELD_T:
        s = (array_src){.f = h->t, .prim = h->prim, .miss_f = -1.0f};
        break;
    case KDR_FIELD_PRIM:
        s = (array_src){.i = h->prim};
        break;
    case KDR_FIELD_U:
        s = (array_src){.f = h->u, .prim = h->prim, .miss_f = 0.0f};
        break;
    case KDR_FIELD_V:
        s = (array_src){.f = h->v, .prim = h->prim, .miss_f = 0.0f};
        break;
    default: /* KDR_FIELD_HIT */
        if (query == KDR_ANY)
            s.u8 = h->hit;
        else
            s.hit_of = h->prim;
        break;
    }
    if (wire && !src_is_bytes(&s)) {
        s.prim = NULL;
        s.wire = 1;
    }
    return s;
}

int kdr_proto_encode_hits_fields(const kdr_hits *hits, size_t n, kdr_query query,
                                 unsigned fields, kdr_encoding enc, kdr_buf *out) {
    return kdr_proto_encode_hits_attrs(hits, NULL, n, query, fields, enc, out);
}

/* The members a hits answer of fields has, or 0 when the fields cannot be
 * encoded for query (or their attributes are missing). */
static size_t hits_members(const kdr_hit_attrs *attrs, kdr_query query, unsigned fields) {
    size_t members = 0;
    for (size_t k = 0; k < KDR_FIELD_COUNT; k++) {
        const kdr_field_info *fi = &kdr_field_table[k];
        if (!(fields & fi->bit)) continue;
        if (fi->closest_only && query == KDR_ANY) return 0;
        members++;
    }
    if (fields & ~(KDR_FIELDS_CLOSEST | KDR_FIELDS_ANY | KDR_FIELDS_ATTRS)) return 0;
    if ((fields & KDR_FIELD_NORMAL && (!attrs || !attrs->normal)) ||
        (fields & KDR_FIELD_MESH && (!attrs || !attrs->mesh)))
        return 0;
    return members;
}

static int encode_hits(const kdr_hits *hits, const kdr_hit_attrs *attrs, size_t n,
                       kdr_query query, unsigned fields, kdr_encoding enc, int wire,
                       kdr_buf *out) {
    const size_t members = hits_members(attrs, query, fields);
    if (members == 0) return KDR_EINVAL;
    if (presize(out, kdr_proto_hits_answer_max(n, query, fields, enc)) ||
        count_head(out, n, members, enc))
        return KDR_ENOMEM;
    for (size_t k = 0; k < KDR_FIELD_COUNT; k++) {
        const kdr_field_info *fi = &kdr_field_table[k];
        if (!(fields & fi->bit)) continue;
        const array_src s = field_src(hits, attrs, query, fi->bit, wire);
        if (named_array(out, fi->name, &s, n * fi->width, enc)) return KDR_ENOMEM;
    }
    return close_answer(out, enc);
}

int kdr_proto_encode_hits_attrs(const kdr_hits *hits, const kdr_hit_attrs *attrs,
                                size_t n, kdr_query query, unsigned fields,
                                kdr_encoding enc, kdr_buf *out) {
    return encode_hits(hits, attrs, n, query, fields, enc, 0, out);
}

int kdr_proto_encode_hits_wire(const kdr_hits *hits, const kdr_hit_attrs *attrs, size_t n,
                               kdr_query query, unsigned fields, kdr_encoding enc,
                               kdr_buf *out) {
    return encode_hits(hits, attrs, n, query, fields, enc, 1, out);
}

/* Bytes of the heads of a pieces answer: the map and "count" (<= 16), and
 * per member its name (<= 9 + 8 bytes) and typed-array head (<= 18). */
#define KDR_PIECES_HEAD_FIXED 32
#define KDR_PIECES_HEAD_MEMBER 48

_Static_assert(KDR_HITS_PIECES_MAX >= 2 * KDR_FIELD_COUNT,
               "a head piece and an array piece per field");

/* head's bytes since *mark as a piece (none if empty); *mark moves on. */
static void head_piece(const kdr_buf *head, size_t *mark, kdr_piece *pieces, size_t *np) {
    if (head->len > *mark)
        pieces[(*np)++] = (kdr_piece){head->data + *mark, head->len - *mark};
    *mark = head->len;
}

int kdr_proto_hits_pieces(const kdr_hits *hits, const kdr_hit_attrs *attrs, size_t n,
                          kdr_query query, unsigned fields, kdr_buf *head,
                          uint8_t **hit_bytes, kdr_piece *pieces, size_t *npieces) {
    *hit_bytes = NULL;
    *npieces = 0;
    const size_t members = hits_members(attrs, query, fields);
    if (members == 0 || head->cap != 0) return KDR_EINVAL;
    /* the one allocation of head: nothing below moves it */
    if (kdr_buf_reserve_exact(head,
                              KDR_PIECES_HEAD_FIXED + members * KDR_PIECES_HEAD_MEMBER) ||
        count_head(head, n, members, KDR_ENCODING_CBOR))
        return KDR_ENOMEM;
    const char *const base = head->data;
    size_t mark = 0, np = 0;
    for (size_t k = 0; k < KDR_FIELD_COUNT; k++) {
        const kdr_field_info *fi = &kdr_field_table[k];
        if (!(fields & fi->bit)) continue;
        const array_src s = field_src(hits, attrs, query, fi->bit, 1);
        const size_t m = n * fi->width;
        const void *data;
        size_t bytes;
        uint64_t tag;
        if (src_is_bytes(&s)) {
            tag = KDR_CBOR_TAG_U8;
            data = s.u8;
            bytes = m;
            if (s.hit_of) { /* as cbor_array writes it */
                uint8_t *hb = malloc(m ? m : 1);
                if (!hb) return KDR_ENOMEM;
                for (size_t i = 0; i < m; i++)
                    hb[i] = s.hit_of[i] >= 0;
                *hit_bytes = hb;
                data = hb;
            }
        } else {
            tag = s.f ? KDR_CBOR_TAG_F32LE : KDR_CBOR_TAG_I32LE;
            data = s.f ? (const void *)s.f : (const void *)s.i;
            bytes = 4 * m;
        }
        if (kdr_cbor_text(head, fi->name) || kdr_cbor_typed_head_only(head, tag, bytes))
            return KDR_ENOMEM;
        head_piece(head, &mark, pieces, &np);
        if (bytes) pieces[np++] = (kdr_piece){data, bytes};
    }
    head_piece(head, &mark, pieces, &np);
    if (head->data != base) return KDR_EINVAL; /* the bound above is wrong */
    *npieces = np;
    return 0;
}

int kdr_proto_encode_hits(const kdr_hits *hits, size_t n, kdr_query query,
                          kdr_encoding enc, kdr_buf *out) {
    return kdr_proto_encode_hits_fields(
        hits, n, query, query == KDR_ANY ? KDR_FIELDS_ANY : KDR_FIELDS_CLOSEST, enc, out);
}

/* ---- all hits and counts ------------------------------------------------------- */

size_t kdr_proto_all_answer_max(size_t n, size_t max_hits, unsigned fields,
                                kdr_encoding enc) {
    const array_src ints = field_kind(KDR_FIELD_PRIM);
    size_t total =
        KDR_ANSWER_FIXED + array_max(&ints, n, enc) + array_max(&ints, n + 1, enc);
    for (size_t k = 0; k < KDR_FIELD_COUNT; k++)
        if (fields & kdr_field_table[k].bit) {
            const array_src s = field_kind(kdr_field_table[k].bit);
            total += array_max(&s, n * max_hits * kdr_field_table[k].width, enc);
        }
    return total;
}

int kdr_proto_encode_all(const kdr_all_answer *a, unsigned fields, kdr_encoding enc,
                         kdr_buf *out) {
    if (!a || !a->nhits || !a->offset || fields == 0 ||
        (fields & ~(KDR_FIELDS_CLOSEST | KDR_FIELDS_ATTRS)) ||
        (fields & KDR_FIELD_NORMAL && !a->attrs.normal) ||
        (fields & KDR_FIELD_MESH && !a->attrs.mesh))
        return KDR_EINVAL;
    size_t members = 2, max_hits = 0;
    for (size_t k = 0; k < KDR_FIELD_COUNT; k++)
        members += (fields & kdr_field_table[k].bit) != 0;
    for (size_t i = 0; i < a->n; i++)
        max_hits = (size_t)a->nhits[i] > max_hits ? (size_t)a->nhits[i] : max_hits;
    const size_t total = (size_t)a->offset[a->n];
    const array_src nh = {.i = a->nhits}, off = {.i = a->offset};
    if (presize(out, kdr_proto_all_answer_max(a->n, max_hits, fields, enc)) ||
        count_head(out, a->n, members, enc) ||
        named_array(out, "nhits", &nh, a->n, enc) ||
        named_array(out, "offset", &off, a->n + 1, enc))
        return KDR_ENOMEM;
    for (size_t k = 0; k < KDR_FIELD_COUNT; k++) {
        const unsigned bit = kdr_field_table[k].bit;
        if (!(fields & bit)) continue;
        const array_src s = bit == KDR_FIELD_T        ? (array_src){.f = a->t}
                            : bit == KDR_FIELD_PRIM   ? (array_src){.i = a->prim}
                            : bit == KDR_FIELD_U      ? (array_src){.f = a->u}
                            : bit == KDR_FIELD_V      ? (array_src){.f = a->v}
                            : bit == KDR_FIELD_NORMAL ? (array_src){.f = a->attrs.normal}
                                                      : (array_src){.i = a->attrs.mesh};
        if (named_array(out, kdr_field_table[k].name, &s,
                        total * kdr_field_table[k].width, enc))
            return KDR_ENOMEM;
    }
    return close_answer(out, enc);
}

size_t kdr_proto_counts_answer_max(size_t n, kdr_encoding enc) {
    const array_src ints = field_kind(KDR_FIELD_PRIM);
    return KDR_ANSWER_FIXED + array_max(&ints, n, enc);
}

int kdr_proto_encode_counts(const uint32_t *counts, size_t n, kdr_encoding enc,
                            kdr_buf *out) {
    if (!counts) return KDR_EINVAL;
    /* counts are at most the triangle count (< 2^30): int32 on the wire */
    const array_src s = {.i = (const int32_t *)(const void *)counts};
    if (presize(out, kdr_proto_counts_answer_max(n, enc)) || count_head(out, n, 1, enc) ||
        named_array(out, "nhits", &s, n, enc))
        return KDR_ENOMEM;
    return close_answer(out, enc);
}

/* ---- closest points ------------------------------------------------------------ */

size_t kdr_proto_closest_answer_max(size_t n, kdr_encoding enc) {
    const array_src ints = field_kind(KDR_FIELD_PRIM), f = field_kind(KDR_FIELD_T);
    return KDR_ANSWER_FIXED + array_max(&ints, n, enc) + 3 * array_max(&f, n, enc) +
           array_max(&f, 3 * n, enc);
}

/* The core's answers are an array of structs: each member (what: 0 prim,
 * 1 distance, 2 point, three per entry, 3 u, 4 v) is copied into a plain
 * array (at most 12 bytes per point, freed before the next member) and
 * written as one. */
static int closest_member(kdr_buf *b, const char *name, const kdr_closest *c, size_t n,
                          int what, kdr_encoding enc) {
    const size_t per = what == 2 ? 3 : 1, total = per * n;
    int32_t *ibuf = NULL;
    float *fbuf = NULL;
    if (what == 0)
        ibuf = malloc((total ? total : 1) * sizeof *ibuf);
    else
        fbuf = malloc((total ? total : 1) * sizeof *fbuf);
    if (!ibuf && !fbuf) return KDR_ENOMEM;
    for (size_t i = 0; i < n; i++) {
        switch (what) {
        case 0:
            ibuf[i] = c[i].prim;
            break;
        case 1:
            fbuf[i] = c[i].distance;
            break;
        case 2:
            for (int k = 0; k < 3; k++)
                fbuf[3 * i + k] = c[i].point[k];
            break;
        case 3:
            fbuf[i] = c[i].u;
            break;
        default:
            fbuf[i] = c[i].v;
            break;
        }
    }
    const array_src s = what == 0 ? (array_src){.i = ibuf} : (array_src){.f = fbuf};
    const int rc = named_array(b, name, &s, total, enc);
    free(ibuf);
    free(fbuf);
    return rc;
}

int kdr_proto_encode_closest(const kdr_closest *c, size_t n, kdr_encoding enc,
                             kdr_buf *out) {
    if (!c) return KDR_EINVAL;
    static const char *const names[5] = {"prim", "distance", "point", "u", "v"};
    if (presize(out, kdr_proto_closest_answer_max(n, enc)) || count_head(out, n, 5, enc))
        return KDR_ENOMEM;
    for (int w = 0; w < 5; w++)
        if (closest_member(out, names[w], c, n, w, enc)) return KDR_ENOMEM;
    return close_answer(out, enc);
}

size_t kdr_proto_occupancy_answer_max(size_t n, kdr_encoding enc) {
    const array_src s = field_kind(KDR_FIELD_HIT);
    return KDR_ANSWER_FIXED + array_max(&s, n, enc);
}

int kdr_proto_encode_occupancy(const uint8_t *inside, size_t n, kdr_encoding enc,
                               kdr_buf *out) {
    if (!inside) return KDR_EINVAL;
    const array_src s = {.u8 = inside};
    if (presize(out, kdr_proto_occupancy_answer_max(n, enc)) ||
        count_head(out, n, 1, enc) || named_array(out, "inside", &s, n, enc))
        return KDR_ENOMEM;
    return close_answer(out, enc);
}

static int shadow_stats(kdr_buf *out, const kdr_shadow_stats *stats, kdr_encoding enc) {
    if (enc == KDR_ENCODING_CBOR)
        return kdr_cbor_text(out, "stats") || kdr_cbor_map(out, 3) ||
               kdr_cbor_text(out, "cones_decided") ||
               kdr_cbor_uint(out, stats->cones_decided) ||
               kdr_cbor_text(out, "rays_traced") ||
               kdr_cbor_uint(out, stats->rays_traced) ||
               kdr_cbor_text(out, "nodes_visited") ||
               kdr_cbor_uint(out, stats->nodes_visited);
    char tail[160];
    int len = snprintf(tail, sizeof tail,
                       ",\"stats\":{\"cones_decided\":%llu,\"rays_traced\":%llu,"
                       "\"nodes_visited\":%llu}",
                       (unsigned long long)stats->cones_decided,
                       (unsigned long long)stats->rays_traced,
                       (unsigned long long)stats->nodes_visited);
    return kdr_buf_append(out, tail, (size_t)len);
}

int kdr_proto_encode_shadow(const float *visibility, size_t n, size_t nlights,
                            const kdr_shadow_stats *stats, kdr_encoding enc,
                            kdr_buf *out) {
    const array_src vis = {.f = visibility};
    if (presize(out, kdr_proto_shadow_answer_max(n, nlights, stats != NULL, enc)) ||
        count_head(out, n, stats ? 2 : 1, enc) ||
        named_array(out, "visibility", &vis, n * nlights, enc) ||
        (stats && shadow_stats(out, stats, enc)))
        return KDR_ENOMEM;
    return close_answer(out, enc);
}

/* ---- scenes and health ------------------------------------------------------- */

/* Shortest of %.15g / %.17g that reads back exactly; null if not finite. */
static int put_double(kdr_buf *b, double d) {
    char tmp[40];
    if (!isfinite(d)) return KDR_BUF_LIT(b, "null");
    int len = snprintf(tmp, sizeof tmp, "%.15g", d);
    if (strtod(tmp, NULL) != d) len = snprintf(tmp, sizeof tmp, "%.17g", d);
    return kdr_buf_append(b, tmp, (size_t)len);
}

static int put_vec3(kdr_buf *b, const float v[3]) {
    const array_src s = {.f = v};
    return json_array(b, &s, 3);
}

static int put_u64(kdr_buf *b, const char *key, uint64_t v) {
    char tmp[64];
    int len = snprintf(tmp, sizeof tmp, "\"%s\":%llu", key, (unsigned long long)v);
    return kdr_buf_append(b, tmp, (size_t)len);
}

static int put_kdtree(kdr_buf *b, const kdr_tree_stats *t) {
    return KDR_BUF_LIT(b, ",\"kdtree\":{") || put_u64(b, "nodes", t->nodes) ||
           KDR_BUF_LIT(b, ",") || put_u64(b, "leaves", t->leaves) ||
           KDR_BUF_LIT(b, ",") || put_u64(b, "empty_leaves", t->empty_leaves) ||
           KDR_BUF_LIT(b, ",") || put_u64(b, "max_depth", t->max_depth) ||
           KDR_BUF_LIT(b, ",\"refs_per_leaf\":") || put_double(b, t->refs_per_leaf) ||
           KDR_BUF_LIT(b, ",\"sah_cost\":") || put_double(b, t->sah_cost) ||
           KDR_BUF_LIT(b, ",\"build_ms\":") || put_double(b, t->build_ms) ||
           KDR_BUF_LIT(b, "}");
}

static int put_mesh(kdr_buf *b, const kdr_proto_mesh_range *m) {
    char tmp[192];
    int len = snprintf(tmp, sizeof tmp,
                       "{\"node\":%lld,\"mesh\":%lld,\"primitive\":%lld,"
                       "\"first_prim\":%llu,\"count\":%llu}",
                       (long long)m->node, (long long)m->mesh, (long long)m->primitive,
                       (unsigned long long)m->first_prim, (unsigned long long)m->count);
    return kdr_buf_append(b, tmp, (size_t)len);
}

int kdr_proto_encode_scene(const kdr_proto_scene_info *s, kdr_buf *out) {
    if (KDR_BUF_LIT(out, "{\"name\":") ||
        kdr_buf_json_string(out, s->name ? s->name : "") || KDR_BUF_LIT(out, ",") ||
        put_u64(out, "triangles", s->triangles) ||
        KDR_BUF_LIT(out, ",\"bounds\":{\"min\":") || put_vec3(out, s->bounds.min) ||
        KDR_BUF_LIT(out, ",\"max\":") || put_vec3(out, s->bounds.max) ||
        KDR_BUF_LIT(out, "}") || put_kdtree(out, &s->tree) ||
        KDR_BUF_LIT(out, ",\"meshes\":["))
        return KDR_ENOMEM;
    for (size_t i = 0; i < s->nmeshes; i++)
        if ((i && KDR_BUF_LIT(out, ",")) || put_mesh(out, &s->meshes[i]))
            return KDR_ENOMEM;
    return KDR_BUF_LIT(out, "]}");
}

int kdr_proto_encode_scenes(const kdr_proto_scene_info *scenes, size_t n, kdr_buf *out) {
    if (KDR_BUF_LIT(out, "{\"scenes\":[")) return KDR_ENOMEM;
    for (size_t i = 0; i < n; i++)
        if ((i && KDR_BUF_LIT(out, ",")) || kdr_proto_encode_scene(&scenes[i], out))
            return KDR_ENOMEM;
    return KDR_BUF_LIT(out, "]}");
}

int kdr_proto_encode_health(const char *status, size_t nscenes, kdr_buf *out) {
    char tail[48];
    int len = snprintf(tail, sizeof tail, ",\"scenes\":%zu}", nscenes);
    if (KDR_BUF_LIT(out, "{\"status\":") ||
        kdr_buf_json_string(out, status ? status : "") ||
        kdr_buf_append(out, tail, (size_t)len))
        return KDR_ENOMEM;
    return 0;
}
