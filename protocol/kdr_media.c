/*
 * kdr_media.c — which body formats a request speaks: the request's
 * Content-Type names its media type (application/json or application/cbor,
 * anything else is a 415), and its Accept header picks the answer's, by
 * the q-values of RFC 9110 section 12.5.1 (the most specific range that
 * matches a type gives its q). Plain string work, no allocation; the server
 * hands the header values over as they came.
 */
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "kdr_proto_internal.h"

static const char *const MEDIA_NAMES[3] = {"application/json", "application/cbor",
                                           "application/cbor-seq"};

static const char *skip_ws(const char *s) { return s + strspn(s, " \t"); }

/* Does s start with word (case-insensitively), followed by a delimiter? */
static int word_is(const char *s, size_t n, const char *word) {
    return n == strlen(word) && strncasecmp(s, word, n) == 0;
}

/* application/json, optionally with parameters; a charset must be UTF-8. */
static int json_params_ok(const char *p) {
    for (;;) {
        p = skip_ws(p);
        if (*p == '\0') return 1;
        if (*p++ != ';') return 0;
        p = skip_ws(p);
        if (!strncasecmp(p, "charset=", 8)) {
            const char *v = p + 8 + (p[8] == '"');
            size_t n = strcspn(v, "\"; \t");
            if (!(word_is(v, n, "utf-8") || word_is(v, n, "utf8"))) return 0;
        }
        p += strcspn(p, ";");
    }
}

kdr_media kdr_proto_media_of(const char *ct) {
    if (!ct) return KDR_MEDIA_OTHER;
    ct = skip_ws(ct);
    const size_t n = strcspn(ct, "; \t");
    if (word_is(ct, n, MEDIA_NAMES[KDR_MEDIA_JSON]))
        return json_params_ok(ct + n) ? KDR_MEDIA_JSON : KDR_MEDIA_OTHER;
    if (word_is(ct, n, MEDIA_NAMES[KDR_MEDIA_CBOR])) {
        const char *rest = skip_ws(ct + n);
        return *rest == '\0' || *rest == ';' ? KDR_MEDIA_CBOR : KDR_MEDIA_OTHER;
    }
    return KDR_MEDIA_OTHER;
}

/* The q parameter of one media range's parameters [p, end); 1 if absent,
 * -1 if malformed (the range is then ignored). In thousandths. */
static int range_q(const char *p, const char *end) {
    while (p < end) {
        p += strspn(p, " \t;");
        if (p < end && (*p == 'q' || *p == 'Q') && p + 1 < end && p[1] == '=') {
            char tmp[16];
            size_t n = strcspn(p + 2, "; \t,");
            if (n == 0 || n >= sizeof tmp || p + 2 + n > end) return -1;
            memcpy(tmp, p + 2, n);
            tmp[n] = '\0';
            char *stop;
            double q = strtod(tmp, &stop);
            if (*stop || !(q >= 0.0) || q > 1.0) return -1;
            return (int)(q * 1000.0 + 0.5);
        }
        p += strcspn(p, ";");
        if (p >= end) break;
    }
    return 1000;
}

kdr_media kdr_proto_answer_media(const char *accept, kdr_media request) {
    /* per media type: q of the most specific matching range so far */
    int q[2] = {-1, -1}, spec[2] = {0, 0};
    int qs = 0; /* application/cbor-seq, named exactly (a stream is opt-in) */
    if (!accept) return request;
    for (const char *p = accept; *p;) {
        const char *end = p + strcspn(p, ",");
        const char *r = skip_ws(p);
        const size_t n = strcspn(r, "; \t,");
        const int rq = range_q(r + n, end);
        if (rq > qs && word_is(r, n, MEDIA_NAMES[KDR_MEDIA_CBOR_SEQ])) qs = rq;
        for (int m = 0; m < 2 && rq >= 0; m++) {
            int s = 0; /* 3 exact, 2 application/STAR, 1 STAR/STAR */
            if (word_is(r, n, MEDIA_NAMES[m])) s = 3;
            else if (word_is(r, n, "application/*")) s = 2;
            else if (word_is(r, n, "*/*")) s = 1;
            if (s > spec[m]) {
                spec[m] = s;
                q[m] = rq;
            }
        }
        p = *end ? end + 1 : end;
    }
    const int qj = q[KDR_MEDIA_JSON] > 0 ? q[KDR_MEDIA_JSON] : 0;
    const int qc = q[KDR_MEDIA_CBOR] > 0 ? q[KDR_MEDIA_CBOR] : 0;
    if (qs > 0 && qs >= qj && qs >= qc) return KDR_MEDIA_CBOR_SEQ;
    if (qj == qc) return request;
    return qc > qj ? KDR_MEDIA_CBOR : KDR_MEDIA_JSON;
}

const char *kdr_proto_media_name(kdr_media m) {
    return m == KDR_MEDIA_CBOR || m == KDR_MEDIA_CBOR_SEQ ? MEDIA_NAMES[m]
                                                          : MEDIA_NAMES[KDR_MEDIA_JSON];
}

const char *kdr_proto_encoding_media(kdr_encoding enc) {
    return kdr_proto_media_name(enc == KDR_ENCODING_CBOR ? KDR_MEDIA_CBOR : KDR_MEDIA_JSON);
}
