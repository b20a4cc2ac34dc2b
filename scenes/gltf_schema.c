/*
 * gltf_schema.c — the JSON checks that run before tinygltf sees a file.
 *
 * tinygltf silently skips a property of the wrong JSON type, which would
 * turn a broken file into a quietly different scene; it also converts
 * `extras` recursively, so deep nesting could overflow the stack. Here the
 * JSON (cJSON, its own nesting limit) is checked against the types of the
 * glTF 2.0 schema for every property we or tinygltf read; unknown properties
 * are allowed, as the spec says. Also refused here: glTF 1.0 and required
 * extensions that move the geometry out of plain accessors.
 */
#include "gltf_schema.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include <cjson/cJSON.h>

/* glTF itself nests about 6 deep; extras may nest more, but not this much. */
#define MAX_JSON_DEPTH 256
#define MAX_PATH 256

typedef enum kind {
    K_STR,
    K_NUM,
    K_UINT,
    K_BOOL,
    K_OBJ,
    K_ARR_NUM,
    K_ARR_UINT,
    K_ARR_STR,
    K_ARR_OBJ,
    K_MAP_UINT
} kind;

static const char *const expect[] = {"a string",
                                     "a number",
                                     "a non-negative integer",
                                     "a boolean",
                                     "an object",
                                     "an array of numbers",
                                     "an array of non-negative integers",
                                     "an array of strings",
                                     "an array of objects",
                                     "an object of non-negative integers"};

typedef struct field {
    const char *name;
    kind kind;
    const struct field *sub; /* element schema of K_OBJ / K_ARR_OBJ (or NULL) */
} field;

#define END                                                                              \
    { NULL, K_STR, NULL }

/* ---- the schema, leaves first ------------------------------------------- */

static const field asset_f[] = {{"version", K_STR, NULL},
                                {"generator", K_STR, NULL},
                                {"minVersion", K_STR, NULL},
                                {"copyright", K_STR, NULL},
                                END};
static const field scene_f[] = {{"nodes", K_ARR_UINT, NULL}, END};
static const field node_f[] = {
    {"children", K_ARR_UINT, NULL}, {"mesh", K_UINT, NULL},
    {"camera", K_UINT, NULL},       {"skin", K_UINT, NULL},
    {"matrix", K_ARR_NUM, NULL},    {"rotation", K_ARR_NUM, NULL},
    {"scale", K_ARR_NUM, NULL},     {"translation", K_ARR_NUM, NULL},
    {"weights", K_ARR_NUM, NULL},   END};
static const field primitive_f[] = {
    {"attributes", K_MAP_UINT, NULL}, {"indices", K_UINT, NULL},
    {"material", K_UINT, NULL},       {"mode", K_UINT, NULL},
    {"targets", K_ARR_OBJ, NULL},     END};
static const field mesh_f[] = {
    {"primitives", K_ARR_OBJ, primitive_f}, {"weights", K_ARR_NUM, NULL}, END};
static const field sparse_part_f[] = {{"bufferView", K_UINT, NULL},
                                      {"byteOffset", K_UINT, NULL},
                                      {"componentType", K_UINT, NULL},
                                      END};
static const field sparse_f[] = {{"count", K_UINT, NULL},
                                 {"indices", K_OBJ, sparse_part_f},
                                 {"values", K_OBJ, sparse_part_f},
                                 END};
static const field accessor_f[] = {
    {"bufferView", K_UINT, NULL},    {"byteOffset", K_UINT, NULL},
    {"componentType", K_UINT, NULL}, {"normalized", K_BOOL, NULL},
    {"count", K_UINT, NULL},         {"type", K_STR, NULL},
    {"max", K_ARR_NUM, NULL},        {"min", K_ARR_NUM, NULL},
    {"sparse", K_OBJ, sparse_f},     END};
static const field buffer_view_f[] = {
    {"buffer", K_UINT, NULL},     {"byteOffset", K_UINT, NULL},
    {"byteLength", K_UINT, NULL}, {"byteStride", K_UINT, NULL},
    {"target", K_UINT, NULL},     END};
static const field buffer_f[] = {{"uri", K_STR, NULL}, {"byteLength", K_UINT, NULL}, END};
static const field tex_info_f[] = {{"index", K_UINT, NULL},
                                   {"texCoord", K_UINT, NULL},
                                   {"scale", K_NUM, NULL},
                                   {"strength", K_NUM, NULL},
                                   END};
static const field pbr_f[] = {{"baseColorFactor", K_ARR_NUM, NULL},
                              {"baseColorTexture", K_OBJ, tex_info_f},
                              {"metallicFactor", K_NUM, NULL},
                              {"roughnessFactor", K_NUM, NULL},
                              {"metallicRoughnessTexture", K_OBJ, tex_info_f},
                              END};
