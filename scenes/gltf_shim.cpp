/*
 * gltf_shim.cpp — the project's one C++ file: tinygltf parses the file, and
 * this shim flattens the default scene into world-space triangles behind the
 * C API of kdr_gltf.h.
 *
 * The JSON is type-checked first (gltf_schema.c), because tinygltf skips
 * properties of the wrong type instead of failing. tinygltf also trusts the
 * file's numbers, so every index, offset, stride and count it hands back is
 * checked here before a byte is read (sizes are compared by subtraction so
 * no sum can overflow). The flattening runs in
 * two passes: the first walks the node tree, validates every primitive and
 * counts triangles (so the 2^30 limit is enforced before allocating), the
 * second decodes positions, applies the node's world matrix in double
 * precision and writes floats. Internal failures throw LoadError; the
 * extern "C" boundary turns it, and any other exception, into one error line.
 */
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

#include "gltf_schema.h"
#include "kdr_gltf.h"

namespace {

/* A node hierarchy deeper than this is treated as malformed (it also bounds
 * the recursion of the tree walk). */
constexpr int kMaxNodeDepth = 1024;

/* tinygltf takes 32-bit lengths, and GLB caps files at 4 GiB. */
constexpr size_t kMaxFileBytes = 0xFFFFFFF0u;

/* The triangle array may use at most this fraction of physical memory: an
 * instancing bomb must fail with a message, not wake the OOM killer. */
constexpr double kMaxMemoryFraction = 0.5;

/* Required extensions that move positions out of plain accessors (also
 * refused by the JSON check; repeated here for files it could not read). */
const char *const kUnsupportedExtensions[] = {
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
    "EXT_mesh_gpu_instancing",
};

struct LoadError : std::runtime_error {
    explicit LoadError(const std::string &m) : std::runtime_error(m) {}
};

[[noreturn]] __attribute__((format(printf, 1, 2))) void fail(const char *fmt, ...) {
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    throw LoadError(buf);
}

/* Column-major 4x4, as glTF stores `matrix`. */
struct Mat4 {
    double m[16];
};

Mat4 mat_identity() {
    Mat4 r{};
    r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1.0;
    return r;
}

Mat4 mat_mul(const Mat4 &a, const Mat4 &b) {
    Mat4 r{};
    for (int c = 0; c < 4; c++)
        for (int row = 0; row < 4; row++) {
            double s = 0;
            for (int k = 0; k < 4; k++)
                s += a.m[k * 4 + row] * b.m[c * 4 + k];
            r.m[c * 4 + row] = s;
        }
    return r;
}

bool all_finite(const std::vector<double> &v) {
    for (double x : v)
        if (!std::isfinite(x)) return false;
    return true;
}

/* T * R * S from the node's TRS, or its matrix. */
Mat4 node_local_matrix(const tinygltf::Node &n, int idx) {
    const auto &M = n.matrix, &T = n.translation, &R = n.rotation, &S = n.scale;
    if ((!M.empty() && M.size() != 16) || (!T.empty() && T.size() != 3) ||
        (!R.empty() && R.size() != 4) || (!S.empty() && S.size() != 3))
        fail("node %d: matrix/translation/rotation/scale has the wrong length", idx);
    if (!all_finite(M) || !all_finite(T) || !all_finite(R) || !all_finite(S))
        fail("node %d: transform is not finite", idx);
    Mat4 r = mat_identity();
    if (!M.empty()) {
        for (int i = 0; i < 16; i++)
            r.m[i] = M[(size_t)i];
        return r;
    }
    double x = 0, y = 0, z = 0, w = 1;
    if (!R.empty()) x = R[0], y = R[1], z = R[2], w = R[3];
    double sx = S.empty() ? 1 : S[0], sy = S.empty() ? 1 : S[1],
           sz = S.empty() ? 1 : S[2];
    /* Rotation of the unit quaternion, columns scaled by S. */
    r.m[0] = (1 - 2 * (y * y + z * z)) * sx;
    r.m[1] = (2 * (x * y + z * w)) * sx;
    r.m[2] = (2 * (x * z - y * w)) * sx;
    r.m[4] = (2 * (x * y - z * w)) * sy;
    r.m[5] = (1 - 2 * (x * x + z * z)) * sy;
    r.m[6] = (2 * (y * z + x * w)) * sy;
    r.m[8] = (2 * (x * z + y * w)) * sz;
    r.m[9] = (2 * (y * z - x * w)) * sz;
    r.m[10] = (1 - 2 * (x * x + y * y)) * sz;
    if (!T.empty()) r.m[12] = T[0], r.m[13] = T[1], r.m[14] = T[2];
    return r;
}

/* A checked window onto one accessor's elements. base == nullptr means an
 * accessor without bufferView: every element is zero (glTF 2.0 §3.6.2.3). */
struct View {
    const unsigned char *base = nullptr;
    size_t count = 0, stride = 0;
    int ctype = 0, ncomp = 0;
    bool normalized = false;
};

int component_size(int ctype) {
    switch (ctype) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
        return 4;
    default:
        return 0;
    }
}

