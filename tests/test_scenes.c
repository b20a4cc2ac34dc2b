/*
 * test_scenes.c — the glTF loader (scenes/kdr_gltf.h) on tiny files written
 * by the test itself (test_scenes_util.h), so every expected position and
 * count is known exactly: triangle numbering and ranges (scene choice, root
 * order, pre-order, own mesh before children), TRS versus matrix,
 * instancing, strip/fan vertex order, non-indexed primitives, every
 * component type (normalised or not), byteStride and offsets, data: URI
 * versus .glb versus external .bin, and skipped LINES primitives. Every way
 * a file can be wrong is test_scenes_errors.c's.
 */
#include "test_scenes_util.h"

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

int main(void) {
    if (make_tmpdir() != 0)
        return 2;
    test_trs_matrix();
    test_order_hierarchy();
    test_instancing();
    test_strip_fan();
    test_non_indexed_and_lines();
    test_component_types();
    test_stride_offsets();
    test_empty_and_free();
    remove_tmpdir();
    return check_exit("test_scenes");
}
