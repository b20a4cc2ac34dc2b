/*
 * kdr_response.c — response bodies: hits (bundle, frustum), visibilities
 * (cone-shadow), scene descriptions and health. Large arrays never go
 * through a cJSON tree: they are written as text straight into the output
 * buffer, a chunk at a time (kdr_format_float for floats), or as base64 of
 * their little-endian bytes, encoded from a small staging block so misses
 * can be normalised on the way without a second full-size copy.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "kdr_proto_internal.h"

/* Values per chunk: a multiple of 3 so that each chunk's 4-byte values make
 * whole base64 groups and chunk encodings concatenate. */
#define KDR_CHUNK 3072
#define KDR_INT_CHARS 12 /* "-2147483648" + ',' */

/* Where an array's values come from: floats or int32 or bytes, with misses
 * (prim < 0) replaced by miss_f / -1 when prim is given. */
typedef struct array_src {
    const float *f;
    const int32_t *i;
    const uint8_t *u8;
    const int32_t *prim;
    float miss_f;
} array_src;

static float src_float(const array_src *s, size_t k) {
    return s->prim && s->prim[k] < 0 ? s->miss_f : s->f[k];
}

static int32_t src_int(const array_src *s, size_t k) {
    if (s->u8)
        return s->u8[k] ? 1 : 0;
    return s->i[k] < 0 ? -1 : s->i[k];
}

static size_t put_int(char *p, int64_t v) {
    char tmp[24];
    size_t n = 0, len = 0;
    uint64_t u = v < 0 ? (uint64_t)0 - (uint64_t)v : (uint64_t)v;
    if (v < 0)
        p[len++] = '-';
    do {
        tmp[n++] = (char)('0' + u % 10);
        u /= 10;
    } while (u);
    while (n)
        p[len++] = tmp[--n];
    return len;
}

static int json_array(kdr_buf *b, const array_src *s, size_t n) {
    const size_t per = s->f ? KDR_FLOAT_CHARS + 1 : KDR_INT_CHARS;
    if (kdr_buf_append(b, "[", 1))
        return KDR_ENOMEM;
    for (size_t k0 = 0; k0 < n; k0 += KDR_CHUNK) {
        const size_t k1 = n - k0 < KDR_CHUNK ? n : k0 + KDR_CHUNK;
        if (kdr_buf_reserve(b, (k1 - k0) * per))
            return KDR_ENOMEM;
        char *p = b->data + b->len;
        for (size_t k = k0; k < k1; k++) {
            if (k)
                *p++ = ',';
            p += s->f ? kdr_format_float(src_float(s, k), p) : put_int(p, src_int(s, k));
        }
        b->len = (size_t)(p - b->data);
    }
    return kdr_buf_append(b, "]", 1);
}

static int base64_array(kdr_buf *b, const array_src *s, size_t n) {
    union {
        float f[KDR_CHUNK];
        int32_t i[KDR_CHUNK];
    } stage;
    if (kdr_buf_append(b, s->f ? "{\"f32\":\"" : "{\"i32\":\"", 8) ||
        kdr_buf_reserve(b, kdr_base64_encoded_len(4 * n) + 2))
        return KDR_ENOMEM;
    for (size_t k0 = 0; k0 < n; k0 += KDR_CHUNK) {
        const size_t m = n - k0 < KDR_CHUNK ? n - k0 : KDR_CHUNK;
        for (size_t k = 0; k < m; k++) {
            if (s->f)
                stage.f[k] = src_float(s, k0 + k);
            else
                stage.i[k] = src_int(s, k0 + k);
        }
        b->len += kdr_base64_encode(&stage, 4 * m, b->data + b->len);
    }
    return KDR_BUF_LIT(b, "\"}");
}

/* ,"name":<array> */
static int named_array(kdr_buf *b, const char *name, const array_src *s, size_t n,
                       kdr_encoding enc) {
    if (kdr_buf_append(b, ",", 1) || kdr_buf_json_string(b, name) ||
        kdr_buf_append(b, ":", 1))
        return KDR_ENOMEM;
    return enc == KDR_ENCODING_BASE64 ? base64_array(b, s, n) : json_array(b, s, n);
}

