/*
 * test_scenes_util.h — what the two glTF loader test programs share: a
 * writer for tiny glTF files whose every position and count is known (one
 * binary buffer, its views and accessors as JSON text, written as a data:
 * URI, a .glb or an external .bin), the load helpers (load_ok; load_fails,
 * which wants one error line naming the file) and the scratch directory.
 * test_scenes.c checks features, test_scenes_errors.c every way a file can
 * be wrong. Header-only (static inline) so each program stays one
 * translation unit with its own check.h counter.
 */
#ifndef TEST_SCENES_UTIL_H
#define TEST_SCENES_UTIL_H

#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "kdr_gltf.h"
#include "check.h"

static char tmpdir[64];

/* Makes tmpdir (a fresh /tmp/kdray_test_scenes_XXXXXX); 0 on success. */
static inline int make_tmpdir(void) {
    snprintf(tmpdir, sizeof tmpdir, "/tmp/kdray_test_scenes_XXXXXX");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return -1;
    }
    return 0;
}

static inline void remove_tmpdir(void) {
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
}

/* ---- writing glTF files ------------------------------------------------- */

/* A model under construction: one binary buffer, its views and accessors
 * (as JSON text), and the rest of the JSON supplied per test. */
typedef struct model {
    unsigned char bin[8192];
    size_t len;
    char views[4096], accs[4096];
    int nviews, naccs;
} model;

static inline void appendf(char *dst, size_t cap, const char *fmt, ...) {
    size_t n = strlen(dst);
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(dst + n, cap - n, fmt, ap);
    va_end(ap);
}

/* Appends data as a new bufferView (4-byte aligned); stride 0 = tight. */
static inline int add_view(model *m, const void *data, size_t n, size_t stride) {
    while (m->len % 4)
        m->bin[m->len++] = 0;
    memcpy(m->bin + m->len, data, n);
    appendf(m->views, sizeof m->views,
            "%s{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu", m->nviews ? "," : "",
            m->len, n);
    if (stride) appendf(m->views, sizeof m->views, ",\"byteStride\":%zu", stride);
    appendf(m->views, sizeof m->views, "}");
    m->len += n;
    return m->nviews++;
}

static inline int add_acc(model *m, int view, size_t offset, int ctype, size_t count,
                          const char *type, int normalized) {
    appendf(m->accs, sizeof m->accs, "%s{", m->naccs ? "," : "");
    if (view >= 0) appendf(m->accs, sizeof m->accs, "\"bufferView\":%d,", view);
    appendf(m->accs, sizeof m->accs,
            "\"byteOffset\":%zu,\"componentType\":%d,\"count\":%zu,\"type\":\"%s\"%s}",
            offset, ctype, count, type, normalized ? ",\"normalized\":true" : "");
    return m->naccs++;
}

/* Convenience: float VEC3 positions as their own view and accessor. */
static inline int add_positions(model *m, const float *xyz, size_t n) {
    return add_acc(m, add_view(m, xyz, n * 12, 0), 0, 5126, n, "VEC3", 0);
}

static inline int add_indices_u16(model *m, const uint16_t *idx, size_t n) {
    return add_acc(m, add_view(m, idx, n * 2, 0), 0, 5123, n, "SCALAR", 0);
}

static inline void base64(const unsigned char *in, size_t n, char *out) {
    static const char tab[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    size_t o = 0;
    for (size_t i = 0; i < n; i += 3) {
        uint32_t v = (uint32_t)in[i] << 16;
        if (i + 1 < n) v |= (uint32_t)in[i + 1] << 8;
        if (i + 2 < n) v |= in[i + 2];
        out[o++] = tab[(v >> 18) & 63];
        out[o++] = tab[(v >> 12) & 63];
        out[o++] = i + 1 < n ? tab[(v >> 6) & 63] : '=';
        out[o++] = i + 2 < n ? tab[v & 63] : '=';
    }
    out[o] = '\0';
}

typedef enum { AS_DATA_URI, AS_GLB, AS_EXTERNAL_BIN } file_kind;

static inline void write_bytes(const char *path, const void *data, size_t n) {
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(data, 1, n, f) != n) {
        perror(path);
        exit(2);
    }
    fclose(f);
}

