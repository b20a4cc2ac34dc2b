/*
 * test_scenes.c — the glTF loader (scenes/kdr_gltf.h) on tiny files written
 * by the test itself, so every expected position and count is known exactly:
 * triangle numbering and ranges (scene choice, root order, pre-order, own
 * mesh before children), TRS versus matrix, instancing, strip/fan vertex
 * order, non-indexed primitives, every component type (normalised or not),
 * byteStride and offsets, data: URI versus .glb versus external .bin, and
 * skipped LINES primitives. Then every way a file can be wrong must give one
 * error line naming the file, never a crash (run under ASan in CI): bad
 * indices and ranges, wrong types, non-finite positions, unsupported
 * extensions, sparse accessors, cycles, every truncation of a .glb and
 * random byte mutations of a .gltf.
 */
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

/* ---- writing glTF files ------------------------------------------------- */

/* A model under construction: one binary buffer, its views and accessors
 * (as JSON text), and the rest of the JSON supplied per test. */
typedef struct model {
    unsigned char bin[8192];
    size_t len;
    char views[4096], accs[4096];
    int nviews, naccs;
} model;

static void appendf(char *dst, size_t cap, const char *fmt, ...) {
    size_t n = strlen(dst);
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(dst + n, cap - n, fmt, ap);
    va_end(ap);
}

