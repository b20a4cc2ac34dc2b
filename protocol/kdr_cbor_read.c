/*
 * kdr_cbor_read.c — a CBOR request body (RFC 8949, application/cbor) into
 * the same kdr_pf_doc the JSON reader makes, so both media types share
 * every field rule and message. libcbor's streaming decoder (Debian
 * libcbor-dev, cbor_stream_decode) reads one item head at a time into a
 * token; nothing is allocated per item except the small members, which
 * become cJSON nodes:
 *  - the contract's float-array members (kdr_pf_float_array_field) take a
 *    fast path: a float32 typed array (RFC 8746 tag 85, little-endian) is
 *    kept as a pointer into the body (kdr_pf_view then uses it in place
 *    when aligned), a CBOR array of numbers is converted straight to
 *    float32 with the JSON walk's rules;
 *  - every other member is converted to cJSON (typed arrays there become
 *    arrays of numbers), within a depth limit and a node budget, so a
 *    nesting bomb or a small body declaring millions of items is a 400
 *    naming the member, not a crash or a memory blow-up.
 * Strings must be definite-length (a typed array must be one piece to be
 * read in place); maps and arrays may be indefinite. Map keys are text.
 * The reader records where each big array sits in the body, which is what
 * an incremental reader (rays traced while the body arrives) would need.
 */
#include <cbor.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "kdr_proto_internal.h"

#define KDR_CBOR_MAX_DEPTH 16     /* the contract needs 4 (lights[i].center[k]) */
#define KDR_CBOR_MAX_NODES 65536  /* cJSON nodes for the small members */
#define KDR_CBOR_MAX_KEY 255
#define KDR_CBOR_TAG_SELF 55799   /* "self-described CBOR" prefix: ignored */
#define KDR_CBOR_TAG_TYPED_LO 64  /* RFC 8746 typed arrays: tags 64..87 */
#define KDR_CBOR_TAG_TYPED_HI 87

typedef enum tok_kind {
    T_UINT, T_NEG, T_BYTES, T_TEXT, T_ARRAY, T_MAP, T_INDEF_ARRAY, T_INDEF_MAP,
    T_INDEF_STRING, T_TAG, T_FLOAT, T_BOOL, T_NULL, T_BREAK
} tok_kind;

/* One item head as libcbor reported it. */
typedef struct token {
    tok_kind kind;
    uint64_t u;                 /* UINT, NEG (value -1-u), ARRAY/MAP size, TAG */
    double d;                   /* FLOAT */
    const unsigned char *p;     /* BYTES, TEXT */
    size_t len;
    size_t at;                  /* offset of the head in the body */
} token;

typedef struct reader {
    const unsigned char *body;
    size_t len, pos, nodes;
    kdr_proto_error *err;
    char path[128]; /* the value being read, for messages */
} reader;

/* ---- libcbor callbacks: each one fills the token ------------------------------- */

