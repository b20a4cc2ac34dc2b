/*
 * kdr_json_fast.c — the top level of a request body without a cJSON node
 * per number. Large requests are mostly flat arrays of numbers
 * ("directions": [...]); cJSON would spend a malloc'd 64-byte node and a
 * strtod call on each. Here the top-level object is walked by hand: a
 * member whose value is a flat array of plain JSON numbers is converted
 * straight to float32 (exact decimals with at most 15 digits and a power of
 * ten up to 22 are converted in one correctly rounded double operation,
 * others through strtod), and {"f32": "..."} is decoded from the body
 * itself, without cJSON's copy; every other member value goes to cJSON.
 * Anything unusual (escapes in keys, a body that is not an object) makes
 * the caller parse the whole body with cJSON instead, so behaviour never
 * depends on which path ran, only speed and memory do.
 */
#include <math.h>
#include <stdlib.h>

#include "kdr_proto_internal.h"

/* Longest number token converted here; longer ones go to cJSON. */
#define KDR_FAST_TOKEN 64
#define KDR_FAST_MAX_KEY 256

static const double exact_pow10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                       1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                       1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

typedef struct cursor {
    const char *p, *end, *body;
} cursor;

static void skip_ws(cursor *c) {
    while (c->p < c->end &&
           (*c->p == ' ' || *c->p == '\t' || *c->p == '\n' || *c->p == '\r'))
        c->p++;
}

static int is_digit(char ch) { return ch >= '0' && ch <= '9'; }

/* Length of the JSON number at s (strict grammar), 0 if there is none. */
static size_t number_len(const char *s, const char *end) {
    const char *p = s;
    if (p < end && *p == '-') p++;
    if (p >= end || !is_digit(*p)) return 0;
    if (*p == '0') p++;
    else while (p < end && is_digit(*p)) p++;
    if (p < end && *p == '.') {
        if (++p >= end || !is_digit(*p)) return 0;
        while (p < end && is_digit(*p)) p++;
    }
    if (p < end && (*p == 'e' || *p == 'E')) {
        p++;
        if (p < end && (*p == '+' || *p == '-')) p++;
        if (p >= end || !is_digit(*p)) return 0;
        while (p < end && is_digit(*p)) p++;
    }
    return (size_t)(p - s);
}

/* Clinger's fast path: digits (<= 15 significant) times 10^e, |e| <= 22,
 * is one correctly rounded operation. 0 if the token (already checked by
 * number_len) does not qualify. */
static int fast_decimal(const char *s, size_t n, double *out) {
    const char *p = s, *end = s + n;
    const int neg = *p == '-';
    int digits = 0, frac = 0, e = 0;
    uint64_t m = 0;
    for (p += neg; p < end && *p != 'e' && *p != 'E'; p++) {
        if (*p == '.') {
            frac = 1;
            continue;
        }
        e -= frac;
        if (m == 0 && *p == '0')
            continue; /* leading zeros */
        if (++digits > 15)
            return 0;
        m = m * 10 + (uint64_t)(*p - '0');
    }
    if (p < end) {
        int es = 1, ev = 0;
        p++;
        if (*p == '+' || *p == '-')
            es = *p++ == '-' ? -1 : 1;
        for (; p < end; p++)
            if (ev < 100000)
                ev = ev * 10 + (*p - '0');
        e += es * ev;
    }
    if (m == 0)
        e = 0;
    if (e < -22 || e > 22)
        return 0;
    const double d = e < 0 ? (double)m / exact_pow10[-e] : (double)m * exact_pow10[e];
    *out = neg ? -d : d;
    return 1;
}

static double token_value(const char *s, size_t n) {
    double d;
    char tmp[KDR_FAST_TOKEN + 1];
    if (fast_decimal(s, n, &d))
        return d;
    memcpy(tmp, s, n);
    tmp[n] = '\0';
    return strtod(tmp, NULL);
}

