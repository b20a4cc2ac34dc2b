/*
 * bench_rival_mem.c — is the rival at its best on memory? (issue 11's
 * fairness check.) Builds Embree's scene the way the benchmarks do
 * (tests/support/oracle.c: rtcSetNewGeometryBuffer, one thread, fast mode
 * or --robust), then prints how much of the process is in transparent huge
 * pages, whether the vertex and index buffers are (smaps of their
 * mappings), and how much of those buffers random rays actually read:
 * the kernel's referenced bits are cleared (/proc/self/clear_refs) before
 * the rays and read after. A buffer no traversal reads cannot gain from
 * huge pages. Prints only.
 *
 *   kdray-bench-rival-mem SCENE.glb [--robust]
 */
#define _GNU_SOURCE
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_gltf.h"
#include "oracle.h"
#include "test_util.h"
#include "thp_smaps.h"

static uint64_t rng = 0x9e3779b97f4a7c15ull;
static float rnd(float lo, float hi) {
    return lo + (hi - lo) * (float)(xorshift64(&rng) >> 40) * 0x1p-24f;
}

int main(int argc, char **argv) {
    if (argc < 2 || strcmp(argv[1], "--help") == 0) {
        fprintf(stderr, "usage: %s SCENE.glb [--robust]\n", argv[0]);
        return argc < 2 ? 2 : 0;
    }
    const int robust = argc > 2 && strcmp(argv[2], "--robust") == 0;
    kdr_gltf_scene g;
    char err[512];
    if (kdr_gltf_load(argv[1], &g, err, sizeof err) != 0) {
        fprintf(stderr, "%s: %s\n", argv[1], err);
        return 1;
    }
    const long before = thp_smaps_kb(NULL, "AnonHugePages");
    oracle_opts oo;
    oracle_opts_default(&oo);
    oo.robust = robust;
    oo.device_config = "threads=1";
    oracle *o = oracle_create(g.tris, g.ntris, &oo);
    if (!o) return 1;
    RTCGeometry geo = rtcGetGeometry(oracle_rtc_scene(o), 0);
    const void *buf[2] = {rtcGetGeometryBufferData(geo, RTC_BUFFER_TYPE_VERTEX, 0),
                          rtcGetGeometryBufferData(geo, RTC_BUFFER_TYPE_INDEX, 0)};
    const char *name[2] = {"vertex", "index"};
    printf("%s: %zu triangles, Embree %s mode, %.1f MB allocated by Embree\n", argv[1],
           g.ntris, robust ? "robust" : "fast", (double)oracle_bytes(o) / 1e6);
    printf("  process AnonHugePages: %ld kB before Embree's build, %ld kB after\n", before,
           thp_smaps_kb(NULL, "AnonHugePages"));
    for (int i = 0; i < 2; i++)
        printf("  %-6s buffer at %p, its mapping: Rss %ld kB, AnonHugePages %ld kB\n", name[i], buf[i],
               thp_smaps_kb(buf[i], "Rss"), thp_smaps_kb(buf[i], "AnonHugePages"));
    FILE *c = fopen("/proc/self/clear_refs", "w");
    if (!c || fputs("1", c) < 0 || fclose(c) != 0) {
        perror("/proc/self/clear_refs");
        return 1;
    }
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (size_t i = 0; i < 3 * g.ntris; i++)
        for (int k = 0; k < 3; k++) {
            const float x = g.tris[3 * i + k];
            lo[k] = x < lo[k] ? x : lo[k];
            hi[k] = x > hi[k] ? x : hi[k];
        }
    const int nrays = 200000;
    long hits = 0;
    for (int i = 0; i < nrays; i++) {
        kdr_ray r = {{rnd(lo[0], hi[0]), rnd(lo[1], hi[1]), rnd(lo[2], hi[2])},
                     {rnd(-1, 1), rnd(-1, 1), rnd(-1, 1)}, 0, 1e30f};
        kdr_hit h;
        hits += oracle_intersect1(o, &r, &h) + oracle_occluded1(o, &r);
    }
    printf("  after %d random rays (closest and any-hit, %ld hits), referenced in:\n", nrays,
           hits);
    for (int i = 0; i < 2; i++)
        printf("  the %-6s buffer's mapping: %ld of %ld kB\n", name[i], thp_smaps_kb(buf[i], "Referenced"),
               thp_smaps_kb(buf[i], "Rss"));
    oracle_free(o);
    kdr_gltf_free(&g);
    return 0;
}