/* Appends data as a new bufferView (4-byte aligned); stride 0 = tight. */
static int add_view(model *m, const void *data, size_t n, size_t stride) {
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

static int add_acc(model *m, int view, size_t offset, int ctype, size_t count,
                   const char *type, int normalized) {
    appendf(m->accs, sizeof m->accs, "%s{", m->naccs ? "," : "");
    if (view >= 0) appendf(m->accs, sizeof m->accs, "\"bufferView\":%d,", view);
    appendf(m->accs, sizeof m->accs,
            "\"byteOffset\":%zu,\"componentType\":%d,\"count\":%zu,\"type\":\"%s\"%s}",
            offset, ctype, count, type, normalized ? ",\"normalized\":true" : "");
    return m->naccs++;
}

/* Convenience: float VEC3 positions as their own view and accessor. */
static int add_positions(model *m, const float *xyz, size_t n) {
    return add_acc(m, add_view(m, xyz, n * 12, 0), 0, 5126, n, "VEC3", 0);
}

static int add_indices_u16(model *m, const uint16_t *idx, size_t n) {
    return add_acc(m, add_view(m, idx, n * 2, 0), 0, 5123, n, "SCALAR", 0);
}

static void base64(const unsigned char *in, size_t n, char *out) {
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

static void write_bytes(const char *path, const void *data, size_t n) {
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(data, 1, n, f) != n) {
        perror(path);
        exit(2);
    }
    fclose(f);
}

/* Writes the model to tmpdir/name with `rest` (more top-level JSON members,
 * e.g. meshes, nodes, scenes) and returns the path (static storage). */
static const char *write_model(const model *m, const char *name, file_kind kind,
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

static int load_ok(const char *path, kdr_gltf_scene *s) {
    char err[512];
    if (kdr_gltf_load(path, s, err, sizeof err) == 0) return 1;
    failures++;
    fprintf(stderr, "unexpected load error: %s\n", err);
    return 0;
}

/* Loading must fail with one line that names the file and contains `want`. */
static void load_fails(const char *path, const char *want, int line) {
    char err[512];
    kdr_gltf_scene s;
    int rc = kdr_gltf_load(path, &s, err, sizeof err);
    if (rc == 0) {
        failures++;
        fprintf(stderr, "line %d: %s loaded (%zu triangles) but should fail (%s)\n", line,
                path, s.ntris, want);
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

static int near3(const float *p, float x, float y, float z) {
    return fabsf(p[0] - x) < 1e-5f && fabsf(p[1] - y) < 1e-5f && fabsf(p[2] - z) < 1e-5f;
}

static int ranges_tile(const kdr_gltf_scene *s) {
    size_t next = 0;
    for (size_t i = 0; i < s->nranges; i++) {
        if (s->ranges[i].first_prim != next) return 0;
        next += s->ranges[i].count;
    }
    return next == s->ntris;
}

static const float kTri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};

/* ---- features --------------------------------------------------------------- */

/* TRS (scale, then rotate, then translate) and the equivalent matrix agree. */
static void test_trs_matrix(void) {
    model m = {0};
    add_positions(&m, kTri, 3);
    const char *rest =
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
        "\"nodes\":[{\"mesh\":0,\"translation\":[1,2,3],"
        "\"rotation\":[0,0,0.70710678118654752,0.70710678118654752],\"scale\":[2,2,2]},"
        "{\"mesh\":0,\"matrix\":[0,2,0,0, -2,0,0,0, 0,0,2,0, 1,2,3,1]}],"
        "\"scenes\":[{\"nodes\":[0,1]}]";
    kdr_gltf_scene s;
    if (!load_ok(write_model(&m, "trs.gltf", AS_DATA_URI, rest), &s)) return;
    CHECK(s.ntris == 2, "%zu", s.ntris);
    /* (1,0,0) scaled to (2,0,0), turned 90 degrees about z to (0,2,0), moved. */
    for (int t = 0; t < 2 && s.ntris == 2; t++) {
        const float *p = s.tris + 9 * t;
        CHECK(near3(p, 1, 2, 3) && near3(p + 3, 1, 4, 3) && near3(p + 6, -1, 2, 3),
              "triangle %d: (%g %g %g) (%g %g %g) (%g %g %g)", t, p[0], p[1], p[2], p[3],
              p[4], p[5], p[6], p[7], p[8]);
    }
    kdr_gltf_free(&s);
}

/* Numbering: default scene `scene` (not 0), roots in array order, own mesh
 * before children, children pre-order, parents' transforms inherited. */
static void test_order_hierarchy(void) {
    model m = {0};
    float one[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    float two[18] = {0, 0, 0, 0, 0, 1, 0, 1, 0, 5, 5, 5, 6, 5, 5, 5, 6, 5};
    add_positions(&m, one, 3);
    add_positions(&m, two, 6);
    const char *rest = "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]},"
                       "{\"primitives\":[{\"attributes\":{\"POSITION\":1}}]}],"
                       "\"nodes\":[{\"mesh\":1}," /* 0: scene 0 only */
                       "{\"mesh\":0,\"translation\":[10,0,0],\"children\":[3,2]}," /* 1 */
                       "{\"mesh\":1,\"translation\":[0,10,0]},"                    /* 2 */
                       "{\"children\":[4],\"translation\":[0,0,10]},"              /* 3 */
                       "{\"mesh\":0},"                                             /* 4 */
                       "{\"mesh\":0}],"                                            /* 5 */
                       "\"scene\":1,\"scenes\":[{\"nodes\":[0]},{\"nodes\":[5,1]}]";
    kdr_gltf_scene s;
    if (!load_ok(write_model(&m, "order.gltf", AS_DATA_URI, rest), &s)) return;
    /* Expected walk: 5, 1, 3 (no mesh), 4, 2. */
    static const uint32_t node[] = {5, 1, 4, 2}, mesh[] = {0, 0, 0, 1},
                          count[] = {1, 1, 1, 2};
    CHECK(s.ntris == 5 && s.nranges == 4, "%zu triangles, %zu ranges", s.ntris,
          s.nranges);
    for (size_t i = 0; i < 4 && s.nranges == 4; i++)
        CHECK(s.ranges[i].node == node[i] && s.ranges[i].mesh == mesh[i] &&
                  s.ranges[i].primitive == 0 && s.ranges[i].count == count[i],
              "range %zu: node %u mesh %u count %u", i, s.ranges[i].node,
              s.ranges[i].mesh, s.ranges[i].count);
    CHECK(ranges_tile(&s), "ranges do not tile the triangles");
    if (s.ntris == 5) {
        CHECK(near3(s.tris + 0, 0, 0, 0), "node 5 untransformed");
        CHECK(near3(s.tris + 9, 10, 0, 0), "node 1 moved by its translation");
        CHECK(near3(s.tris + 18, 10, 0, 10), "node 4 inherits 1 and 3");
        CHECK(near3(s.tris + 27, 10, 10, 0) && near3(s.tris + 36, 15, 15, 5),
              "node 2 inherits 1, keeps triangle order");
    }
    kdr_gltf_free(&s);
}

/* Rewrites a .glb with four NULs appended to its JSON chunk (padding some
 * exporters write instead of spaces); returns the new path. */
static const char *nul_padded_copy(const char *src) {
    static char path[256];
    static unsigned char in[65536], out[65536 + 4];
    FILE *f = fopen(src, "rb");
    size_t n = f ? fread(in, 1, sizeof in, f) : 0;
    if (f) fclose(f);
    uint32_t jl, total;
    memcpy(&jl, in + 12, 4);
    if (n < 20 || jl > n - 20) return src;
    memcpy(out, in, 20 + jl);
    memset(out + 20 + jl, 0, 4);
    memcpy(out + 24 + jl, in + 20 + jl, n - 20 - jl);
    total = (uint32_t)n + 4, jl += 4;
    memcpy(out + 8, &total, 4);
    memcpy(out + 12, &jl, 4);
    snprintf(path, sizeof path, "%s/nulpad.glb", tmpdir);
    write_bytes(path, out, n + 4);
    return path;
}

/* One mesh, three nodes: three copies, three ranges naming the same mesh. */
static void test_instancing(void) {
    model m = {0};
    add_positions(&m, kTri, 3);
    const char *rest =
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
        "\"nodes\":[{\"mesh\":0},{\"mesh\":0,\"translation\":[0,0,1]},"
        "{\"mesh\":0,\"translation\":[0,0,2]}],"
        "\"scenes\":[{\"nodes\":[0,1,2]}]";
    const char *glb = write_model(&m, "inst.glb", AS_GLB, rest);
    for (int padded = 0; padded < 2; padded++) {
        kdr_gltf_scene s;
        if (!load_ok(padded ? nul_padded_copy(glb) : glb, &s)) return;
        CHECK(s.ntris == 3 && s.nranges == 3, "%zu %zu", s.ntris, s.nranges);
        for (size_t i = 0; i < s.ntris && s.ntris == 3; i++) {
            CHECK(s.ranges[i].node == i && s.ranges[i].mesh == 0, "range %zu", i);
            CHECK(near3(s.tris + 9 * i + 3, 1, 0, (float)i), "copy %zu at z=%zu", i, i);
        }
        kdr_gltf_free(&s);
    }
}

/* Vertex i of the strip/fan tests is (i, i*i, 7): every corner identifies
 * its vertex. */
static int vertex_of(const float *p) { return (int)lroundf(p[0]); }

static void check_corners(const kdr_gltf_scene *s, const int *want, size_t ntris,
                          const char *what) {
    CHECK(s->ntris == ntris, "%s: %zu triangles", what, s->ntris);
    for (size_t i = 0; i < 3 * ntris && s->ntris == ntris; i++)
        CHECK(vertex_of(s->tris + 3 * i) == want[i], "%s: corner %zu is v%d, want v%d",
              what, i, vertex_of(s->tris + 3 * i), want[i]);
}

/* glTF 2.0 3.7.2.1: strip p_i = {v_i, v_{i+(1+i%2)}, v_{i+(2-i%2)}},
 * fan p_i = {v_{i+1}, v_{i+2}, v_0}. */
static void test_strip_fan(void) {
    float v[15];
    for (int i = 0; i < 5; i++)
        v[3 * i] = (float)i, v[3 * i + 1] = (float)(i * i), v[3 * i + 2] = 7;
    static const uint16_t rev[5] = {4, 3, 2, 1, 0};
    static const int strip[9] = {0, 1, 2, 1, 3, 2, 2, 3, 4},
                     fan[9] = {1, 2, 0, 2, 3, 0, 3, 4, 0};
    static const int strip_rev[9] = {4, 3, 2, 3, 1, 2, 2, 1, 0};
    static const int fan_rev[9] = {3, 2, 4, 2, 1, 4, 1, 0, 4};
    for (int indexed = 0; indexed < 2; indexed++)
        for (int mode = 5; mode <= 6; mode++) {
            model m = {0};
            add_positions(&m, v, 5);
            if (indexed) add_indices_u16(&m, rev, 5);
            char rest[512], name[32];
            snprintf(
                rest, sizeof rest,
                "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
                "\"mode\":%d%s}]}],\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]",
                mode, indexed ? ",\"indices\":1" : "");
            snprintf(name, sizeof name, "mode%d_%d.gltf", mode, indexed);
            kdr_gltf_scene s;
            if (!load_ok(write_model(&m, name, AS_DATA_URI, rest), &s)) continue;
            const int *want =
                mode == 5 ? (indexed ? strip_rev : strip) : (indexed ? fan_rev : fan);
            check_corners(&s, want, 3, name);
            kdr_gltf_free(&s);
        }
}

/* Non-indexed TRIANGLES, and a LINES primitive before it that is skipped
 * (the range keeps the primitive's real index, 1). */
static void test_non_indexed_and_lines(void) {
    model m = {0};
    float v[18] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 2, 2, 2, 3, 2, 2, 2, 3, 2};
    add_positions(&m, v, 6);
    const char *rest =
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"mode\":1},"
        "{\"attributes\":{\"POSITION\":0},\"mode\":0},{\"attributes\":{\"POSITION\":0}}]}"
        "],"
        "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]";
    kdr_gltf_scene s;
    if (!load_ok(write_model(&m, "lines.gltf", AS_DATA_URI, rest), &s)) return;
    CHECK(s.ntris == 2 && s.nranges == 1, "%zu %zu", s.ntris, s.nranges);
    if (s.nranges == 1) CHECK(s.ranges[0].primitive == 2, "%u", s.ranges[0].primitive);
    if (s.ntris == 2)
        CHECK(memcmp(s.tris, v, sizeof v) == 0, "non-indexed positions copied exactly");
    kdr_gltf_free(&s);
}

/* Positions in every KHR_mesh_quantization type, normalised or not, and
 * indices in every unsigned type: decoded exactly as glTF 2.0 3.11 says. */
static void test_component_types(void) {
    static const struct {
        int ctype, normalized;
        int raw[3];
        float want[3];
    } cases[] = {
        {5120, 1, {127, -127, -128}, {1.0f, -1.0f, -1.0f}},
        {5120, 0, {5, -6, 7}, {5, -6, 7}},
        {5121, 1, {255, 0, 51}, {1.0f, 0.0f, (float)(51 / 255.0)}},
        {5121, 0, {200, 1, 2}, {200, 1, 2}},
        {5122, 1, {32767, -32768, 16384}, {1.0f, -1.0f, (float)(16384 / 32767.0)}},
        {5122, 0, {-300, 300, 0}, {-300, 300, 0}},
        {5123, 1, {65535, 0, 13107}, {1.0f, 0.0f, 0.2f}},
        {5123, 0, {60000, 1, 2}, {60000, 1, 2}},
    };
    static const int index_types[3] = {5121, 5123, 5125};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        model m = {0};
        unsigned char vbuf[64] = {0};
        int size = cases[c].ctype <= 5121 ? 1 : 2;
        size_t stride = (size_t)(3 * size + 3) & ~(size_t)3; /* padded to 4 bytes */
        for (int vtx = 0; vtx < 3; vtx++)
            for (int k = 0; k < 3; k++) {
                int x = vtx == 0 ? cases[c].raw[k] : 0; /* vertices 1, 2 are zero */
                if (size == 1)
                    vbuf[vtx * stride + k] = (unsigned char)(x & 0xff);
                else {
                    int16_t h = (int16_t)x;
                    memcpy(vbuf + vtx * stride + 2 * k, &h, 2);
                }
            }
        add_acc(&m, add_view(&m, vbuf, 3 * stride, stride), 0, cases[c].ctype, 3, "VEC3",
                cases[c].normalized);
        unsigned char ibuf[12] = {0};
        int it = index_types[c % 3], isz = it == 5121 ? 1 : it == 5123 ? 2 : 4;
        for (int i = 0; i < 3; i++)
            ibuf[i * isz] = (unsigned char)(2 - i); /* 2, 1, 0 */
        add_acc(&m, add_view(&m, ibuf, (size_t)(3 * isz), 0), 0, it, 3, "SCALAR", 0);
        const char *rest =
            "\"extensionsUsed\":[\"KHR_mesh_quantization\"],"
            "\"extensionsRequired\":[\"KHR_mesh_quantization\"],"
            "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
            "\"indices\":1}]}],\"nodes\":[{\"mesh\":0}],"
            "\"scenes\":[{\"nodes\":[0]}]";
        kdr_gltf_scene s;
        if (!load_ok(write_model(&m, "quant.glb", AS_GLB, rest), &s)) continue;
        CHECK(s.ntris == 1, "%zu", s.ntris);
        if (s.ntris == 1) {
            const float *p = s.tris + 6; /* index order 2, 1, 0: vertex 0 is last */
            CHECK(p[0] == cases[c].want[0] && p[1] == cases[c].want[1] &&
                      p[2] == cases[c].want[2],
                  "type %d norm %d: got (%.9g %.9g %.9g)", cases[c].ctype,
                  cases[c].normalized, p[0], p[1], p[2]);
        }
        kdr_gltf_free(&s);
    }
}

/* Interleaved vertices (position + a 3-float normal, stride 24), with both
 * a bufferView byteOffset and an accessor byteOffset in play. */
static void test_stride_offsets(void) {
    model m = {0};
    float junk[5] = {99, 99, 99, 99, 99};
    add_view(&m, junk, sizeof junk, 0); /* pushes the next view's byteOffset */
    float inter[2 + 3 * 6];
    inter[0] = inter[1] = -1; /* 8 bytes skipped by the accessor's byteOffset */
    for (int i = 0; i < 3; i++) {
        for (int k = 0; k < 3; k++)
            inter[2 + 6 * i + k] = kTri[3 * i + k] + 0.5f;
        for (int k = 0; k < 3; k++)
            inter[2 + 6 * i + 3 + k] = 1e30f; /* the normal */
    }
    int view = add_view(&m, inter, sizeof inter - 12, 24); /* last normal cut off */
    add_acc(&m, view, 8, 5126, 3, "VEC3", 0);
    const char *rest =
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
        "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]";
    for (int kind = 0; kind < 3; kind++) {
        static const char *names[3] = {"stride.gltf", "stride.glb", "stride_ext.gltf"};
        kdr_gltf_scene s;
        if (!load_ok(write_model(&m, names[kind], (file_kind)kind, rest), &s)) continue;
        CHECK(s.ntris == 1 && near3(s.tris, 0.5f, 0.5f, 0.5f) &&
                  near3(s.tris + 3, 1.5f, 0.5f, 0.5f) &&
                  near3(s.tris + 6, 0.5f, 1.5f, 0.5f),
              "%s: strided positions", names[kind]);
        kdr_gltf_free(&s);
    }
}

/* The default scene (`scene` absent) is scene 0; an empty scene loads as
 * zero triangles; free is idempotent. */
static void test_empty_and_free(void) {
    model m = {0};
    add_positions(&m, kTri, 3);
    kdr_gltf_scene s;
    if (load_ok(write_model(&m, "empty.gltf", AS_DATA_URI, "\"scenes\":[{\"nodes\":[]}]"),
                &s)) {
        CHECK(s.ntris == 0 && s.nranges == 0, "%zu", s.ntris);
        CHECK(s.load_ms >= 0, "%g", s.load_ms);
        kdr_gltf_free(&s);
        kdr_gltf_free(&s);
    }
    kdr_gltf_free(NULL);
}

/* ---- errors --------------------------------------------------------------- */

static const char *one_tri_file(const char *name, const char *mesh_json,
                                const char *extra) {
    static char rest[2048];
    model m = {0};
    float v[9];
    memcpy(v, kTri, sizeof v);
    add_positions(&m, v, 3);
    uint16_t idx[3] = {0, 1, 2};
    add_indices_u16(&m, idx, 3);
    snprintf(rest, sizeof rest,
             "\"meshes\":[%s],\"nodes\":[{\"mesh\":0}],"
             "\"scenes\":[{\"nodes\":[0]}]%s",
             mesh_json, extra);
    return write_model(&m, name, AS_DATA_URI, rest);
}

static void test_errors_structure(void) {
    const char *prim =
        "{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1}]}";
    LOAD_FAILS(one_tri_file("draco.gltf", prim,
                            ",\"extensionsRequired\":[\"KHR_draco_mesh_compression\"]"),
               "unsupported");
    LOAD_FAILS(one_tri_file("meshopt.gltf", prim,
                            ",\"extensionsRequired\":[\"EXT_meshopt_compression\"]"),
               "unsupported");
    LOAD_FAILS(one_tri_file("draco_prim.gltf",
                            "{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
                            "\"extensions\":{\"KHR_draco_mesh_compression\":{}}}]}",
                            ""),
               "unsupported");
    LOAD_FAILS(
        one_tri_file("noposition.gltf", "{\"primitives\":[{\"attributes\":{}}]}", ""),
        "POSITION");
    LOAD_FAILS(one_tri_file(
                   "badmode.gltf",
                   "{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"mode\":7}]}", ""),
               "mode");
    LOAD_FAILS(one_tri_file("badacc.gltf",
                            "{\"primitives\":[{\"attributes\":{\"POSITION\":9}}]}", ""),
               "accessor 9");
    LOAD_FAILS(one_tri_file("idxpos.gltf",
                            "{\"primitives\":[{\"attributes\":{\"POSITION\":1}}]}", ""),
               "POSITION must be VEC3");
    LOAD_FAILS(one_tri_file("posidx.gltf",
                            "{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
                            "\"indices\":0}]}",
                            ""),
               "indices must be SCALAR");
    LOAD_FAILS(one_tri_file("badmesh.gltf", prim, ",\"scene\":3"), "scene 3");
    LOAD_FAILS(
        one_tri_file("wrongtype.gltf", prim, ",\"materials\":[{\"doubleSided\":1}]"),
        "materials[0].doubleSided");
    LOAD_FAILS(one_tri_file("badjson.gltf", prim, ",\"extras\":0}"), "JSON");
}

static void test_errors_geometry(void) {
    model m = {0};
    float v[9] = {0, 0, 0, 1, NAN, 0, 0, 1, 0};
    add_positions(&m, v, 3);
    const char *rest =
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
        "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]";
    LOAD_FAILS(write_model(&m, "nan.gltf", AS_DATA_URI, rest),
               "node 0 mesh 0 primitive 0: position 1 is not finite");

    /* A huge scale overflows float only after the transform. */
    model h = {0};
    add_positions(&h, kTri, 3);
    LOAD_FAILS(
        write_model(&h, "overflow.gltf", AS_DATA_URI,
                    "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                    "\"nodes\":[{\"mesh\":0,\"scale\":[1e300,1,1]}],"
                    "\"scenes\":[{\"nodes\":[0]}]"),
        "not finite");

    model r = {0};
    add_positions(&r, kTri, 3);
    uint16_t idx[3] = {0, 1, 3};
    add_indices_u16(&r, idx, 3);
    add_acc(&r, 0, 4, 5126, 3, "VEC3", 0);            /* 2: 4 bytes past the view */
    add_acc(&r, 0, 0, 5126, 3, "VEC3", 0);            /* 3: fine */
    add_acc(&r, -1, 0, 5126, 3221225475u, "VEC3", 0); /* 4: no view, 2^30 + 1 triangles */
    static const struct {
        const char *name, *prim, *want;
    } bad[] = {
        {"idx_range.gltf", "\"indices\":1", "index 3 is out of range"},
        {"acc_range.gltf", "\"indices\":2", "exceeds bufferView"},
        {"too_many.gltf", "\"indices\":4", "more than 2^30"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char rest2[512];
        snprintf(rest2, sizeof rest2,
                 "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":%d},%s}]}],"
                 "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]",
                 i == 1   ? 2
                 : i == 2 ? 4
                          : 0,
                 i == 0 ? bad[i].prim : "\"mode\":4");
        LOAD_FAILS(write_model(&r, bad[i].name, AS_DATA_URI, rest2), bad[i].want);
    }
}