static void cb_uint8(void *t, uint8_t v) { ((token *)t)->kind = T_UINT, ((token *)t)->u = v; }
static void cb_uint16(void *t, uint16_t v) { ((token *)t)->kind = T_UINT, ((token *)t)->u = v; }
static void cb_uint32(void *t, uint32_t v) { ((token *)t)->kind = T_UINT, ((token *)t)->u = v; }
static void cb_uint64(void *t, uint64_t v) { ((token *)t)->kind = T_UINT, ((token *)t)->u = v; }
static void cb_neg8(void *t, uint8_t v) { ((token *)t)->kind = T_NEG, ((token *)t)->u = v; }
static void cb_neg16(void *t, uint16_t v) { ((token *)t)->kind = T_NEG, ((token *)t)->u = v; }
static void cb_neg32(void *t, uint32_t v) { ((token *)t)->kind = T_NEG, ((token *)t)->u = v; }
static void cb_neg64(void *t, uint64_t v) { ((token *)t)->kind = T_NEG, ((token *)t)->u = v; }
static void cb_string(token *t, tok_kind k, cbor_data p, size_t n) {
    t->kind = k;
    t->p = p;
    t->len = n;
}
static void cb_bytes(void *t, cbor_data p, size_t n) { cb_string(t, T_BYTES, p, n); }
static void cb_text(void *t, cbor_data p, size_t n) { cb_string(t, T_TEXT, p, n); }
static void cb_indef_string(void *t) { ((token *)t)->kind = T_INDEF_STRING; }
static void cb_array(void *t, size_t n) { ((token *)t)->kind = T_ARRAY, ((token *)t)->u = n; }
static void cb_map(void *t, size_t n) { ((token *)t)->kind = T_MAP, ((token *)t)->u = n; }
static void cb_indef_array(void *t) { ((token *)t)->kind = T_INDEF_ARRAY; }
static void cb_indef_map(void *t) { ((token *)t)->kind = T_INDEF_MAP; }
static void cb_tag(void *t, uint64_t v) { ((token *)t)->kind = T_TAG, ((token *)t)->u = v; }
static void cb_float(void *t, float v) { ((token *)t)->kind = T_FLOAT, ((token *)t)->d = v; }
static void cb_double(void *t, double v) { ((token *)t)->kind = T_FLOAT, ((token *)t)->d = v; }
static void cb_bool(void *t, bool v) { ((token *)t)->kind = T_BOOL, ((token *)t)->u = v; }
static void cb_null(void *t) { ((token *)t)->kind = T_NULL; }
static void cb_break(void *t) { ((token *)t)->kind = T_BREAK; }

static const struct cbor_callbacks CALLBACKS = {
    .uint8 = cb_uint8, .uint16 = cb_uint16, .uint32 = cb_uint32, .uint64 = cb_uint64,
    .negint8 = cb_neg8, .negint16 = cb_neg16, .negint32 = cb_neg32, .negint64 = cb_neg64,
    .byte_string_start = cb_indef_string, .byte_string = cb_bytes,
    .string = cb_text, .string_start = cb_indef_string,
    .indef_array_start = cb_indef_array, .array_start = cb_array,
    .indef_map_start = cb_indef_map, .map_start = cb_map,
    .tag = cb_tag, .float2 = cb_float, .float4 = cb_float, .float8 = cb_double,
    .undefined = cb_null, .null = cb_null, .boolean = cb_bool, .indef_break = cb_break,
};

/* ---- tokens ----------------------------------------------------------------------- */

static int fail(reader *r, int status, const char *what, size_t at) {
    if (r->path[0])
        return kdr_proto_error_set(r->err, status, "%s: %s (CBOR offset %zu)", r->path,
                                   what, at);
    return kdr_proto_error_set(r->err, status, "body: %s (CBOR offset %zu)", what, at);
}

static int next(reader *r, token *t) {
    memset(t, 0, sizeof *t);
    t->at = r->pos;
    if (r->pos >= r->len)
        return fail(r, 400, "truncated CBOR", r->pos);
    const struct cbor_decoder_result res =
        cbor_stream_decode(r->body + r->pos, r->len - r->pos, &CALLBACKS, t);
    if (res.status == CBOR_DECODER_NEDATA)
        return fail(r, 400, "truncated CBOR: an item needs more bytes than the body has",
                    r->pos);
    if (res.status != CBOR_DECODER_FINISHED || res.read == 0)
        return fail(r, 400, "malformed CBOR: reserved or unsupported initial byte",
                    r->pos);
    if (t->kind == T_INDEF_STRING)
        return fail(r, 400, "indefinite-length strings are not supported", r->pos);
    r->pos += res.read;
    return 0;
}

/* Appends ".key" or "[i]" to the path; returns the old length to restore. */
static size_t path_push(reader *r, const char *key, size_t index) {
    const size_t old = strlen(r->path);
    const size_t room = sizeof r->path - old;
    if (key)
        snprintf(r->path + old, room, old ? ".%s" : "%s", key);
    else
        snprintf(r->path + old, room, "[%zu]", index);
    return old;
}

static int is_number(const token *t) {
    return t->kind == T_UINT || t->kind == T_NEG || t->kind == T_FLOAT;
}

/* A CBOR integer or float as a double. Integers beyond 2^53 stay beyond it
 * (rounding could bring 2^53 + 1 down into a range such as seed's). */
