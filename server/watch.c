/*
 * watch.c — the watcher thread (see watch.h). Its list is guarded by one
 * mutex, held while it walks the list: kdr_query_watch may finish a query
 * right there (cancelled, or past its deadline while queued), and that
 * query's on_done resumes its connection; the connection's thread then
 * takes the query off the list with kdr_watcher_remove, which waits for
 * the walk to end, so no entry is freed under the walker's feet.
 */
#define _POSIX_C_SOURCE 200809L
#include "watch.h"

#include <errno.h>
#include <pthread.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <time.h>

/* How often the clients of suspended queries are looked at. */
static const long TICK_MS = 20;

struct kdr_watcher {
    pthread_t thread;
    pthread_mutex_t lock;
    pthread_cond_t cv; /* an entry was added, or stop */
    kdr_watch_entry *head;
    int stop;
};

/* 1 once the client has closed its end (or the socket failed). A client
 * that only shut down its sending side looks the same: it is treated as
 * gone, as nginx does, since it can no longer send anything. */
static int fd_gone(int fd) {
    char b;
    if (fd < 0) return 0;
    ssize_t n = recv(fd, &b, 1, MSG_PEEK | MSG_DONTWAIT);
    return n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR);
}

static void *watch_main(void *arg) {
    kdr_watcher *w = arg;
    pthread_mutex_lock(&w->lock);
    while (!w->stop) {
        if (!w->head) {
            pthread_cond_wait(&w->cv, &w->lock);
            continue;
        }
        for (kdr_watch_entry *e = w->head; e; e = e->next)
            kdr_query_watch(e->call, fd_gone(e->fd));
        struct timespec ts;
        clock_gettime(CLOCK_MONOTONIC, &ts);
        ts.tv_nsec += TICK_MS * 1000000L;
        if (ts.tv_nsec >= 1000000000L) {
            ts.tv_sec++;
            ts.tv_nsec -= 1000000000L;
        }
        pthread_cond_timedwait(&w->cv, &w->lock, &ts);
    }
    pthread_mutex_unlock(&w->lock);
    return NULL;
}

kdr_watcher *kdr_watcher_start(void) {
    kdr_watcher *w = calloc(1, sizeof *w);
    if (!w) return NULL;
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&w->cv, &ca);
    pthread_condattr_destroy(&ca);
    pthread_mutex_init(&w->lock, NULL);
    int rc = pthread_create(&w->thread, NULL, watch_main, w);
    if (rc) {
        pthread_cond_destroy(&w->cv);
        pthread_mutex_destroy(&w->lock);
        free(w);
        errno = rc;
        return NULL;
    }
    return w;
}

void kdr_watcher_stop(kdr_watcher *w) {
    if (!w) return;
    pthread_mutex_lock(&w->lock);
    w->stop = 1;
    pthread_cond_signal(&w->cv);
    pthread_mutex_unlock(&w->lock);
    pthread_join(w->thread, NULL);
    pthread_cond_destroy(&w->cv);
    pthread_mutex_destroy(&w->lock);
    free(w);
}

void kdr_watcher_add(kdr_watcher *w, kdr_watch_entry *e) {
    pthread_mutex_lock(&w->lock);
    if (!e->listed) {
        e->prev = NULL;
        e->next = w->head;
        if (w->head) w->head->prev = e;
        w->head = e;
        e->listed = 1;
        pthread_cond_signal(&w->cv);
    }
    pthread_mutex_unlock(&w->lock);
}

void kdr_watcher_remove(kdr_watcher *w, kdr_watch_entry *e) {
    pthread_mutex_lock(&w->lock);
    if (e->listed) {
        if (e->prev)
            e->prev->next = e->next;
        else
            w->head = e->next;
        if (e->next) e->next->prev = e->prev;
        e->listed = 0;
    }
    pthread_mutex_unlock(&w->lock);
}