static int push(kdr_numarray *a, size_t *cap, double d) {
    if (a->n == *cap) {
        size_t ncap = *cap ? 2 * *cap : 64;
        float *v = realloc(a->v, ncap * sizeof *v);
        if (!v) return -1;
        a->v = v;
        *cap = ncap;
    }
    if (isinf(d) && a->first_inf == SIZE_MAX) a->first_inf = a->n;
    if (isfinite(d) && fabs(d) >= KDR_FLOAT_OVERFLOW && a->first_big == SIZE_MAX)
        a->first_big = a->n;
    a->v[a->n++] = fabs(d) >= KDR_FLOAT_OVERFLOW ? (d > 0 ? INFINITY : -INFINITY)
                                                 : (float)d;
    return 0;
}

/* A flat array of numbers at c->p ('['). 1: parsed (c->p after ']');
 * 0: not such an array (c->p unchanged); -1: out of memory. */
static int number_array(cursor *c, kdr_numarray *a) {
    cursor k = *c;
    size_t cap = 0;
    memset(a, 0, sizeof *a);
    a->first_inf = a->first_big = a->first_nan = SIZE_MAX;
    k.p++;
    skip_ws(&k);
    if (k.p < k.end && *k.p == ']') {
        c->p = k.p + 1;
        return 1;
    }
    for (;;) {
        size_t n = number_len(k.p, k.end);
        if (n == 0 || n > KDR_FAST_TOKEN) break;
        if (push(a, &cap, token_value(k.p, n))) {
            free(a->v);
            return -1;
        }
        k.p += n;
        skip_ws(&k);
        if (k.p < k.end && *k.p == ',') {
            k.p++;
            skip_ws(&k);
            continue;
        }
        if (k.p < k.end && *k.p == ']') {
            c->p = k.p + 1;
            return 1;
        }
        break;
    }
    free(a->v);
    memset(a, 0, sizeof *a);
    return 0;
}

/* The first byte in [p, end) that ends or complicates a JSON string: '"',
 * '\\' or a control character (end if none). Eight bytes per step: a byte
 * b is flagged by (b - x) & ~b & 0x80 when it is below x (here 0x20) or,
 * after an exclusive or with '"' or '\\', zero; borrows can only flag
 * bytes after a true hit, so the lowest flag is exact. */
static const char *string_stop(const char *p, const char *end) {
    const uint64_t ones = 0x0101010101010101ull, high = 0x8080808080808080ull;
    for (; end - p >= 8; p += 8) {
        uint64_t w;
        memcpy(&w, p, 8);
        const uint64_t q = w ^ (ones * '"'), b = w ^ (ones * '\\');
        const uint64_t hit =
            (((q - ones) & ~q) | ((b - ones) & ~b) | ((w - ones * 0x20) & ~w)) & high;
        if (hit)
            return p + (__builtin_ctzll(hit) >> 3);
    }
    while (p < end && *p != '"' && *p != '\\' && (unsigned char)*p >= 0x20)
        p++;
    return p;
}

/* {"f32": "<text without escapes>"} at c->p ('{'): 1 and the text's span
 * (c->p after '}'), or 0 (c->p unchanged) for anything else, which cJSON
 * then reads. */
static int f32_object(cursor *c, kdr_numarray *a) {
    static const char key[] = "\"f32\"";
    cursor k = *c;
    k.p++;
    skip_ws(&k);
    if ((size_t)(k.end - k.p) < sizeof key || memcmp(k.p, key, sizeof key - 1))
        return 0;
    k.p += sizeof key - 1;
    skip_ws(&k);
    if (k.p >= k.end || *k.p++ != ':')
        return 0;
    skip_ws(&k);
    if (k.p >= k.end || *k.p++ != '"')
        return 0;
    const char *text = k.p;
    k.p = string_stop(k.p, k.end);
    if (k.p >= k.end || *k.p != '"')
        return 0;
    memset(a, 0, sizeof *a);
    a->b64 = text;
    a->b64_len = (size_t)(k.p - text);
    k.p++;
    skip_ws(&k);
    if (k.p >= k.end || *k.p != '}')
        return 0;
    c->p = k.p + 1;
    return 1;
}

