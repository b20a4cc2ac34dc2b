/*
 * log.h — the daemon's log: one line per event on stderr, each prefixed with
 * a UTC timestamp, written with a single write() so lines from different
 * threads never interleave. Lines below the level set by --log-level are
 * not formatted at all. Errors and warnings say so in the line ("error: ",
 * "warning: "), so a grep needs no knowledge of levels.
 */
#ifndef KDR_SRV_LOG_H
#define KDR_SRV_LOG_H

#if defined(__GNUC__)
#define KDR_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define KDR_PRINTF(a, b)
#endif

typedef enum kdr_log_level {
    KDR_LOG_ERROR, /* the daemon cannot do something it was asked to */
    KDR_LOG_WARN,  /* it coped, but an operator should know */
    KDR_LOG_INFO,  /* start-up, scenes, reloads, shutdown (the default) */
    KDR_LOG_DEBUG, /* per-request decisions: refusals, deadlines, hang-ups */
} kdr_log_level;

/* "error", "warn", "info", "debug" -> level; -1 if none matches. */
int kdr_log_parse_level(const char *name);
void kdr_log_set_level(kdr_log_level level);
int kdr_log_enabled(kdr_log_level level);

void kdr_logl(kdr_log_level level, const char *fmt, ...) KDR_PRINTF(2, 3);
#define kdr_log(...) kdr_logl(KDR_LOG_INFO, __VA_ARGS__)
#define kdr_log_error(...) kdr_logl(KDR_LOG_ERROR, __VA_ARGS__)
#define kdr_log_warn(...) kdr_logl(KDR_LOG_WARN, __VA_ARGS__)
#define kdr_log_debug(...) kdr_logl(KDR_LOG_DEBUG, __VA_ARGS__)

/* Monotonic clock in seconds, for durations. */
double kdr_now(void);

/* "2026-01-31T12:00:00.123Z" for the current time into buf (>= 25 bytes);
 * returns its length. */
unsigned long kdr_log_timestamp(char *buf, unsigned long size);

#endif
