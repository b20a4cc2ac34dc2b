/*
 * kdr_fields.c — reading one field of a request: the body itself, float
 * arrays in both contract forms (JSON numbers or {"f32": base64}), numbers,
 * integers and enums. Every failure becomes a 400 whose detail names the
 * field and, for arrays, the element ("directions[17]: not a finite
 * number"), so the request parsers stay a list of fields.
 */
#include <float.h>
#include <math.h>
#include <stdlib.h>

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
    while (at < len && (body[at] == ' ' || body[at] == '\t' || body[at] == '\n' ||
                        body[at] == '\r'))
        at++;
    if (at < len)
        return kdr_proto_error_set(
            err, 400, "body: malformed JSON at offset %zu (data after the value)", at);
    if (!cJSON_IsObject(root))
        return kdr_proto_error_set(err, 400, "body: expected a JSON object");
    return 0;
}

int kdr_pf_parse_body(const char *body, size_t len, kdr_pf_doc *doc,
                      kdr_proto_error *err) {
    memset(doc, 0, sizeof *doc);
    if (!body || len == 0)
        return kdr_proto_error_set(err, 400, "body: empty");
    int st = kdr_pf_fast_doc(body, len, doc, err);
    if (st == 1) {
        kdr_pf_doc_free(doc);
        st = cjson_doc(body, len, doc, err);
    }
    if (st)
        kdr_pf_doc_free(doc);
    return st;
}

void kdr_pf_doc_free(kdr_pf_doc *doc) {
    cJSON_Delete(doc->root);
    for (int i = 0; i < doc->nfast; i++)
        free(doc->fast[i].v);
    memset(doc, 0, sizeof *doc);
}

static int wrong_form(const char *name, kdr_proto_error *err) {
    return kdr_proto_error_set(
        err, 400, "%s: expected an array of numbers or {\"f32\": base64}", name);
}

/* The base64 string of {"f32": "..."}, or NULL after setting err. */
static const char *f32_string(const cJSON *item, const char *name,
                              kdr_proto_error *err) {
    const cJSON *s = cJSON_GetObjectItemCaseSensitive(item, "f32");
    if (!s) {
        wrong_form(name, err);
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
        return kdr_proto_error_set(err, 400, "%s.f32: invalid base64 at offset %zu",
                                   name, n);
    size_t bytes = n / 4 * 3;
    if (n && s[n - 1] == '=') bytes--;
    if (n && s[n - 2] == '=') bytes--;
    if (bytes % 4)
        return kdr_proto_error_set(err, 400, "%s.f32: %zu bytes is not a multiple of 4",
                                   name, bytes);
    *count = bytes / 4;
    return 0;
}

int kdr_pf_count(kdr_pf_field f, const char *name, size_t *count,
                 kdr_proto_error *err) {
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
    if (!cJSON_IsObject(item))
        return wrong_form(name, err);
    const char *s = f32_string(item, name, err);
    if (!s)
        return err->status;
    return b64_count(s, strlen(s), name, count, err);
}

/* One JSON number as float32 (saturating to +-inf when allowed). */
static int json_element(const cJSON *c, const char *name, size_t i, unsigned flags,
                        float *out, kdr_proto_error *err) {
    if (!cJSON_IsNumber(c))
        return kdr_proto_error_set(err, 400, "%s[%zu]: not a number", name, i);
    const double d = c->valuedouble;
    if (isnan(d))
        return kdr_proto_error_set(err, 400, "%s[%zu]: not a number", name, i);
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

static int check_decoded(const float *v, size_t count, const char *name,
                         unsigned flags, kdr_proto_error *err) {
    for (size_t i = 0; i < count; i++) {
        if (isfinite(v[i]))
            continue;
        if (isnan(v[i]))
            return kdr_proto_error_set(err, 400, "%s[%zu]: %s", name, i,
                                       flags & KDR_PF_SATURATE ? "not a number"
                                                               : "not a finite number");
        if (!(flags & KDR_PF_SATURATE))
            return kdr_proto_error_set(err, 400, "%s[%zu]: not a finite number", name, i);
    }
    return 0;
}

/* A numeric array parsed by the fast walk: the same errors as element by
 * element (JSON numbers are never NaN; the earliest problem is named). */
static int read_fast(const kdr_numarray *a, const char *name, float *dst, size_t count,
                     unsigned flags, kdr_proto_error *err) {
    if (!(flags & KDR_PF_SATURATE) && (a->first_inf < count || a->first_big < count)) {
        if (a->first_inf < a->first_big)
            return kdr_proto_error_set(err, 400, "%s[%zu]: not a finite number", name,
                                       a->first_inf);
        return kdr_proto_error_set(err, 400, "%s[%zu]: out of float32 range", name,
                                   a->first_big);
    }
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
        return kdr_proto_error_set(err, 400, "%s.f32: invalid base64 at offset %zu",
                                   name, bad);
    if (got != count * sizeof(float))
        return kdr_proto_error_set(err, 500, "%s.f32: decoded size mismatch", name);
    return check_decoded(dst, count, name, flags, err);
}

int kdr_pf_read(kdr_pf_field f, const char *name, float *dst, size_t count,
                unsigned flags, kdr_proto_error *err) {
    const cJSON *item = f.item;
    if (f.arr && f.arr->b64)
        return b64_read(f.arr->b64, f.arr->b64_len, name, dst, count, flags, err);
    if (f.arr)
        return read_fast(f.arr, name, dst, count, flags, err);
    if (cJSON_IsArray(item)) {
        size_t i = 0;
        for (const cJSON *c = item->child; c && i < count; c = c->next, i++)
            if (json_element(c, name, i, flags, &dst[i], err))
                return err->status;
        return 0;
    }
    const char *s = f32_string(item, name, err);
    if (!s)
        return err->status;
    return b64_read(s, strlen(s), name, dst, count, flags, err);
}

int kdr_pf_vec3(const cJSON *item, const char *name, float out[3],
                kdr_proto_error *err) {
    size_t n;
    if (!item)
        return kdr_proto_error_set(err, 400, "%s: required", name);
    if (kdr_pf_count(kdr_pf_wrap(item), name, &n, err))
        return err->status;
    if (n != 3)
        return kdr_proto_error_set(err, 400, "%s: expected 3 numbers, got %zu", name, n);
    return kdr_pf_read(kdr_pf_wrap(item), name, out, 3, 0, err);
}

int kdr_pf_float(const cJSON *item, const char *name, float *out,
                 kdr_proto_error *err) {
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
static int pf_choice(const cJSON *root, const char *name, const char *a,
                     const char *b, int *out, kdr_proto_error *err) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(root, name);
    *out = 0;
    if (!it)
        return 0;
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
    if (pf_choice(root, "query", "closest", "any", &v, err))
        return err->status;
    *out = v ? KDR_ANY : KDR_CLOSEST;
    return 0;
}

int kdr_pf_encoding(const cJSON *root, kdr_encoding *out, kdr_proto_error *err) {
    int v;
    if (pf_choice(root, "encoding", "json", "base64", &v, err))
        return err->status;
    *out = v ? KDR_ENCODING_BASE64 : KDR_ENCODING_JSON;
    return 0;
}

int kdr_pf_deadline(const cJSON *root, double *out, kdr_proto_error *err) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(root, "deadline_ms");
    *out = 0.0;
    if (!it)
        return 0;
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
