/*
 * kdr_render_params.c — a render's parameters: parsing them from text (the
 * values of an HTTP query string, though nothing here knows HTTP), and the
 * defaults that frame a scene's bounds, so a request with no parameters
 * gives a useful picture. Errors name the parameter and what it expects.
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_render.h"

/* Defaults that do not depend on the scene. */
static const float DEFAULT_FOV = 45.0f;
static const uint32_t DEFAULT_WIDTH = 640, DEFAULT_HEIGHT = 480;
static const uint32_t DEFAULT_SAMPLES = 16;
/* The default view looks at the bounds' centre from this direction (front,
 * right, above; y up as glTF), from far enough that the bounding sphere
 * nearly fills the picture's height. */
static const float VIEW_DIR[3] = {0.62f, 0.42f, 0.66f};
static const float FRAME_FILL = 1.40f;
/* The default light: above the scene and to the right, its radius a
 * fraction of the bounding radius (a soft, visible penumbra). */
static const float LIGHT_OFFSET[3] = {0.45f, 1.30f, 0.60f};
static const float LIGHT_RADIUS = 0.10f;
/* ao rays reach this fraction of the bounding radius. */
static const float AO_RADIUS = 0.15f;

void kdr_render_params_init(kdr_render_params *p) {
    memset(p, 0, sizeof *p);
    p->cam.up[1] = 1.0f;
    p->cam.fov_y_deg = DEFAULT_FOV;
    p->cam.width = DEFAULT_WIDTH;
    p->cam.height = DEFAULT_HEIGHT;
    p->samples = DEFAULT_SAMPLES;
    p->mode = KDR_RENDER_SHADE;
}

/* n comma-separated finite floats, nothing else. */
static int floats(const char *s, float *out, int n) {
    for (int i = 0; i < n; i++) {
        char *end;
        errno = 0;
        float v = strtof(s, &end);
        if (end == s || errno == ERANGE || !isfinite(v)) return -1;
        out[i] = v;
        s = end;
        if (i + 1 < n) {
            if (*s != ',') return -1;
            s++;
        }
    }
    return *s ? -1 : 0;
}

static int integer(const char *s, long lo, long hi, uint32_t *out) {
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (end == s || *end || errno || v < lo || v > hi) return -1;
    *out = (uint32_t)v;
    return 0;
}

static int bad(char *err, size_t n, const char *name, const char *want) {
    snprintf(err, n, "%s: expected %s", name, want);
    return -1;
}

int kdr_render_param(kdr_render_params *p, const char *name, const char *value, char *err,
                     size_t errlen) {
    if (!value) value = "";
    if (!strcmp(name, "eye") || !strcmp(name, "target") || !strcmp(name, "up")) {
        float *dst = name[0] == 'e'   ? p->cam.eye
                     : name[0] == 't' ? p->cam.target
                                      : p->cam.up;
        if (floats(value, dst, 3))
            return bad(err, errlen, name, "three finite numbers x,y,z");
        p->set |= name[0] == 'e'   ? KDR_RP_EYE
                  : name[0] == 't' ? KDR_RP_TARGET
                                   : KDR_RP_UP;
    } else if (!strcmp(name, "fov")) {
        float f;
        if (floats(value, &f, 1) || !(f > 0.0f && f < 180.0f))
            return bad(err, errlen, name, "degrees in (0, 180)");
        p->cam.fov_y_deg = f;
        p->set |= KDR_RP_FOV;
    } else if (!strcmp(name, "width") || !strcmp(name, "height")) {
        uint32_t *dst = name[0] == 'w' ? &p->cam.width : &p->cam.height;
        if (integer(value, 1, KDR_RENDER_MAX_SIDE, dst))
            return bad(err, errlen, name, "an integer in 1..16384");
        p->set |= name[0] == 'w' ? KDR_RP_WIDTH : KDR_RP_HEIGHT;
    } else if (!strcmp(name, "light")) {
        float l[4];
        if (floats(value, l, 4) || !(l[3] > 0.0f))
            return bad(err, errlen, name, "x,y,z,radius (finite, radius > 0)");
        memcpy(p->light.center, l, sizeof p->light.center);
        p->light.radius = l[3];
        p->set |= KDR_RP_LIGHT;
    } else if (!strcmp(name, "samples")) {
        if (integer(value, 1, KDR_RENDER_MAX_SAMPLES, &p->samples))
            return bad(err, errlen, name, "an integer in 1..4096");
        p->set |= KDR_RP_SAMPLES;
    } else if (!strcmp(name, "mode")) {
        int m = -1;
        for (int i = 0; i <= KDR_RENDER_AO; i++)
            if (!strcmp(value, kdr_render_mode_name((kdr_render_mode)i))) m = i;
        if (m < 0) return bad(err, errlen, name, "shade, depth, normal, shadow or ao");
        p->mode = (kdr_render_mode)m;
        p->set |= KDR_RP_MODE;
    } else {
        snprintf(err, errlen,
                 "%.64s: unknown parameter (eye, target, up, fov, width, height, light, "
                 "samples, mode)",
                 name);
        return 1;
    }
    return 0;
}

static float dist3(const float a[3], const float b[3]) {
    const float d[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
    return sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
}

int kdr_render_frame(const kdr_scene *scene, kdr_render_params *p, char *err,
                     size_t errlen) {
    kdr_bounds b;
    kdr_scene_bounds(scene, &b);
    float c[3], r = 0.5f * kdr_scene_diagonal(scene);
    for (int i = 0; i < 3; i++)
        c[i] = kdr_scene_triangle_count(scene) ? 0.5f * (b.min[i] + b.max[i]) : 0.0f;
    if (!(r > 0.0f)) r = 1.0f;
    if (!(p->set & KDR_RP_TARGET)) memcpy(p->cam.target, c, sizeof c);
    if (!(p->set & KDR_RP_EYE)) {
        const float half = p->cam.fov_y_deg * 0.5f * 0.017453292f;
        const float d = r / (FRAME_FILL * sinf(half));
        const float vl = sqrtf(VIEW_DIR[0] * VIEW_DIR[0] + VIEW_DIR[1] * VIEW_DIR[1] +
                               VIEW_DIR[2] * VIEW_DIR[2]);
        for (int i = 0; i < 3; i++)
            p->cam.eye[i] = p->cam.target[i] + VIEW_DIR[i] / vl * d;
    }
    if (!(p->set & KDR_RP_LIGHT)) {
        for (int i = 0; i < 3; i++)
            p->light.center[i] = c[i] + LIGHT_OFFSET[i] * r;
        p->light.center[1] = b.max[1] + LIGHT_OFFSET[1] * r;
        if (!kdr_scene_triangle_count(scene)) p->light.center[1] = LIGHT_OFFSET[1] * r;
        p->light.radius = LIGHT_RADIUS * r;
    }
    /* the camera, named by what is wrong with it */
    if (dist3(p->cam.eye, p->cam.target) == 0.0f) {
        snprintf(err, errlen, "eye: equal to target");
        return -1;
    }
    if (kdr_camera_validate(&p->cam) != KDR_OK) {
        snprintf(err, errlen, "up: parallel to the view direction (or zero)");
        return -1;
    }
    const float e = dist3(p->cam.eye, c);
    p->near_d = e > r ? e - r : 0.0f;
    p->far_d = e + r;
    p->ao_radius = AO_RADIUS * r;
    return 0;
}
