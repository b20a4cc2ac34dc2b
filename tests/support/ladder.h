/*
 * ladder.h — the real-scene ladder prepared by scenes/fetch: a text file
 * ${KDRAY_SCENE_DIR}/ladder.txt with one scene per line,
 * `name path triangles` (path absolute or relative to the directory),
 * smallest first. Tests get the directory from the KDRAY_SCENE_DIR compile
 * definition or from argv.
 */
#ifndef KDRAY_TEST_LADDER_H
#define KDRAY_TEST_LADDER_H

#include <stddef.h>

typedef struct ladder_entry {
    char name[64];
    char path[1024];
    size_t triangles; /* as listed; the loaded count is authoritative */
} ladder_entry;

/* Reads dir/ladder.txt. Returns the number of entries (>= 0; *out is
 * malloc'ed, free it) or -1 if the file is missing or malformed (message in
 * err). */
int ladder_read(const char *dir, ladder_entry **out, char *err, size_t errlen);

/* Loads one scene into a malloc'ed 9-float triangle array (free() it).
 * Returns 0, or -1 with err set (also when kdray was built without the
 * glTF loader). */
int ladder_load(const ladder_entry *e, float **tris, size_t *ntris, char *err,
                size_t errlen);

/* The directory given at build time (KDRAY_SCENE_DIR) or NULL. */
const char *ladder_default_dir(void);

#endif /* KDRAY_TEST_LADDER_H */