/* Context prefix of every per-primitive message. */
struct Where {
    int node, mesh, prim;
};

View checked_view(const tinygltf::Model &m, int acc_idx, const Where &w,
                  const char *what) {
    if (acc_idx < 0 || (size_t)acc_idx >= m.accessors.size())
        fail("node %d mesh %d primitive %d: %s accessor %d does not exist", w.node,
             w.mesh, w.prim, what, acc_idx);
    const tinygltf::Accessor &a = m.accessors[(size_t)acc_idx];
    if (a.sparse.isSparse)
        fail("node %d mesh %d primitive %d: %s accessor %d is sparse (unsupported)",
             w.node, w.mesh, w.prim, what, acc_idx);
    View v;
    v.count = a.count;
    v.ctype = a.componentType;
    v.ncomp = tinygltf::GetNumComponentsInType((uint32_t)a.type);
    v.normalized = a.normalized;
    size_t csize = (size_t)component_size(a.componentType);
    if (csize == 0 || v.ncomp <= 0)
        fail("node %d mesh %d primitive %d: %s accessor %d has an invalid component type "
             "%d",
             w.node, w.mesh, w.prim, what, acc_idx, a.componentType);
    size_t elem = csize * (size_t)v.ncomp;
    if (a.bufferView < 0) return v;
    if ((size_t)a.bufferView >= m.bufferViews.size())
        fail("node %d mesh %d primitive %d: %s accessor %d: bufferView %d does not exist",
             w.node, w.mesh, w.prim, what, acc_idx, a.bufferView);
    const tinygltf::BufferView &bv = m.bufferViews[(size_t)a.bufferView];
    if (!bv.extensions.empty() && bv.extensions.count("EXT_meshopt_compression"))
        fail("node %d mesh %d primitive %d: %s accessor %d uses EXT_meshopt_compression "
             "(unsupported)",
             w.node, w.mesh, w.prim, what, acc_idx);
    if (bv.buffer < 0 || (size_t)bv.buffer >= m.buffers.size())
        fail("node %d mesh %d primitive %d: bufferView %d: buffer %d does not exist",
             w.node, w.mesh, w.prim, a.bufferView, bv.buffer);
    const std::vector<unsigned char> &data = m.buffers[(size_t)bv.buffer].data;
    if (bv.byteOffset > data.size() || bv.byteLength > data.size() - bv.byteOffset)
        fail("node %d mesh %d primitive %d: bufferView %d (offset %zu, length %zu) "
             "exceeds "
             "buffer %d (%zu bytes)",
             w.node, w.mesh, w.prim, a.bufferView, bv.byteOffset, bv.byteLength,
             bv.buffer, data.size());
    v.stride = bv.byteStride ? bv.byteStride : elem;
    if (v.stride < elem)
        fail(
            "node %d mesh %d primitive %d: bufferView %d: byteStride %zu is smaller than "
            "the element (%zu bytes)",
            w.node, w.mesh, w.prim, a.bufferView, v.stride, elem);
    if (v.count > 0) {
        size_t room = bv.byteLength;
        bool fits = a.byteOffset <= room && elem <= room - a.byteOffset &&
                    (v.count - 1) <= (room - a.byteOffset - elem) / v.stride;
        if (!fits)
            fail(
                "node %d mesh %d primitive %d: %s accessor %d (offset %zu, %zu elements, "
                "stride %zu) exceeds bufferView %d (%zu bytes)",
                w.node, w.mesh, w.prim, what, acc_idx, a.byteOffset, v.count, v.stride,
                a.bufferView, room);
    }
    static const unsigned char none = 0;
    v.base = v.count ? data.data() + bv.byteOffset + a.byteOffset : &none;
    return v;
}