static int count_head(kdr_buf *b, size_t n) {
    char head[48];
    int len = snprintf(head, sizeof head, "{\"count\":%zu", n);
    return kdr_buf_append(b, head, (size_t)len);
}

int kdr_proto_encode_hits(const kdr_hits *hits, size_t n, kdr_query query,
                          kdr_encoding enc, kdr_buf *out) {
    if (count_head(out, n))
        return KDR_ENOMEM;
    if (query == KDR_ANY) {
        const array_src hit = {.u8 = hits->hit};
        if (named_array(out, "hit", &hit, n, enc))
            return KDR_ENOMEM;
    } else {
        const array_src t = {.f = hits->t, .prim = hits->prim, .miss_f = -1.0f};
        const array_src prim = {.i = hits->prim};
        const array_src u = {.f = hits->u, .prim = hits->prim, .miss_f = 0.0f};
        const array_src v = {.f = hits->v, .prim = hits->prim, .miss_f = 0.0f};
        if (named_array(out, "t", &t, n, enc) || named_array(out, "prim", &prim, n, enc) ||
            named_array(out, "u", &u, n, enc) || named_array(out, "v", &v, n, enc))
            return KDR_ENOMEM;
    }
    return kdr_buf_append(out, "}", 1);
}

int kdr_proto_encode_shadow(const float *visibility, size_t n, size_t nlights,
                            const kdr_shadow_stats *stats, kdr_encoding enc,
                            kdr_buf *out) {
    const array_src vis = {.f = visibility};
    if (count_head(out, n) || named_array(out, "visibility", &vis, n * nlights, enc))
        return KDR_ENOMEM;
    if (stats) {
        char tail[160];
        int len = snprintf(tail, sizeof tail,
                           ",\"stats\":{\"cones_decided\":%llu,\"rays_traced\":%llu,"
                           "\"nodes_visited\":%llu}",
                           (unsigned long long)stats->cones_decided,
                           (unsigned long long)stats->rays_traced,
                           (unsigned long long)stats->nodes_visited);
        if (kdr_buf_append(out, tail, (size_t)len))
            return KDR_ENOMEM;
    }
    return kdr_buf_append(out, "}", 1);
}

/* ---- scenes and health ------------------------------------------------------- */

/* Shortest of %.15g / %.17g that reads back exactly; null if not finite. */
static int put_double(kdr_buf *b, double d) {
    char tmp[40];
    if (!isfinite(d))
        return KDR_BUF_LIT(b, "null");
    int len = snprintf(tmp, sizeof tmp, "%.15g", d);
    if (strtod(tmp, NULL) != d)
        len = snprintf(tmp, sizeof tmp, "%.17g", d);
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
           KDR_BUF_LIT(b, ",") || put_u64(b, "leaves", t->leaves) || KDR_BUF_LIT(b, ",") ||
           put_u64(b, "empty_leaves", t->empty_leaves) || KDR_BUF_LIT(b, ",") ||
           put_u64(b, "max_depth", t->max_depth) || KDR_BUF_LIT(b, ",\"refs_per_leaf\":") ||
           put_double(b, t->refs_per_leaf) || KDR_BUF_LIT(b, ",\"sah_cost\":") ||
           put_double(b, t->sah_cost) || KDR_BUF_LIT(b, ",\"build_ms\":") ||
           put_double(b, t->build_ms) || KDR_BUF_LIT(b, "}");
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

int kdr_proto_encode_scenes(const kdr_proto_scene_info *scenes, size_t n,
                            kdr_buf *out) {
    if (KDR_BUF_LIT(out, "{\"scenes\":["))
        return KDR_ENOMEM;
    for (size_t i = 0; i < n; i++)
        if ((i && KDR_BUF_LIT(out, ",")) || kdr_proto_encode_scene(&scenes[i], out))
            return KDR_ENOMEM;
    return KDR_BUF_LIT(out, "]}");
}

int kdr_proto_encode_health(const char *status, size_t nscenes, kdr_buf *out) {
    char tail[48];
    int len = snprintf(tail, sizeof tail, ",\"scenes\":%zu}", nscenes);
    if (KDR_BUF_LIT(out, "{\"status\":") || kdr_buf_json_string(out, status ? status : "") ||
        kdr_buf_append(out, tail, (size_t)len))
        return KDR_ENOMEM;
    return 0;
}