static const field material_f[] = {{"pbrMetallicRoughness", K_OBJ, pbr_f},
                                   {"normalTexture", K_OBJ, tex_info_f},
                                   {"occlusionTexture", K_OBJ, tex_info_f},
                                   {"emissiveTexture", K_OBJ, tex_info_f},
                                   {"emissiveFactor", K_ARR_NUM, NULL},
                                   {"alphaMode", K_STR, NULL},
                                   {"alphaCutoff", K_NUM, NULL},
                                   {"doubleSided", K_BOOL, NULL},
                                   END};
static const field texture_f[] = {
    {"sampler", K_UINT, NULL}, {"source", K_UINT, NULL}, END};
static const field image_f[] = {
    {"uri", K_STR, NULL}, {"mimeType", K_STR, NULL}, {"bufferView", K_UINT, NULL}, END};
static const field sampler_f[] = {{"magFilter", K_UINT, NULL},
                                  {"minFilter", K_UINT, NULL},
                                  {"wrapS", K_UINT, NULL},
                                  {"wrapT", K_UINT, NULL},
                                  END};
static const field skin_f[] = {{"inverseBindMatrices", K_UINT, NULL},
                               {"skeleton", K_UINT, NULL},
                               {"joints", K_ARR_UINT, NULL},
                               END};
static const field camera_f[] = {{"type", K_STR, NULL},
                                 {"perspective", K_OBJ, NULL},
                                 {"orthographic", K_OBJ, NULL},
                                 END};
static const field animation_f[] = {
    {"channels", K_ARR_OBJ, NULL}, {"samplers", K_ARR_OBJ, NULL}, END};
static const field root_f[] = {{"asset", K_OBJ, asset_f},
                               {"scene", K_UINT, NULL},
                               {"scenes", K_ARR_OBJ, scene_f},
                               {"nodes", K_ARR_OBJ, node_f},
                               {"meshes", K_ARR_OBJ, mesh_f},
                               {"accessors", K_ARR_OBJ, accessor_f},
                               {"bufferViews", K_ARR_OBJ, buffer_view_f},
                               {"buffers", K_ARR_OBJ, buffer_f},
                               {"materials", K_ARR_OBJ, material_f},
                               {"textures", K_ARR_OBJ, texture_f},
                               {"images", K_ARR_OBJ, image_f},
                               {"samplers", K_ARR_OBJ, sampler_f},
                               {"skins", K_ARR_OBJ, skin_f},
                               {"cameras", K_ARR_OBJ, camera_f},
                               {"animations", K_ARR_OBJ, animation_f},
                               {"extensionsUsed", K_ARR_STR, NULL},
                               {"extensionsRequired", K_ARR_STR, NULL},
                               END};

/* Extensions that move positions out of plain accessors: a file that
 * requires one of them cannot be flattened faithfully. */
static const char *const unsupported_ext[] = {
    "KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_meshopt_compression",
    "EXT_mesh_gpu_instancing", NULL};

/* ---- checking ----------------------------------------------------------- */

static int fail(char *err, size_t errlen, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, errlen, fmt, ap);
    va_end(ap);
    return -1;
}

static int is_uint(const cJSON *v) {
    if (!cJSON_IsNumber(v)) return 0;
    double d = v->valuedouble;
    return d >= 0 && d <= 4294967295.0 && d == floor(d);
}

/* For arrays and objects alike: every element or member value passes. */
static int children_all(const cJSON *v, int (*ok)(const cJSON *)) {
    const cJSON *e;
    cJSON_ArrayForEach(e, v) if (!ok(e)) return 0;
    return 1;
}

static int all_of(const cJSON *v, int (*ok)(const cJSON *)) {
    return cJSON_IsArray(v) && children_all(v, ok);
}

static int is_num(const cJSON *v) { return cJSON_IsNumber(v); }
static int is_str(const cJSON *v) { return cJSON_IsString(v); }
static int is_obj(const cJSON *v) { return cJSON_IsObject(v); }

static int has_kind(const cJSON *v, kind k) {
    switch (k) {
    case K_STR:
        return cJSON_IsString(v);
    case K_NUM:
        return cJSON_IsNumber(v);
    case K_UINT:
        return is_uint(v);
    case K_BOOL:
        return cJSON_IsBool(v);
    case K_OBJ:
        return cJSON_IsObject(v);
    case K_ARR_NUM:
        return all_of(v, is_num);
    case K_ARR_UINT:
        return all_of(v, is_uint);
    case K_ARR_STR:
        return all_of(v, is_str);
    case K_ARR_OBJ:
        return all_of(v, is_obj);
    case K_MAP_UINT:
        return cJSON_IsObject(v) && children_all(v, is_uint);
    }
    return 0;
}

static int check_object(const cJSON *o, const field *schema, const char *path, char *err,
                        size_t errlen);