/* Component c of element i as a double, normalised as glTF 2.0 §3.11 says. */
double read_component(const View &v, size_t i, int c) {
    if (!v.base) return 0.0;
    const unsigned char *p = v.base + i * v.stride + (size_t)c * component_size(v.ctype);
    switch (v.ctype) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
        float f;
        memcpy(&f, p, 4);
        return f;
    }
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
        int8_t x;
        memcpy(&x, p, 1);
        return v.normalized ? std::fmax(x / 127.0, -1.0) : x;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
        uint8_t x;
        memcpy(&x, p, 1);
        return v.normalized ? x / 255.0 : x;
    }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
        int16_t x;
        memcpy(&x, p, 2);
        return v.normalized ? std::fmax(x / 32767.0, -1.0) : x;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t x;
        memcpy(&x, p, 2);
        return v.normalized ? x / 65535.0 : x;
    }
    default: {
        uint32_t x;
        memcpy(&x, p, 4);
        return x;
    }
    }
}

uint32_t read_index(const View &v, size_t i) {
    if (!v.base) return 0;
    const unsigned char *p = v.base + i * v.stride;
    switch (v.ctype) {
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return *p;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t x;
        memcpy(&x, p, 2);
        return x;
    }
    default: {
        uint32_t x;
        memcpy(&x, p, 4);
        return x;
    }
    }
}

/* One (node, mesh, primitive) to flatten, validated in pass 1. */
struct Job {
    Where w;
    Mat4 world;
    View pos, idx;
    bool indexed;
    int mode;
    size_t ntris;
};

bool produces_triangles(int mode) {
    return mode == TINYGLTF_MODE_TRIANGLES || mode == TINYGLTF_MODE_TRIANGLE_STRIP ||
           mode == TINYGLTF_MODE_TRIANGLE_FAN;
}

