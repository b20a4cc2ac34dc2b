/*
 * kdr_fields.c — reading one field of a request: the body itself (JSON or
 * CBOR), float arrays in every form (JSON numbers or {"f32": base64}, CBOR
 * arrays or float32 typed arrays), numbers, integers, enums and the answer
 * field list. Every failure becomes a 400 whose detail names the
 * field and, for arrays, the element ("directions[17]: not a finite
 * number"), so the request parsers stay a list of fields.
 */
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_proto_internal.h"

/* The whole body through cJSON: the general path, and the one that names
 * the offset of malformed JSON. */
static int cjson_doc(const char *body, size_t len, kdr_pf_doc *doc,
                     kdr_proto_error *err) {
    const char *end = NULL;
    cJSON *root = cJSON_ParseWithLengthOpts(body, len, &end, 0);
    size_t at = end && end >= body && end <= body + len ? (size_t)(end - body) : 0;
    if (!root)
        return kdr_proto_error_set(err, 400, "body: malformed JSON at offset %zu", at);
    doc->root = root;
    while (at < len &&
           (body[at] == ' ' || body[at] == '\t' || body[at] == '\n' || body[at] == '\r'))
        at++;
    if (at < len)
        return kdr_proto_error_set(
            err, 400, "body: malformed JSON at offset %zu (data after the value)", at);
    if (!cJSON_IsObject(root))
        return kdr_proto_error_set(err, 400, "body: expected a JSON object");
    return 0;
}

/* An allocation failed during the parse (cJSON reports it as a NULL, as it
 * does malformed input): out of memory, whatever else was reported. */
static int out_of_memory(unsigned long failures0, int st, kdr_pf_doc *doc,
                         kdr_proto_error *err) {
    if (kdr_pf_alloc_failures() == failures0) return st;
    kdr_pf_doc_free(doc);
    return kdr_proto_error_set(err, 500, "body: out of memory");
}

int kdr_pf_parse_body(kdr_media media, const char *body, size_t len, kdr_pf_doc *doc,
                      kdr_proto_error *err) {
    const unsigned long failures0 = kdr_pf_alloc_failures();
    memset(doc, 0, sizeof *doc);
    if (!body || len == 0) return kdr_proto_error_set(err, 400, "body: empty");
    if (media == KDR_MEDIA_CBOR) {
        doc->media = KDR_MEDIA_CBOR;
        const int st =
            out_of_memory(failures0, kdr_pf_cbor_doc(body, len, doc, err), doc, err);
        if (st) kdr_pf_doc_free(doc);
        return st;
    }
    if (media != KDR_MEDIA_JSON)
        return kdr_proto_error_set(err, 415, "body: not a media type this server reads");
    int st = out_of_memory(failures0, kdr_pf_fast_doc(body, len, doc, err), doc, err);
    if (st == 1) {
        kdr_pf_doc_free(doc);
        st = out_of_memory(failures0, cjson_doc(body, len, doc, err), doc, err);
    }
    if (st) kdr_pf_doc_free(doc);
    return st;
}

void kdr_pf_doc_free(kdr_pf_doc *doc) {
    cJSON_Delete(doc->root);
    for (int i = 0; i < doc->nfast; i++)
        kdr_pf_free(doc->fast[i].v);
    memset(doc, 0, sizeof *doc);
}

static int wrong_form(const char *name, int cbor, kdr_proto_error *err) {
    if (cbor)
        return kdr_proto_error_set(
            err, 400,
            "%s: expected a float32 typed array (tag 85) or an array of numbers", name);
    return kdr_proto_error_set(
        err, 400, "%s: expected an array of numbers or {\"f32\": base64}", name);
}

/* The base64 string of {"f32": "..."}, or NULL after setting err. */
static const char *f32_string(const cJSON *item, const char *name, int cbor,
                              kdr_proto_error *err) {
    const cJSON *s = cJSON_GetObjectItemCaseSensitive(item, "f32");
    if (!s) {
        wrong_form(name, cbor, err);
        return NULL;
    }
    if (!cJSON_IsString(s) || !s->valuestring) {
        kdr_proto_error_set(err, 400, "%s.f32: expected a base64 string", name);
        return NULL;
    }
    return s->valuestring;
}

/* Number of floats in the base64 text s[0..n), from length and padding. */
static int b64_count(const char *s, size_t n, const char *name, size_t *count,
                     kdr_proto_error *err) {
    if (n % 4)
        return kdr_proto_error_set(err, 400, "%s.f32: invalid base64 at offset %zu", name,
                                   n);
    size_t bytes = n / 4 * 3;
    if (n && s[n - 1] == '=') bytes--;
    if (n && s[n - 2] == '=') bytes--;
    if (bytes % 4)
        return kdr_proto_error_set(err, 400, "%s.f32: %zu bytes is not a multiple of 4",
                                   name, bytes);
    *count = bytes / 4;
    return 0;
}