static int check_field(const cJSON *v, const field *f, const char *path, char *err,
                       size_t errlen) {
    if (!has_kind(v, f->kind))
        return fail(err, errlen, "schema: %s is not %s", path, expect[f->kind]);
    if (f->kind == K_OBJ && f->sub) return check_object(v, f->sub, path, err, errlen);
    if (f->kind != K_ARR_OBJ || !f->sub) return 0;
    int i = 0;
    const cJSON *e;
    cJSON_ArrayForEach(e, v) {
        char sub[MAX_PATH];
        snprintf(sub, sizeof sub, "%s[%d]", path, i++);
        if (check_object(e, f->sub, sub, err, errlen)) return -1;
    }
    return 0;
}

/* `name` and `extensions` are typed wherever they appear; `extras` is free. */
static int check_member(const cJSON *v, const field *schema, const char *path, char *err,
                        size_t errlen) {
    static const field name_f = {"name", K_STR, NULL},
                       ext_f = {"extensions", K_OBJ, NULL};
    if (strcmp(v->string, "name") == 0) return check_field(v, &name_f, path, err, errlen);
    if (strcmp(v->string, "extensions") == 0) {
        if (check_field(v, &ext_f, path, err, errlen)) return -1;
        const cJSON *e;
        cJSON_ArrayForEach(e, v) if (!cJSON_IsObject(e)) return fail(
            err, errlen, "schema: %s.%s is not an object", path, e->string);
        return 0;
    }
    for (const field *f = schema; f->name; f++)
        if (strcmp(v->string, f->name) == 0) return check_field(v, f, path, err, errlen);
    return 0;
}

static int check_object(const cJSON *o, const field *schema, const char *path, char *err,
                        size_t errlen) {
    const cJSON *v;
    cJSON_ArrayForEach(v, o) {
        char sub[MAX_PATH];
        snprintf(sub, sizeof sub, "%s%s%s", path, path[0] ? "." : "", v->string);
        if (check_member(v, schema, sub, err, errlen)) return -1;
    }
    return 0;
}

/* Refused before any parser recurses into it. */
static int check_nesting(const char *text, size_t len, char *err, size_t errlen) {
    int depth = 0, in_string = 0, escaped = 0;
    for (size_t i = 0; i < len; i++) {
        char c = text[i];
        if (in_string) {
            if (escaped)
                escaped = 0;
            else if (c == '\\')
                escaped = 1;
            else if (c == '"')
                in_string = 0;
        } else if (c == '"') {
            in_string = 1;
        } else if (c == '[' || c == '{') {
            if (++depth > MAX_JSON_DEPTH)
                return fail(err, errlen, "JSON nested deeper than %d levels",
                            MAX_JSON_DEPTH);
        } else if (c == ']' || c == '}') {
            depth--;
        }
    }
    return 0;
}

static int check_version(const cJSON *root, char *err, size_t errlen) {
    const cJSON *asset = cJSON_GetObjectItemCaseSensitive(root, "asset");
    if (!cJSON_IsObject(asset)) return fail(err, errlen, "schema: no \"asset\" object");
    const cJSON *ver = cJSON_GetObjectItemCaseSensitive(asset, "version");
    if (cJSON_IsString(ver) && strncmp(ver->valuestring, "2.", 2) != 0)
        return fail(err, errlen, "glTF version \"%.32s\" is not supported (need 2.x)",
                    ver->valuestring);
    return 0;
}

static int check_required(const cJSON *root, char *err, size_t errlen) {
    const cJSON *e, *req = cJSON_GetObjectItemCaseSensitive(root, "extensionsRequired");
    cJSON_ArrayForEach(
        e, req) for (int i = 0; unsupported_ext[i];
                     i++) if (strcmp(e->valuestring, unsupported_ext[i]) ==
                              0) return fail(err, errlen,
                                             "requires extension %s (unsupported)",
                                             unsupported_ext[i]);
    return 0;
}

int kdr_gltf_check_json(const char *text, size_t len, char *err, size_t errlen) {
    if (check_nesting(text, len, err, errlen)) return -1;
    const char *end = NULL;
    cJSON *root = cJSON_ParseWithLengthOpts(text, len, &end, 0);
    if (!root)
        return fail(err, errlen, "invalid JSON at byte %zu",
                    end && end >= text ? (size_t)(end - text) : (size_t)0);
    size_t used = (size_t)(end - text);
    /* GLB pads its JSON chunk with spaces; some exporters pad with NULs. */
    while (used < len && memchr(" \t\r\n", text[used], 5))
        used++;
    int rc = -1;
    if (used < len)
        fail(err, errlen, "invalid JSON: trailing characters at byte %zu", used);
    else if (!cJSON_IsObject(root))
        fail(err, errlen, "schema: the top level is not an object");
    else if (!check_version(root, err, errlen) &&
             !check_object(root, root_f, "", err, errlen))
        rc = check_required(root, err, errlen);
    cJSON_Delete(root);
    return rc;
}
