/*
 * kdr_base64.c — RFC 4648 base64 (standard alphabet, '=' padding), the
 * binary fast path of the protocol. Table-driven, one 4-character group at
 * a time; the decoder is strict so that a corrupted body is an error naming
 * the offset rather than a silently different array of floats.
 */
#include "kdr_proto_internal.h"

static const char b64_alphabet[64] =
    "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/* 0..63 for alphabet characters, 0xFF for everything else (incl. '='). */
#define X 0xFF
static const unsigned char b64_value[256] = {
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  62, X,  X,  X,  63,
    52, 53, 54, 55, 56, 57, 58, 59, 60, 61, X,  X,  X,  X,  X,  X,
    X,  0,  1,  2,  3,  4,  5,  6,  7,  8,  9,  10, 11, 12, 13, 14,
    15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, X,  X,  X,  X,  X,
    X,  26, 27, 28, 29, 30, 31, 32, 33, 34, 35, 36, 37, 38, 39, 40,
    41, 42, 43, 44, 45, 46, 47, 48, 49, 50, 51, X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
    X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,  X,
};
#undef X

size_t kdr_base64_encoded_len(size_t n) { return (n + 2) / 3 * 4; }

size_t kdr_base64_decoded_max(size_t n) { return n / 4 * 3; }

size_t kdr_base64_encode(const void *src, size_t n, char *dst) {
    const unsigned char *s = src;
    char *d = dst;
    size_t i = 0;
    for (; i + 3 <= n; i += 3, d += 4) {
        uint32_t v = (uint32_t)s[i] << 16 | (uint32_t)s[i + 1] << 8 | s[i + 2];
        d[0] = b64_alphabet[v >> 18];
        d[1] = b64_alphabet[(v >> 12) & 63];
        d[2] = b64_alphabet[(v >> 6) & 63];
        d[3] = b64_alphabet[v & 63];
    }
    if (i < n) {
        uint32_t v = (uint32_t)s[i] << 16;
        if (i + 1 < n)
            v |= (uint32_t)s[i + 1] << 8;
        d[0] = b64_alphabet[v >> 18];
        d[1] = b64_alphabet[(v >> 12) & 63];
        d[2] = i + 1 < n ? b64_alphabet[(v >> 6) & 63] : '=';
        d[3] = '=';
        d += 4;
    }
    return (size_t)(d - dst);
}

/* The first character of group g (4 chars at src) that is not valid there;
 * -1 if the group is a valid final group (padding allowed). */
static int bad_in_last_group(const unsigned char *g, size_t *nbytes) {
    unsigned char v[4];
    for (int k = 0; k < 4; k++)
        v[k] = b64_value[g[k]];
    if (v[0] == 0xFF) return 0;
    if (v[1] == 0xFF) return 1;
    if (g[2] == '=') {
        if (g[3] != '=') return 3;
        if (v[1] & 15) return 1; /* bits that no byte uses must be zero */
        *nbytes = 1;
        return -1;
    }
    if (v[2] == 0xFF) return 2;
    if (g[3] == '=') {
        if (v[2] & 3) return 2;
        *nbytes = 2;
        return -1;
    }
    if (v[3] == 0xFF) return 3;
    *nbytes = 3;
    return -1;
}

int kdr_base64_decode(const char *src, size_t n, void *dst, size_t *out_len,
                      size_t *err_offset) {
    const unsigned char *s = (const unsigned char *)src;
    unsigned char *d = dst;
    *out_len = 0;
    if (n % 4) {
        /* the input stops in the middle of a group: report its end */
        *err_offset = n;
        return -1;
    }
    size_t full = n ? n - 4 : 0; /* the last group may carry padding */
    size_t i = 0;
    for (; i < full; i += 4, d += 3) {
        uint32_t a = b64_value[s[i]], b = b64_value[s[i + 1]];
        uint32_t c = b64_value[s[i + 2]], e = b64_value[s[i + 3]];
        if ((a | b | c | e) & 0x80) {
            size_t k = a & 0x80 ? 0 : b & 0x80 ? 1 : c & 0x80 ? 2 : 3;
            *err_offset = i + k;
            return -1;
        }
        uint32_t v = a << 18 | b << 12 | c << 6 | e;
        d[0] = (unsigned char)(v >> 16);
        d[1] = (unsigned char)(v >> 8);
        d[2] = (unsigned char)v;
    }
    if (n) {
        size_t nbytes = 0;
        int bad = bad_in_last_group(s + i, &nbytes);
        if (bad >= 0) {
            *err_offset = i + (size_t)bad;
            return -1;
        }
        uint32_t v = (uint32_t)b64_value[s[i]] << 18 | (uint32_t)b64_value[s[i + 1]] << 12;
        if (nbytes > 1) v |= (uint32_t)b64_value[s[i + 2]] << 6;
        if (nbytes > 2) v |= b64_value[s[i + 3]];
        d[0] = (unsigned char)(v >> 16);
        if (nbytes > 1) d[1] = (unsigned char)(v >> 8);
        if (nbytes > 2) d[2] = (unsigned char)v;
        d += nbytes;
    }
    *out_len = (size_t)(d - (unsigned char *)dst);
    return 0;
}
