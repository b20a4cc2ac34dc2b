/*
 * old_codecs.c — the protocol's scalar codecs as they were at commit
 * 9466b74 (table-driven base64, binary-search shortest float printer),
 * kept verbatim apart from names as the reference the new SIMD base64 and
 * the Dragonbox-based printer are property-tested against
 * (tests/test_codecs.c). Not linked into the product.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "old_codecs.h"


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

size_t old_base64_encode(const void *src, size_t n, char *dst) {
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

int old_base64_decode(const char *src, size_t n, void *dst, size_t *out_len,
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



/* Acceptance margin, relative to the candidate: doubles carry 2^-53, the
 * check makes at most three roundings. */
#define KDR_FLOAT_MARGIN 0x1p-44
/* Plain notation for decimal-point positions in [MIN, MAX], else 1.5e-7. */
#define KDR_FLOAT_PLAIN_MIN (-4)
#define KDR_FLOAT_PLAIN_MAX 12
#define KDR_POW10_BIAS 64

static const double pow10_tab[2 * KDR_POW10_BIAS + 1] = {
    1e-64, 1e-63, 1e-62, 1e-61, 1e-60, 1e-59, 1e-58, 1e-57,
    1e-56, 1e-55, 1e-54, 1e-53, 1e-52, 1e-51, 1e-50, 1e-49,
    1e-48, 1e-47, 1e-46, 1e-45, 1e-44, 1e-43, 1e-42, 1e-41,
    1e-40, 1e-39, 1e-38, 1e-37, 1e-36, 1e-35, 1e-34, 1e-33,
    1e-32, 1e-31, 1e-30, 1e-29, 1e-28, 1e-27, 1e-26, 1e-25,
    1e-24, 1e-23, 1e-22, 1e-21, 1e-20, 1e-19, 1e-18, 1e-17,
    1e-16, 1e-15, 1e-14, 1e-13, 1e-12, 1e-11, 1e-10, 1e-9,
    1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1,
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7,
    1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
    1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22, 1e23,
    1e24, 1e25, 1e26, 1e27, 1e28, 1e29, 1e30, 1e31,
    1e32, 1e33, 1e34, 1e35, 1e36, 1e37, 1e38, 1e39,
    1e40, 1e41, 1e42, 1e43, 1e44, 1e45, 1e46, 1e47,
    1e48, 1e49, 1e50, 1e51, 1e52, 1e53, 1e54, 1e55,
    1e56, 1e57, 1e58, 1e59, 1e60, 1e61, 1e62, 1e63,
    1e64
};

static double pow10i(int k) { return pow10_tab[k + KDR_POW10_BIAS]; }

/* floor(log10(x)) for a positive finite float-valued double. */
static int decimal_exponent(double x) {
    uint64_t bits;
    memcpy(&bits, &x, 8);
    const int e2 = (int)(bits >> 52) - 1023; /* x in [2^e2, 2^(e2+1)) */
    /* e2 * log10(2), floored (arithmetic shift-free: e2 may be negative) */
    const double l = e2 * 0.30102999566398119521;
    int est = (int)l;
    if (est > l)
        est--;
    if (x >= pow10i(est + 1))
        est++;
    else if (x < pow10i(est))
        est--;
    return est;
}

/* Is c * 10^q strictly inside (lo, hi), safely? lo_s, hi_s are the bounds
 * already scaled by 10^-q. */
static int inside(double c, double lo_s, double hi_s) {
    const double m = c * KDR_FLOAT_MARGIN;
    return c > lo_s + m && c < hi_s - m;
}

/* Exact ties: a decimal on a rounding boundary reads back as x only when
 * x's mantissa is even (ties-to-even). Decidable exactly in double when
 * c * 10^q is an integer below 2^53, which is where short ties occur. */
static int exact_tie_ok(double c, int q, double lo, double hi, int even) {
    if (!even || q < 0 || q > 22)
        return 0;
    const double v = c * pow10i(q);
    return v < 0x1p53 && v >= lo && v <= hi;
}

/* The rounding interval of x as exact doubles, with its decimal exponent. */
typedef struct float_span {
    double x, lo, hi;
    int e10, even;
} float_span;

static void span_init(float x, float_span *sp) {
    uint32_t bits;
    memcpy(&bits, &x, 4);
    const int be = (int)(bits >> 23);
    /* 2^((be ? be : 1) - 150) built directly: ldexp is a libm call */
    const uint64_t ulp_bits = (uint64_t)((be ? be : 1) - 150 + 1023) << 52;
    double ulp;
    memcpy(&ulp, &ulp_bits, 8);
    sp->x = x;
    /* below a power of two the spacing halves */
    sp->lo = sp->x - ((bits & 0x7fffff) == 0 && be > 1 ? ulp / 4 : ulp / 2);
    sp->hi = sp->x + ulp / 2;
    sp->e10 = decimal_exponent(sp->x);
    sp->even = (bits & 1) == 0;
}

