/*
 * ladder.c — parsing ladder.txt and loading its scenes through the glTF
 * shim (scenes/kdr_gltf.h) when kdray_scenes exists; without it (the scenes
 * module not built yet) loading fails with a clear message, so tests that
 * need the ladder fail rather than silently pass.
 */
#define _POSIX_C_SOURCE 200809L
#include "ladder.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef KDRAY_HAVE_GLTF
#include "kdr_gltf.h"
#endif

const char *ladder_default_dir(void) {
#ifdef KDRAY_SCENE_DIR
    return KDRAY_SCENE_DIR;
#else
    return NULL;
#endif
}

static int parse_line(const char *dir, const char *line, ladder_entry *e) {
    char name[64], path[1024];
    unsigned long long n;
    if (sscanf(line, "%63s %1023s %llu", name, path, &n) != 3)
        return -1;
    memcpy(e->name, name, sizeof e->name);
    const size_t ld = path[0] == '/' ? 0 : strlen(dir) + 1, lp = strlen(path);
    if (ld + lp + 1 > sizeof e->path)
        return -1;
    if (ld) {
        memcpy(e->path, dir, ld - 1);
        e->path[ld - 1] = '/';
    }
    memcpy(e->path + ld, path, lp + 1);
    e->triangles = (size_t)n;
    return 0;
}

int ladder_read(const char *dir, ladder_entry **out, char *err, size_t errlen) {
    char fname[1100], line[1200];
    *out = NULL;
    if (!dir)
        dir = ".";
    snprintf(fname, sizeof fname, "%s/ladder.txt", dir);
    FILE *f = fopen(fname, "r");
    if (!f) {
        snprintf(err, errlen, "%s: cannot open (run scenes/fetch)", fname);
        return -1;
    }
    ladder_entry *v = NULL;
    int n = 0, cap = 0, lineno = 0;
    while (fgets(line, sizeof line, f)) {
        lineno++;
        if (line[0] == '#' || strspn(line, " \t\r\n") == strlen(line))
            continue;
        if (n == cap) {
            cap = cap ? 2 * cap : 8;
            ladder_entry *nv = realloc(v, (size_t)cap * sizeof *nv);
            if (!nv)
                break;
            v = nv;
        }
        if (parse_line(dir, line, &v[n]) != 0) {
            snprintf(err, errlen, "%s:%d: expected `name path triangles`",
                     fname, lineno);
            free(v);
            fclose(f);
            return -1;
        }
        n++;
    }
    fclose(f);
    *out = v;
    return n;
}

int ladder_load(const ladder_entry *e, float **tris, size_t *ntris, char *err,
                size_t errlen) {
    *tris = NULL;
    *ntris = 0;
#ifdef KDRAY_HAVE_GLTF
    kdr_gltf_scene s;
    if (kdr_gltf_load(e->path, &s, err, errlen) != 0)
        return -1;
    /* a private copy, so callers free() it whatever the shim allocates with */
    *tris = malloc((s.ntris ? s.ntris : 1) * 9 * sizeof(float));
    if (!*tris) {
        snprintf(err, errlen, "%s: out of memory", e->path);
        kdr_gltf_free(&s);
        return -1;
    }
    if (s.ntris)
        memcpy(*tris, s.tris, s.ntris * 9 * sizeof(float));
    *ntris = s.ntris;
    kdr_gltf_free(&s);
    return 0;
#else
    snprintf(err, errlen, "%s: kdray built without the glTF loader", e->path);
    return -1;
#endif
}
