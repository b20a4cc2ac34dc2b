/*
 * kdr_float.c — float32 to the shortest JSON number that reads back as the
 * same float (kdr_format_float). Answers carry millions of floats, so this
 * runs at the speed of a shortest-round-trip printer: the digits come from
 * Dragonbox (kdr_float_shortest.cpp, Debian libdragonbox-dev), the layout
 * (sign, plain notation for decimal points in [-4, 12], else 1.5e-7) is
 * done here. Until commit 9466b74 this file had its own binary-search
 * printer, now tests/support/old_codecs.c, the reference the Dragonbox
 * output is checked against (same digits wherever that printer found the
 * shortest, never longer; tests/test_codecs.c).
 *
 * Shortest is not quite enough: most JSON readers (ours in kdr_json_fast.c,
 * Python's json) parse a number into the nearest double and only then round
 * to float32. A decimal that lies within half a double ulp of the midpoint
 * between two floats reads back as the wrong float that way, though strtof
 * reads it right. Each decimal is therefore checked through the double
 * path too (one multiply or divide), and the rare one that fails is
 * replaced by the shortest longer decimal that passes both ways.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "kdr_proto_internal.h"

/* Plain notation for decimal-point positions in [MIN, MAX], else 1.5e-7. */
#define KDR_FLOAT_PLAIN_MIN (-4)
#define KDR_FLOAT_PLAIN_MAX 12

/* kdr_float_shortest.cpp: x finite and > 0 -> digits (no trailing zeros,
 * at most 9) and exponent, digits * 10^exp10 reading back as x. */
void kdr_float_shortest(float x, uint32_t *digits, int *exp10);

static const double exact_pow10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                       1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                       1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

/* c * 10^q as the correctly rounded double: one rounding when 10^|q| is
 * exact in double (Clinger), strtod otherwise. */
static double decimal_to_double(uint32_t c, int q) {
    if (q >= 0 && q <= 22)
        return (double)c * exact_pow10[q];
    if (q < 0 && q >= -22)
        return (double)c / exact_pow10[-q];
    char tmp[32];
    snprintf(tmp, sizeof tmp, "%ue%d", (unsigned)c, q);
    return strtod(tmp, NULL);
}

/* The shortest decimal of at least ndig digits that reads back as x both
 * through strtof and through a double (the fallback of kdr_format_float;
 * 9 digits always do: they lie within 5e-9 relative of x, the float's
 * rounding interval is at least 3e-8 wide on either side). */
static void safe_digits(float x, int ndig, uint32_t *c, int *q) {
    for (int p = ndig; p <= 9; p++) {
        char tmp[32], *e;
        snprintf(tmp, sizeof tmp, "%.*e", p - 1, (double)x);
        if (strtof(tmp, NULL) != x || (float)strtod(tmp, NULL) != x)
            continue;
        uint32_t digits = 0;
        for (const char *s = tmp; *s && *s != 'e'; s++)
            if (*s >= '0' && *s <= '9')
                digits = digits * 10 + (uint32_t)(*s - '0');
        e = strchr(tmp, 'e');
        *q = atoi(e + 1) - (p - 1);
        while (digits % 10 == 0 && digits) {
            digits /= 10;
            ++*q;
        }
        *c = digits;
        return;
    }
}

/* Two digits at a time: "00".."99". */
static const char digit_pairs[201] =
    "00010203040506070809101112131415161718192021222324252627282930313233343536373839"
    "40414243444546474849505152535455565758596061626364656667686970717273747576777879"
    "8081828384858687888990919293949596979899";

/* The number of decimal digits of c (1..10). */
static int digit_count(uint32_t c) {
    int n = 1;
    while (n < 10 && c >= (uint32_t)exact_pow10[n])
        n++;
    return n;
}

/* The n digits of c into dst[0..n), two at a time from the right. */
static void put_digits(uint32_t c, int n, char *dst) {
    char *p = dst + n;
    while (c >= 100) {
        const uint32_t r = c % 100;
        c /= 100;
        p -= 2;
        memcpy(p, digit_pairs + 2 * r, 2);
    }
    if (c >= 10)
        memcpy(p - 2, digit_pairs + 2 * c, 2);
    else
        p[-1] = (char)('0' + c);
}

static char *put_exponent(char *p, int e) {
    *p++ = 'e';
    if (e < 0) {
        *p++ = '-';
        e = -e;
    }
    if (e >= 10)
        *p++ = (char)('0' + e / 10);
    *p++ = (char)('0' + e % 10);
    return p;
}

/* Lays out c * 10^q (c: n <= 9 digits, no trailing zeros) in plain or
 * scientific notation at p, returns the end. Every copy has a fixed size
 * (a few moves, never a memcpy call): dig holds the digits zero-padded,
 * and the text fits in 16 bytes, so the over-long copies stay in the
 * caller's 40-byte buffer. */
static char *layout(uint32_t c, int q, char *p) {
    char dig[16] = {0};
    const int n = digit_count(c);
    put_digits(c, n, dig);
    const int point = n + q; /* digits before the decimal point */
    if (point > KDR_FLOAT_PLAIN_MAX || point < KDR_FLOAT_PLAIN_MIN) {
        p[0] = dig[0];
        p[1] = '.';
        memcpy(p + 2, dig + 1, 8);
        p += n > 1 ? n + 1 : 1;
        return put_exponent(p, point - 1);
    }
    if (point <= 0) { /* 0.000ddd */
        memcpy(p, "0.0000", 6);
        p += 2 - point;
        memcpy(p, dig, 16);
        return p + n;
    }
    memcpy(p, dig, 16);
    if (q >= 0) { /* ddd000 */
        memcpy(p + n, "000000000000", 12);
        return p + n + q;
    }
    p[point] = '.'; /* ddd.ddd */
    memcpy(p + point + 1, dig + point, 8);
    return p + n + 1;
}

/* The text is made in a local buffer and copied out with one fixed-size
 * copy of KDR_FLOAT_CHARS bytes (the most the contract lets us write). */
size_t kdr_format_float(float f, char *dst) {
    char buf[40];
    char *p = buf;
    if (!isfinite(f)) {
        memcpy(dst, "null", 4);
        return 4;
    }
    if (signbit(f)) {
        *p++ = '-';
        f = -f;
    }
    if (f == 0.0f) {
        *p++ = '0';
    } else {
        uint32_t c;
        int q;
        kdr_float_shortest(f, &c, &q);
        if ((float)decimal_to_double(c, q) != f)
            safe_digits(f, digit_count(c) + 1, &c, &q);
        p = layout(c, q, p);
    }
    memcpy(dst, buf, KDR_FLOAT_CHARS);
    return (size_t)(p - buf);
}
