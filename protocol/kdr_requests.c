/*
 * kdr_requests.c — the three query bodies of shared/API.md (bundle,
 * cone-shadow, frustum), in JSON or CBOR, turned into the core's query
 * structs; both media types go through the same field readers, so they
 * share every rule and error message but the form of float arrays. Each
 * parser
 * checks shapes and limits before it allocates or decodes a request array
 * (so a 413 costs no more than the parse), then reads the arrays, then
 * checks the geometry a core call would
 * otherwise reject (zero directions, points inside lights, degenerate
 * cameras), so the server only ever hands the core valid queries.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "kdr_proto_internal.h"

static const cJSON *field(const cJSON *root, const char *name) {
    return cJSON_GetObjectItemCaseSensitive(root, name);
}

static float *alloc_floats(size_t n) { return kdr_pf_malloc((n ? n : 1) * sizeof(float)); }

static size_t limit_of(size_t max_rays) {
    return max_rays ? max_rays : KDR_PROTO_DEFAULT_MAX_RAYS;
}

/* ---- bundle ------------------------------------------------------------------ */

/* Shapes of a bundle, known before any array is decoded. */
typedef struct bundle_shape {
    size_t n, norg, ntmin, ntmax; /* ntmin/ntmax: 0 number/absent, else N */
} bundle_shape;

/* tmin/tmax: absent, a number, or an array of N. */
static int interval_shape(kdr_pf_field f, const char *name, size_t n, size_t *count,
                          kdr_proto_error *err) {
    *count = 0;
    if (!kdr_pf_present(f) || (f.item && cJSON_IsNumber(f.item)))
        return 0;
    if (f.item && !cJSON_IsArray(f.item) && !cJSON_IsObject(f.item))
        return kdr_proto_error_set(
            err, 400, "%s: expected a number, an array of N numbers or {\"f32\": base64}",
            name);
    if (kdr_pf_count(f, name, count, err))
        return err->status;
    if (*count != n)
        return kdr_proto_error_set(err, 400, "%s: length %zu is not N=%zu", name, *count,
                                   n);
    return 0;
}

static int bundle_shapes(const kdr_pf_doc *doc, size_t max, bundle_shape *sh,
                         kdr_proto_error *err) {
    const kdr_pf_field dir = kdr_pf_get(doc, "directions");
    const kdr_pf_field org = kdr_pf_get(doc, "origins");
    size_t nd;
    if (!kdr_pf_present(dir))
        return kdr_proto_error_set(err, 400, "directions: required");
    if (kdr_pf_count(dir, "directions", &nd, err))
        return err->status;
    if (nd == 0 || nd % 3)
        return kdr_proto_error_set(err, 400,
                                   "directions: length %zu is not 3*N with N >= 1", nd);
    sh->n = nd / 3;
    if (sh->n > max)
        return kdr_pf_too_many(err, sh->n, max, "rays");
    if (!kdr_pf_present(org))
        return kdr_proto_error_set(err, 400, "origins: required");
    if (kdr_pf_count(org, "origins", &sh->norg, err))
        return err->status;
    if (sh->norg != 3 && sh->norg != nd)
        return kdr_proto_error_set(err, 400, "origins: length %zu is not 3 or 3*N (N=%zu)",
                                   sh->norg, sh->n);
    if (interval_shape(kdr_pf_get(doc, "tmin"), "tmin", sh->n, &sh->ntmin, err) ||
        interval_shape(kdr_pf_get(doc, "tmax"), "tmax", sh->n, &sh->ntmax, err))
        return err->status;
    return 0;
}

/* Fills one of tmin/tmax: a shared value (stride 0) or N values. */
static int read_interval(kdr_pf_field f, const char *name, size_t count, float dflt,
                         float **storage, const float **ptr, size_t *stride,
                         kdr_proto_error *err) {
    *stride = count ? 1 : 0;
    if (count)
        return kdr_pf_view(f, name, count, KDR_PF_SATURATE, storage, ptr, err);
    *storage = alloc_floats(1);
    if (!*storage)
        return kdr_proto_error_set(err, 500, "%s: out of memory", name);
    *ptr = *storage;
    (*storage)[0] = dflt;
    if (!f.item)
        return 0;
    double d = f.item->valuedouble; /* any number; huge saturates to +-inf */
    if (isnan(d)) /* only CBOR can carry one */
        return kdr_proto_error_set(err, 400, "%s: not a number", name);
    (*storage)[0] = d >= KDR_FLOAT_OVERFLOW    ? INFINITY
                    : d <= -KDR_FLOAT_OVERFLOW ? -INFINITY
                                               : (float)d;
    return 0;
}