/* Checks one primitive's accessors; returns false for modes we skip. */
bool plan_primitive(const tinygltf::Model &m, const tinygltf::Primitive &p, Job &j) {
    const Where &w = j.w;
    int mode = p.mode; /* tinygltf gives TRIANGLES when the file omits it */
    if (mode < 0 || mode > TINYGLTF_MODE_TRIANGLE_FAN)
        fail("node %d mesh %d primitive %d: invalid mode %d", w.node, w.mesh, w.prim,
             mode);
    if (!produces_triangles(mode)) return false;
    if (p.extensions.count("KHR_draco_mesh_compression"))
        fail("node %d mesh %d primitive %d: KHR_draco_mesh_compression is unsupported",
             w.node, w.mesh, w.prim);
    auto it = p.attributes.find("POSITION");
    if (it == p.attributes.end())
        fail("node %d mesh %d primitive %d: no POSITION attribute", w.node, w.mesh,
             w.prim);
    j.pos = checked_view(m, it->second, w, "POSITION");
    if (j.pos.ncomp != 3 || j.pos.ctype == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        fail(
            "node %d mesh %d primitive %d: POSITION must be VEC3 of float, byte or short "
            "(got %d components of type %d)",
            w.node, w.mesh, w.prim, j.pos.ncomp, j.pos.ctype);
    j.indexed = p.indices >= 0;
    size_t nverts = j.pos.count;
    if (j.indexed) {
        j.idx = checked_view(m, p.indices, w, "index");
        if (j.idx.ncomp != 1 || j.idx.ctype == TINYGLTF_COMPONENT_TYPE_FLOAT ||
            j.idx.ctype == TINYGLTF_COMPONENT_TYPE_BYTE ||
            j.idx.ctype == TINYGLTF_COMPONENT_TYPE_SHORT)
            fail("node %d mesh %d primitive %d: indices must be SCALAR unsigned byte, "
                 "short "
                 "or int",
                 w.node, w.mesh, w.prim);
        nverts = j.idx.count;
    }
    j.mode = mode;
    if (mode == TINYGLTF_MODE_TRIANGLES && nverts % 3 != 0)
        fail("node %d mesh %d primitive %d: %zu %s is not a multiple of 3 (TRIANGLES)",
             w.node, w.mesh, w.prim, nverts, j.indexed ? "indices" : "vertices");
    if (mode == TINYGLTF_MODE_TRIANGLES)
        j.ntris = nverts / 3;
    else
        j.ntris = nverts >= 3 ? nverts - 2 : 0;
    return true;
}

/* Pass 1 state: the walk over the default scene's node forest. */
struct Planner {
    const tinygltf::Model &m;
    std::vector<Job> jobs;
    std::vector<char> seen;
    size_t total = 0;

    explicit Planner(const tinygltf::Model &model)
        : m(model), seen(model.nodes.size(), 0) {}

    void visit(int ni, const Mat4 &parent, int depth) {
        if (ni < 0 || (size_t)ni >= m.nodes.size()) fail("node %d does not exist", ni);
        if (seen[(size_t)ni] == 1) fail("node %d is its own ancestor (cycle)", ni);
        if (seen[(size_t)ni] == 2) fail("node %d has more than one parent", ni);
        if (depth > kMaxNodeDepth) fail("node hierarchy deeper than %d", kMaxNodeDepth);
        seen[(size_t)ni] = 1;
        const tinygltf::Node &n = m.nodes[(size_t)ni];
        Mat4 world = mat_mul(parent, node_local_matrix(n, ni));
        if (n.mesh >= 0) plan_mesh(ni, n.mesh, world);
        for (int c : n.children)
            visit(c, world, depth + 1);
        seen[(size_t)ni] = 2;
    }

    void plan_mesh(int ni, int mi, const Mat4 &world) {
        if ((size_t)mi >= m.meshes.size())
            fail("node %d: mesh %d does not exist", ni, mi);
        const auto &prims = m.meshes[(size_t)mi].primitives;
        for (size_t pi = 0; pi < prims.size(); pi++) {
            Job j{};
            j.w = Where{ni, mi, (int)pi};
            j.world = world;
            if (!plan_primitive(m, prims[pi], j)) continue;
            if (j.ntris > KDR_GLTF_MAX_TRIANGLES - total)
                fail("more than 2^30 triangles");
            total += j.ntris;
            jobs.push_back(j);
        }
    }
};

/* Vertex k of triangle t of a primitive, as the glTF 2.0 spec orders
 * strips (alternating winding) and fans (pivot last). */
size_t corner(int mode, size_t t, int k) {
    if (mode == TINYGLTF_MODE_TRIANGLES) return 3 * t + (size_t)k;
    if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
        static const int even[3] = {0, 1, 2}, odd[3] = {0, 2, 1};
        return t + (size_t)((t & 1) ? odd[k] : even[k]);
    }
    return k == 2 ? 0 : t + 1 + (size_t)k;
}

void emit_job(const Job &j, float *out) {
    const double *M = j.world.m;
    for (size_t t = 0; t < j.ntris; t++)
        for (int k = 0; k < 3; k++) {
            size_t vi = corner(j.mode, t, k);
            if (j.indexed) {
                vi = read_index(j.idx, vi);
                if (vi >= j.pos.count)
                    fail("node %d mesh %d primitive %d: index %zu is out of range (%zu "
                         "positions)",
                         j.w.node, j.w.mesh, j.w.prim, vi, j.pos.count);
            }
            double x = read_component(j.pos, vi, 0), y = read_component(j.pos, vi, 1),
                   z = read_component(j.pos, vi, 2);
            if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
                fail("node %d mesh %d primitive %d: position %zu is not finite", j.w.node,
                     j.w.mesh, j.w.prim, vi);
            float *o = out + 9 * t + 3 * (size_t)k;
            for (int r = 0; r < 3; r++) {
                double v = M[r] * x + M[4 + r] * y + M[8 + r] * z + M[12 + r];
                o[r] = (float)v;
                if (!std::isfinite(o[r]))
                    fail("node %d mesh %d primitive %d: position %zu is not finite after "
                         "the node transform",
                         j.w.node, j.w.mesh, j.w.prim, vi);
            }
        }
}

void check_extensions(const tinygltf::Model &m) {
    for (const std::string &e : m.extensionsRequired)
        for (const char *u : kUnsupportedExtensions)
            if (e == u) fail("requires extension %s (unsupported)", u);
}

