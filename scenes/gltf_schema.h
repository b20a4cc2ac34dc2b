/*
 * gltf_schema.h — private to the scenes library: the JSON checks that run
 * before tinygltf parses a file (gltf_schema.c explains why).
 */
#ifndef KDR_GLTF_SCHEMA_H
#define KDR_GLTF_SCHEMA_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Checks the glTF JSON text[0..len): nesting depth, JSON syntax, the types
 * of the glTF 2.0 schema, version 2.x and no unsupported required extension.
 * Returns 0, or -1 with one line (without the file name) in err. */
int kdr_gltf_check_json(const char *text, size_t len, char *err, size_t errlen);

#ifdef __cplusplus
}
#endif
#endif /* KDR_GLTF_SCHEMA_H */