static int zero_direction(const float *dir, size_t n, kdr_proto_error *err) {
    for (size_t i = 0; i < n; i++)
        if (dir[3 * i] == 0.0f && dir[3 * i + 1] == 0.0f && dir[3 * i + 2] == 0.0f)
            return kdr_proto_error_set(err, 400, "directions[%zu]: zero direction", i);
    return 0;
}

static int bundle_arrays(const kdr_pf_doc *doc, const bundle_shape *sh,
                         kdr_bundle_request *out, kdr_proto_error *err) {
    kdr_ray_batch *b = &out->batch;
    if (kdr_pf_view(kdr_pf_get(doc, "origins"), "origins", sh->norg, 0, &out->owned[0],
                    &b->org, err) ||
        kdr_pf_view(kdr_pf_get(doc, "directions"), "directions", 3 * sh->n, 0,
                    &out->owned[1], &b->dir, err))
        return err->status;
    b->n = sh->n;
    b->org_stride = sh->norg == 3 ? 0 : 3;
    if (read_interval(kdr_pf_get(doc, "tmin"), "tmin", sh->ntmin, 0.0f, &out->owned[2],
                      &b->tmin, &b->tmin_stride, err) ||
        read_interval(kdr_pf_get(doc, "tmax"), "tmax", sh->ntmax, INFINITY, &out->owned[3],
                      &b->tmax, &b->tmax_stride, err))
        return err->status;
    return zero_direction(b->dir, sh->n, err);
}

/* "max_hits": only with "query": "all" (1..KDR_MAX_HITS_LIMIT, default
 * KDR_PROTO_DEFAULT_MAX_HITS). An all answer may hold n * max_hits hits,
 * so that product, not n, is held to the ray limit. */
static int bundle_max_hits(const cJSON *root, kdr_query q, size_t n, size_t max,
                           uint32_t *out, kdr_proto_error *err) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(root, "max_hits");
    *out = 0;
    if (q != KDR_ALL) {
        if (it)
            return kdr_proto_error_set(err, 400,
                                       "max_hits: only with \"query\": \"all\"");
        return 0;
    }
    uint64_t v = KDR_PROTO_DEFAULT_MAX_HITS;
    if (it && kdr_pf_int(it, "max_hits", 1, KDR_MAX_HITS_LIMIT, "1..1024", &v, err))
        return err->status;
    *out = (uint32_t)v;
    if ((uint64_t)n * v > max)
        return kdr_pf_too_many(err, (uint64_t)n * v, max, "hit slots (rays * max_hits)");
    return 0;
}

int kdr_proto_parse_bundle(const char *body, size_t len, size_t max_rays,
                           kdr_bundle_request *out, kdr_proto_error *err) {
    return kdr_proto_parse_bundle_as(KDR_MEDIA_JSON, body, len, max_rays, out, err);
}

int kdr_proto_parse_bundle_as(kdr_media media, const char *body, size_t len,
                              size_t max_rays, kdr_bundle_request *out,
                              kdr_proto_error *err) {
    kdr_pf_doc doc;
    bundle_shape sh = {0, 0, 0, 0};
    memset(out, 0, sizeof *out);
    err->status = 0;
    err->detail[0] = '\0';
    if (kdr_pf_parse_body(media, body, len, &doc, err))
        return err->status;
    int st = bundle_shapes(&doc, limit_of(max_rays), &sh, err);
    if (!st)
        st = kdr_pf_bundle_query(doc.root, &out->query, err);
    if (!st)
        st = bundle_max_hits(doc.root, out->query, sh.n, limit_of(max_rays), &out->max_hits,
                             err);
    if (!st)
        st = kdr_pf_fields(doc.root, out->query, &out->fields, err);
    if (!st)
        st = kdr_pf_encoding(doc.root, &out->encoding, err);
    if (!st)
        st = kdr_pf_deadline(doc.root, &out->deadline_ms, err);
    if (!st)
        st = bundle_arrays(&doc, &sh, out, err);
    kdr_pf_doc_free(&doc);
    if (st)
        kdr_bundle_request_free(out);
    return st;
}

void kdr_bundle_request_free(kdr_bundle_request *req) {
    if (!req)
        return;
    for (int i = 0; i < 4; i++)
        kdr_pf_free(req->owned[i]);
    memset(req, 0, sizeof *req);
}

