/*
 * kdr_stub.c — temporary placeholders so the server can link against the
 * protocol API while the real implementation lands file by file.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_protocol.h"

void kdr_buf_init(kdr_buf *b) { memset(b, 0, sizeof *b); }
void kdr_buf_free(kdr_buf *b) { free(b->data); memset(b, 0, sizeof *b); }
int kdr_buf_reserve(kdr_buf *b, size_t extra) { (void)b; (void)extra; return KDR_ENOMEM; }
int kdr_buf_append(kdr_buf *b, const void *bytes, size_t n) { (void)b; (void)bytes; (void)n; return KDR_ENOMEM; }
const char *kdr_buf_cstr(kdr_buf *b) { return b->data; }

int kdr_proto_error_set(kdr_proto_error *err, int status, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    err->status = status;
    vsnprintf(err->detail, sizeof err->detail, fmt, ap);
    va_end(ap);
    return status;
}
const char *kdr_proto_status_title(int status) { (void)status; return "Error"; }
int kdr_proto_encode_error(const kdr_proto_error *err, kdr_buf *out) { (void)err; (void)out; return KDR_ENOMEM; }

static int stub(kdr_proto_error *err) { return kdr_proto_error_set(err, 500, "not implemented"); }
int kdr_proto_parse_bundle(const char *body, size_t len, size_t max_rays, kdr_bundle_request *out, kdr_proto_error *err) {
    (void)body; (void)len; (void)max_rays; memset(out, 0, sizeof *out); return stub(err);
}
void kdr_bundle_request_free(kdr_bundle_request *req) { (void)req; }
int kdr_proto_parse_shadow(const char *body, size_t len, size_t max_rays, kdr_shadow_request *out, kdr_proto_error *err) {
    (void)body; (void)len; (void)max_rays; memset(out, 0, sizeof *out); return stub(err);
}
void kdr_shadow_request_free(kdr_shadow_request *req) { (void)req; }
int kdr_proto_parse_frustum(const char *body, size_t len, size_t max_rays, kdr_frustum_request *out, kdr_proto_error *err) {
    (void)body; (void)len; (void)max_rays; memset(out, 0, sizeof *out); return stub(err);
}
int kdr_proto_encode_hits(const kdr_hits *hits, size_t n, kdr_query query, kdr_encoding enc, kdr_buf *out) {
    (void)hits; (void)n; (void)query; (void)enc; (void)out; return KDR_ENOMEM;
}
int kdr_proto_encode_shadow(const float *visibility, size_t n, size_t nlights, const kdr_shadow_stats *stats, kdr_encoding enc, kdr_buf *out) {
    (void)visibility; (void)n; (void)nlights; (void)stats; (void)enc; (void)out; return KDR_ENOMEM;
}
int kdr_proto_encode_scene(const kdr_proto_scene_info *scene, kdr_buf *out) { (void)scene; (void)out; return KDR_ENOMEM; }
int kdr_proto_encode_scenes(const kdr_proto_scene_info *scenes, size_t n, kdr_buf *out) { (void)scenes; (void)n; (void)out; return KDR_ENOMEM; }
int kdr_proto_encode_health(const char *status, size_t nscenes, kdr_buf *out) { (void)status; (void)nscenes; (void)out; return KDR_ENOMEM; }
size_t kdr_format_float(float f, char *dst) { return (size_t)snprintf(dst, KDR_FLOAT_CHARS, "%.9g", (double)f); }
size_t kdr_base64_encoded_len(size_t n) { return (n + 2) / 3 * 4; }
size_t kdr_base64_encode(const void *src, size_t n, char *dst) { (void)src; (void)n; (void)dst; return 0; }
size_t kdr_base64_decoded_max(size_t n) { return n / 4 * 3; }
int kdr_base64_decode(const char *src, size_t n, void *dst, size_t *out_len, size_t *err_offset) {
    (void)src; (void)dst; *out_len = 0; *err_offset = n; return -1;
}
