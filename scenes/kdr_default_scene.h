/*
 * kdr_default_scene.h — where the bundled default scene is: the file that
 * kdrayd serves, and kdray-trace traces, when no scene is named.
 */
#ifndef KDR_DEFAULT_SCENE_H
#define KDR_DEFAULT_SCENE_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Writes the path into buf (n bytes) and returns buf. An installed binary
 * finds the scene installed beside it (BINDIR/../share/kdray/default.glb, the
 * relative path fixed at configure time, so a relocated or DESTDIR tree
 * works too); a binary in the build tree, where that file does not exist,
 * gets the source tree's scenes/default.glb. */
const char *kdr_default_scene_path(char *buf, size_t n);

#ifdef __cplusplus
}
#endif
#endif