/* ---- cone-shadow ------------------------------------------------------------- */

static int read_light(const cJSON *it, size_t l, kdr_sphere_light *out,
                      kdr_proto_error *err) {
    char name[48];
    snprintf(name, sizeof name, "lights[%zu]", l);
    if (!cJSON_IsObject(it))
        return kdr_proto_error_set(err, 400, "%s: expected an object", name);
    snprintf(name, sizeof name, "lights[%zu].center", l);
    if (kdr_pf_vec3(field(it, "center"), name, out->center, err))
        return err->status;
    snprintf(name, sizeof name, "lights[%zu].radius", l);
    const cJSON *r = field(it, "radius");
    if (!r)
        return kdr_proto_error_set(err, 400, "%s: required", name);
    if (kdr_pf_float(r, name, &out->radius, err))
        return err->status;
    if (!(out->radius > 0.0f))
        return kdr_proto_error_set(err, 400, "%s: must be > 0", name);
    return 0;
}

static int read_lights(const cJSON *root, kdr_shadow_request *out,
                       kdr_proto_error *err) {
    const cJSON *ls = field(root, "lights");
    if (!ls)
        return kdr_proto_error_set(err, 400, "lights: required");
    int nl = cJSON_IsArray(ls) ? cJSON_GetArraySize(ls) : -1;
    if (nl < 1 || nl > KDR_PROTO_MAX_LIGHTS)
        return kdr_proto_error_set(err, 400, "lights: expected an array of 1..%d lights",
                                   KDR_PROTO_MAX_LIGHTS);
    out->owned_lights = kdr_pf_malloc((size_t)nl * sizeof *out->owned_lights);
    if (out->owned_lights)
        memset(out->owned_lights, 0, (size_t)nl * sizeof *out->owned_lights);
    if (!out->owned_lights)
        return kdr_proto_error_set(err, 500, "lights: out of memory");
    size_t l = 0;
    for (const cJSON *it = ls->child; it; it = it->next, l++)
        if (read_light(it, l, &out->owned_lights[l], err))
            return err->status;
    out->query.lights = out->owned_lights;
    out->query.nlights = (size_t)nl;
    return 0;
}

/* samples, seed, epsilon, stats, deadline_ms, encoding: the scalar options. */
static int shadow_options(const cJSON *root, kdr_shadow_request *out,
                          kdr_proto_error *err) {
    kdr_shadow_query *q = &out->query;
    const cJSON *it;
    uint64_t v;
    q->samples = KDR_PROTO_DEFAULT_SAMPLES;
    q->seed = KDR_PROTO_DEFAULT_SEED;
    q->offset = KDR_OFFSET_AUTO; /* API v1.1: "epsilon": "auto" by default */
    q->epsilon = 0.0f;
    if ((it = field(root, "samples"))) {
        if (kdr_pf_int(it, "samples", 1, KDR_PROTO_MAX_SAMPLES, "1..4096", &v, err))
            return err->status;
        q->samples = (uint32_t)v;
    }
    if ((it = field(root, "seed"))) {
        if (kdr_pf_int(it, "seed", 0, 0x1p53, "0..2^53", &q->seed, err))
            return err->status;
    }
    if ((it = field(root, "epsilon")) &&
        !(cJSON_IsString(it) && !strcmp(it->valuestring, "auto"))) {
        q->offset = KDR_OFFSET_DIAGONAL;
        if (kdr_pf_float(it, "epsilon", &q->epsilon, err) || !(q->epsilon >= 0.0f))
            return kdr_proto_error_set(err, 400,
                                       "epsilon: must be \"auto\" or a finite number >= 0");
    }
    if ((it = field(root, "stats"))) {
        if (!cJSON_IsBool(it))
            return kdr_proto_error_set(err, 400, "stats: must be true or false");
        out->want_stats = cJSON_IsTrue(it);
    }
    if (kdr_pf_deadline(root, &out->deadline_ms, err))
        return err->status;
    return kdr_pf_encoding(root, &out->encoding, err);
}