int kdr_pf_count(kdr_pf_field f, const char *name, size_t *count, kdr_proto_error *err) {
    const cJSON *item = f.item;
    *count = 0;
    if (f.arr && f.arr->b64)
        return b64_count(f.arr->b64, f.arr->b64_len, name, count, err);
    if (f.arr) {
        *count = f.arr->n;
        return 0;
    }
    if (cJSON_IsArray(item)) {
        for (const cJSON *c = item->child; c; c = c->next)
            (*count)++;
        return 0;
    }
    if (!cJSON_IsObject(item)) return wrong_form(name, f.cbor, err);
    const char *s = f32_string(item, name, f.cbor, err);
    if (!s) return err->status;
    return b64_count(s, strlen(s), name, count, err);
}

/* One JSON number as float32 (saturating to +-inf when allowed). */
static int json_element(const cJSON *c, const char *name, size_t i, unsigned flags,
                        float *out, kdr_proto_error *err) {
    if (!cJSON_IsNumber(c))
        return kdr_proto_error_set(err, 400, "%s[%zu]: not a number", name, i);
    const double d = c->valuedouble;
    if (isnan(d)) return kdr_proto_error_set(err, 400, "%s[%zu]: not a number", name, i);
    if (fabs(d) >= KDR_FLOAT_OVERFLOW) {
        if (flags & KDR_PF_SATURATE) {
            *out = d > 0 ? INFINITY : -INFINITY;
            return 0;
        }
        if (isinf(d))
            return kdr_proto_error_set(err, 400, "%s[%zu]: not a finite number", name, i);
        return kdr_proto_error_set(err, 400, "%s[%zu]: out of float32 range", name, i);
    }
    *out = (float)d;
    return 0;
}

/* 1 when every v[i] is finite. A float is not finite exactly when its
 * exponent bits are all ones; adding one to the exponent field then carries
 * into the sign bit, so one OR over the sums says whether any is: a loop
 * the compiler vectorises, where the element-wise loop below with its early
 * exits is not (kdray_bench_e2e on haus, 1M rays in a 24 MiB CBOR body:
 * the parse step 11.7-12.4 ms -> 2.6-2.9 ms). */
static int all_finite(const float *v, size_t count) {
    uint32_t acc = 0;
    for (size_t i = 0; i < count; i++) {
        uint32_t b;
        memcpy(&b, &v[i], sizeof b);
        acc |= (b & 0x7f800000u) + 0x00800000u;
    }
    return !(acc & 0x80000000u);
}

static int check_decoded(const float *v, size_t count, const char *name, unsigned flags,
                         kdr_proto_error *err) {
    if (all_finite(v, count)) return 0;
    for (size_t i = 0; i < count; i++) {
        if (isfinite(v[i])) continue;
        if (isnan(v[i]))
            return kdr_proto_error_set(err, 400, "%s[%zu]: %s", name, i,
                                       flags & KDR_PF_SATURATE ? "not a number"
                                                               : "not a finite number");
        if (!(flags & KDR_PF_SATURATE))
            return kdr_proto_error_set(err, 400, "%s[%zu]: not a finite number", name, i);
    }
    return 0;
}

/* A numeric array converted while the body was walked: the same errors as
 * element by element, the earliest element at fault named. */
static int read_fast(const kdr_numarray *a, const char *name, float *dst, size_t count,
                     unsigned flags, kdr_proto_error *err) {
    size_t inf = a->first_inf, big = a->first_big;
    if (flags & KDR_PF_SATURATE) inf = big = SIZE_MAX;
    if (a->first_nan < count && a->first_nan < inf && a->first_nan < big)
        return kdr_proto_error_set(err, 400, "%s[%zu]: not a number", name, a->first_nan);
    if (inf < count && inf < big)
        return kdr_proto_error_set(err, 400, "%s[%zu]: not a finite number", name, inf);
    if (big < count)
        return kdr_proto_error_set(err, 400, "%s[%zu]: out of float32 range", name, big);
    memcpy(dst, a->v, (count < a->n ? count : a->n) * sizeof *dst);
    return 0;
}

