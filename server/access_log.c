/*
 * access_log.c — the access log's file handling and line format (see
 * access_log.h). Rotation swaps the file behind the descriptor with dup2(),
 * which is atomic for concurrent writers: a line goes wholly to the old file
 * or wholly to the new one, and no writer ever sees a closed descriptor.
 */
#define _POSIX_C_SOURCE 200809L
#include "access_log.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "log.h"

enum { LINE_MAX_BYTES = 2048, PATH_MAX_SHOWN = 1024 };

static int open_file(const char *path) {
    return open(path, O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0640);
}

int kdr_access_log_open(kdr_access_log *a, const char *path) {
    a->path = path;
    a->fd = strcmp(path, "-") ? open_file(path) : STDOUT_FILENO;
    return a->fd < 0 ? -1 : 0;
}

int kdr_access_log_reopen(kdr_access_log *a) {
    if (a->fd < 0 || a->fd == STDOUT_FILENO) return 0;
    int fd = open_file(a->path);
    if (fd < 0) return -1;
    int rc = dup2(fd, a->fd) < 0 ? -1 : 0;
    int saved = errno;
    close(fd);
    errno = saved;
    return rc;
}

void kdr_access_log_close(kdr_access_log *a) {
    if (a->fd > STDERR_FILENO) close(a->fd);
    a->fd = -1;
}

/* Copies s into dst (at most max bytes of s), %XX-escaping what would
 * break the line into fields. Returns the bytes written (room >= 3*max+1). */
static size_t escaped(char *dst, const char *s, size_t max) {
    static const char hex[] = "0123456789ABCDEF";
    size_t n = 0;
    for (size_t i = 0; s && s[i] && i < max; i++) {
        unsigned char c = (unsigned char)s[i];
        if (c <= 0x20 || c >= 0x7f || c == '%' || c == '"') {
            dst[n++] = '%';
            dst[n++] = hex[c >> 4];
            dst[n++] = hex[c & 15];
        } else {
            dst[n++] = (char)c;
        }
    }
    if (n == 0) dst[n++] = '-';
    dst[n] = '\0';
    return n;
}

void kdr_access_log_write(const kdr_access_log *a, const kdr_access_entry *e) {
    if (a->fd < 0) return;
    char line[LINE_MAX_BYTES + 3 * PATH_MAX_SHOWN], method[3 * 16 + 1],
        path[3 * PATH_MAX_SHOWN + 1];
    size_t n = kdr_log_timestamp(line, sizeof line);
    escaped(method, e->method, 16);
    escaped(path, e->path, PATH_MAX_SHOWN);
    int m = snprintf(line + n, sizeof line - n, " %s %s %s %u %llu %llu %llu %.3f\n",
                     e->client && *e->client ? e->client : "-", method, path, e->status,
                     (unsigned long long)e->rays, (unsigned long long)e->bytes_in,
                     (unsigned long long)e->bytes_out, e->ms);
    if (m < 0) return;
    n += (size_t)m < sizeof line - n ? (size_t)m : sizeof line - n - 1;
    ssize_t w = write(a->fd, line, n);
    (void)w; /* a full disk must not stop the service; nothing to report to */
}
