/*
 * access_log.h — --access-log FILE|-: one line per answered request,
 *
 *   TIME CLIENT METHOD PATH STATUS RAYS BYTES_IN BYTES_OUT MS
 *   2026-01-31T12:00:00.123Z 127.0.0.1 POST /v1/scenes/default/bundle 200 10000 240211
 * 440017 12.345
 *
 * space-separated, so `awk '{print $5}'` is the status. PATH has spaces,
 * control bytes, '%' and non-ASCII bytes written as %XX. STATUS 499 means
 * the client hung up before its answer (as nginx logs it). RAYS is what the
 * query traced (bundle rays, frustum pixels, cone-shadow rays), 0 for the
 * other endpoints. MS is from the first byte to the last byte sent.
 * Each line is one write() on an O_APPEND descriptor, so lines never
 * interleave; SIGHUP reopens the file (log rotation).
 */
#ifndef KDR_SRV_ACCESS_LOG_H
#define KDR_SRV_ACCESS_LOG_H

#include <stdint.h>

typedef struct kdr_access_log {
    int fd;           /* -1: off */
    const char *path; /* "-": stdout */
} kdr_access_log;

typedef struct kdr_access_entry {
    const char *client, *method, *path;
    unsigned status;
    uint64_t rays, bytes_in, bytes_out;
    double ms;
} kdr_access_entry;

/* Opens path for appending (created 0640); 0, or -1 with errno. */
int kdr_access_log_open(kdr_access_log *a, const char *path);
/* Reopens the same path in place (the descriptor number stays): 0 or -1. */
int kdr_access_log_reopen(kdr_access_log *a);
void kdr_access_log_write(const kdr_access_log *a, const kdr_access_entry *e);
void kdr_access_log_close(kdr_access_log *a);

#endif
