/*
 * check.h — the failure counter and assertion macros every C test program
 * shares, so that a failed check reads the same in every test's output.
 *
 *   CHECK(cond, fmt, ...)  counts a failure and prints file:line, the
 *                          condition and a printf-style note saying which
 *                          case failed (the note is required: a bare
 *                          condition rarely says which input broke it);
 *   EXPECT(cond)           the same without a note, for table-like checks
 *                          whose condition already names the case;
 *   FAIL(fmt, ...)         counts a failure and prints only the note, for
 *                          tests that compare first and explain after;
 *   check_exit(name)       main's last line: prints "name: N failures" or
 *                          "name: all passed" and returns the exit status.
 *
 * Every failure is counted; only the first CHECK_PRINT_MAX (define it
 * before including this header to change it) are printed, so that a broken
 * loop over thousands of cases does not bury the first, telling one.
 * Header-only with a static counter: each test program is one translation
 * unit with its own count.
 */
#ifndef KDRAY_TESTS_CHECK_H
#define KDRAY_TESTS_CHECK_H

#include <stdio.h>

#ifndef CHECK_PRINT_MAX
#define CHECK_PRINT_MAX 50
#endif

static int failures;

#define CHECK(cond, ...)                                                             \
    do {                                                                             \
        if (!(cond) && ++failures <= CHECK_PRINT_MAX) {                              \
            fprintf(stderr, "%s:%d: CHECK(%s) failed: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                            \
            fputc('\n', stderr);                                                     \
        }                                                                            \
    } while (0)

#define EXPECT(cond)                                                                 \
    do {                                                                             \
        if (!(cond) && ++failures <= CHECK_PRINT_MAX)                                \
            fprintf(stderr, "%s:%d: EXPECT(%s) failed\n", __FILE__, __LINE__, #cond); \
    } while (0)

#define FAIL(...)                                                                    \
    do {                                                                             \
        if (++failures <= CHECK_PRINT_MAX)                                           \
            fprintf(stderr, __VA_ARGS__);                                            \
    } while (0)

/* The exit status of a test program: 0 only when no check failed. */
static inline int check_exit(const char *name) {
    if (failures) {
        fprintf(stderr, "%s: %d failures\n", name, failures);
        return 1;
    }
    printf("%s: all passed\n", name);
    return 0;
}

#endif