static double number_of(const token *t) {
    if (t->kind == T_FLOAT)
        return t->d;
    double d = (double)t->u;
    if (t->u > (1ull << 53) && d <= 0x1p53)
        d = 0x1p53 + 2.0;
    return t->kind == T_NEG ? -d - 1.0 : d;
}

/* ---- small members: cJSON ---------------------------------------------------------- */

static int value(reader *r, int depth, cJSON **out);

static int count_node(reader *r, size_t at) {
    if (++r->nodes > KDR_CBOR_MAX_NODES) {
        char what[64];
        snprintf(what, sizeof what, "more than %d items", KDR_CBOR_MAX_NODES);
        return fail(r, 400, what, at);
    }
    return 0;
}

/* A node for a token already read (scalars, strings); NULL on error. */
static cJSON *scalar(reader *r, const token *t) {
    cJSON *j = NULL;
    if (count_node(r, t->at))
        return NULL;
    switch (t->kind) {
    case T_UINT:
    case T_NEG:
    case T_FLOAT:
        /* valuedouble set directly: cJSON_CreateNumber would cast a NaN to int */
        if ((j = cJSON_CreateNumber(0.0)))
            j->valuedouble = number_of(t);
        break;
    case T_TEXT: {
        if (memchr(t->p, '\0', t->len)) {
            fail(r, 400, "text contains a NUL byte", t->at);
            return NULL;
        }
        char *s = malloc(t->len + 1);
        if (s) {
            memcpy(s, t->p, t->len);
            s[t->len] = '\0';
            j = cJSON_CreateString(s);
            free(s);
        }
        break;
    }
    case T_BOOL: j = cJSON_CreateBool(t->u != 0); break;
    case T_NULL: j = cJSON_CreateNull(); break;
    default: fail(r, 400, "unexpected CBOR item", t->at); return NULL;
    }
    if (!j)
        kdr_proto_error_set(r->err, 500, "body: out of memory");
    return j;
}

/* A typed array (tag already read) outside the fast path: float32 becomes
 * an array of numbers; other element types are refused. */
static int typed_to_json(reader *r, const token *tag, cJSON **out) {
    token t;
    if (next(r, &t))
        return r->err->status;
    if (t.kind != T_BYTES)
        return fail(r, 400, "a typed-array tag must tag a byte string", t.at);
    if (tag->u != KDR_CBOR_TAG_F32LE)
        return fail(r, 400, "only float32 little-endian typed arrays (tag 85) are read",
                    tag->at);
    if (t.len % 4)
        return fail(r, 400, "typed array length is not a multiple of 4 bytes", t.at);
    if (!out)
        return 0;
    if (!(*out = cJSON_CreateArray()))
        return kdr_proto_error_set(r->err, 500, "body: out of memory");
    for (size_t k = 0; k < t.len / 4; k++) {
        float f;
        memcpy(&f, t.p + 4 * k, 4);
        const token num = {.kind = T_FLOAT, .d = f, .at = t.at};
        cJSON *j = scalar(r, &num);
        if (!j)
            return r->err->status;
        cJSON_AddItemToArray(*out, j);
    }
    return 0;
}