/* Decodes count floats (as counted by b64_count) from s[0..n). */
static int b64_read(const char *s, size_t n, const char *name, float *dst, size_t count,
                    unsigned flags, kdr_proto_error *err) {
    size_t got = 0, bad = 0;
    /* b64_count derived count from this text's length and padding; the
     * decoder writes only the bytes of valid groups, so never past count
     * floats, even when it then fails. */
    if (kdr_base64_decode(s, n, dst, &got, &bad))
        return kdr_proto_error_set(err, 400, "%s.f32: invalid base64 at offset %zu", name,
                                   bad);
    if (got != count * sizeof(float))
        return kdr_proto_error_set(err, 500, "%s.f32: decoded size mismatch", name);
    return check_decoded(dst, count, name, flags, err);
}

int kdr_pf_read(kdr_pf_field f, const char *name, float *dst, size_t count,
                unsigned flags, kdr_proto_error *err) {
    const cJSON *item = f.item;
    if (f.arr && f.arr->raw) {
        memcpy(dst, f.arr->raw, (count < f.arr->n ? count : f.arr->n) * sizeof *dst);
        return check_decoded(dst, count, name, flags, err);
    }
    if (f.arr && f.arr->b64)
        return b64_read(f.arr->b64, f.arr->b64_len, name, dst, count, flags, err);
    if (f.arr) return read_fast(f.arr, name, dst, count, flags, err);
    if (cJSON_IsArray(item)) {
        size_t i = 0;
        for (const cJSON *c = item->child; c && i < count; c = c->next, i++)
            if (json_element(c, name, i, flags, &dst[i], err)) return err->status;
        return 0;
    }
    const char *s = f32_string(item, name, f.cbor, err);
    if (!s) return err->status;
    return b64_read(s, strlen(s), name, dst, count, flags, err);
}

int kdr_pf_view(kdr_pf_field f, const char *name, size_t count, unsigned flags,
                float **storage, const float **view, kdr_proto_error *err) {
    *storage = NULL;
    *view = NULL;
    if (f.arr && f.arr->raw && (uintptr_t)f.arr->raw % _Alignof(float) == 0 &&
        count <= f.arr->n) {
        const float *in_place = (const float *)(const void *)f.arr->raw;
        if (check_decoded(in_place, count, name, flags, err)) return err->status;
        *view = in_place;
        return 0;
    }
    if (!(*storage = kdr_pf_malloc((count ? count : 1) * sizeof(float))))
        return kdr_proto_error_set(err, 500, "%s: out of memory", name);
    *view = *storage;
    return kdr_pf_read(f, name, *storage, count, flags, err);
}

int kdr_pf_vec3(const cJSON *item, const char *name, float out[3], kdr_proto_error *err) {
    size_t n;
    if (!item) return kdr_proto_error_set(err, 400, "%s: required", name);
    if (kdr_pf_count(kdr_pf_wrap(item), name, &n, err)) return err->status;
    if (n != 3)
        return kdr_proto_error_set(err, 400, "%s: expected 3 numbers, got %zu", name, n);
    return kdr_pf_read(kdr_pf_wrap(item), name, out, 3, 0, err);
}

int kdr_pf_float(const cJSON *item, const char *name, float *out, kdr_proto_error *err) {
    if (!cJSON_IsNumber(item))
        return kdr_proto_error_set(err, 400, "%s: not a number", name);
    const double d = item->valuedouble;
    if (!isfinite(d))
        return kdr_proto_error_set(err, 400, "%s: not a finite number", name);
    if (fabs(d) >= KDR_FLOAT_OVERFLOW)
        return kdr_proto_error_set(err, 400, "%s: out of float32 range", name);
    *out = (float)d;
    return 0;
}

int kdr_pf_int(const cJSON *item, const char *name, double lo, double hi,
               const char *range_text, uint64_t *out, kdr_proto_error *err) {
    if (!cJSON_IsNumber(item) || !(item->valuedouble >= lo) ||
        !(item->valuedouble <= hi) || item->valuedouble != floor(item->valuedouble))
        return kdr_proto_error_set(err, 400, "%s: must be an integer in %s", name,
                                   range_text);
    *out = (uint64_t)item->valuedouble;
    return 0;
}

/* A string field with one of two values; absent gives the first. */
static int pf_choice(const cJSON *root, const char *name, const char *a, const char *b,
                     int *out, kdr_proto_error *err) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(root, name);
    *out = 0;
    if (!it) return 0;
    if (cJSON_IsString(it) && it->valuestring && strcmp(it->valuestring, a) == 0)
        return 0;
    if (cJSON_IsString(it) && it->valuestring && strcmp(it->valuestring, b) == 0) {
        *out = 1;
        return 0;
    }
    return kdr_proto_error_set(err, 400, "%s: must be \"%s\" or \"%s\"", name, a, b);
}

int kdr_pf_query(const cJSON *root, kdr_query *out, kdr_proto_error *err) {
    int v;
    if (pf_choice(root, "query", "closest", "any", &v, err)) return err->status;
    *out = v ? KDR_ANY : KDR_CLOSEST;
    return 0;
}

