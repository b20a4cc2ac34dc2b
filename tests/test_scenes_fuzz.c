/*
 * test_scenes_fuzz.c — libFuzzer target for the glTF loader: each input is
 * written to a scratch file (the loader's API takes paths, as the daemon's
 * --scene does) and loaded; any crash, sanitizer report or leak fails.
 * Built with clang only when -DKDRAY_FUZZ=ON (tests/scenes.cmake); seeded
 * with assimp-testmodels' small glTF 2.0 files.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdint.h>
#include <stdio.h>
#include <unistd.h>

#include "kdr_gltf.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static char path[64];
    if (!path[0])
        snprintf(path, sizeof path, "scenes-fuzz-input-%ld.gltf", (long)getpid());
    FILE *f = fopen(path, "wb");
    if (!f) return 0;
    size_t written = fwrite(data, 1, size, f);
    fclose(f);
    if (written != size) return 0;
    kdr_gltf_scene s;
    char err[256];
    if (kdr_gltf_load(path, &s, err, sizeof err) == 0) kdr_gltf_free(&s);
    return 0;
}