static void test_errors_views(void) {
    model m = {0};
    add_positions(&m, kTri, 3);
    /* bufferView 0 claims more bytes than the buffer has (byteLength 36). */
    char rest[1024];
    snprintf(rest, sizeof rest,
             "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
             "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]");
    model big = m;
    strcpy(big.views, "{\"buffer\":0,\"byteOffset\":8,\"byteLength\":36}");
    LOAD_FAILS(write_model(&big, "view_range.gltf", AS_DATA_URI, rest), "exceeds buffer");
    model stride = m;
    strcpy(stride.views,
           "{\"buffer\":0,\"byteOffset\":0,\"byteLength\":36,\"byteStride\":8}");
    LOAD_FAILS(write_model(&stride, "stride_small.gltf", AS_DATA_URI, rest),
               "byteStride");
    model sparse = m;
    strcpy(sparse.accs, "{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                        "\"type\":\"VEC3\",\"sparse\":{\"count\":1,"
                        "\"indices\":{\"bufferView\":0,\"componentType\":5125},"
                        "\"values\":{\"bufferView\":0}}}");
    LOAD_FAILS(write_model(&sparse, "sparse.gltf", AS_DATA_URI, rest), "unsupported");
    model four = {0};
    float v4[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    add_positions(&four, v4, 4);
    LOAD_FAILS(write_model(&four, "multi3.gltf", AS_DATA_URI, rest),
               "not a multiple of 3");
    LOAD_FAILS(write_model(&m, "cycle.gltf", AS_DATA_URI,
                           "\"nodes\":[{\"children\":[1]},{\"children\":[0]}],"
                           "\"scenes\":[{\"nodes\":[0]}]"),
               "cycle");
    LOAD_FAILS(write_model(&m, "twoparents.gltf", AS_DATA_URI,
                           "\"nodes\":[{\"children\":[2]},{\"children\":[2]},{}],"
                           "\"scenes\":[{\"nodes\":[0,1]}]"),
               "more than one parent");
    snprintf(rest, sizeof rest, "%s/v1.gltf", tmpdir);
    static const char v1[] = "{\"asset\":{\"version\":\"1.0\"},\"scene\":\"s\","
                             "\"scenes\":{\"s\":{\"nodes\":[]}}}";
    write_bytes(rest, v1, sizeof v1 - 1);
    LOAD_FAILS(rest, "version \"1.0\" is not supported");
    snprintf(rest, sizeof rest, "%s/does-not-exist.glb", tmpdir);
    LOAD_FAILS(rest, "cannot open");
    LOAD_FAILS(tmpdir, NULL); /* a directory */
    char err[64];
    kdr_gltf_scene s;
    CHECK(kdr_gltf_load(NULL, &s, err, sizeof err) == -1, "NULL path");
    CHECK(kdr_gltf_load("x", NULL, NULL, 0) == -1, "NULL output");
}

/* Files built to exhaust the stack or memory must fail with a message. */
static void test_errors_limits(void) {
    char path[256];
    snprintf(path, sizeof path, "%s/deep.gltf", tmpdir);
    enum { DEPTH = 100000 };
    static char deep[2 * DEPTH + 64];
    int n = snprintf(deep, sizeof deep, "{\"asset\":{\"version\":\"2.0\"},\"extras\":");
    memset(deep + n, '[', DEPTH);
    memset(deep + n + DEPTH, ']', DEPTH);
    deep[n + 2 * DEPTH] = '}';
    write_bytes(path, deep, (size_t)n + 2 * DEPTH + 1);
    LOAD_FAILS(path, "nested deeper");

    /* 2^30 triangles (the count limit itself): 36 GiB of floats, which the
     * loader must refuse on any machine with less than 72 GiB. */
    long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    if (pages > 0 && page > 0 && (double)pages * (double)page < 72.0 * 1073741824.0) {
        model m = {0};
        add_positions(&m, kTri, 3);
        /* positions: 3 * 2^30 zero vertices, an accessor without bufferView */
        add_acc(&m, -1, 0, 5126, (size_t)3 << 30, "VEC3", 0);
        const char *rest =
            "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":1}}]}],"
            "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]";
        LOAD_FAILS(write_model(&m, "bomb.gltf", AS_DATA_URI, rest), "GiB");
    }
}