/* Writes the model to tmpdir/name with `rest` (more top-level JSON members,
 * e.g. meshes, nodes, scenes) and returns the path (static storage). */
static inline const char *write_model(const model *m, const char *name, file_kind kind,
                                      const char *rest) {
    static char path[256];
    static char json[65536], uri[16384];
    snprintf(path, sizeof path, "%s/%s", tmpdir, name);
    if (kind == AS_DATA_URI) {
        strcpy(uri, "\"uri\":\"data:application/octet-stream;base64,");
        base64(m->bin, m->len, uri + strlen(uri));
        strcat(uri, "\",");
    } else if (kind == AS_EXTERNAL_BIN) {
        char binpath[300];
        snprintf(binpath, sizeof binpath, "%s.bin", path);
        write_bytes(binpath, m->bin, m->len);
        snprintf(uri, sizeof uri, "\"uri\":\"%s.bin\",", name);
    } else {
        uri[0] = '\0';
    }
    snprintf(json, sizeof json,
             "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{%s\"byteLength\":%zu}],"
             "\"bufferViews\":[%s],\"accessors\":[%s]%s%s}",
             uri, m->len, m->views, m->accs, rest[0] ? "," : "", rest);
    if (kind != AS_GLB) {
        write_bytes(path, json, strlen(json));
        return path;
    }
    size_t jl = strlen(json), jpad = (4 - jl % 4) % 4, bl = (m->len + 3) & ~(size_t)3;
    size_t total = 12 + 8 + jl + jpad + 8 + bl;
    unsigned char *g = calloc(1, total);
    uint32_t hdr[3] = {0x46546C67u, 2, (uint32_t)total};
    uint32_t jc[2] = {(uint32_t)(jl + jpad), 0x4E4F534Au},
             bc[2] = {(uint32_t)bl, 0x004E4942u};
    memcpy(g, hdr, 12);
    memcpy(g + 12, jc, 8);
    memcpy(g + 20, json, jl);
    memset(g + 20 + jl, ' ', jpad);
    memcpy(g + 20 + jl + jpad, bc, 8);
    memcpy(g + 28 + jl + jpad, m->bin, m->len);
    write_bytes(path, g, total);
    free(g);
    return path;
}

/* ---- loading helpers ------------------------------------------------------ */

static inline int load_ok(const char *path, kdr_gltf_scene *s) {
    char err[512];
    if (kdr_gltf_load(path, s, err, sizeof err) == 0) return 1;
    failures++;
    fprintf(stderr, "unexpected load error: %s\n", err);
    return 0;
}

/* Loading must fail with one line that names the file and contains `want`. */
static inline void load_fails(const char *path, const char *want, int line) {
    char err[512];
    kdr_gltf_scene s;
    int rc = kdr_gltf_load(path, &s, err, sizeof err);
    if (rc == 0) {
        failures++;
        fprintf(stderr, "line %d: %s loaded (%zu triangles) but should fail (%s)\n", line,
                path, s.ntris, want ? want : "any error");
        kdr_gltf_free(&s);
        return;
    }
    if (!strstr(err, path) || (want && !strstr(err, want)) || strchr(err, '\n') ||
        s.tris || s.ntris) {
        failures++;
        fprintf(stderr, "line %d: bad error for %s: \"%s\" (want \"%s\")\n", line, path,
                err, want ? want : "");
    }
}
#define LOAD_FAILS(path, want) load_fails(path, want, __LINE__)

static inline int near3(const float *p, float x, float y, float z) {
    return fabsf(p[0] - x) < 1e-5f && fabsf(p[1] - y) < 1e-5f && fabsf(p[2] - z) < 1e-5f;
}

static inline int ranges_tile(const kdr_gltf_scene *s) {
    size_t next = 0;
    for (size_t i = 0; i < s->nranges; i++) {
        if (s->ranges[i].first_prim != next) return 0;
        next += s->ranges[i].count;
    }
    return next == s->ntris;
}

static const float kTri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};

#endif
