/*
 * test_scenes_errors.c — every way a glTF file can be wrong must give one
 * error line naming the file, never a crash (run under ASan in CI): bad
 * indices and ranges, wrong types, non-finite positions, unsupported
 * extensions, sparse accessors, cycles, size limits, every truncation of a
 * .glb and random byte mutations of a .gltf. The files are written by the
 * test itself (test_scenes_util.h); test_scenes.c checks what loads.
 */
#include "test_scenes_util.h"

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

/* A buffer whose "uri" names a directory (the fuzzer's find: tinygltf's
 * own reader took LONG_MAX for its size and allocated that) or a missing
 * file fails with the reason, not an allocation. */
static void test_errors_external(void) {
    static const char *const uris[][2] = {{".", "not a regular file"},
                                          {"", "'uri' is missing"},
                                          {"missing.bin", "File not found"}};
    for (size_t i = 0; i < sizeof uris / sizeof *uris; i++) {
        char path[256], json[1024];
        snprintf(path, sizeof path, "%s/ext%zu.gltf", tmpdir, i);
        const int n = snprintf(
            json, sizeof json,
            "{\"asset\":{\"version\":\"2.0\"},"
            "\"buffers\":[{\"uri\":\"%s\",\"byteLength\":36}],"
            "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
            "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
            "\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[1,1,0]}],"
            "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
            "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]}",
            uris[i][0]);
        write_bytes(path, json, (size_t)n);
        LOAD_FAILS(path, uris[i][1]);
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

int main(void) {
    if (make_tmpdir() != 0)
        return 2;
    test_errors_structure();
    test_errors_geometry();
    test_errors_views();
    test_errors_limits();
    test_errors_external();
    test_truncation_garbage();
    test_mutations();
    remove_tmpdir();
    return check_exit("test_scenes_errors");
}