/* Every proper prefix of a .glb fails cleanly; so does garbage. */
static void test_truncation_garbage(void) {
    model m = {0};
    add_positions(&m, kTri, 3);
    uint16_t idx[3] = {0, 1, 2};
    add_indices_u16(&m, idx, 3);
    const char *full =
        write_model(&m, "whole.glb", AS_GLB,
                    "\"meshes\":[{\"primitives\":[{\"attributes\":"
                    "{\"POSITION\":0},\"indices\":1}]}],"
                    "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]");
    FILE *f = fopen(full, "rb");
    unsigned char buf[4096];
    size_t n = f ? fread(buf, 1, sizeof buf, f) : 0;
    if (f) fclose(f);
    CHECK(n > 100, "glb of %zu bytes", n);
    char path[256];
    snprintf(path, sizeof path, "%s/cut.glb", tmpdir);
    for (size_t len = 0; len < n; len++) {
        write_bytes(path, buf, len);
        LOAD_FAILS(path, NULL);
    }
    uint64_t x = 0x9E3779B97F4A7C15u;
    for (int trial = 0; trial < 20; trial++) {
        for (size_t i = 0; i < sizeof buf; i++) {
            x ^= x << 13, x ^= x >> 7, x ^= x << 17;
            buf[i] = (unsigned char)x;
        }
        if (trial % 2) memcpy(buf, "glTF\2\0\0\0", 8); /* a plausible header */
        write_bytes(path, buf, 64 + (size_t)trial * 97);
        LOAD_FAILS(path, NULL);
    }
}

