/*
 * kdr_gltf.h — loading a glTF 2.0 file (.gltf with external or data: buffers,
 * or .glb) into the flat world-space triangle soup the core builds on.
 *
 * Triangles come out in the numbering of the HTTP contract (shared/API.md):
 * the default scene (`scene`, else scene 0), its root nodes in array order,
 * each node depth-first pre-order (its own mesh before its children), the
 * mesh's primitives in order, each primitive's triangles in index order.
 * Only geometry is read: images are never decoded; materials, animations,
 * skins and morph targets are ignored (base positions are used).
 *
 * Primitive modes TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN produce
 * triangles (strip/fan vertex order as the glTF 2.0 spec defines it);
 * POINTS and LINE* primitives are skipped and get no range. Anything the
 * loader cannot represent faithfully (sparse accessors, Draco or meshopt
 * compression, out-of-range indices or accessors, non-finite positions,
 * glTF 1.0, node cycles) is an error, never a crash and never a silent
 * partial scene.
 *
 * Thread safety: kdr_gltf_load may run on several threads at once (it keeps
 * no state of its own; cJSON records its last syntax error in a global that
 * nothing reads). The result is owned by the caller: kdr_gltf_free.
 */
#ifndef KDR_GLTF_H
#define KDR_GLTF_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Hard limit on the flattened triangle count (the core's limit too). */
#define KDR_GLTF_MAX_TRIANGLES ((size_t)1 << 30)

/* The triangles [first_prim, first_prim + count) came from primitive
 * `primitive` of mesh `mesh` as instanced by node `node` (glTF indices). */
typedef struct kdr_mesh_range {
    uint32_t node, mesh, primitive;
    uint32_t first_prim, count;
} kdr_mesh_range;

typedef struct kdr_gltf_scene {
    float *tris; /* 9 * ntris floats: p0, p1, p2 in world space */
    size_t ntris;
    kdr_mesh_range *ranges; /* one per triangle-producing (node, mesh, prim),
                               in triangle order; they tile [0, ntris) */
    size_t nranges;
    double load_ms; /* wall time of parse + flatten */
} kdr_gltf_scene;

/* Loads path (.glb is recognised by its magic, not its name). Returns 0 and
 * fills *out, or -1 with *out zeroed and err holding one line that names the
 * file and the problem (truncated to errlen; err may be NULL). */
int kdr_gltf_load(const char *path, kdr_gltf_scene *out, char *err, size_t errlen);

/* Frees what kdr_gltf_load allocated and zeroes *s (NULL-safe, idempotent). */
void kdr_gltf_free(kdr_gltf_scene *s);

#ifdef __cplusplus
}
#endif
#endif /* KDR_GLTF_H */
