/*
 * log.h — the daemon's log: one line per event on stderr, each prefixed with
 * a UTC timestamp, written with a single write() so lines from different
 * threads never interleave.
 */
#ifndef KDR_SRV_LOG_H
#define KDR_SRV_LOG_H

#if defined(__GNUC__)
#define KDR_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define KDR_PRINTF(a, b)
#endif

void kdr_log(const char *fmt, ...) KDR_PRINTF(1, 2);

/* Monotonic clock in seconds, for durations. */
double kdr_now(void);

#endif
