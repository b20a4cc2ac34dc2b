/*
 * watch.h — the watcher: one thread that looks after queries whose
 * connection is suspended (libmicrohttpd does not look at a suspended
 * connection's socket). Every tick it asks each query whether its client
 * is still there, and lets the executor stop one that is past its deadline
 * while no worker is looking at it (kdr_query_watch).
 */
#ifndef KDR_SRV_WATCH_H
#define KDR_SRV_WATCH_H

#include "server.h"

/* Embedded in a request's state; owned by its connection. */
typedef struct kdr_watch_entry {
    int fd;               /* the client's socket */
    kdr_query_call *call; /* its query, started */
    int listed;           /* on the watcher's list (under its lock) */
    struct kdr_watch_entry *next, *prev;
} kdr_watch_entry;

typedef struct kdr_watcher kdr_watcher;

/* NULL on failure (errno set). */
kdr_watcher *kdr_watcher_start(void);
/* Joins the thread; nothing may be listed any more. NULL-safe. */
void kdr_watcher_stop(kdr_watcher *w);
/* Both idempotent. After kdr_watcher_remove returns, the watcher no longer
 * touches e: the entry (and its query) may be freed. */
void kdr_watcher_add(kdr_watcher *w, kdr_watch_entry *e);
void kdr_watcher_remove(kdr_watcher *w, kdr_watch_entry *e);

#endif