int kdr_pf_bundle_query(const cJSON *root, kdr_query *out, kdr_proto_error *err) {
    static const char *const names[] = {"closest", "any", "all", "count"};
    static const kdr_query values[] = {KDR_CLOSEST, KDR_ANY, KDR_ALL, KDR_COUNT};
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(root, "query");
    *out = KDR_CLOSEST;
    if (!it) return 0;
    for (size_t k = 0; k < 4; k++)
        if (cJSON_IsString(it) && it->valuestring &&
            strcmp(it->valuestring, names[k]) == 0) {
            *out = values[k];
            return 0;
        }
    return kdr_proto_error_set(
        err, 400, "query: must be \"closest\", \"any\", \"all\" or \"count\"");
}

int kdr_pf_encoding(const cJSON *root, kdr_encoding *out, kdr_proto_error *err) {
    int v;
    if (pf_choice(root, "encoding", "json", "base64", &v, err)) return err->status;
    *out = v ? KDR_ENCODING_BASE64 : KDR_ENCODING_JSON;
    return 0;
}

int kdr_pf_deadline(const cJSON *root, double *out, kdr_proto_error *err) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(root, "deadline_ms");
    *out = 0.0;
    if (!it) return 0;
    if (!cJSON_IsNumber(it) || !(it->valuedouble > 0.0) ||
        !(it->valuedouble <= KDR_PROTO_MAX_DEADLINE_MS))
        return kdr_proto_error_set(err, 400,
                                   "deadline_ms: must be a number of milliseconds in "
                                   "(0, 86400000]");
    *out = it->valuedouble;
    return 0;
}

int kdr_pf_too_many(kdr_proto_error *err, uint64_t rays, size_t max_rays,
                    const char *what) {
    return kdr_proto_error_set(err, 413, "batch of %llu %s exceeds the limit of %zu",
                               (unsigned long long)rays, what, max_rays);
}

/* ---- answer fields ------------------------------------------------------------- */

const kdr_field_info kdr_field_table[KDR_FIELD_COUNT] = {
    {"t", KDR_FIELD_T, 1, 1},       {"prim", KDR_FIELD_PRIM, 1, 1},
    {"u", KDR_FIELD_U, 1, 1},       {"v", KDR_FIELD_V, 1, 1},
    {"hit", KDR_FIELD_HIT, 0, 1},   {"normal", KDR_FIELD_NORMAL, 1, 3},
    {"mesh", KDR_FIELD_MESH, 1, 3},
};

int kdr_pf_fields(const cJSON *root, kdr_query query, unsigned *out,
                  kdr_proto_error *err) {
    const cJSON *fs = cJSON_GetObjectItemCaseSensitive(root, "fields");
    *out = query == KDR_ANY     ? KDR_FIELDS_ANY
           : query == KDR_COUNT ? 0
                                : KDR_FIELDS_CLOSEST;
    if (!fs) return 0;
    if (query == KDR_COUNT)
        return kdr_proto_error_set(err, 400,
                                   "fields: not used by \"query\": \"count\" (its answer "
                                   "is nhits)");
    if (!cJSON_IsArray(fs) || !fs->child)
        return kdr_proto_error_set(err, 400,
                                   "fields: expected a non-empty array of field names");
    unsigned bits = 0;
    size_t i = 0;
    for (const cJSON *it = fs->child; it; it = it->next, i++) {
        if (!cJSON_IsString(it) || !it->valuestring)
            return kdr_proto_error_set(err, 400, "fields[%zu]: expected a field name", i);
        const kdr_field_info *fi = NULL;
        for (size_t k = 0; k < KDR_FIELD_COUNT && !fi; k++)
            if (!strcmp(it->valuestring, kdr_field_table[k].name))
                fi = &kdr_field_table[k];
        if (!fi)
            return kdr_proto_error_set(
                err, 400,
                "fields[%zu]: unknown field \"%.40s\" (t, prim, u, v, "
                "hit, normal, mesh)",
                i, it->valuestring);
        if (query == KDR_ALL && fi->bit == KDR_FIELD_HIT)
            return kdr_proto_error_set(
                err, 400,
                "fields[%zu]: \"hit\" is not a field of \"query\": "
                "\"all\" (t, prim, u, v, normal, mesh)",
                i);
        if (fi->closest_only && query == KDR_ANY)
            return kdr_proto_error_set(err, 400,
                                       "fields[%zu]: \"%s\" needs \"query\": \"closest\"",
                                       i, fi->name);
        bits |= fi->bit;
    }
    *out = bits;
    return 0;
}