/* Random single-byte mutations of a valid .gltf: each must load or fail
 * with a message; never crash or leak (ASan checks the rest). */
static void test_mutations(void) {
    model m = {0};
    add_positions(&m, kTri, 3);
    uint16_t idx[3] = {0, 1, 2};
    add_indices_u16(&m, idx, 3);
    const char *src = write_model(&m, "mut_src.gltf", AS_DATA_URI,
                                  "\"meshes\":[{\"primitives\":[{\"attributes\":"
                                  "{\"POSITION\":0},\"indices\":1}]}],"
                                  "\"nodes\":[{\"mesh\":0,\"translation\":[1,2,3]}],"
                                  "\"scenes\":[{\"nodes\":[0]}]");
    char text[8192];
    FILE *f = fopen(src, "rb");
    size_t n = f ? fread(text, 1, sizeof text, f) : 0;
    if (f) fclose(f);
    static const char alphabet[] = "0123456789-.e,:[]{}\"9 ";
    char path[256];
    snprintf(path, sizeof path, "%s/mut.gltf", tmpdir);
    uint64_t x = 12345;
    int loaded = 0;
    for (int trial = 0; trial < 400 && n; trial++) {
        char copy[8192];
        memcpy(copy, text, n);
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        copy[x % n] = alphabet[(x >> 32) % (sizeof alphabet - 1)];
        write_bytes(path, copy, n);
        char err[512];
        kdr_gltf_scene s;
        if (kdr_gltf_load(path, &s, err, sizeof err) == 0) {
            loaded++;
            CHECK(ranges_tile(&s), "mutation %d: ranges", trial);
            for (size_t i = 0; i < 9 * s.ntris; i++)
                CHECK(isfinite(s.tris[i]), "mutation %d: non-finite output", trial);
            kdr_gltf_free(&s);
        } else {
            CHECK(strstr(err, path) != NULL, "mutation %d: %s", trial, err);
        }
    }
    printf("mutations: %d of 400 still loaded\n", loaded);
}

static void remove_tmpdir(void) {
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
}

int main(void) {
    snprintf(tmpdir, sizeof tmpdir, "/tmp/kdray_test_scenes_XXXXXX");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 2;
    }
    test_trs_matrix();
    test_order_hierarchy();
    test_instancing();
    test_strip_fan();
    test_non_indexed_and_lines();
    test_component_types();
    test_stride_offsets();
    test_empty_and_free();
    test_errors_structure();
    test_errors_geometry();
    test_errors_views();
    test_errors_limits();
    test_truncation_garbage();
    test_mutations();
    remove_tmpdir();
    if (failures)
        fprintf(stderr, "test_scenes: %d failure(s)\n", failures);
    else
        printf("test_scenes: all passed\n");
    return failures ? 1 : 0;
}
