/*
 * rival.c — Embree's device and scene for the benchmarks, the report of
 * what Embree selected on this machine, the floating-point mode and the
 * API list (rival.h). The timed calls live in rival_trace.c.
 *
 * The scene itself is built by the test oracle (tests/support/oracle.c:
 * one geometry, primID == kdray's prim, the same triangles), here with the
 * rival's flags, quality and device, and with FTZ/DAZ on.
 *
 * The ISA is not guessed from CPUID: Embree 3 has no device property for
 * it, so rival_print_setup commits a one-triangle probe scene on a device
 * with "verbose=2", captures the report Embree writes to stdout and prints
 * the builder and the kernel it selected for each API (their names start
 * with the ISA they were compiled for, e.g. avx512::).
 */
#define _POSIX_C_SOURCE 200809L
#include "rival.h"

#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <xmmintrin.h>

#include "oracle.h"

struct rival {
    oracle *o;
    int robust;
};

/* ---- floating-point mode ------------------------------------------------------- */

#define MXCSR_FTZ 0x8000u
#define MXCSR_DAZ 0x0040u

rival_fp rival_fp_enter(void) {
    rival_fp old = {_mm_getcsr()};
    _mm_setcsr(old.csr | MXCSR_FTZ | MXCSR_DAZ);
    return old;
}

void rival_fp_leave(rival_fp saved) { _mm_setcsr(saved.csr); }

/* ---- scene --------------------------------------------------------------------- */

rival *rival_create(const float *tris, size_t ntris, int robust,
                    enum RTCBuildQuality quality) {
    rival *r = calloc(1, sizeof *r);
    if (!r)
        return NULL;
    oracle_opts oo;
    oracle_opts_default(&oo);
    oo.robust = robust;
    oo.quality = quality;
    oo.device_config = RIVAL_DEVICE_CONFIG;
    const rival_fp fp = rival_fp_enter();
    r->o = oracle_create(tris, ntris, &oo);
    rival_fp_leave(fp);
    r->robust = robust;
    if (!r->o) {
        free(r);
        return NULL;
    }
    return r;
}

rival *rival_create_filter(const float *tris, size_t ntris,
                           enum RTCBuildQuality quality) {
    rival *r = calloc(1, sizeof *r);
    if (!r)
        return NULL;
    oracle_opts oo;
    oracle_opts_default(&oo);
    oo.robust = 0;
    oo.quality = quality;
    oo.device_config = RIVAL_DEVICE_CONFIG;
    oo.context_filter = 1;
    const rival_fp fp = rival_fp_enter();
    r->o = oracle_create(tris, ntris, &oo);
    rival_fp_leave(fp);
    if (!r->o) {
        free(r);
        return NULL;
    }
    return r;
}

const struct oracle *rival_oracle(const rival *r) { return r->o; }

void rival_free(rival *r) {
    if (!r)
        return;
    oracle_free(r->o);
    free(r);
}

double rival_build_ms(const rival *r) { return oracle_build_cpu_ms(r->o); }
int64_t rival_bytes(const rival *r) { return oracle_bytes(r->o); }
int rival_robust(const rival *r) { return r->robust; }
RTCScene rival_rtc_scene(const rival *r) { return oracle_rtc_scene(r->o); }

/* ---- what Embree selected ------------------------------------------------------ */

/* Native packet widths; -1 until probed. */
static int g_native[3] = {-1, -1, -1}; /* 4, 8, 16 */
static int g_stream = -1;

static void probe_properties(void) {
    if (g_native[0] >= 0)
        return;
    RTCDevice d = rtcNewDevice(RIVAL_DEVICE_CONFIG);
    if (!d) {
        g_native[0] = g_native[1] = g_native[2] = g_stream = 0;
        return;
    }
    g_native[0] = (int)rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED);
    g_native[1] = (int)rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED);
    g_native[2] =
        (int)rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED);
    g_stream = (int)rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED);
    rtcReleaseDevice(d);
}

