/*
 * log.c — timestamped single-line logging for kdrayd. A line is formatted
 * into a stack buffer first so that one write() emits it whole; a line too
 * long for the buffer is cut rather than split. The level is one atomic
 * read per call, so a debug line costs nothing when debug is off.
 */
#define _POSIX_C_SOURCE 200809L
#include "log.h"

#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>

enum { LOG_LINE_MAX = 1024 };

static atomic_int log_level = KDR_LOG_INFO;

static const char *const LEVEL_NAMES[] = {"error", "warn", "info", "debug"};
static const char *const LEVEL_PREFIX[] = {"error: ", "warning: ", "", "debug: "};

int kdr_log_parse_level(const char *name) {
    for (int i = 0; i < 4; i++)
        if (!strcasecmp(name, LEVEL_NAMES[i])) return i;
    return -1;
}

void kdr_log_set_level(kdr_log_level level) { atomic_store(&log_level, (int)level); }

int kdr_log_enabled(kdr_log_level level) {
    return (int)level <= atomic_load_explicit(&log_level, memory_order_relaxed);
}

unsigned long kdr_log_timestamp(char *buf, unsigned long size) {
    struct timespec ts;
    struct tm tm;
    clock_gettime(CLOCK_REALTIME, &ts);
    gmtime_r(&ts.tv_sec, &tm);
    size_t n = strftime(buf, size, "%Y-%m-%dT%H:%M:%S", &tm);
    int m = snprintf(buf + n, size - n, ".%03ldZ", ts.tv_nsec / 1000000L);
    return (unsigned long)(n + (m > 0 ? (size_t)m : 0));
}

void kdr_logl(kdr_log_level level, const char *fmt, ...) {
    if (!kdr_log_enabled(level)) return;
    char line[LOG_LINE_MAX];
    size_t n = kdr_log_timestamp(line, sizeof line);
    n += (size_t)snprintf(line + n, sizeof line - n, " kdrayd: %s", LEVEL_PREFIX[level]);
    va_list ap;
    va_start(ap, fmt);
    int m = vsnprintf(line + n, sizeof line - n - 1, fmt, ap);
    va_end(ap);
    if (m < 0) m = 0;
    n += (size_t)m < sizeof line - n - 1 ? (size_t)m : sizeof line - n - 2;
    line[n++] = '\n';
    ssize_t w = write(STDERR_FILENO, line, n);
    (void)w; /* nowhere left to report a failing stderr */
}

double kdr_now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}
