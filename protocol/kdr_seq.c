/*
 * kdr_seq.c — the items of a streamed answer (application/cbor-seq, RFC
 * 8742: CBOR items one after another, no framing): a head, one item per
 * chunk of the answer, and a final item that says whether the answer is
 * whole (status 200) or why it stopped (the problem details). A chunk item
 * is the one-shot CBOR answer of its rays (kdr_response.c, same member
 * names and typed arrays) with a "first" member put in front, so a client
 * decodes both the same way. docs/API.md has the format.
 */
#include <string.h>

#include "kdr_proto_internal.h"

int kdr_proto_seq_head(kdr_buf *out, const char *kind, size_t count, size_t items) {
    return kdr_cbor_map(out, 3) || kdr_cbor_text(out, "kind") ||
           kdr_cbor_text(out, kind) || kdr_cbor_text(out, "count") ||
           kdr_cbor_uint(out, count) || kdr_cbor_text(out, "items") ||
           kdr_cbor_uint(out, items);
}

/* The entry count of the map head at s[0..n) and the head's length; -1 if
 * s does not start with a definite-length map head. */
static int map_head(const unsigned char *s, size_t n, uint64_t *entries, size_t *len) {
    if (n == 0 || (s[0] >> 5) != 5) return -1;
    const unsigned ai = s[0] & 31u;
    if (ai < 24) {
        *entries = ai;
        *len = 1;
        return 0;
    }
    if (ai > 27) return -1; /* indefinite or reserved */
    const size_t k = (size_t)1 << (ai - 24);
    if (n < 1 + k) return -1;
    uint64_t v = 0;
    for (size_t i = 0; i < k; i++)
        v = v << 8 | s[1 + i];
    *entries = v;
    *len = 1 + k;
    return 0;
}

int kdr_proto_seq_item(kdr_buf *out, size_t first, const kdr_buf *slice) {
    uint64_t entries;
    size_t head;
    if (!slice ||
        map_head((const unsigned char *)slice->data, slice->len, &entries, &head) != 0)
        return KDR_EINVAL;
    if (kdr_buf_reserve(out, slice->len + 32) || kdr_cbor_map(out, entries + 1) ||
        kdr_cbor_text(out, "first") || kdr_cbor_uint(out, first))
        return KDR_ENOMEM;
    return kdr_buf_append(out, slice->data + head, slice->len - head);
}

int kdr_proto_seq_end(kdr_buf *out, uint64_t rays, size_t items,
                      const uint64_t timing_us[3], const kdr_shadow_stats *stats) {
    if (kdr_cbor_map(out, stats ? 5 : 4) || kdr_cbor_text(out, "status") ||
        kdr_cbor_uint(out, 200) || kdr_cbor_text(out, "rays") ||
        kdr_cbor_uint(out, rays) || kdr_cbor_text(out, "items") ||
        kdr_cbor_uint(out, items) || kdr_cbor_text(out, "timing") ||
        kdr_cbor_map(out, 3) || kdr_cbor_text(out, "queue_us") ||
        kdr_cbor_uint(out, timing_us[0]) || kdr_cbor_text(out, "parse_us") ||
        kdr_cbor_uint(out, timing_us[1]) || kdr_cbor_text(out, "trace_us") ||
        kdr_cbor_uint(out, timing_us[2]))
        return KDR_ENOMEM;
    if (!stats) return 0;
    return kdr_cbor_text(out, "stats") || kdr_cbor_map(out, 3) ||
           kdr_cbor_text(out, "cones_decided") ||
           kdr_cbor_uint(out, stats->cones_decided) ||
           kdr_cbor_text(out, "rays_traced") || kdr_cbor_uint(out, stats->rays_traced) ||
           kdr_cbor_text(out, "nodes_visited") ||
           kdr_cbor_uint(out, stats->nodes_visited);
}

int kdr_proto_seq_problem(kdr_buf *out, int status, const char *detail) {
    return kdr_cbor_map(out, 4) || kdr_cbor_text(out, "type") ||
           kdr_cbor_text(out, "about:blank") || kdr_cbor_text(out, "title") ||
           kdr_cbor_text(out, kdr_proto_status_title(status)) ||
           kdr_cbor_text(out, "status") || kdr_cbor_uint(out, (uint64_t)status) ||
           kdr_cbor_text(out, "detail") || kdr_cbor_text(out, detail ? detail : "");
}