/* Commits a one-triangle scene (fast, then robust) on a verbose device
 * with FTZ/DAZ on, Embree's report going to `sink`. */
static void probe_scenes(FILE *sink) {
    static const float tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    fflush(stdout);
    const int saved = dup(STDOUT_FILENO);
    if (saved < 0 || dup2(fileno(sink), STDOUT_FILENO) < 0)
        return;
    const rival_fp fp = rival_fp_enter();
    for (int robust = 0; robust < 2; robust++) {
        RTCDevice d = rtcNewDevice(RIVAL_DEVICE_CONFIG ",verbose=2");
        RTCScene s = d ? rtcNewScene(d) : NULL;
        if (!s)
            break;
        RTCGeometry g = rtcNewGeometry(d, RTC_GEOMETRY_TYPE_TRIANGLE);
        float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0,
                                           RTC_FORMAT_FLOAT3, 12, 3);
        unsigned *idx = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0,
                                                RTC_FORMAT_UINT3, 12, 1);
        memcpy(v, tri, sizeof tri);
        idx[0] = 0, idx[1] = 1, idx[2] = 2;
        rtcCommitGeometry(g);
        rtcAttachGeometry(s, g);
        rtcReleaseGeometry(g);
        rtcSetSceneFlags(s, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
        rtcSetSceneBuildQuality(s, RIVAL_QUALITY);
        rtcCommitScene(s);
        rtcReleaseScene(s);
        rtcReleaseDevice(d);
    }
    rival_fp_leave(fp);
    fflush(stdout);
    dup2(saved, STDOUT_FILENO);
    close(saved);
}

/* What the report says, for the fast scene [0] and the robust one [1]. */
typedef struct probe_report {
    char mxcsr[64];
    char builder[2][128];
    char kernel[2][5][128]; /* intersector1, 4, 8, 16, N */
} probe_report;

static void copy_value(char *dst, size_t len, const char *src) {
    while (*src == ' ')
        src++;
    snprintf(dst, len, "%s", src);
    dst[strcspn(dst, " \r\n")] = '\0';
}

static void parse_report(FILE *f, probe_report *p) {
    static const char *const keys[5] = {"intersector1 ", "intersector4 ",
                                        "intersector8 ", "intersector16 ",
                                        "intersectorN "};
    char line[512];
    int scene = -1, selected = 0;
    memset(p, 0, sizeof *p);
    rewind(f);
    while (fgets(line, sizeof line, f)) {
        const char *s = line + strspn(line, " ");
        if (!strncmp(s, "MXCSR", 5) && !p->mxcsr[0]) {
            snprintf(p->mxcsr, sizeof p->mxcsr, "%s",
                     strchr(s, ':') ? strchr(s, ':') + 2 : s);
            p->mxcsr[strcspn(p->mxcsr, "\r\n")] = '\0';
        } else if (!strncmp(s, "building BVH", 12) && scene < 1) {
            scene++;
            selected = 0;
            const char *u = strstr(s, " using ");
            if (u)
                copy_value(p->builder[scene], sizeof p->builder[scene], u + 7);
        } else if (!strncmp(s, "selected scene intersector", 26)) {
            selected = 1;
        } else if (selected && scene >= 0) {
            for (int k = 0; k < 5; k++)
                if (!strncmp(s, keys[k], strlen(keys[k])) && strchr(s, '='))
                    copy_value(p->kernel[scene][k], sizeof p->kernel[scene][k],
                               strchr(s, '=') + 1);
        }
    }
}

/* "avx512" from "avx512::BVH8Triangle4Intersector1Moeller". */
static void isa_of(const char *kernel, char *isa, size_t len) {
    const char *c = strstr(kernel, "::");
    snprintf(isa, len, "%.*s", c ? (int)(c - kernel) : 0, kernel);
}

