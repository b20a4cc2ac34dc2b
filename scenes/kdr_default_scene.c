/*
 * kdr_default_scene.c — the default scene's path, looked up at run time from
 * the running binary's own location (/proc/self/exe), so that `cmake
 * --install` output never depends on the source tree still being there.
 */
#define _XOPEN_SOURCE 700 /* realpath */
#include "kdr_default_scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#ifndef KDRAY_DEFAULT_SCENE_REL
#define KDRAY_DEFAULT_SCENE_REL "../share/kdray/default.glb"
#endif

const char *kdr_default_scene_path(char *buf, size_t n) {
    char exe[4096];
    ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (len > 0) {
        exe[len] = '\0';
        char *slash = strrchr(exe, '/');
        if (slash) {
            slash[1] = '\0';
            char installed[4096 + 64], real[4096];
            snprintf(installed, sizeof installed, "%s%s", exe, KDRAY_DEFAULT_SCENE_REL);
            if (access(installed, R_OK) == 0 && realpath(installed, real) &&
                (size_t)snprintf(buf, n, "%s", real) < n)
                return buf;
        }
    }
    snprintf(buf, n, "%s", KDRAY_DEFAULT_SCENE);
    return buf;
}