static int shadow_points(const kdr_pf_doc *doc, size_t max, kdr_shadow_request *out,
                         kdr_proto_error *err) {
    const kdr_pf_field pts = kdr_pf_get(doc, "points"), nrm = kdr_pf_get(doc, "normals");
    size_t np, nn = 0;
    if (!kdr_pf_present(pts))
        return kdr_proto_error_set(err, 400, "points: required");
    if (kdr_pf_count(pts, "points", &np, err))
        return err->status;
    if (np == 0 || np % 3)
        return kdr_proto_error_set(err, 400, "points: length %zu is not 3*N with N >= 1",
                                   np);
    if (kdr_pf_present(nrm) && kdr_pf_count(nrm, "normals", &nn, err))
        return err->status;
    if (kdr_pf_present(nrm) && nn != np)
        return kdr_proto_error_set(err, 400, "normals: length %zu is not 3*N (N=%zu)", nn,
                                   np / 3);
    kdr_shadow_query *q = &out->query;
    const uint64_t rays = (uint64_t)(np / 3) * q->nlights * q->samples;
    if (np / 3 > max || rays > max)
        return kdr_pf_too_many(err, rays, max, "rays (points*lights*samples)");
    q->n = np / 3;
    if (kdr_pf_view(pts, "points", np, 0, &out->owned_points, &q->points, err))
        return err->status;
    if (!kdr_pf_present(nrm))
        return 0;
    return kdr_pf_view(nrm, "normals", nn, 0, &out->owned_normals, &q->normals, err);
}

/* The core rejects a point whose distance to a light's centre is not above
 * its radius; the same test, in double as the core does it. */
static int inside_light(const kdr_shadow_query *q, kdr_proto_error *err) {
    for (size_t i = 0; i < q->n; i++) {
        const float *p = q->points + 3 * i;
        for (size_t l = 0; l < q->nlights; l++) {
            const kdr_sphere_light *s = &q->lights[l];
            double d2 = 0.0;
            for (int k = 0; k < 3; k++) {
                const double w = (double)s->center[k] - p[k];
                d2 += w * w;
            }
            if (!(sqrt(d2) > s->radius))
                return kdr_proto_error_set(err, 400, "points[%zu]: inside lights[%zu]", i,
                                           l);
        }
    }
    return 0;
}

int kdr_proto_parse_shadow(const char *body, size_t len, size_t max_rays,
                           kdr_shadow_request *out, kdr_proto_error *err) {
    return kdr_proto_parse_shadow_as(KDR_MEDIA_JSON, body, len, max_rays, out, err);
}

int kdr_proto_parse_shadow_as(kdr_media media, const char *body, size_t len,
                              size_t max_rays, kdr_shadow_request *out,
                              kdr_proto_error *err) {
    kdr_pf_doc doc;
    memset(out, 0, sizeof *out);
    err->status = 0;
    err->detail[0] = '\0';
    if (kdr_pf_parse_body(media, body, len, &doc, err))
        return err->status;
    int st = read_lights(doc.root, out, err);
    if (!st)
        st = shadow_options(doc.root, out, err);
    if (!st)
        st = shadow_points(&doc, limit_of(max_rays), out, err);
    if (!st)
        st = inside_light(&out->query, err);
    kdr_pf_doc_free(&doc);
    if (st)
        kdr_shadow_request_free(out);
    return st;
}

int kdr_proto_check_shadow_scene(const kdr_shadow_request *req, float diagonal,
                                 kdr_proto_error *err) {
    const kdr_shadow_query *q = &req->query;
    /* the core's own product, in float: it refuses exactly these */
    if (q->offset == KDR_OFFSET_DIAGONAL && !isfinite(q->epsilon * diagonal))
        return kdr_proto_error_set(err, 400,
                                   "epsilon: %g times the scene diagonal %g is not a "
                                   "finite offset",
                                   (double)q->epsilon, (double)diagonal);
    return 0;
}

void kdr_shadow_request_free(kdr_shadow_request *req) {
    if (!req)
        return;
    kdr_pf_free(req->owned_points);
    kdr_pf_free(req->owned_normals);
    kdr_pf_free(req->owned_lights);
    memset(req, 0, sizeof *req);
}

/* ---- frustum ----------------------------------------------------------------- */

static int camera_size(const cJSON *cam, const char *key, const char *name,
                       uint32_t *out, kdr_proto_error *err) {
    uint64_t v;
    const cJSON *it = field(cam, key);
    if (!it)
        return kdr_proto_error_set(err, 400, "%s: required", name);
    if (kdr_pf_int(it, name, 1, KDR_PROTO_MAX_IMAGE_SIDE, "1..16384", &v, err))
        return err->status;
    *out = (uint32_t)v;
    return 0;
}

/* eye != target and up not parallel to the view, judged exactly as the
 * core's camera frame will be built (float cross product, then length). */