/* A p-digit decimal c * 10^q that reads back as x, or 0. */
static double try_digits(const float_span *sp, int p, int *q_out) {
    const int q = sp->e10 - p + 1;
    const double sc = pow10i(-q);
    const double s = sp->x * sc, lo_s = sp->lo * sc, hi_s = sp->hi * sc;
    /* s < 10^10 and > 0: truncation is floor, without a libm call */
    const double c0 = (double)(int64_t)s, c1 = c0 + 1.0;
    const int c1_first = c1 - s < s - c0;
    const double a = c1_first ? c1 : c0, b = c1_first ? c0 : c1;
    *q_out = q;
    if (inside(a, lo_s, hi_s)) return a;
    if (inside(b, lo_s, hi_s)) return b;
    if (exact_tie_ok(a, q, sp->lo, sp->hi, sp->even)) return a;
    if (exact_tie_ok(b, q, sp->lo, sp->hi, sp->even)) return b;
    return 0.0;
}

/* Shortest c, q with c * 10^q reading back as x (x > 0, finite float).
 * Binary search over the digit count: fitting is monotonic in p (a fitting
 * p-digit decimal is also a (p+1)-digit one, and the bracketing (p+1)-digit
 * decimals lie between it and x); where the safety margin breaks that, the
 * search can only end one digit long, never wrong. */
static int shortest(float x, uint64_t *c_out, int *q_out) {
    float_span sp;
    span_init(x, &sp);
    int lo = 1, hi = 9, found = 0;
    while (lo <= hi) {
        const int mid = (lo + hi) / 2;
        int q;
        const double c = try_digits(&sp, mid, &q);
        if (c > 0.0) {
            *c_out = (uint64_t)c;
            *q_out = q;
            found = 1;
            hi = mid - 1;
        } else {
            lo = mid + 1;
        }
    }
    return found;
}

/* Writes the digits of c (no leading zeros) to dst, returns their count. */
static int put_digits(uint64_t c, char *dst) {
    char tmp[24];
    int n = 0;
    do {
        tmp[n++] = (char)('0' + c % 10);
        c /= 10;
    } while (c);
    for (int i = 0; i < n; i++)
        dst[i] = tmp[n - 1 - i];
    return n;
}

static size_t put_exponent(char *p, int e) {
    char *s = p;
    *p++ = 'e';
    if (e < 0) {
        *p++ = '-';
        e = -e;
    }
    if (e >= 10)
        *p++ = (char)('0' + e / 10);
    *p++ = (char)('0' + e % 10);
    return (size_t)(p - s);
}

/* Lays out c * 10^q in plain or scientific notation. */
static size_t layout(uint64_t c, int q, char *p) {
    char dig[24] = {0}; /* initialised: gcc -fsanitize cannot see put_digits fill it */
    while (c % 10 == 0) {
        c /= 10;
        q++;
    }
    const int n = put_digits(c, dig);
    const int point = n + q; /* digits before the decimal point */
    char *s = p;
    if (point > KDR_FLOAT_PLAIN_MAX || point < KDR_FLOAT_PLAIN_MIN) {
        *p++ = dig[0];
        if (n > 1) {
            *p++ = '.';
            memcpy(p, dig + 1, (size_t)n - 1);
            p += n - 1;
        }
        return (size_t)(p - s) + put_exponent(p, point - 1);
    }
    if (point <= 0) {
        *p++ = '0';
        *p++ = '.';
        for (int i = 0; i < -point; i++)
            *p++ = '0';
        memcpy(p, dig, (size_t)n);
        return (size_t)(p + n - s);
    }
    if (q >= 0) {
        memcpy(p, dig, (size_t)n);
        p += n;
        for (int i = 0; i < q; i++)
            *p++ = '0';
        return (size_t)(p - s);
    }
    memcpy(p, dig, (size_t)point);
    p += point;
    *p++ = '.';
    memcpy(p, dig + point, (size_t)(n - point));
    return (size_t)(p + (n - point) - s);
}

size_t old_format_float(float f, char *dst) {
    if (!isfinite(f)) {
        memcpy(dst, "null", 4);
        return 4;
    }
    size_t neg = 0;
    if (signbit(f)) {
        dst[neg++] = '-';
        f = -f;
    }
    if (f == 0.0f) {
        dst[neg] = '0';
        return neg + 1;
    }
    uint64_t c;
    int q;
    if (shortest(f, &c, &q))
        return neg + layout(c, q, dst + neg);
    char tmp[32];
    int n = snprintf(tmp, sizeof tmp, "%.9g", (double)f);
    memcpy(dst + neg, tmp, (size_t)n);
    return neg + (size_t)n;
}
