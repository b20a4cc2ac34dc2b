/*
 * kdr_meter.c — what a parse allocates, counted before it is allocated.
 *
 * The fast paths keep a parse near the size of its body's float arrays, but
 * a body they cannot read goes to cJSON, whose 64-byte node per value costs
 * up to ~40 bytes of heap per body byte ("[1,1,1,..." in JSON; CBOR's
 * one-byte items are capped by the reader's node budget); no fixed multiple
 * of the body that a caller could charge up front covers that without
 * refusing most honest bodies. So every block a parse allocates, its own
 * arrays and cJSON's nodes and strings alike (through cJSON's allocation
 * hooks), is counted on the calling thread's meter, if it has one, BEFORE
 * it is allocated: a block that does not fit asks the meter's owner for
 * more room (the executor charges its in-flight budget) and fails, like
 * malloc, when refused. Frees are counted back, so the meter follows what
 * is live and its limit bounds the peak.
 *
 * Blocks are counted at their heap footprint (glibc's malloc_usable_size
 * plus its 8-byte header), checked beforehand against an upper bound of
 * that footprint; sizes need not be remembered, and cJSON's frees, which
 * carry no size, are counted back exactly.
 *
 * The same accounting tells an out-of-memory apart from a malformed body:
 * cJSON returns NULL for both, but every failed allocation on a thread is
 * counted here, so a parser that sees NULL can ask whether one failed.
 *
 * cJSON's hooks are process-wide; they are installed once, before main (a
 * constructor), while no other thread can be inside cJSON. They are malloc
 * and free with bookkeeping, so blocks of threads without a meter (the
 * scene loader) mix freely with the parsers'.
 */
#include <malloc.h>
#include <stdlib.h>

#include "kdr_proto_internal.h"

static _Thread_local kdr_proto_meter *thread_meter;
static _Thread_local unsigned long thread_failures;

kdr_proto_meter *kdr_proto_meter_set(kdr_proto_meter *m) {
    kdr_proto_meter *old = thread_meter;
    thread_meter = m;
    return old;
}

unsigned long kdr_pf_alloc_failures(void) { return thread_failures; }

/* The heap a block takes: what malloc_usable_size reports plus glibc's
 * 8-byte size header. */
static size_t footprint(void *p) { return p ? malloc_usable_size(p) + 8 : 0; }

/* An upper bound of footprint() for a block of n bytes, before it exists:
 * small blocks are rounded to 16 bytes with the header (32 at least),
 * large ones are pages (mmap) with a 16-byte header. */
static size_t bound(size_t n) {
    if (n > SIZE_MAX / 2) return SIZE_MAX;
    if (n < 65536) return n + 24 < 32 ? 32 : n + 24;
    return ((n + 16 + 4095) & ~(size_t)4095) + 16;
}

/* Room for a block of n bytes on the thread's meter (none: always). */
static int room(size_t n) {
    kdr_proto_meter *m = thread_meter;
    if (!m) return 1;
    const size_t need = bound(n);
    if (need <= m->limit && m->used <= m->limit - need) return 1;
    if (!m->refused && m->grow && m->grow(m->ctx, m, m->used + need - m->limit) == 0 &&
        need <= m->limit && m->used <= m->limit - need)
        return 1;
    m->refused = 1; /* once refused, every later block is too */
    return 0;
}

static void credit(void *p) {
    if (thread_meter) thread_meter->used += footprint(p);
}

static void debit(size_t bytes) {
    kdr_proto_meter *m = thread_meter;
    if (m) m->used = m->used > bytes ? m->used - bytes : 0;
}

void *kdr_pf_malloc(size_t n) {
    void *p = room(n) ? malloc(n ? n : 1) : NULL;
    if (!p) thread_failures++;
    credit(p);
    return p;
}

/* The old block stays counted until the new one exists: realloc may hold
 * both while it copies. */
void *kdr_pf_realloc(void *p, size_t n) {
    const size_t old = thread_meter ? footprint(p) : 0;
    void *q = room(n) ? realloc(p, n ? n : 1) : NULL;
    if (!q) {
        thread_failures++;
        return NULL;
    }
    credit(q);
    debit(old);
    return q;
}

void kdr_pf_free(void *p) {
    if (thread_meter) debit(footprint(p));
    free(p);
}

static void *cjson_malloc(size_t n) { return kdr_pf_malloc(n); }

__attribute__((constructor)) static void kdr_meter_install_hooks(void) {
    cJSON_Hooks hooks = {cjson_malloc, kdr_pf_free};
    cJSON_InitHooks(&hooks);
}
