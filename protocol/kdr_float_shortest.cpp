/*
 * kdr_float_shortest.cpp — the one C++ file of protocol/: the shortest
 * decimal of a float32 from Dragonbox (Debian libdragonbox-dev, Junekey
 * Jeon's algorithm: the shortest digit string that reads back exactly under
 * round-to-nearest-even, the one nearest the float when several are
 * shortest), behind a C function. kdr_float.c does the rest (sign, zero,
 * null, plain or exponent notation). Dragonbox is noexcept and allocates
 * nothing, so nothing can escape this boundary.
 */
#include <cstdint>

#include <dragonbox/dragonbox.h>

extern "C" void kdr_float_shortest(float x, uint32_t *digits, int *exp10);

/* x finite and > 0: x reads back from digits * 10^exp10, with digits
 * holding no trailing zeros (at most 9 digits). */
extern "C" void kdr_float_shortest(float x, uint32_t *digits, int *exp10) {
    const auto d = jkj::dragonbox::to_decimal(x, jkj::dragonbox::policy::sign::ignore);
    *digits = d.significand;
    *exp10 = d.exponent;
}