int default_scene(const tinygltf::Model &m) {
    if (m.scenes.empty()) fail("file has no scene");
    int s = m.defaultScene >= 0 ? m.defaultScene : 0;
    if ((size_t)s >= m.scenes.size()) fail("default scene %d does not exist", s);
    return s;
}

std::string one_line(std::string s) {
    for (char &c : s)
        if (c == '\n' || c == '\r') c = ' ';
    while (!s.empty() && s.back() == ' ')
        s.pop_back();
    return s;
}

/* The whole file: tinygltf parses from memory so the file is read once and
 * the JSON can be schema-checked first. */
std::vector<unsigned char> read_file(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) fail("cannot open: %s", strerror(errno));
    std::vector<unsigned char> bytes;
    unsigned char buf[1 << 16];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, f)) > 0) {
        if (bytes.size() + n > kMaxFileBytes) {
            fclose(f);
            fail("file larger than %zu bytes", kMaxFileBytes);
        }
        bytes.insert(bytes.end(), buf, buf + n);
    }
    int bad = ferror(f) ? errno : 0;
    fclose(f);
    if (bad) fail("read error: %s", strerror(bad));
    if (bytes.empty()) fail("file is empty");
    return bytes;
}

bool is_glb(const std::vector<unsigned char> &b) {
    return b.size() >= 4 && memcmp(b.data(), "glTF", 4) == 0;
}

/* The JSON text of a .gltf, or of a .glb's first chunk (empty if the GLB
 * header is inconsistent: tinygltf then reports the precise problem). */
std::string json_text(const std::vector<unsigned char> &b) {
    if (!is_glb(b)) return std::string(b.begin(), b.end());
    if (b.size() < 20) return {};
    uint32_t len, type;
    memcpy(&len, b.data() + 12, 4);
    memcpy(&type, b.data() + 16, 4);
    if (type != 0x4E4F534Au || len > b.size() - 20) return {};
    return std::string(b.begin() + 20, b.begin() + 20 + len);
}

/* tinygltf's reader of external buffers (a .gltf's "uri" naming a file),
 * bounded as read_file is: only a regular file, at most kMaxFileBytes.
 * tinygltf's own takes the size from seeking to the end, which for a
 * directory ("uri": "." or "") is LONG_MAX, and then allocates that much
 * (std::bad_alloc; under AddressSanitizer an abort, found by the glTF
 * fuzzer). Errors go to *err, which tinygltf puts in its message. */
bool read_external(std::vector<unsigned char> *out, std::string *err,
                   const std::string &path, void *) {
    auto refuse = [&](const std::string &why) {
        if (err) *err += "external file " + path + ": " + why + "\n";
        return false;
    };
    struct stat st;
    if (stat(path.c_str(), &st) != 0) return refuse(strerror(errno));
    if (!S_ISREG(st.st_mode)) return refuse("not a regular file");
    if (st.st_size <= 0) return refuse("empty");
    if ((unsigned long long)st.st_size > kMaxFileBytes)
        return refuse("larger than " + std::to_string(kMaxFileBytes) + " bytes");
    FILE *f = fopen(path.c_str(), "rb");
    if (!f) return refuse(strerror(errno));
    out->resize((size_t)st.st_size);
    const size_t got = fread(out->data(), 1, out->size(), f);
    const int bad = ferror(f);
    fclose(f);
    if (bad || got != out->size()) return refuse("short read");
    return true;
}

/* A no-op image loader: tinygltf 2.7 refuses images without one, and
 * queries never look at textures. */
bool skip_image(tinygltf::Image *, const int, std::string *, std::string *, int, int,
                const unsigned char *, int, void *) {
    return true;
}

std::string base_dir(const char *path) {
    std::string p(path);
    size_t slash = p.find_last_of('/');
    return slash == std::string::npos ? std::string() : p.substr(0, slash + 1);
}