/* The items of an array or map whose head t was read; out NULL: skip. */
static int container(reader *r, const token *t, int depth, cJSON **out) {
    const int is_map = t->kind == T_MAP || t->kind == T_INDEF_MAP;
    const int indef = t->kind == T_INDEF_ARRAY || t->kind == T_INDEF_MAP;
    if (depth >= KDR_CBOR_MAX_DEPTH)
        return fail(r, 400, "nested too deeply", t->at);
    if (out) {
        if (count_node(r, t->at))
            return r->err->status;
        if (!(*out = is_map ? cJSON_CreateObject() : cJSON_CreateArray()))
            return kdr_proto_error_set(r->err, 500, "body: out of memory");
    }
    for (uint64_t i = 0; indef || i < t->u; i++) {
        char key[KDR_CBOR_MAX_KEY + 1];
        token k;
        if (indef || is_map) {
            const size_t at = r->pos;
            if (next(r, &k))
                return r->err->status;
            if (indef && k.kind == T_BREAK)
                return 0;
            if (!is_map)
                r->pos = at; /* an array item: read it again below */
        }
        if (is_map) {
            if (k.kind != T_TEXT)
                return fail(r, 400, "map keys must be text strings", k.at);
            if (k.len > KDR_CBOR_MAX_KEY || memchr(k.p, '\0', k.len))
                return fail(r, 400, "map key too long or holding a NUL byte", k.at);
            memcpy(key, k.p, k.len);
            key[k.len] = '\0';
        }
        const size_t old = path_push(r, is_map ? key : NULL, (size_t)i);
        cJSON *item = NULL;
        const int st = value(r, depth + 1, out ? &item : NULL);
        r->path[old] = '\0';
        if (st) {
            cJSON_Delete(item);
            return st;
        }
        if (!out)
            continue;
        if (is_map)
            cJSON_AddItemToObject(*out, key, item);
        else
            cJSON_AddItemToArray(*out, item);
    }
    return 0;
}

/* Reads one value; converts it into *out unless out is NULL (skip). */
static int value(reader *r, int depth, cJSON **out) {
    token t;
    if (next(r, &t))
        return r->err->status;
    while (t.kind == T_TAG && t.u == KDR_CBOR_TAG_SELF)
        if (next(r, &t))
            return r->err->status;
    switch (t.kind) {
    case T_ARRAY:
    case T_MAP:
    case T_INDEF_ARRAY:
    case T_INDEF_MAP: return container(r, &t, depth, out);
    case T_TAG:
        if (t.u >= KDR_CBOR_TAG_TYPED_LO && t.u <= KDR_CBOR_TAG_TYPED_HI)
            return typed_to_json(r, &t, out);
        return fail(r, 400, "unsupported CBOR tag", t.at);
    case T_BYTES:
        return fail(r, 400, "a byte string needs a typed-array tag (float32: 85)", t.at);
    case T_BREAK: return fail(r, 400, "break outside an indefinite-length item", t.at);
    default:
        if (!out)
            return 0;
        *out = scalar(r, &t);
        return *out ? 0 : r->err->status;
    }
}

/* ---- float-array members: the fast path ---------------------------------------------- */

static int push(kdr_numarray *a, size_t *cap, double d) {
    if (a->n == *cap) {
        const size_t ncap = *cap ? 2 * *cap : 64;
        float *v = realloc(a->v, ncap * sizeof *v);
        if (!v)
            return -1;
        a->v = v;
        *cap = ncap;
    }
    if (isnan(d) && a->first_nan == SIZE_MAX) a->first_nan = a->n;
    if (isinf(d) && a->first_inf == SIZE_MAX) a->first_inf = a->n;
    if (isfinite(d) && fabs(d) >= KDR_FLOAT_OVERFLOW && a->first_big == SIZE_MAX)
        a->first_big = a->n;
    a->v[a->n++] = isnan(d)                        ? NAN
                   : fabs(d) >= KDR_FLOAT_OVERFLOW ? (d > 0 ? INFINITY : -INFINITY)
                                                   : (float)d;
    return 0;
}

/* The items of an array (head t read) as float32; an item that is not a
 * number is skipped and counts as "not a number". */
static int number_array(reader *r, const token *t, kdr_numarray *a) {
    const int indef = t->kind == T_INDEF_ARRAY;
    /* each item takes a byte at least: never trust a declared size beyond that */
    size_t cap = indef ? 0 : (size_t)(t->u < r->len - r->pos ? t->u : r->len - r->pos);
    if (cap && !(a->v = malloc(cap * sizeof *a->v)))
        return kdr_proto_error_set(r->err, 500, "body: out of memory");
    for (uint64_t i = 0; indef || i < t->u; i++) {
        const size_t at = r->pos;
        token e;
        if (next(r, &e))
            return r->err->status;
        if (indef && e.kind == T_BREAK)
            return 0;
        double d = NAN;
        if (is_number(&e)) {
            d = number_of(&e);
        } else {
            r->pos = at;
            const size_t old = path_push(r, NULL, a->n);
            const int st = value(r, 1, NULL);
            r->path[old] = '\0';
            if (st)
                return st;
        }
        if (push(a, &cap, d)) /* d NaN: counted as "not a number" */
            return kdr_proto_error_set(r->err, 500, "body: out of memory");
    }
    return 0;
}