static int camera_geometry(const kdr_camera *c, kdr_proto_error *err) {
    float f[3], r[3];
    for (int k = 0; k < 3; k++)
        f[k] = c->target[k] - c->eye[k];
    if (f[0] == 0.0f && f[1] == 0.0f && f[2] == 0.0f)
        return kdr_proto_error_set(err, 400, "camera: eye and target coincide");
    if (c->up[0] == 0.0f && c->up[1] == 0.0f && c->up[2] == 0.0f)
        return kdr_proto_error_set(err, 400, "camera.up: zero vector");
    r[0] = f[1] * c->up[2] - f[2] * c->up[1];
    r[1] = f[2] * c->up[0] - f[0] * c->up[2];
    r[2] = f[0] * c->up[1] - f[1] * c->up[0];
    if (r[0] == 0.0f && r[1] == 0.0f && r[2] == 0.0f)
        return kdr_proto_error_set(err, 400, "camera.up: parallel to the view direction");
    if (kdr_camera_validate(c) != KDR_OK)
        return kdr_proto_error_set(err, 400, "camera: degenerate view (eye, target, up)");
    return 0;
}

static int read_camera(const cJSON *root, kdr_camera *c, kdr_proto_error *err) {
    const cJSON *cam = field(root, "camera"), *up, *fov;
    if (!cam)
        return kdr_proto_error_set(err, 400, "camera: required");
    if (!cJSON_IsObject(cam))
        return kdr_proto_error_set(err, 400, "camera: expected an object");
    if (kdr_pf_vec3(field(cam, "eye"), "camera.eye", c->eye, err) ||
        kdr_pf_vec3(field(cam, "target"), "camera.target", c->target, err))
        return err->status;
    c->up[0] = 0.0f, c->up[1] = 1.0f, c->up[2] = 0.0f;
    if ((up = field(cam, "up")) && kdr_pf_vec3(up, "camera.up", c->up, err))
        return err->status;
    fov = field(cam, "fov_y_deg");
    if (!fov)
        return kdr_proto_error_set(err, 400, "camera.fov_y_deg: required");
    if (!cJSON_IsNumber(fov) || !(fov->valuedouble > 0.0) ||
        !(fov->valuedouble < 180.0) || !((float)fov->valuedouble < 180.0f) ||
        !((float)fov->valuedouble > 0.0f))
        return kdr_proto_error_set(err, 400,
                                   "camera.fov_y_deg: must be a number in (0, 180)");
    c->fov_y_deg = (float)fov->valuedouble;
    if (camera_size(cam, "width", "camera.width", &c->width, err) ||
        camera_size(cam, "height", "camera.height", &c->height, err))
        return err->status;
    return camera_geometry(c, err);
}

int kdr_proto_parse_frustum(const char *body, size_t len, size_t max_rays,
                            kdr_frustum_request *out, kdr_proto_error *err) {
    return kdr_proto_parse_frustum_as(KDR_MEDIA_JSON, body, len, max_rays, out, err);
}

int kdr_proto_parse_frustum_as(kdr_media media, const char *body, size_t len,
                               size_t max_rays, kdr_frustum_request *out,
                               kdr_proto_error *err) {
    kdr_pf_doc doc;
    const cJSON *it, *root;
    uint64_t tile = KDR_PROTO_DEFAULT_TILE;
    memset(out, 0, sizeof *out);
    err->status = 0;
    err->detail[0] = '\0';
    if (kdr_pf_parse_body(media, body, len, &doc, err))
        return err->status;
    root = doc.root;
    int st = read_camera(root, &out->camera, err);
    if (!st && (it = field(root, "tile")))
        st = kdr_pf_int(it, "tile", KDR_PROTO_MIN_TILE, KDR_PROTO_MAX_TILE, "4..64", &tile,
                        err);
    if (!st)
        st = kdr_pf_query(root, &out->query, err);
    if (!st)
        st = kdr_pf_fields(root, out->query, &out->fields, err);
    if (!st)
        st = kdr_pf_encoding(root, &out->encoding, err);
    if (!st)
        st = kdr_pf_deadline(root, &out->deadline_ms, err);
    kdr_pf_doc_free(&doc);
    if (st) {
        memset(out, 0, sizeof *out);
        return st;
    }
    out->tile = (uint32_t)tile;
    out->rays = (size_t)out->camera.width * out->camera.height;
    if (out->rays > limit_of(max_rays))
        return kdr_pf_too_many(err, out->rays, limit_of(max_rays), "rays");
    return 0;
}