int rival_print_setup(FILE *out) {
    probe_properties();
    FILE *sink = tmpfile();
    probe_report p;
    if (!sink) {
        fprintf(out, "rival: cannot capture Embree's report (tmpfile failed)\n");
        return -1;
    }
    probe_scenes(sink);
    parse_report(sink, &p);
    fclose(sink);
    char isa[32], bisa[32];
    isa_of(p.kernel[0][0], isa, sizeof isa);
    isa_of(p.builder[0], bisa, sizeof bisa);
    RTCDevice d = rtcNewDevice(RIVAL_DEVICE_CONFIG);
    const long ver = d ? (long)rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_VERSION) : 0;
    if (d)
        rtcReleaseDevice(d);
    fprintf(out,
            "rival: Embree %ld.%ld.%ld, rtcNewDevice(\"%s\"), scene flags NONE (fast; "
            "ROBUST only for accuracy references), build quality HIGH\n",
            ver / 10000, ver / 100 % 100, ver % 100, RIVAL_DEVICE_CONFIG);
    fprintf(out, "rival: FTZ/DAZ on while Embree runs (Embree's own report: MXCSR %s), "
                 "off for kdray\n", p.mxcsr[0] ? p.mxcsr : "?");
    fprintf(out, "rival: Embree selected ISA %s for tracing, %s for building (its "
                 "verbose report of a probe scene):\n",
            isa[0] ? isa : "?", bisa[0] ? bisa : "?");
    static const char *const api[5] = {"rtc*1", "rtc*4", "rtc*8", "rtc*16", "rtc*1M"};
    for (int s = 0; s < 2; s++) {
        fprintf(out, "  %s: builder %s\n", s ? "robust" : "fast  ",
                p.builder[s][0] ? p.builder[s] : "?");
        for (int k = 0; k < 5; k++)
            fprintf(out, "  %s: %-7s %s\n", s ? "robust" : "fast  ", api[k],
                    p.kernel[s][k][0] ? p.kernel[s][k] : "?");
    }
    fprintf(out, "rival: native packets 4/8/16: %s/%s/%s (rtcGetDeviceProperty), ray "
                 "streams: %s\n",
            g_native[0] ? "yes" : "no", g_native[1] ? "yes" : "no",
            g_native[2] ? "yes" : "no", g_stream ? "yes" : "no");
    fflush(out);
    if (!isa[0]) {
        fprintf(out, "rival: Embree's verbose report did not name its kernels\n");
        return -1;
    }
    return 0;
}

/* ---- APIs ---------------------------------------------------------------------- */

size_t rival_apis(rival_work work, rival_api *out) {
    probe_properties();
    /* The coherent hint selects Embree's frustum-style walk of a packet or
     * stream: it wins on camera tiles and on a point's samples toward a
     * small light, and loses on hemisphere and random rays (measured: AO any
     * hit 0.45-0.75x the same API without it on haus, 2CylinderEngine and
     * the 1.09M scene), so those get the incoherent calls only. */
    const int coherent = work == RIVAL_WORK_CAMERA || work == RIVAL_WORK_SHADOW;
    const int plain = work != RIVAL_WORK_CAMERA;
    static const int widths[3] = {RIVAL_STREAM, 8, 16};
    const int have[3] = {g_stream, g_native[1], g_native[2]};
    size_t n = 0;
    out[n++] = (rival_api){1, 0};
    for (int k = 0; k < 3; k++) {
        if (!have[k])
            continue;
        if (plain)
            out[n++] = (rival_api){widths[k], 0};
        if (coherent)
            out[n++] = (rival_api){widths[k], 1};
    }
    return n;
}

void rival_api_name(const rival *r, rival_api api, kdr_query q, char *buf,
                    size_t len) {
    char w[8];
    if (api.width == RIVAL_STREAM)
        snprintf(w, sizeof w, "1M");
    else
        snprintf(w, sizeof w, "%d", api.width);
    snprintf(buf, len, "embree_%srtc%s%s%s", r && r->robust ? "robust_" : "",
             q == KDR_ANY ? "Occluded" : "Intersect", w,
             api.coherent ? "_coherent" : "");
}
