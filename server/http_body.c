/*
 * http_body.c — a query's request body on its way in: its admission (a
 * query slot and the bytes of its announced Content-Length, charged to the
 * executor before anything is allocated), its accumulation under the size
 * limit (a chunked body's buffer grows by doubling, each step charged
 * first), and what happens to a body that is refused or too large: it is
 * read and thrown away, up to DRAIN_MAX, so that the client sees our answer
 * instead of a broken pipe.
 */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "http_internal.h"
#include "log.h"

/* A body past the limit, or refused, is drained (so the client reads our
 * answer) for at most this many bytes, then the connection is dropped. */
static const size_t DRAIN_MAX = 16u << 20;
/* Initial body buffer when the length is not announced. */
static const size_t BODY_MIN_CAP = 64 * 1024;

long long kdr_http_content_length(struct MHD_Connection *c) {
    const char *v =
        MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_CONTENT_LENGTH);
    if (!v || !*v) return -1;
    char *end;
    errno = 0;
    unsigned long long n = strtoull(v, &end, 10);
    if (errno || *end || n > (unsigned long long)LLONG_MAX) return -1;
    return (long long)n;
}

/* From now on the body is read and thrown away, and `answer` follows it. */
static void refuse(kdr_http *h, req_state *rs, kdr_response *answer) {
    rs->refusal = *answer;
    rs->refused = 1;
    free(rs->body);
    rs->body = NULL;
    rs->cap = 0;
    rs->dropped += rs->len;
    rs->len = 0;
    kdr_exec_release(h->srv->exec, &rs->claim); /* a drain needs no slot */
}

/* Grows the body buffer for n more bytes of a body of unknown length,
 * charging the claim before allocating. 0, or -1 after refuse(). */
static int grow(kdr_http *h, req_state *rs, size_t n) {
    size_t max = h->srv->max_body, cap = rs->cap ? rs->cap : BODY_MIN_CAP;
    while (cap < rs->len + n)
        cap *= 2;
    if (cap > max) cap = max;
    kdr_response no = {0};
    size_t more = kdr_exec_body_charge(cap) - kdr_exec_body_charge(rs->cap);
    kdr_admit a = kdr_exec_charge(h->srv->exec, &rs->claim, more);
    if (a != KDR_ADMIT_OK) {
        kdr_route_refusal(h->srv, a, more, &no);
    } else {
        char *p = realloc(rs->body, cap);
        if (p) {
            rs->body = p;
            rs->cap = cap;
            return 0;
        }
        kdr_route_problem(&no, 503, "out of memory for the request body");
        no.retry_after = 1;
    }
    no.ep = rs->ep;
    refuse(h, rs, &no);
    return -1;
}

/* Appends a piece of the body, or counts it as discarded once the body is
 * over the limit or refused. 0 to go on, -1 to drop the connection. */
int kdr_http_append(kdr_http *h, req_state *rs, const char *data, size_t n) {
    if (rs->refused || rs->dropped || rs->len + n > h->srv->max_body) {
        rs->dropped += n;
        return rs->dropped <= DRAIN_MAX ? 0 : -1;
    }
    if (rs->len + n > rs->cap && grow(h, rs, n) != 0) {
        rs->dropped += n;
        return rs->dropped <= DRAIN_MAX ? 0 : -1;
    }
    memcpy(rs->body + rs->len, data, n);
    rs->len += n;
    return 0;
}

/* An early answer is sent at once only when the client will not push a
 * body at us first (none announced, or Expect: 100-continue) or the body is
 * too big to drain; otherwise we read and discard the body and answer after
 * it, because MHD closes a connection whose body it has not read and a
 * client still writing would see a broken pipe instead of our answer. */
int kdr_http_answer_now(struct MHD_Connection *c, long long clen, size_t max_body) {
    const char *te = MHD_lookup_connection_value(c, MHD_HEADER_KIND,
                                                 MHD_HTTP_HEADER_TRANSFER_ENCODING);
    const char *ex =
        MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_EXPECT);
    if (ex && !strcasecmp(ex, "100-continue")) return 1;
    if (te) return 0; /* chunked: length unknown, drain up to the cap */
    return clen <= 0 || (unsigned long long)clen > max_body + DRAIN_MAX;
}

/* A query body's admission: a slot and the bytes of its announced length
 * (as the block it will be read into holds them: up to 2 MiB of whole huge
 * pages more, kdr_block_size), before anything is allocated for it. 0, or
 * 1 with rs->refusal set. */
int kdr_http_admit(kdr_http *h, req_state *rs, long long clen, const char *path) {
    const size_t len = clen > 0 ? (size_t)clen : 0;
    size_t need = len ? kdr_exec_body_charge(len) + (kdr_block_size(len) - len) : 0;
    kdr_admit a = kdr_exec_admit(h->srv->exec, &rs->claim, need);
    if (a != KDR_ADMIT_OK) {
        kdr_route_refusal(h->srv, a, need, &rs->refusal);
        kdr_log_debug("%s: %u %s", path, rs->refusal.status,
                      a == KDR_ADMIT_QUEUE_FULL  ? "queue full"
                      : a == KDR_ADMIT_TOO_LARGE ? "over the whole in-flight budget"
                      : a == KDR_ADMIT_STOPPED   ? "shutting down"
                                                 : "memory full");
        return 1;
    }
    if (clen > 0) {
        /* a large body's block faults in 2 MiB pages (kdr_block_alloc) */
        size_t usable = 0;
        rs->body = kdr_block_alloc(len, &usable);
        rs->cap = rs->body ? usable : 0; /* the query's body_held */
        if (!rs->body) {
            kdr_exec_release(h->srv->exec, &rs->claim);
            kdr_route_problem(&rs->refusal, 503, "out of memory for the request body");
            rs->refusal.retry_after = 1;
            return 1;
        }
    }
    return 0;
}
