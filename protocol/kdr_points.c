/*
 * kdr_points.c — the point-query bodies (issue 15): POST
 * /v1/scenes/{name}/closest-point {points, max_distance?, signed?,
 * encoding?, deadline_ms?} and POST /v1/scenes/{name}/occupancy {points,
 * encoding?, deadline_ms?}, in JSON or CBOR, through the same field readers as the
 * ray queries (kdr_fields.c), so "points" has every form and error message
 * of the cone-shadow's points. Shapes and limits are checked before the
 * array is decoded: N points count as N rays against the ray limit.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "kdr_proto_internal.h"

static size_t limit_of(size_t max_rays) {
    return max_rays ? max_rays : KDR_PROTO_DEFAULT_MAX_RAYS;
}

/* "points": 3N floats, N >= 1, at most max. */
static int read_points(const kdr_pf_doc *doc, size_t max, float **owned,
                       const float **view, size_t *n, kdr_proto_error *err) {
    const kdr_pf_field pts = kdr_pf_get(doc, "points");
    size_t np;
    if (!kdr_pf_present(pts)) return kdr_proto_error_set(err, 400, "points: required");
    if (kdr_pf_count(pts, "points", &np, err)) return err->status;
    if (np == 0 || np % 3)
        return kdr_proto_error_set(err, 400, "points: length %zu is not 3*N with N >= 1",
                                   np);
    *n = np / 3;
    if (*n > max) return kdr_pf_too_many(err, *n, max, "points");
    return kdr_pf_view(pts, "points", np, 0, owned, view, err);
}

/* "max_distance": a number >= 0 (huge saturates to +inf, so 1e300 means no
 * limit); absent: +inf. */
static int read_max_distance(const cJSON *root, float *out, kdr_proto_error *err) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(root, "max_distance");
    *out = INFINITY;
    if (!it) return 0;
    if (!cJSON_IsNumber(it) || !(it->valuedouble >= 0.0))
        return kdr_proto_error_set(err, 400, "max_distance: must be a number >= 0");
    *out = it->valuedouble >= KDR_FLOAT_OVERFLOW ? INFINITY : (float)it->valuedouble;
    return 0;
}

int kdr_proto_parse_closest_as(kdr_media media, const char *body, size_t len,
                               size_t max_rays, kdr_closest_request *out,
                               kdr_proto_error *err) {
    kdr_pf_doc doc;
    memset(out, 0, sizeof *out);
    err->status = 0;
    err->detail[0] = '\0';
    if (kdr_pf_parse_body(media, body, len, &doc, err)) return err->status;
    int st = read_max_distance(doc.root, &out->max_distance, err);
    const cJSON *sg = cJSON_GetObjectItemCaseSensitive(doc.root, "signed");
    if (!st && sg && !cJSON_IsBool(sg))
        st = kdr_proto_error_set(err, 400, "signed: must be true or false");
    out->is_signed = sg && cJSON_IsTrue(sg);
    if (!st && out->is_signed &&
        cJSON_GetObjectItemCaseSensitive(doc.root, "max_distance"))
        st = kdr_proto_error_set(
            err, 400,
            "max_distance: not with \"signed\": true (a signed answer "
            "has no miss marker)");
    if (!st) st = kdr_pf_encoding(doc.root, &out->encoding, err);
    if (!st) st = kdr_pf_deadline(doc.root, &out->deadline_ms, err);
    if (!st)
        st = read_points(&doc, limit_of(max_rays), &out->owned_points, &out->points,
                         &out->n, err);
    kdr_pf_doc_free(&doc);
    if (st) kdr_closest_request_free(out);
    return st;
}

int kdr_proto_parse_closest(const char *body, size_t len, size_t max_rays,
                            kdr_closest_request *out, kdr_proto_error *err) {
    return kdr_proto_parse_closest_as(KDR_MEDIA_JSON, body, len, max_rays, out, err);
}

void kdr_closest_request_free(kdr_closest_request *req) {
    if (!req) return;
    kdr_pf_free(req->owned_points);
    memset(req, 0, sizeof *req);
}

int kdr_proto_parse_occupancy_as(kdr_media media, const char *body, size_t len,
                                 size_t max_rays, kdr_occupancy_request *out,
                                 kdr_proto_error *err) {
    kdr_pf_doc doc;
    memset(out, 0, sizeof *out);
    err->status = 0;
    err->detail[0] = '\0';
    if (kdr_pf_parse_body(media, body, len, &doc, err)) return err->status;
    int st = kdr_pf_encoding(doc.root, &out->encoding, err);
    if (!st) st = kdr_pf_deadline(doc.root, &out->deadline_ms, err);
    if (!st)
        st = read_points(&doc, limit_of(max_rays), &out->owned_points, &out->points,
                         &out->n, err);
    kdr_pf_doc_free(&doc);
    if (st) kdr_occupancy_request_free(out);
    return st;
}

void kdr_occupancy_request_free(kdr_occupancy_request *req) {
    if (!req) return;
    kdr_pf_free(req->owned_points);
    memset(req, 0, sizeof *req);
}