/* A float-array member: 1 if read here into a, 0 if it is of another form
 * (r->pos unchanged: the general path reads it), or an error status. */
static int fast_array(reader *r, kdr_numarray *a) {
    const size_t at = r->pos;
    token t;
    memset(a, 0, sizeof *a);
    a->first_inf = a->first_big = a->first_nan = SIZE_MAX;
    if (next(r, &t))
        return r->err->status;
    if (t.kind == T_ARRAY || t.kind == T_INDEF_ARRAY) {
        const int st = number_array(r, &t, a);
        return st ? st : 1;
    }
    if (t.kind == T_TAG && t.u == KDR_CBOR_TAG_F32LE) {
        token b;
        if (next(r, &b))
            return r->err->status;
        if (b.kind != T_BYTES)
            return fail(r, 400, "a typed-array tag must tag a byte string", b.at);
        if (b.len % 4)
            return fail(r, 400, "typed array length is not a multiple of 4 bytes", b.at);
        a->raw = b.p;
        a->n = b.len / 4;
        return 1;
    }
    r->pos = at;
    return 0;
}

/* ---- the body -------------------------------------------------------------------------- */

static int has_member(const kdr_pf_doc *doc, const char *key) {
    for (int i = 0; i < doc->nfast; i++)
        if (!strcmp(doc->fast[i].key, key))
            return 1;
    return cJSON_GetObjectItemCaseSensitive(doc->root, key) != NULL;
}

/* One top-level member whose key has been read. */
static int member(reader *r, kdr_pf_doc *doc, const char *key) {
    const size_t old = path_push(r, key, 0);
    int st;
    if (has_member(doc, key)) { /* as in JSON, the first of duplicates wins */
        st = value(r, 1, NULL);
    } else if (kdr_pf_float_array_field(key) && doc->nfast < KDR_PF_MAX_FAST &&
               (st = fast_array(r, &doc->fast[doc->nfast])) != 0) {
        if (st == 1) {
            strcpy(doc->fast[doc->nfast++].key, key);
            st = 0;
        } else {
            free(doc->fast[doc->nfast].v);
            doc->fast[doc->nfast].v = NULL;
        }
    } else {
        cJSON *item = NULL;
        st = value(r, 1, &item);
        if (!st)
            cJSON_AddItemToObject(doc->root, key, item);
        else
            cJSON_Delete(item);
    }
    r->path[old] = '\0';
    return st;
}

int kdr_pf_cbor_doc(const char *body, size_t len, kdr_pf_doc *doc, kdr_proto_error *err) {
    reader r = {(const unsigned char *)body, len, 0, 0, err, ""};
    token t;
    if (!(doc->root = cJSON_CreateObject()))
        return kdr_proto_error_set(err, 500, "body: out of memory");
    do {
        if (next(&r, &t))
            return err->status;
    } while (t.kind == T_TAG && t.u == KDR_CBOR_TAG_SELF);
    if (t.kind != T_MAP && t.kind != T_INDEF_MAP)
        return fail(&r, 400, "expected a CBOR map", t.at);
    const int indef = t.kind == T_INDEF_MAP;
    for (uint64_t i = 0; indef || i < t.u; i++) {
        char key[KDR_CBOR_MAX_KEY + 1];
        token k;
        if (next(&r, &k))
            return err->status;
        if (indef && k.kind == T_BREAK)
            break;
        if (k.kind != T_TEXT)
            return fail(&r, 400, "map keys must be text strings", k.at);
        if (k.len > KDR_CBOR_MAX_KEY || memchr(k.p, '\0', k.len))
            return fail(&r, 400, "map key too long or holding a NUL byte", k.at);
        memcpy(key, k.p, k.len);
        key[k.len] = '\0';
        if (member(&r, doc, key))
            return err->status;
    }
    if (r.pos != len)
        return fail(&r, 400, "data after the CBOR map", r.pos);
    return 0;
}