void parse(const char *path, tinygltf::Model &m) {
    std::vector<unsigned char> bytes = read_file(path);
    if (is_glb(bytes) && bytes.size() >= 8 && bytes[4] != 2)
        fail("GLB container version %u is not supported (glTF 1.0?), need 2", bytes[4]);
    std::string json = json_text(bytes);
    char err_json[512];
    if (!json.empty() &&
        kdr_gltf_check_json(json.data(), json.size(), err_json, sizeof err_json) != 0)
        fail("%s", err_json);
    tinygltf::TinyGLTF loader;
    loader.SetImageLoader(skip_image, nullptr);
    loader.SetFsCallbacks(tinygltf::FsCallbacks{tinygltf::FileExists, tinygltf::ExpandFilePath,
                                                read_external, tinygltf::WriteWholeFile,
                                                nullptr});
    std::string err, warn, dir = base_dir(path);
    bool ok = is_glb(bytes) ? loader.LoadBinaryFromMemory(&m, &err, &warn, bytes.data(),
                                                          (unsigned)bytes.size(), dir)
                            : loader.LoadASCIIFromString(&m, &err, &warn,
                                                         (const char *)bytes.data(),
                                                         (unsigned)bytes.size(), dir);
    if (!ok) fail("%s", err.empty() ? "not a valid glTF file" : one_line(err).c_str());
    if (m.asset.version.compare(0, 2, "2.") != 0)
        fail("glTF version \"%s\" is not supported (need 2.x)", m.asset.version.c_str());
}

void check_memory(size_t ntris) {
    long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    if (pages <= 0 || page <= 0) return;
    double need = (double)ntris * 9 * sizeof(float);
    double have = (double)pages * (double)page;
    if (need > kMaxMemoryFraction * have)
        fail("%zu triangles need %.1f GiB, more than %.0f%% of this machine's %.1f GiB",
             ntris, need / 1073741824.0, kMaxMemoryFraction * 100, have / 1073741824.0);
}

void flatten(const tinygltf::Model &m, kdr_gltf_scene *out) {
    check_extensions(m);
    Planner plan(m);
    for (int root : m.scenes[(size_t)default_scene(m)].nodes)
        plan.visit(root, mat_identity(), 0);
    size_t nt = plan.total, nr = plan.jobs.size();
    check_memory(nt);
    out->tris = (float *)malloc(nt ? nt * 9 * sizeof(float) : 1);
    out->ranges = (kdr_mesh_range *)malloc(nr ? nr * sizeof(kdr_mesh_range) : 1);
    if (!out->tris || !out->ranges) fail("out of memory for %zu triangles", nt);
    size_t first = 0;
    for (size_t i = 0; i < nr; i++) {
        const Job &j = plan.jobs[i];
        emit_job(j, out->tris + 9 * first);
        out->ranges[i] =
            kdr_mesh_range{(uint32_t)j.w.node, (uint32_t)j.w.mesh, (uint32_t)j.w.prim,
                           (uint32_t)first, (uint32_t)j.ntris};
        first += j.ntris;
    }
    out->ntris = nt;
    out->nranges = nr;
}

void set_err(char *err, size_t errlen, const char *path, const char *msg) {
    if (err && errlen) snprintf(err, errlen, "%s: %s", path ? path : "(null)", msg);
}

} // namespace

extern "C" int kdr_gltf_load(const char *path, kdr_gltf_scene *out, char *err,
                             size_t errlen) {
    if (err && errlen) err[0] = '\0';
    if (!out) {
        set_err(err, errlen, path, "no output scene given");
        return -1;
    }
    *out = kdr_gltf_scene{};
    if (!path || !*path) {
        set_err(err, errlen, path, "empty path");
        return -1;
    }
    auto t0 = std::chrono::steady_clock::now();
    try {
        tinygltf::Model m;
        parse(path, m);
        flatten(m, out);
    } catch (const std::bad_alloc &) {
        kdr_gltf_free(out);
        set_err(err, errlen, path, "out of memory");
        return -1;
    } catch (const std::exception &e) {
        kdr_gltf_free(out);
        set_err(err, errlen, path, e.what());
        return -1;
    } catch (...) {
        kdr_gltf_free(out);
        set_err(err, errlen, path, "unexpected error while loading");
        return -1;
    }
    out->load_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
            .count();
    return 0;
}

extern "C" void kdr_gltf_free(kdr_gltf_scene *s) {
    if (!s) return;
    free(s->tris);
    free(s->ranges);
    *s = kdr_gltf_scene{};
}