/* A member name without escapes, copied NUL-terminated; 0 otherwise. */
static int read_key(cursor *c, char *key) {
    if (c->p >= c->end || *c->p != '"')
        return 0;
    size_t n = 0;
    for (c->p++; c->p < c->end && *c->p != '"'; c->p++) {
        const unsigned char ch = (unsigned char)*c->p;
        if (ch == '\\' || ch < 0x20 || n + 1 >= KDR_FAST_MAX_KEY)
            return 0;
        key[n++] = (char)ch;
    }
    if (c->p >= c->end)
        return 0;
    c->p++;
    key[n] = '\0';
    return 1;
}

static const kdr_numarray *find_fast(const kdr_pf_doc *doc, const char *key) {
    for (int i = 0; i < doc->nfast; i++)
        if (!strcmp(doc->fast[i].key, key))
            return &doc->fast[i];
    return NULL;
}

/* As cJSON, the first of duplicate members wins. */
static int has_key(const kdr_pf_doc *doc, const char *key) {
    return find_fast(doc, key) || cJSON_GetObjectItemCaseSensitive(doc->root, key);
}

/* Only the float-array fields of the contract take the fast path, so that
 * every other field is seen (and type-checked) through cJSON. */
int kdr_pf_float_array_field(const char *key) {
    static const char *const names[] = {"origins", "directions", "tmin",
                                        "tmax",    "points",     "normals"};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (!strcmp(key, names[i]))
            return 1;
    return 0;
}

/* One member value: 0 done, 1 give up (use cJSON), or an error status. */
static int member_value(cursor *c, const char *key, kdr_pf_doc *doc,
                        kdr_proto_error *err) {
    const int is_array = c->p < c->end && *c->p == '[';
    const int is_object = c->p < c->end && *c->p == '{';
    if ((is_array || is_object) && kdr_pf_float_array_field(key)) {
        kdr_numarray a;
        const int r = is_array ? number_array(c, &a) : f32_object(c, &a);
        if (r < 0)
            return kdr_proto_error_set(err, 500, "body: out of memory");
        if (r == 1) {
            const int dup = has_key(doc, key);
            if (dup || doc->nfast == KDR_PF_MAX_FAST) {
                free(a.v);
                return dup ? 0 : 1; /* many arrays: not the common case */
            }
            strcpy(a.key, key);
            doc->fast[doc->nfast++] = a;
            return 0;
        }
    }
    const char *vend = NULL;
    cJSON *item = cJSON_ParseWithLengthOpts(c->p, (size_t)(c->end - c->p), &vend, 0);
    if (!item)
        return 1;
    c->p = vend;
    if (has_key(doc, key)) {
        cJSON_Delete(item);
        return 0;
    }
    if (!cJSON_AddItemToObject(doc->root, key, item)) {
        cJSON_Delete(item);
        return kdr_proto_error_set(err, 500, "body: out of memory");
    }
    return 0;
}

int kdr_pf_fast_doc(const char *body, size_t len, kdr_pf_doc *doc, kdr_proto_error *err) {
    cursor c = {body, body + len, body};
    char key[KDR_FAST_MAX_KEY];
    skip_ws(&c);
    if (c.p >= c.end || *c.p != '{')
        return 1;
    if (!(doc->root = cJSON_CreateObject()))
        return kdr_proto_error_set(err, 500, "body: out of memory");
    c.p++;
    skip_ws(&c);
    if (c.p < c.end && *c.p == '}') {
        c.p++;
    } else {
        for (;;) {
            skip_ws(&c);
            if (!read_key(&c, key))
                return 1;
            skip_ws(&c);
            if (c.p >= c.end || *c.p != ':')
                return 1;
            c.p++;
            skip_ws(&c);
            int r = member_value(&c, key, doc, err);
            if (r)
                return r;
            skip_ws(&c);
            if (c.p < c.end && *c.p == ',') {
                c.p++;
                continue;
            }
            if (c.p < c.end && *c.p == '}') {
                c.p++;
                break;
            }
            return 1;
        }
    }
    skip_ws(&c);
    return c.p < c.end; /* trailing data: cJSON names the offset */
}

kdr_pf_field kdr_pf_get(const kdr_pf_doc *doc, const char *name) {
    kdr_pf_field f = {cJSON_GetObjectItemCaseSensitive(doc->root, name),
                      find_fast(doc, name), doc->media == KDR_MEDIA_CBOR};
    return f;
}
